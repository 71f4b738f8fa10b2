"""Correlation-extremum gravity matching (paper A), chain path.

Paper A's pipeline, one step per function (each testable on its own):

1. search windows of fixed size around each INS fix (:meth:`Grid.window`);
2. iso-value masks ``|g_i − M| ≤ δ`` (:func:`~jaxgrav.match.candidates.iso_candidates`);
3. padded candidate sets with mask, count and overflow flag (same);
4. step-length and step-direction constraints, forward and backward elimination
   (:func:`~jaxgrav.match.chains.eliminate`);
5. weighted least squares over the surviving chains by k-best min-sum dynamic
   programming (:func:`~jaxgrav.match.chains.kbest_chains`), with weights μ_i
   decreasing along the track, on the paper's Eötvös-free difference form (or the
   absolute form), the K best then re-scored with the requested form
   (:mod:`~jaxgrav.match.scoring`);
6. the ``k_best`` (5) best chains, of which the one nearest the INS track is taken.

Every match also reports the covariance of its fix and an integrity decision, from the
GLS likelihood of :mod:`~jaxgrav.match.gls` (covariance ``σ_n² I + C_map`` along the INS
track, bias marginalised; ``σ_m = 0`` gives the white-noise model of the weighted
score), σ_n² grown by the node quantisation of the map values (``node_allowance``). With
the displacement stencil (``stencil_size`` > 0, as :func:`config_for` sizes it) the
posterior is over the window's rigid chains (the INS track shifted by every node
displacement of the window, all scored); otherwise over the programme's ``k_posterior``
best chains. The covariance is the likelihood-weighted spread of their mean offsets
about the fix plus the node quantisation ``cell²/12``, plus the Gauss–Newton curvature
of the GLS misfit at the chosen chain (map gradient at its nodes) when the posterior
sits on fewer than 3 of them (:mod:`~jaxgrav.match.fix_covariance`); ``fix="posterior"``
returns the INS track shifted to the posterior mean. With a map error
(``ChainConfig.map_error_mgal`` > 0) the chains are ranked by that GLS score instead of
the white one. The dynamic programme itself still runs on the paper's per-step
(difference or absolute) costs: a GLS score with correlated errors is not a sum of
per-step terms, so it only re-scores the programme's best chains.

:func:`match_chains` handles one track; batch it with ``jax.vmap`` over tracks (the map
is shared). The dense-offset fast path is :mod:`jaxgrav.match.dense`.
"""


import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import concrete
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match.candidates import iso_candidates, lattice_candidates
from jaxgrav.match.chain_quality import chain_gls_scores, chain_quality
from jaxgrav.match.chains import (
    compact,
    count_chains,
    eliminate,
    kbest_chains,
    step_compatibility,
)
from jaxgrav.match.lattice_chains import lattice_steps, search_lattice
from jaxgrav.match.offsets import shifted_tracks
from jaxgrav.match.result import MatchResult, nearest_to_ins
from jaxgrav.match.scoring import SCORES, decreasing_weights, score_track
from jaxgrav.prepared import as_grid

__all__ = ["ChainConfig", "chain_tolerances", "match_chains", "pair_cost"]



@pytree_dataclass
class ChainConfig:
    """Settings of the chain matcher.

    Numbers a user may sweep are pytree leaves (changing them does not recompile);
    the rest decides shapes or code paths and is static.

    Attributes
    ----------
    delta : float
        Iso-value tolerance δ (mGal).
    node_allowance : float
        Weight of the allowances for positions quantised to map nodes (0 = the
        paper's plain tolerances; 1 = exact allowance): the iso-value tolerance
        grows by ¾ of the largest change to a neighbouring node (see
        :mod:`~jaxgrav.match.candidates`) and the step-length tolerance by one cell
        diagonal (two nodes, each up to half a diagonal from the true position).
    step_tol_m : float
        Tolerance on the length of each step between consecutive candidates (m), on
        top of the node allowance: INS step error over one interval.
    angle_tol_deg : float
        Tolerance on the direction of each step (degrees), on top of the angle the
        length tolerance subtends (see :func:`~jaxgrav.match.chains.compatibility`).
    weight_decay : float
        μ_i = exp(−decay · i/(N−1)) (0 = equal weights).
    half_size : int
        Window half-width in map nodes (static).
    capacity : int
        Candidate slots per fix (static).
    survivor_capacity : int
        Slots per fix after elimination (static; 0 = ``capacity``). The survivors
        are moved into this smaller set, on which the compatibility of each step is
        computed once and the chain count and dynamic programme run: far less work
        than on all ``capacity`` slots. More survivors than this raise the overflow
        flag (the best-fitting are kept; the elimination is repeated on them).
    stencil_size : int
        Side in nodes of the displacement stencil (static; 0 = off). When set, every
        window node is a candidate slot (no capacity, no candidate overflow) and each
        node's possible predecessors are the nodes of a ``stencil_size²`` box of
        displacements around the INS step (:mod:`~jaxgrav.match.lattice_chains`):
        the same chains as the pairwise search over all window nodes, for
        O(C·stencil_size²) instead of O(C²) work per step. A step whose accepted
        displacements do not fit raises status bit 256
        (:func:`~jaxgrav.match.lattice_chains.stencil_size_for` sizes it).
        ``capacity`` and ``survivor_capacity`` apply only when it is 0.
    k_dp : int
        Chains kept per candidate by the dynamic programme (static), for the bias
        form, which re-scores the programme's ``k_dp`` best chains (ranked by the
        difference form). The difference and absolute forms rank the chains as the
        programme does, so it keeps only ``k_best`` (the same ``k_best`` chains:
        the programme is exact for any k, up to chains whose scores agree to float32
        resolution, which it ranks in float32).
    k_best : int
        Chains among which the final one is selected (static; paper: 5).
    score : {"difference", "bias", "absolute"}
        Final score form (static); the programme itself runs on the difference form
        unless ``"absolute"``.
    selection : {"nearest", "best"}
        Paper A's nearest-to-INS rule, or the least score (static).
    noise_mgal : float
        Reading noise σ_n (mGal) of the GLS likelihood behind the fix's covariance.
    map_error_mgal : float
        σ of the map's error (mGal), traced. 0 (default): chains ranked as without
        this field, the covariance from the white-noise likelihood; > 0: the
        ``k_posterior`` best chains ranked by the GLS score (covariance
        ``σ_n² I + C_map`` along the track, bias marginalised; none for
        ``score="absolute"``), ``score`` then in mGal² (χ² × ``σ_n² Σμ²``).
    map_error_length_m : float
        Correlation length L of the map error (m), traced.
    map_error_order : {1, 2}
        Gauss–Markov order of the map-error covariance (static).
    k_posterior : int
        Chains of the dynamic programme scored for the posterior of the fix (pairwise
        search) and ranked by the GLS score (static; the programme then keeps at least
        this many).
    score_model : {"auto", "white", "gls"}
        How the chains are ranked (static). ``"auto"`` (default): by the white score,
        or by the GLS score of the programme's ``k_posterior`` best when
        ``map_error_mgal > 0`` at run time. ``"white"``: by the white score only
        (paper A; ``map_error_mgal`` must be 0), so the stencil search's programme keeps
        only the ``k_best`` chains it returns (``k_dp`` for the bias form) instead of
        ``k_posterior``: at N = 16 on 21 × 21 windows the matcher takes ~0.6 × the time.
        ``"gls"``: by the GLS score always (σ = 0 gives the white-noise likelihood).
    fix : {"chain", "posterior"}
        The returned track (static): the selected chain, or the INS track shifted to
        the posterior mean offset (module docstring).
    max_sigma_m, max_second_mode, max_chi2_per_dof, max_edge_mass : float
        Integrity thresholds (traced): the fix is rejected (INS track returned, status
        512, 1024, 2048, 4096) when the largest 1-σ of its covariance (m), the
        posterior's second-mode likelihood ratio
        (:func:`~jaxgrav.match.gls.offset_posterior`; for the pairwise search, of the
        best chain outside the 3-σ curvature ellipse of the best), the chosen chain's
        GLS χ² per degree of freedom, or the window posterior's mass on its outermost
        ring of offsets (the stencil search only; the pairwise search has no window
        posterior and never rejects on it) exceeds it. Defaults ``inf``: every found
        fix is accepted.
    """

    delta: float = 1.0
    node_allowance: float = 1.0
    step_tol_m: float = 100.0
    angle_tol_deg: float = 2.0
    weight_decay: float = 0.5
    half_size: int = static_field(8)
    capacity: int = static_field(128)
    survivor_capacity: int = static_field(0)
    stencil_size: int = static_field(0)
    k_dp: int = static_field(16)
    k_best: int = static_field(5)
    score: str = static_field("difference")
    selection: str = static_field("nearest")
    noise_mgal: float = 1.0
    map_error_mgal: float = 0.0
    map_error_length_m: float = 10000.0
    map_error_order: int = static_field(2)
    k_posterior: int = static_field(16)
    score_model: str = static_field("auto")
    fix: str = static_field("chain")
    max_sigma_m: float = float("inf")
    max_second_mode: float = float("inf")
    max_chi2_per_dof: float = float("inf")
    max_edge_mass: float = float("inf")

    def __post_init__(self):
        if isinstance(self.fix, str) and self.fix not in ("chain", "posterior"):
            raise ValueError(f"fix must be 'chain' or 'posterior'; got {self.fix!r}")
        if self.map_error_order not in (1, 2):
            raise ValueError(f"map_error_order must be 1 or 2; got {self.map_error_order!r}")
        if isinstance(self.k_posterior, int) and self.k_posterior < 1:
            raise ValueError(f"k_posterior must be >= 1; got {self.k_posterior!r}")
        for name in ("map_error_mgal", "map_error_length_m", "noise_mgal"):
            arr = concrete(getattr(self, name))
            if arr is not None and arr.dtype != object and not (
                    np.all(np.isfinite(arr)) and np.all(arr >= 0)):
                raise ValueError(f"{name} must be finite and >= 0; got {arr}")
        if isinstance(self.score, str) and self.score not in SCORES:
            raise ValueError(f"score must be one of {SCORES}; got {self.score!r}")
        if self.score_model not in ("auto", "white", "gls"):
            raise ValueError(f"score_model must be 'auto', 'white' or 'gls'; got "
                             f"{self.score_model!r}")
        sigma = concrete(self.map_error_mgal)
        if (self.score_model == "white" and sigma is not None and sigma.dtype != object
                and np.any(sigma > 0)):
            raise ValueError(f"score_model='white' ignores the map error; got map_error_mgal="
                             f"{sigma} (use 'gls' or 'auto')")
        if isinstance(self.selection, str) and self.selection not in ("nearest", "best"):
            raise ValueError(f"selection must be 'nearest' or 'best'; got {self.selection!r}")
        if isinstance(self.stencil_size, int) and self.stencil_size < 0:
            raise ValueError(f"stencil_size must be >= 0 (0 = pairwise search); "
                             f"got {self.stencil_size!r}")
        if isinstance(self.survivor_capacity, int) and self.survivor_capacity < 0:
            raise ValueError(f"survivor_capacity must be >= 0 (0 = capacity); "
                             f"got {self.survivor_capacity!r}")


def pair_cost(readings, w_diff):
    """Difference-form cost of a step from value v0 at fix i to v1 at fix i+1 (broadcasts)."""
    dg = jnp.diff(readings)

    def pair(i, v0, v1):
        return w_diff[i] * (dg[i] - (v1 - v0)) ** 2

    return pair


@jax.jit
def match_chains(grid, lat, lon, readings, config=ChainConfig()):  # noqa: B008
    """Match one track by paper A's constrained chain search.

    Parameters
    ----------
    grid : Grid or PreparedMap
        Anomaly map (mGal), refined to the node spacing wanted (paper A: 0.005°).
    lat, lon : Array, shape ``(N,)``
        INS-indicated fixes (degrees).
    readings : Array, shape ``(N,)``
        Gravimeter readings (mGal), Eötvös-corrected if ``config.score="absolute"``.
    config : ChainConfig

    Returns
    -------
    MatchResult
        If no chain survives, the INS fixes are returned with status bit 1.
    """
    grid = as_grid(grid)  # the chain search reads node values only
    lat, lon, readings = (jnp.asarray(a) for a in (lat, lon, readings))
    n = lat.shape[0]
    steps = local_offsets_m(lat[1:], lon[1:], lat[:-1], lon[:-1])
    tol = chain_tolerances(grid, lat, config)
    w = decreasing_weights(n, config.weight_decay)
    dtype = jnp.result_type(grid.values.dtype, readings.dtype)
    if config.score == "absolute":
        unary_fn = lambda value: w[:, None] * (readings[:, None] - value) ** 2  # noqa: E731
        pair = lambda i, v0, v1: jnp.zeros(jnp.broadcast_shapes(v0.shape, v1.shape),  # noqa: E731
                                           dtype)
    else:
        unary_fn = lambda value: jnp.zeros(value.shape, dtype)  # noqa: E731
        pair = pair_cost(readings, w[:-1] / jnp.sum(w[:-1]))
    search_args = (grid, lat, lon, readings, steps, tol, unary_fn, pair, config)
    if config.stencil_size > 0:
        cands, alive, work_constrained, search, stencil_overflow = _lattice_search(*search_args)
    else:
        cands, alive, work_constrained, search = _pairwise_search(*search_args)
        stencil_overflow = jnp.zeros((), bool)
    work_unconstrained = jnp.prod(cands.count.astype(dtype))
    work_pairs = jnp.sum(jnp.sum(alive[:-1], axis=1) * jnp.sum(alive[1:], axis=1))
    n_candidates, complete, overflow = cands.count, cands.window_complete, cands.overflow

    fix = jnp.arange(n)[None, :]
    values = cands.value[fix, search.index]  # (K_dp, N)
    rescored, bias = score_track(readings, values, w, config.score)
    alive_chain = jnp.isfinite(search.score)
    rescored = jnp.where(alive_chain, rescored, jnp.inf)
    wh, j_gls, b_gls, sigma_b, scale = chain_gls_scores(grid, lat, lon, readings, values, w,
                                                    config, dtype)
    j_gls = jnp.where(alive_chain, j_gls, jnp.inf)
    told = {"auto": jnp.asarray(config.map_error_mgal) > 0, "white": False,
            "gls": True}[config.score_model]
    rank = jnp.where(told, j_gls * scale, rescored)
    bias = jnp.where(told, b_gls, bias)
    order = jnp.argsort(rank)[: config.k_best]
    idx = search.index[order]
    topk_score = rank[order]
    north, east = cands.north_m[fix, idx], cands.east_m[fix, idx]  # (K, N)
    distance = jnp.sum(jnp.hypot(north, east), axis=1)
    chosen = nearest_to_ins(topk_score, distance, config.selection)
    found = jnp.isfinite(topk_score[chosen])

    topk_lat, topk_lon = cands.lat[fix, idx], cands.lon[fix, idx]
    q = chain_quality(grid, cands, search.index, order[chosen], j_gls, wh, sigma_b, readings,
                       config)
    accepted = found & (q["status"] == 0)
    m_lat, m_lon = topk_lat[chosen], topk_lon[chosen]
    if config.fix == "posterior":  # the INS track shifted to the posterior mean
        m_lat, m_lon = shifted_tracks(lat, lon, q["fix"][0], q["fix"][1], jnp.zeros((), dtype))
    edge = _on_window_edge(grid, cands, idx[chosen], lat, lon, config.half_size)
    status = (
        jnp.where(found, 0, 1)
        | jnp.where(jnp.any(overflow), 2, 0)
        | jnp.where(jnp.all(complete), 0, 4)
        | jnp.where(found & edge, 8, 0)
        | jnp.where(stencil_overflow, 256, 0)
        | jnp.where(found, q["status"], 0)
    )
    return MatchResult(
        lat=jnp.where(accepted, m_lat, lat),
        lon=jnp.where(accepted, m_lon, lon),
        offset_north_m=jnp.where(accepted, q["fix"][0], 0.0),
        offset_east_m=jnp.where(accepted, q["fix"][1], 0.0),
        rotation_deg=jnp.zeros((), dtype),
        score=topk_score[chosen],
        bias=bias[order][chosen],
        topk_lat=topk_lat,
        topk_lon=topk_lon,
        topk_score=topk_score,
        chosen=chosen,
        n_candidates=n_candidates,
        work_unconstrained=work_unconstrained,
        work_constrained=work_constrained,
        work_pairs=work_pairs.astype(dtype),
        status=status,
        covariance_m2=q["covariance"].astype(dtype),
        accepted=accepted,
        n_effective=q["n_effective"].astype(dtype),
        second_mode_ratio=q["second_mode"].astype(dtype),
        edge_mass=q["edge_mass"].astype(dtype),
        chi2_per_dof=q["chi2_per_dof"].astype(dtype),
    )


def chain_tolerances(grid, lat, config):
    """The step tolerances the chain search applies: ``(step_tol_m, angle_tol_deg)``.

    The step-length tolerance is ``config.step_tol_m`` plus ``node_allowance`` cell
    diagonals at the track's mean latitude (two nodes, each up to half a diagonal from
    the true positions).
    """
    dy, dx = grid.spacing_m(jnp.mean(jnp.asarray(lat)))
    return config.step_tol_m + config.node_allowance * jnp.hypot(dy, dx), config.angle_tol_deg


def _k_dp(config):
    """Chains the programme keeps: re-scoring (bias form) needs more than it returns, the
    GLS ranking and the pairwise search's posterior ``k_posterior``."""
    k = config.k_dp if config.score == "bias" else config.k_best
    if config.score_model == "white" and config.stencil_size > 0:
        return k  # the stencil search's posterior is over the window's rigid chains
    return max(k, config.k_posterior)


def _candidates_args(config):
    return dict(half_size=config.half_size, delta=config.delta,
                slope_factor=config.node_allowance)


def _pairwise_search(grid, lat, lon, readings, steps, tol, unary_fn, pair, config):
    """Steps 2–5 on padded candidate sets, every pair of consecutive candidates tested."""
    cands = iso_candidates(grid, lat, lon, readings, capacity=config.capacity,
                           **_candidates_args(config))
    alive = eliminate(cands, steps, *tol)
    compat = None
    if 0 < config.survivor_capacity < config.capacity:
        cands, lost = compact(cands, alive, config.survivor_capacity)  # count kept
        compat = step_compatibility(cands, steps, *tol)
        alive = eliminate(cands, steps, *tol, compat=compat)  # unchanged unless `lost`
        cands = cands._replace(overflow=cands.overflow | lost)
    work = count_chains(cands, alive, steps, *tol, compat=compat)
    search = kbest_chains(cands, alive, steps, *tol, unary_fn(cands.value), pair, _k_dp(config),
                          compat=compat)
    return cands, alive, work, search


def _lattice_search(grid, lat, lon, readings, steps, tol, unary_fn, pair, config):
    """Steps 2–5 on the window lattices with the displacement stencil."""
    cands, origin = lattice_candidates(grid, lat, lon, readings, **_candidates_args(config))
    geo = lattice_steps(grid, cands, origin, lat, steps, *tol, config.stencil_size)
    alive, work, search = search_lattice(cands, geo, *tol, unary_fn(cands.value), pair,
                                         _k_dp(config))
    return cands, alive, work, search, jnp.any(geo.overflow)


def _on_window_edge(grid, cands, idx, lat, lon, half_size):
    """True when a chosen candidate sits on the outer ring of its search window."""
    row = jnp.round((cands.lat[jnp.arange(lat.shape[0]), idx] - grid.lat0) / grid.dlat)
    col = jnp.round((cands.lon[jnp.arange(lat.shape[0]), idx] - grid.lon0) / grid.dlon)
    iy, ix = grid.fractional_index(lat, lon)
    return jnp.any(
        (jnp.abs(row - jnp.round(iy)) >= half_size) | (jnp.abs(col - jnp.round(ix)) >= half_size)
    )
