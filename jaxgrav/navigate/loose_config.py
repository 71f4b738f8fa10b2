"""Settings of the loosely coupled loop (:func:`~jaxgrav.navigate.navigate_loose`).

:class:`LooseConfig` holds them; :func:`loose_config` builds them as the examples,
``jaxgrav navigate`` and ``jaxgrav montecarlo`` use them: for the dense matcher the
segment's own error told given its offset, the filter's prior on the offsets and the
lattice's cell told (:data:`DENSE_LOOP`), for the other matchers the Markov form.
"""

import math

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.match.correlation import ChainConfig
from jaxgrav.match.dense import DenseConfig
from jaxgrav.match.entropy import EntropyConfig
from jaxgrav.match.iccp_config import IccpConfig
from jaxgrav.navigate.loose_match import CHAIN_REACH_M, matcher_config
from jaxgrav.sim.ins import INSErrorModel

__all__ = ["DENSE_LOOP", "SEGMENT_ERRORS", "LooseConfig", "loose_config"]

SEGMENT_ERRORS = ("markov", "linear", "conditional")
"""How the loop tells a matcher the filter's own error (:attr:`LooseConfig.segment_error`)."""

DENSE_LOOP = {"segment_error": "conditional", "fix_prior": True, "n_fixes": 60, "stride": 30,
              "fix_cov_scale": 1.0, "cell_error": True, "first_n_fixes": None,
              "shape_update": True, "reacquire_after": 1, "reacquire_inflation": 16.0}
"""The dense matcher's loop settings of :func:`loose_config` (unless ``segment_error``
is ``"markov"``): 2 h segments every hour (the first fix after 2 h), the segment's
Eötvös and stretch errors told given its offset, the offsets weighed by the filter's
prior, the lattice's cell told, the fix covariance as the matcher gives it, and the
segment's readings updating the rest of the state given the fix (``shape_update``: on
1000 patrols with the 3 mGal map error told the last hour went from 0.121 / 0.128 to
0.099 / 0.083 of the free INS on seeds 0 / 1; on the perfect map from 0.058 / 0.077 to
0.160 / 0.075, a few fast-drifting voyages whose segments the linear model does not fit
left unaided, ``docs/voyages.md``), and a fix on the window's edge or not fitting the
segment widening the filter's covariance × 16 (``reacquire_after`` 1,
``reacquire_inflation`` 16: :mod:`~jaxgrav.navigate.loose_reacquire`; those voyages
found again: the perfect map's last hour 0.013 / 0.032 of the free INS on seeds 0 / 1,
the 3 mGal rows 0.088 / 0.083). A first fix
after 1 h (``first_n_fixes=30``) aids the second hour but, on 1000 patrols with the
3 mGal map error, left the last hour and the share of voyages worse than the free INS
worse (``docs/voyages.md``), so it is an option."""


@pytree_dataclass
class LooseConfig:
    """Settings of the loosely coupled loop.

    Attributes
    ----------
    matcher : DenseConfig or ChainConfig or tuple of (EntropyConfig, IccpConfig)
        The matcher's settings: the dense matcher (``spacing_m`` is set per segment from
        the window), the chain matcher (its window of ``half_size`` map nodes is fixed:
        pass the map refined to the nodes wanted, see :func:`loose_config`), or the
        entropy+ICCP matcher (the entropy grid's ``spacing_m`` set
        the same way, ICCP's ``window_m`` raised to 1.2 × the reach; set
        ``IccpConfig.bias_sigma`` for the gravimeter bias and the Eötvös error, as
        :func:`loose_config` does).
    ins : INSErrorModel
        The filter's INS error model.
    sigma_pos_m, sigma_vel : float
        Initial 1-σ position (m) and velocity (m/s) error per axis.
    window_p : float
        Rayleigh quantile the search reaches.
    min_spacing_m, max_spacing_m : float
        Bounds of the offset grid's spacing (m); ``max_spacing_m`` is static (the dense
        matcher compiles only the map reads that spacings up to it need).
    gate : float
        Innovation gate on ``νᵀ S⁻¹ ν`` (2 degrees of freedom; 13.8 is the 99.9 % point).
    fix_sigma_floor_m : float
        Added in quadrature to each axis of a fix's covariance (m).
    robust_nis : float
        A fix whose normalised innovation squared exceeds this has its covariance scaled
        by ``nis / robust_nis`` before the update (a Huber-like down-weighting: a fix far
        from the filter moves it less and leaves it less sure); ``inf``: plain update.
    fix_cov_scale : float
        The matcher's covariance is multiplied by this before the update: a segment is
        not a rigid shift of the truth (the filter's residual velocity error stretches
        and bends it) and its Eötvös error varies along it, which the rigid-offset
        matcher does not model. Along an ideal filter's states the dense and
        entropy+ICCP fixes' own covariance covers 89–99 % of their errors
        (``examples/voyage_loose.py --calibrate``), but in the loop, whose filter is
        further off, × 1 leaves the dense loop over-confident (position NEES 3.7–6.1 on
        seeds 0 and 1, against 2.1–2.8 with × 3).
    fix_every : int
        INS steps averaged into one fix (static).
    n_fixes : int
        Fixes per segment (static, >= 5).
    stride : int
        Fixes between segment ends (static; ``n_fixes`` = consecutive segments).
    segment_error : {"markov", "linear", "conditional"}
        How the filter's own error is told (static): a Markov error at the Schuler length
        (:func:`~jaxgrav.navigate.loose_match.told_error`), or (dense only) linear in the
        state, marginal or given the offset (:func:`~.loose_match.segment_error_covariance`).
    fix_prior : bool
        Dense only (static): the offsets weighed by the filter's prior ``H̄ P H̄ᵀ / s``
        (``s`` the inflation above), the posterior (covariance × ``s``) given to the
        filter by Gaussian conditioning (:func:`~jaxgrav.navigate.error_kf.
        posterior_update`; no 1-σ limit, no down-weighting, no floor but the lattice
        cell's with ``cell_error``; gated on the move in prior σ, ``shiftᵀ S⁻¹ shift``,
        which is at most the equivalent measurement's NIS). False: the fix is a
        measurement of its own.
    cell_error : bool
        Dense with ``segment_error`` ``"linear"`` or ``"conditional"`` (static): the
        offset's place within a lattice cell (uniform, ``spacing²/12`` per axis) told as
        a reading error through the map's gradient along the segment, so each node's
        likelihood stands for its cell, and the fix is always the lattice posterior
        (``DenseConfig.resolved_n_effective`` 0), its quantisation term ``spacing²/12``
        taken off again where the lattice resolves it (it is in the likelihood already;
        :func:`~jaxgrav.navigate.loose.less_cell`: the fix no narrower than the cell
        along any axis). Without it
        a lattice coarser than the likelihood (a 2 h segment's peak is ~100 m wide, the
        lattice's spacing ~400 m) weighs modes by where its nodes happen to fall, and an
        unresolved fix falls back on the Gauss–Newton refinement, which does not know the
        offset's coupling: on the perfect map a few voyages in a hundred took a wrong fix
        with a ~0.2 km σ and were lost (position NEES 4–22 over 200 patrols).
    shape_update : bool
        Dense with ``segment_error`` ``"linear"`` or ``"conditional"`` (static): after an
        accepted fix, the segment's readings update the rest of the filter's state given
        the fix's offset (the Eötvös error of the residual velocity, the segment's
        stretch, the gravimeter's bias: :func:`~jaxgrav.navigate.loose_shape.
        shape_update`), their noise × the same inflation as the fix's; a fix whose
        readings do not fit the segment at its offset (``νᵀ S⁻¹ ν`` above the
        :data:`~jaxgrav.navigate.loose_shape.SHAPE_GATE_P` quantile of χ²(n)) is
        rejected (event 5).
    reacquire_after : int or None
        Static. After this many failed fixes in a row (on the window's edge or misfitting,
        disagreeing with the filter, or not fitting the segment's shape:
        :func:`~jaxgrav.navigate.loose_reacquire.lost_fix`), each further failure
        multiplies the filter's covariance by ``reacquire_inflation`` (no wider than the
        widest window the matcher can search), and the fix that ends such a run is not
        followed by the shape update (with ``reacquire_skip_shape``):
        :mod:`~jaxgrav.navigate.loose_reacquire`. None: never.
    reacquire_inflation : float
        The covariance's factor per failure of such a run (>= 1).
    reacquire_skip_shape : bool
        Static; with ``reacquire_after`` and ``shape_update``: the fix that ends a run of
        failures updates the filter by itself — its readings must still pass the shape
        test, but do not update the rest of the state (the filter was off by more than it
        said, so the segment bends more than the linear model allows).
    first_n_fixes : int or None
        Static. Segment ends before ``n_fixes`` fixes exist match the last
        ``first_n_fixes`` (>= 5) instead, once that many exist (the first fix of 2 h
        segments every hour then comes after 1 h, not 2 h); None: they are not matched
        (event 1).
    """

    matcher: DenseConfig = DenseConfig()
    ins: INSErrorModel = INSErrorModel()
    sigma_pos_m: float = 354.0
    sigma_vel: float = 0.035
    window_p: float = 0.999
    min_spacing_m: float = 100.0
    max_spacing_m: float = static_field(1500.0)
    gate: float = 13.8
    fix_sigma_floor_m: float = 50.0
    fix_cov_scale: float = 3.0
    robust_nis: float = 5.99
    fix_every: int = static_field(12)
    n_fixes: int = static_field(30)
    stride: int = static_field(30)
    segment_error: str = static_field("markov")
    fix_prior: bool = static_field(False)
    cell_error: bool = static_field(False)
    first_n_fixes: int | None = static_field(None)
    shape_update: bool = static_field(False)
    reacquire_after: int | None = static_field(None)
    reacquire_inflation: float = 16.0
    reacquire_skip_shape: bool = static_field(True)

    def __post_init__(self):
        if not (isinstance(self.n_fixes, int) and self.n_fixes >= 5):
            raise ValueError(f"n_fixes must be an integer >= 5 (a shorter segment cannot be "
                             f"matched reliably); got {self.n_fixes!r}")
        for name in ("fix_every", "stride"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ValueError(f"{name} must be an integer >= 1; got {v!r}")
        m = self.matcher
        if not (isinstance(m, (DenseConfig, ChainConfig)) or (
                isinstance(m, tuple) and len(m) == 2 and isinstance(m[0], EntropyConfig)
                and isinstance(m[1], IccpConfig))):
            raise TypeError("matcher must be a DenseConfig, a ChainConfig or a tuple "
                            f"(EntropyConfig, IccpConfig); got {type(m).__name__}")
        if not (isinstance(self.max_spacing_m, int | float) and self.max_spacing_m > 0):
            raise ValueError(f"max_spacing_m must be a number > 0 (static); got "
                             f"{self.max_spacing_m!r}")
        dense_only = self.segment_error != "markov" or self.fix_prior
        if self.segment_error not in SEGMENT_ERRORS or (
                dense_only and not isinstance(m, DenseConfig)):
            raise ValueError("segment_error must be 'markov' or, dense only, 'linear' or "
                             f"'conditional' (fix_prior: dense only); got {self.segment_error!r}")
        if self.cell_error and not (self.segment_error != "markov"
                                    and isinstance(m, DenseConfig)):
            raise ValueError("cell_error needs the dense matcher and segment_error 'linear' or "
                             "'conditional' (the map's gradient along the segment)")
        if self.shape_update and not (self.segment_error != "markov"
                                      and isinstance(m, DenseConfig)):
            raise ValueError("shape_update needs the dense matcher and segment_error 'linear' "
                             "or 'conditional' (the segment's error linear in the state)")
        first = self.first_n_fixes
        if first is not None and not (isinstance(first, int) and 5 <= first <= self.n_fixes):
            raise ValueError(f"first_n_fixes must be None or an integer from 5 to n_fixes = "
                             f"{self.n_fixes}; got {first!r}")
        after = self.reacquire_after
        if after is not None and not (isinstance(after, int) and after >= 1):
            raise ValueError(f"reacquire_after must be None or an integer >= 1 (failed fixes "
                             f"in a row); got {after!r}")
        if isinstance(self.reacquire_inflation, int | float) and not (
                self.reacquire_inflation >= 1.0):
            raise ValueError(f"reacquire_inflation must be a number >= 1 (the covariance's "
                             f"factor); got {self.reacquire_inflation!r}")
        if self.stride > self.n_fixes:
            raise ValueError(f"stride must be at most n_fixes = {self.n_fixes} (segments may "
                             f"overlap, not leave gaps); got {self.stride}")


def loose_config(ins=INSErrorModel(), map_error_mgal=3.0, map_error_length_m=10000.0,  # noqa: B008
                 noise_mgal=1.0, matcher="dense", grid=None, step_m=None,
                 chain_reach_m=CHAIN_REACH_M, **changes):
    """The loop's settings used by the examples, ``navigate`` and ``montecarlo``.

    Every matcher is told the map error with the Eötvös error of the filter's velocity at
    its along-track Schuler length, as one Markov error
    (:func:`~jaxgrav.navigate.loose_match.told_error`, set per segment by
    :func:`~jaxgrav.navigate.loose_match.match_segment`). The dense matcher: the GLS score,
    a posterior-mean fix, fixes with a 1-σ
    above 3 km or more than 20 % of the posterior mass on the search edge rejected,
    rotations within ±3° (the dense matcher: five); its reading noise is
    ``noise_mgal / √fix_every`` (a fix averages ``fix_every`` readings). Its loop
    settings are :data:`DENSE_LOOP` unless ``segment_error="markov"`` is given (then
    :class:`LooseConfig`'s own defaults: 1 h segments, the Eötvös error told as a Markov
    error, the fix covariance × 3, the first fix after 1 h); ``changes`` override either.
    ``entropy+iccp`` (the same integrity settings): a 41 × 41 entropy grid (H_CY), ICCP
    as the fine stage of
    :func:`~jaxgrav.match.sizing.iccp_config_for` on ``grid`` (window at least a map
    cell's diagonal, ten least-squares steps), the reading bias (gravimeter offset,
    Eötvös error) marginalised with a flat prior. ``chains``: paper A's search
    (:func:`~jaxgrav.match.sizing.config_for`) on the nodes of ``grid`` (pass the map
    refined to the nodes wanted, :func:`~jaxgrav.navigate.loose_match.loose_map`), its
    window fixed at ``chain_reach_m`` about each fix (the loop cannot widen it per segment
    as it does the other matchers' grids: a segment whose Rayleigh reach is larger is still
    matched in that window, and the fix's edge test and the innovation gate are what guard
    it), the difference score (the reading bias drops out), the GLS posterior fix, a fix
    with more than
    :data:`~jaxgrav.navigate.loose_match.LOOSE_MAX_EDGE_MASS` of its posterior on the
    window's edge rejected.

    Parameters
    ----------
    ins : INSErrorModel
        The filter's INS error model.
    map_error_mgal, map_error_length_m : float
        The map error told to the matcher (mGal, m); 0: the white-noise matcher.
    noise_mgal : float
        1-σ of one reading (mGal).
    matcher : {"dense", "chains", "entropy+iccp"}
    grid : Grid or PreparedMap, optional
        The map (``entropy+iccp``: its cell sizes ICCP's window; ``chains``: the map the
        loop will be given, whose nodes are the chains' candidates).
    step_m : float, optional
        ``chains``: the largest distance between consecutive fixes (m; the platform's
        top speed × ``fix_every`` × the log's step), which sizes the chain search's
        displacement stencil; None: the pairwise search over candidate slots.
    chain_reach_m : float
        ``chains``: the window's reach about each fix (m).
    **changes
        Other :class:`LooseConfig` fields (``fix_every``, ``n_fixes``, ``stride``,
        ``sigma_pos_m``, ``segment_error``, ``fix_prior`` …).

    Returns
    -------
    LooseConfig
    """
    fix_every = changes.get("fix_every", LooseConfig.fix_every)
    config = matcher_config(matcher, noise_mgal / math.sqrt(fix_every), map_error_mgal,
                            map_error_length_m, grid, step_m, chain_reach_m)
    base = dict(DENSE_LOOP) if matcher == "dense" and changes.get(
        "segment_error", DENSE_LOOP["segment_error"]) != "markov" else {}
    first = base.get("first_n_fixes")
    if first is not None and first >= changes.get("n_fixes", base["n_fixes"]):
        base["first_n_fixes"] = None  # segments as short as the first's: every end matched
    return LooseConfig(matcher=config, ins=ins, **{**base, **changes})
