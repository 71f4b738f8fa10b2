"""Loosely coupled navigation: matcher fixes as position measurements of the INS error KF.

Every ``stride`` fixes (``stride = n_fixes``: consecutive segments; less: sliding), the
segment of the last ``n_fixes`` fixes is matched. Each fix is the mean of
``fix_every`` INS steps (positions, readings), so the matcher sees a low-passed
reading every ``fix_every · dt`` seconds. What the loop does at each segment end:

1. the INS error KF (:mod:`~jaxgrav.navigate.error_kf`) is predicted to now;
2. its estimate is put back on the segment's steps: the *corrected* track (INS − the
   estimated error) is what the matcher's search is centred on, and the readings are
   Eötvös-corrected with the corrected velocity (a real system knows no other);
3. the search reaches the ``window_p`` quantile of the Rayleigh law of the filter's
   own position σ along the segment (paper A's window, sized by the filter): the dense
   offset grid's spacing is ``reach / half_size``, within ``[min_spacing_m,
   max_spacing_m]``;
4. an accepted fix (matcher integrity, then the innovation gate) updates the filter
   with the fix's own covariance; a rejected one is skipped and its reason recorded
   (:data:`FIX_EVENTS`); a segment with a missing reading or off the map is not matched.

With sliding segments (``stride < n_fixes``) consecutive fixes share readings; their
covariance is inflated by ``n_fixes / stride`` so the filter does not count them twice.
The whole voyage is one ``lax.scan`` over segment ends; ``vmap`` it over voyages.
"""

import dataclasses
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.geodesy import eotvos
from jaxgrav.match.correlation import ChainConfig
from jaxgrav.match.dense import DenseConfig
from jaxgrav.match.entropy import EntropyConfig
from jaxgrav.match.iccp_config import IccpConfig
from jaxgrav.match.integrity import largest_sigma
from jaxgrav.navigate.error_kf import (
    error_kf_tables,
    fix_update,
    innovation_nis,
    posterior_update,
    spread,
)
from jaxgrav.navigate.loose_match import (
    CHAIN_REACH_M,
    LOOSE_MATCHERS,
    eotvos_sigma,
    match_segment,
    matcher_config,
    schuler_length_m,
    segment_error_covariance,
)
from jaxgrav.prepared import prepare_map
from jaxgrav.sim.drift import apply_drift, rayleigh_quantile
from jaxgrav.sim.ins import INSErrorModel, initial_covariance
from jaxgrav.sim.trajectory import Track

__all__ = ["CHAIN_REACH_M", "FIX_EVENTS", "LOOSE_MATCHERS", "LooseConfig", "LooseResult",
           "eotvos_sigma", "fix_segment", "loose_config", "navigate_loose"]

FIX_EVENTS = {
    0: "accepted",
    1: "no fix yet: the first segment is not complete",
    2: "not matched: a reading is missing or the segment leaves the map",
    3: "rejected by the matcher's integrity test",
    4: "rejected by the innovation gate (the fix disagrees with the filter)",
}
"""What happened at each segment end (``LooseResult.fix_event``)."""


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
        posterior_update`; no 1-σ limit, no down-weighting, no floor; gated on the
        move in prior σ). False: the fix is a measurement of its own.
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
        if self.segment_error not in ("markov", "linear", "conditional") or (
                dense_only and not isinstance(m, DenseConfig)):
            raise ValueError("segment_error must be 'markov' or, dense only, 'linear' or "
                             f"'conditional' (fix_prior: dense only); got {self.segment_error!r}")
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
    ``noise_mgal / √fix_every`` (a fix averages ``fix_every`` readings).
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
        ``sigma_pos_m`` …).

    Returns
    -------
    LooseConfig
    """
    fix_every = changes.get("fix_every", LooseConfig.fix_every)
    config = matcher_config(matcher, noise_mgal / math.sqrt(fix_every), map_error_mgal,
                            map_error_length_m, grid, step_m, chain_reach_m)
    return LooseConfig(matcher=config, ins=ins, **changes)


class LooseResult(NamedTuple):
    """The navigation solution of one voyage.

    Attributes
    ----------
    nav : Track
        Corrected trajectory at every INS step (positions in degrees, velocity in m/s).
    cov_north_east : Array, shape ``(N, 2, 2)``
        Covariance of the position error (m², north/east).
    error_estimate : Array, shape ``(N, 13)``
        The filter's INS error estimate at every step.
    fix_time : Array, shape ``(C,)``
        Time of each segment end (s).
    fix_event : Array of int, shape ``(C,)``
        What happened there, see :data:`FIX_EVENTS`.
    fix_status : Array of int, shape ``(C,)``
        The matcher's status bits (0 where it did not run).
    fix_offset_m : Array, shape ``(C, 2)``
        The fix's correction of the corrected segment (north, east; m).
    fix_cov_m2 : Array, shape ``(C, 2, 2)``
        The fix's covariance as given to the filter (m²).
    reach_m : Array, shape ``(C,)``
        Search reach of the segment (m).
    nis : Array, shape ``(C,)``
        Normalised innovation squared of the fix (NaN where not matched).
    """

    nav: Track
    cov_north_east: jax.Array
    error_estimate: jax.Array
    fix_time: jax.Array
    fix_event: jax.Array
    fix_status: jax.Array
    fix_offset_m: jax.Array
    fix_cov_m2: jax.Array
    reach_m: jax.Array
    nis: jax.Array


def _shift(lat, lon, d_n, d_e):
    """Positions moved by ``(−d_n, −d_e)`` metres (the INS minus an error estimate)."""
    return apply_drift(lat, lon, -d_n, -d_e)


def _blocks(a, m):
    """Means of consecutive blocks of ``m`` samples (NaN if any sample is)."""
    return jnp.mean(a.reshape(-1, m), axis=1)


def _segment(cfg, tables, ins, gravity, x, end):
    """The corrected segment ending at INS step ``end``: fix positions and readings."""
    w = cfg.n_fixes * cfg.fix_every
    start = jnp.maximum(end - w, 0)
    take = lambda a: jax.lax.dynamic_slice_in_dim(a, start, w)  # noqa: E731
    err = jnp.einsum("kij,j->ki", tables.backward, x)
    lat, lon = _shift(take(ins.lat), take(ins.lon), err[:, 0], err[:, 1])
    v_e, v_n = take(ins.v_east) - err[:, 3], take(ins.v_north) - err[:, 2]
    g = take(gravity) + eotvos(lat, v_e, v_n)
    return (*(_blocks(a, cfg.fix_every) for a in (lat, lon, g, v_e, v_n)), end - w >= 0)


def fix_segment(config, tables, grid, ins, gravity, x, p, end):
    """Match the segment that ends at INS step ``end``, as the loop does.

    Parameters
    ----------
    config : LooseConfig
    tables : ErrorKFTables
        Of the voyage (:func:`~jaxgrav.navigate.error_kf.error_kf_tables`).
    grid : Grid or PreparedMap
    ins : Track
        The INS-indicated track, shape ``(N,)`` per field.
    gravity : Array, shape ``(N,)``
        Raw readings (mGal).
    x, p : Array, shapes ``(13,)``, ``(13, 13)``
        The filter's predicted state and covariance at ``end``.
    end : int or Array
        INS step the segment ends at (exclusive).

    Returns
    -------
    result : MatchResult
        The fix: its offset corrects the corrected segment (matched − corrected).
    reach : Array
        Search reach (m).
    usable : Array of bool
        The segment was complete, every reading present and every fix on the map.
    """
    cfg = config
    h_mean = tables.h_mean
    lat, lon, g, v_e, v_n, complete = _segment(cfg, tables, ins, gravity, x, end)
    sigma = largest_sigma(h_mean @ p @ h_mean.T)  # closed form: no LAPACK call
    reach = rayleigh_quantile(sigma, cfg.window_p)
    # bilinear: NaN exactly where bicubic is (off the map, a cell with a missing corner)
    on_map = jnp.all(jnp.isfinite(grid.sample(lat, lon, method="bilinear")))
    usable = complete & jnp.all(jnp.isfinite(g)) & on_map
    sig_e = eotvos_sigma(jnp.mean(lat), ins.v_east[end], ins.v_north[end], p[2:4, 2:4])
    length_e = schuler_length_m(jnp.hypot(ins.v_east[end], ins.v_north[end]), jnp.mean(lat))
    extra = coupling = None  # "markov": the Eötvös error told at its Schuler length
    if cfg.segment_error != "markov":
        b = tables.backward[:, :4].reshape(cfg.n_fixes, cfg.fix_every, 4, -1).mean(1)
        extra, coupling = segment_error_covariance(prepare_map(grid), lat, lon, v_e, v_n, b,
                                                   h_mean, p, cfg.segment_error == "conditional")
        extra, sig_e = jnp.where(jnp.isfinite(extra), extra, 0.0), jnp.zeros_like(sig_e)
    matcher = cfg.matcher
    if cfg.fix_prior:  # the filter's prior on the offsets, tempered by the inflation
        prior = h_mean @ p @ h_mean.T / (cfg.fix_cov_scale * cfg.n_fixes / cfg.stride)
        matcher = dataclasses.replace(matcher, offset_prior_m2=0.5 * (prior + prior.T),
                                      max_sigma_m=jnp.inf)
    res = match_segment(matcher, grid, lat, lon, jnp.where(jnp.isfinite(g), g, 0.0), reach,
                        sig_e, (cfg.min_spacing_m, cfg.max_spacing_m), length_e, extra, coupling)
    return res, reach, usable


def _fix(cfg, tables, grid, ins, gravity, x, p, end):
    """Match the segment ending at ``end`` and update the filter with the fix."""
    h_mean = tables.h_mean
    res, reach, usable = fix_segment(cfg, tables, grid, ins, gravity, x, p, end)
    complete = end - cfg.n_fixes * cfg.fix_every >= 0
    offset = jnp.stack([res.offset_north_m, res.offset_east_m])
    inflate = cfg.fix_cov_scale * cfg.n_fixes / cfg.stride
    floor = 0.0 if cfg.fix_prior else cfg.fix_sigma_floor_m**2
    r = (res.covariance_m2 * inflate + floor * jnp.eye(2)).astype(p.dtype)
    good = usable & res.accepted & jnp.all(jnp.isfinite(r))
    r = jnp.where(jnp.isfinite(r), r, jnp.eye(2))
    if cfg.fix_prior:
        x_new, p_new, nis = posterior_update(x, p, h_mean, -offset, r, good)
    else:
        nis = innovation_nis(p, -offset, r, h_mean)
        r = r * jnp.maximum(1.0, nis / cfg.robust_nis)
        x_new, p_new, _ = fix_update(x, p, -offset, r, h_mean, good)
    gated = good & (nis <= cfg.gate)
    x_new, p_new = jnp.where(gated, x_new, x), jnp.where(gated, p_new, p)
    event = jnp.select([~complete, ~usable, ~res.accepted, ~gated], [1, 2, 3, 4], 0)
    status = jnp.where(usable, res.status, 0)
    return x_new, p_new, (event, status, offset, r, reach, jnp.where(usable, nis, jnp.nan))


@jax.jit
def navigate_loose(grid, voyage, config):
    """Loosely coupled map-aided navigation over one voyage (see the module notes).

    Parameters
    ----------
    grid : Grid or PreparedMap
        The anomaly map (mGal); dense and entropy+ICCP prepare it once (a PreparedMap).
    voyage : Voyage
        The INS log and the raw readings (Eötvös not corrected); ``truth`` is not used.
        ``N − 1`` need not be a multiple of the fix interval (the last one is cut short).
    config : LooseConfig

    Returns
    -------
    LooseResult
    """
    cfg = config  # dense, entropy+ICCP: the spline prepared once, not in every segment
    grid = grid if isinstance(cfg.matcher, ChainConfig) else prepare_map(grid)
    ins, n = voyage.ins, voyage.ins.t.shape[0]
    m = cfg.fix_every
    steps_between = cfg.stride * m
    n_seg = -(-(n - 1) // steps_between)
    pad = n_seg * steps_between + 1 - n
    ins_p = Track(*(jnp.concatenate([a, jnp.repeat(a[-1:], pad)]) for a in ins))
    grav_p = jnp.concatenate([voyage.gravity, jnp.full((pad,), jnp.nan, voyage.gravity.dtype)])
    dt = (ins.t[-1] - ins.t[0]) / (ins.t.shape[0] - 1)  # the mean step, not the first's
    tables = error_kf_tables(cfg.ins, jnp.mean(ins.lat), dt, steps_between, cfg.n_fixes * m)
    p0 = initial_covariance(cfg.ins, cfg.sigma_pos_m, cfg.sigma_vel)
    x0 = jnp.zeros(p0.shape[0], p0.dtype)

    def step(carry, j):
        x, p = carry
        xs, pos_cov = spread(tables, x, p)
        x_pred = tables.step_f @ x
        p_pred = tables.step_f @ p @ tables.step_f.T + tables.step_q
        end = (j + 1) * steps_between
        x_new, p_new, events = _fix(cfg, tables, grid, ins_p, grav_p, x_pred, p_pred, end)
        return (x_new, p_new), (xs, pos_cov, events)

    (x_end, p_end), (xs, pos_cov, events) = jax.lax.scan(step, (x0, p0), jnp.arange(n_seg))
    xs = jnp.concatenate([xs.reshape(-1, x0.shape[0]), x_end[None]])[:n]
    pos_cov = jnp.concatenate([pos_cov.reshape(-1, 2, 2), p_end[None, :2, :2]])[:n]
    lat, lon = _shift(ins.lat, ins.lon, xs[:, 0], xs[:, 1])
    nav = Track(ins.t, lat, lon, ins.v_east - xs[:, 3], ins.v_north - xs[:, 2])
    event, status, offset, r, reach, nis = events
    fix_time = ins_p.t[0] + (jnp.arange(n_seg) + 1) * steps_between * dt
    return LooseResult(nav, pos_cov, xs, fix_time, event, status, offset, r, reach, nis)
