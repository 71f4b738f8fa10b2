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
   (:data:`FIX_EVENTS`); a segment with a missing reading or off the map is not matched;
5. with ``LooseConfig.shape_update``, the segment's readings then update the rest of the
   state given the fix's offset (:mod:`~jaxgrav.navigate.loose_shape`), and a fix whose
   readings do not fit the segment at its offset is rejected;
6. with ``LooseConfig.reacquire_after``, a run of failed fixes (on the window's edge, or
   not fitting the segment) widens the filter's covariance, so that the next window
   reaches a truth the filter had lost (:mod:`~jaxgrav.navigate.loose_reacquire`).

With sliding segments (``stride < n_fixes``) consecutive fixes share readings; their
covariance is inflated by ``n_fixes / stride`` so the filter does not count them twice.
Segment ends before ``n_fixes`` fixes exist match the last ``first_n_fixes`` when that
is set (:class:`~jaxgrav.navigate.loose_config.LooseConfig`; a second scan of the same
step, on the shorter span's tables, :func:`first_tables`).
The whole voyage is one ``lax.scan`` over segment ends; ``vmap`` it over voyages.
"""

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.geodesy import eotvos
from jaxgrav.match.correlation import ChainConfig
from jaxgrav.match.integrity import largest_sigma
from jaxgrav.navigate.error_kf import (
    error_kf_tables,
    fix_update,
    innovation_nis,
    posterior_update,
    spread,
)
from jaxgrav.navigate.loose_config import LooseConfig, loose_config
from jaxgrav.navigate.loose_match import (
    CHAIN_REACH_M,
    LOOSE_MATCHERS,
    eotvos_sigma,
    match_segment,
    schuler_length_m,
    segment_error_covariance,
)
from jaxgrav.navigate.loose_reacquire import reacquire
from jaxgrav.navigate.loose_shape import SHAPE_GATE_P, chi2_quantile, shape_update
from jaxgrav.prepared import prepare_map
from jaxgrav.sim.drift import apply_drift, rayleigh_quantile
from jaxgrav.sim.ins import initial_covariance
from jaxgrav.sim.trajectory import Track

__all__ = ["CHAIN_REACH_M", "FIX_EVENTS", "LOOSE_MATCHERS", "LooseConfig", "LooseResult",
           "corrected_segment", "eotvos_sigma", "first_segment_ends", "first_tables",
           "fix_segment", "less_cell", "loose_config", "navigate_loose"]

FIX_EVENTS = {
    0: "accepted",
    1: "no fix yet: the first segment is not complete",
    2: "not matched: a reading is missing or the segment leaves the map",
    3: "rejected by the matcher's integrity test",
    4: "rejected by the innovation gate (the fix disagrees with the filter)",
    5: "rejected: the readings do not fit the segment at the fix (shape test)",
}
"""What happened at each segment end (``LooseResult.fix_event``)."""


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
    shape_nis : Array, shape ``(C,)``
        With ``LooseConfig.shape_update``: the segment's readings' ``νᵀ S⁻¹ ν`` given the
        fix (χ²(``n_fixes``) expected; above its
        :data:`~jaxgrav.navigate.loose_shape.SHAPE_GATE_P` quantile the update was
        skipped); NaN where no fix was accepted or without it.
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
    shape_nis: jax.Array


def _shift(lat, lon, d_n, d_e):
    """Positions moved by ``(−d_n, −d_e)`` metres (the INS minus an error estimate)."""
    return apply_drift(lat, lon, -d_n, -d_e)


def _blocks(a, m):
    """Means of consecutive blocks of ``m`` samples (NaN if any sample is)."""
    return jnp.mean(a.reshape(-1, m), axis=1)


def corrected_segment(cfg, tables, ins, gravity, x, end):
    """The corrected segment ending at INS step ``end``: fix positions, Eötvös-corrected
    readings and velocities (block means of ``cfg.fix_every`` steps; the segment spans
    ``tables.backward``'s steps), and whether the segment is complete."""
    w = tables.backward.shape[0]
    start = jnp.maximum(end - w, 0)
    take = lambda a: jax.lax.dynamic_slice_in_dim(a, start, w)  # noqa: E731
    err = jnp.einsum("kij,j->ki", tables.backward, x)
    lat, lon = _shift(take(ins.lat), take(ins.lon), err[:, 0], err[:, 1])
    v_e, v_n = take(ins.v_east) - err[:, 3], take(ins.v_north) - err[:, 2]
    g = take(gravity) + eotvos(lat, v_e, v_n)
    return (*(_blocks(a, cfg.fix_every) for a in (lat, lon, g, v_e, v_n)), end - w >= 0)


def _inflation(cfg):
    """The fix covariance's factor: ``fix_cov_scale`` × the readings' reuse by overlapping
    segments (``n_fixes / stride``)."""
    return cfg.fix_cov_scale * cfg.n_fixes / cfg.stride


def _cell(cfg, reach):
    """The dense lattice's spacing for a search of ``reach`` (m), as
    :func:`~jaxgrav.navigate.loose_match.match_segment` sets it."""
    return jnp.clip(reach / cfg.matcher.half_size, cfg.min_spacing_m, cfg.max_spacing_m)


def less_cell(cov, q):
    """A lattice posterior's covariance without the cell's variance counted twice.

    With ``LooseConfig.cell_error`` the likelihood already holds the offset's place within
    a cell (``q = spacing²/12`` per axis), and the posterior's quantisation term adds it
    again: each eigenvalue ``λ`` of ``cov`` becomes ``max(λ − q, q)`` — the term taken
    off along the axes the lattice resolves, a posterior no narrower than the cell along
    the others (closed form, no LAPACK call).

    Parameters
    ----------
    cov : Array, shape ``(2, 2)``
        Symmetric (m²).
    q : Array
        The cell's variance per axis (m²).

    Returns
    -------
    Array, shape ``(2, 2)``
    """
    a, b, d = cov[0, 0], 0.5 * (cov[0, 1] + cov[1, 0]), cov[1, 1]
    # an isotropic cov has no axis (any gives the same result), and the derivatives of
    # √ and arctan2 at 0 are not finite there: the double wheres keep the gradient finite
    round_ = (b == 0) & (a == d)
    rad = jnp.where(round_, 0.0, jnp.sqrt(jnp.where(round_, 1.0, 0.25 * (a - d) ** 2 + b * b)))
    big, small = 0.5 * (a + d) + rad, 0.5 * (a + d) - rad
    # the larger eigenvalue's axis
    angle = 0.5 * jnp.arctan2(jnp.where(round_, 0.0, 2.0 * b), jnp.where(round_, 1.0, a - d))
    u = jnp.stack([jnp.cos(angle), jnp.sin(angle)])
    v = jnp.stack([-u[1], u[0]])
    return (jnp.maximum(big - q, q) * jnp.outer(u, u)
            + jnp.maximum(small - q, q) * jnp.outer(v, v))


def first_tables(config, tables):
    """The tables of the first segments' shorter span (``LooseConfig.first_n_fixes``).

    Parameters
    ----------
    config : LooseConfig
    tables : ErrorKFTables
        Of the voyage, for ``n_fixes`` fixes.

    Returns
    -------
    ErrorKFTables
        ``backward`` and ``h_mean`` for the last ``first_n_fixes`` fixes.
    """
    backward = tables.backward[-config.first_n_fixes * config.fix_every:]
    return tables._replace(backward=backward, h_mean=jnp.mean(backward[:, :2, :], axis=0))


def fix_segment(config, tables, grid, ins, gravity, x, p, end):
    """Match the segment that ends at INS step ``end``, as the loop does.

    Parameters
    ----------
    config : LooseConfig
    tables : ErrorKFTables
        Of the voyage (:func:`~jaxgrav.navigate.error_kf.error_kf_tables`); its
        ``backward`` spans the segment (``n_fixes · fix_every`` steps, or the first
        segments' span, :func:`first_tables`).
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
    lat, lon, g, v_e, v_n, complete = corrected_segment(cfg, tables, ins, gravity, x, end)
    sigma = largest_sigma(h_mean @ p @ h_mean.T)  # closed form: no LAPACK call
    reach = rayleigh_quantile(sigma, cfg.window_p)
    # bilinear: NaN exactly where bicubic is (off the map, a cell with a missing corner)
    on_map = jnp.all(jnp.isfinite(grid.sample(lat, lon, method="bilinear")))
    usable = complete & jnp.all(jnp.isfinite(g)) & on_map
    sig_e = eotvos_sigma(jnp.mean(lat), ins.v_east[end], ins.v_north[end], p[2:4, 2:4])
    length_e = schuler_length_m(jnp.hypot(ins.v_east[end], ins.v_north[end]), jnp.mean(lat))
    extra = coupling = None  # "markov": the Eötvös error told at its Schuler length
    matcher = cfg.matcher
    if cfg.segment_error != "markov":
        b = tables.backward[:, :4].reshape(lat.shape[0], cfg.fix_every, 4, -1).mean(1)
        cell = 0.0
        if cfg.cell_error:
            cell = _cell(cfg, reach)
            matcher = dataclasses.replace(matcher, resolved_n_effective=0.0)
        extra, coupling = segment_error_covariance(prepare_map(grid), lat, lon, v_e, v_n, b,
                                                   h_mean, p, cfg.segment_error == "conditional",
                                                   cell)
        extra, sig_e = jnp.where(jnp.isfinite(extra), extra, 0.0), jnp.zeros_like(sig_e)
    if cfg.fix_prior:  # the filter's prior on the offsets, tempered by the inflation
        prior = h_mean @ p @ h_mean.T / _inflation(cfg)
        matcher = dataclasses.replace(matcher, offset_prior_m2=0.5 * (prior + prior.T),
                                      max_sigma_m=jnp.inf)
    res = match_segment(matcher, grid, lat, lon, jnp.where(jnp.isfinite(g), g, 0.0), reach,
                        sig_e, (cfg.min_spacing_m, cfg.max_spacing_m), length_e, extra, coupling)
    return res, reach, usable


def _fix(cfg, tables, grid, ins, gravity, x, p, end, run):
    """Match the segment ending at ``end`` and update the filter with the fix (``run``:
    failed fixes in a row before it, :mod:`~jaxgrav.navigate.loose_reacquire`)."""
    h_mean = tables.h_mean
    res, reach, usable = fix_segment(cfg, tables, grid, ins, gravity, x, p, end)
    complete = end - tables.backward.shape[0] >= 0
    offset = jnp.stack([res.offset_north_m, res.offset_east_m])
    floor = 0.0 if cfg.fix_prior else cfg.fix_sigma_floor_m**2
    cov = res.covariance_m2
    if cfg.cell_error:  # the cell's variance is in the likelihood already
        cov = less_cell(cov, _cell(cfg, reach) ** 2 / 12.0)
    r = (cov * _inflation(cfg) + floor * jnp.eye(2)).astype(p.dtype)
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
    shape_nis, fits = jnp.full_like(nis, jnp.nan), jnp.asarray(True)
    if cfg.shape_update:  # a fix whose readings do not fit the matched segment is rejected
        lat, lon, g, v_e, v_n, _ = corrected_segment(cfg, tables, ins, gravity, x, end)
        b = tables.backward[:, :4].reshape(lat.shape[0], cfg.fix_every, 4, -1).mean(1)
        x_gated, p_gated = x_new, p_new
        x_new, p_new, shape_nis = shape_update(prepare_map(grid), cfg.matcher, lat, lon, g, v_e,
                                               v_n, b, h_mean, x, x_new, p_new, offset,
                                               _inflation(cfg), gated)
        fits = ~(shape_nis > chi2_quantile(SHAPE_GATE_P, lat.shape[0]))
        x_new, p_new = jnp.where(fits, x_new, x), jnp.where(fits, p_new, p)
        if cfg.reacquire_after is not None and cfg.reacquire_skip_shape:
            # the fix that ends a run of failures: tested, but if its readings fit it
            # updates the filter by itself (the filter was off by more than it said: the
            # linearised shape update from there is not to be trusted)
            found = fits & (run >= cfg.reacquire_after)
            x_new, p_new = jnp.where(found, x_gated, x_new), jnp.where(found, p_gated, p_new)
    event = jnp.select([~complete, ~usable, ~res.accepted, ~gated, ~fits], [1, 2, 3, 4, 5], 0)
    status = jnp.where(usable, res.status, 0)
    return x_new, p_new, (event, status, offset, r, reach, jnp.where(usable, nis, jnp.nan),
                          shape_nis)


def first_segment_ends(cfg, n_seg):
    """How many of ``n_seg`` segment ends are matched on the first segments' span (static):
    those before ``n_fixes`` fixes exist, when ``first_n_fixes`` is set; else 0."""
    if cfg.first_n_fixes is None:
        return 0
    return min(-(-cfg.n_fixes // cfg.stride) - 1, n_seg)


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
    # to the last segment end, and at least one segment's span (a voyage shorter than it)
    pad = max(n_seg * steps_between + 1, cfg.n_fixes * m) - n
    ins_p = Track(*(jnp.concatenate([a, jnp.repeat(a[-1:], pad)]) for a in ins))
    grav_p = jnp.concatenate([voyage.gravity, jnp.full((pad,), jnp.nan, voyage.gravity.dtype)])
    dt = (ins.t[-1] - ins.t[0]) / (ins.t.shape[0] - 1)  # the mean step, not the first's
    tables = error_kf_tables(cfg.ins, jnp.mean(ins.lat), dt, steps_between, cfg.n_fixes * m)
    p0 = initial_covariance(cfg.ins, cfg.sigma_pos_m, cfg.sigma_vel)
    x0 = jnp.zeros(p0.shape[0], p0.dtype)

    def step(seg_tables):
        def body(carry, j):
            x, p, lost = carry
            xs, pos_cov = spread(tables, x, p)
            x_pred = tables.step_f @ x
            p_pred = tables.step_f @ p @ tables.step_f.T + tables.step_q
            end = (j + 1) * steps_between
            x_new, p_new, events = _fix(cfg, seg_tables, grid, ins_p, grav_p, x_pred, p_pred,
                                        end, lost)
            p_new, lost = reacquire(cfg, p_new, lost, events[0], events[1])
            return (x_new, p_new, lost), (xs, pos_cov, events)
        return body

    # the first segment ends on the first segments' shorter span, then the full one
    n_first = first_segment_ends(cfg, n_seg)
    carry, out = (x0, p0, jnp.zeros((), jnp.int32)), []
    for seg_tables, js in ((first_tables(cfg, tables) if n_first else None,
                            jnp.arange(n_first)), (tables, jnp.arange(n_first, n_seg))):
        if js.shape[0]:
            carry, o = jax.lax.scan(step(seg_tables), carry, js)
            out.append(o)
    x_end, p_end, _ = carry
    xs, pos_cov, events = jax.tree.map(lambda *a: jnp.concatenate(a), *out)
    xs = jnp.concatenate([xs.reshape(-1, x0.shape[0]), x_end[None]])[:n]
    pos_cov = jnp.concatenate([pos_cov.reshape(-1, 2, 2), p_end[None, :2, :2]])[:n]
    lat, lon = _shift(ins.lat, ins.lon, xs[:, 0], xs[:, 1])
    nav = Track(ins.t, lat, lon, ins.v_east - xs[:, 3], ins.v_north - xs[:, 2])
    fix_time = ins_p.t[0] + (jnp.arange(n_seg) + 1) * steps_between * dt
    return LooseResult(nav, pos_cov, xs, fix_time, *events)
