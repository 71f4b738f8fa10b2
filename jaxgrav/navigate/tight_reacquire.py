"""Re-acquisition of a lost tightly coupled filter by the loosely coupled loop's matcher.

A Kalman filter on the readings (:func:`~jaxgrav.navigate.navigate_tight`) linearises
the map at its own position. Once that position is kilometres off it reads the map in
the wrong place and either drifts on with a covariance that says so (its curvature term
makes it use its readings less and less) or locks onto a wrong track with a covariance
that does not. Neither comes back by itself: its readings are all it has, and it reads
them where it believes it is.

So every ``stride`` fixes of the loop's settings (:class:`~jaxgrav.navigate.LooseConfig`;
with :func:`~jaxgrav.navigate.loose_config`'s dense loop: a 2 h segment every hour), the
segment of the last ``n_fixes`` fixes is matched by the loop's dense matcher
(:func:`~jaxgrav.navigate.fix_segment`) about the filter's corrected track, over a
window sized from the filter's position covariance *opened* by ``sigma_pos`` per axis
(and its velocity by ``sigma_vel``): a filter that is sure and wrong is searched for
beyond its own 1-σ. The fix is a position measurement of the segment's mean error
``H̄ x`` with the matcher's covariance (× ``fix_cov_scale``, plus the loop's floor²);
the matcher is not given the filter's prior (``fix_prior`` False), so the two are
independent estimates of the same position from the same readings. An accepted fix
(the matcher's integrity tests, every reading present, on the map) then

* **resets** the filter when it disagrees with it (``νᵀ(H̄PH̄ᵀ + R)⁻¹ν > gate``,
  χ² with 2 degrees of freedom) or is much sharper than it (the filter's position
  variance over the fix's, traces, above ``ratio²``): the filter's position and
  velocity covariance are opened as for the search, its map-error state returned to
  its prior, and the fix applied to that (Kalman update, Joseph form); with the loop's
  ``shape_update``, the segment's readings then update the rest of the state given the
  fix (:func:`~jaxgrav.navigate.loose_shape.shape_update`: velocity, tilt, bias). The
  filter's own position information, which came from the same readings, is swamped by
  the opening, so the fix is not counted on top of it (its velocity information is only
  widened by ``sigma_vel``: the shape update reuses readings it already holds, an
  approximation taken only on a filter found lost);
* is **not used** otherwise: the filter already holds the segment's readings, and the
  fix on top would count them twice.

The filter runs in one ``lax.scan`` over the fix intervals, each a ``lax.scan`` over its
steps; the check is a masked update (no Python branch), so the whole is ``vmap``-able.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.filters.model import FilterState, prepare_field
from jaxgrav.filters.precision import in_update_precision
from jaxgrav.navigate.error_kf import error_kf_tables, fix_update, innovation_nis
from jaxgrav.navigate.loose import corrected_segment, fix_segment, less_cell
from jaxgrav.navigate.loose_shape import shape_update
from jaxgrav.prepared import prepare_map
from jaxgrav.sim.trajectory import Track

__all__ = ["REACQUIRE_EVENTS", "Reacquisition", "open_covariance", "run_reacquiring"]

REACQUIRE_EVENTS = {
    0: "kept: the fix agrees with the filter (not used: its readings are in the filter)",
    1: "no check: the first segment is not complete",
    2: "not matched: a reading is missing or the segment leaves the map",
    3: "rejected by the matcher's integrity test",
    4: "reset: the fix disagrees with the filter",
    5: "reset: the fix is much sharper than the filter",
}
"""What happened at each check (``Reacquisition.event``)."""


class Reacquisition(NamedTuple):
    """The checks of one voyage (``C`` of them, one per fix interval).

    Attributes
    ----------
    time : Array, shape ``(C,)``
        Time of each check (s): the filter's state after that step's reading.
    event : Array of int, shape ``(C, K)``
        Per stage (``K`` windows, ``TightConfig.reacquire_sigma_m``), see
        :data:`REACQUIRE_EVENTS`.
    nis : Array, shape ``(C, K)``
        ``νᵀ(H̄PH̄ᵀ + R)⁻¹ν`` of the fix against the filter (NaN where not matched).
    offset_m : Array, shape ``(C, K, 2)``
        The fix's correction of the filter's corrected segment (north, east; m).
    fix_cov_m2 : Array, shape ``(C, K, 2, 2)``
        The fix's covariance as used (m²).
    """

    time: jax.Array
    event: jax.Array
    nis: jax.Array
    offset_m: jax.Array
    fix_cov_m2: jax.Array


def open_covariance(p, p0, sigma_pos, sigma_vel, n_ins=13):
    """The filter's covariance with its position and velocity opened and its map error reset.

    Parameters
    ----------
    p : Array, shape ``(n, n)``
        The filter's covariance (13 INS error states, then the map-error states).
    p0 : Array, shape ``(n, n)``
        Its prior: the rows and columns of the states after ``n_ins`` are set to it.
    sigma_pos, sigma_vel : float or Array
        Added in quadrature to each position (m) and velocity (m/s) axis.
    n_ins : int
        INS error states (static).

    Returns
    -------
    Array, shape ``(n, n)``
    """
    add = jnp.zeros(p.shape[0], p.dtype).at[:2].set(sigma_pos**2).at[2:4].set(sigma_vel**2)
    p = p + jnp.diag(add)
    extra = jnp.arange(p.shape[0]) >= n_ins
    mask = extra[:, None] | extra[None, :]
    return jnp.where(mask, p0, p)


def _pad(a, n, fill=None):
    """``a`` padded along its first axis to ``n`` rows (its last row, or ``fill``)."""
    tail = a[-1:] if fill is None else jnp.full((1, *a.shape[1:]), fill, a.dtype)
    return jnp.concatenate([a, jnp.repeat(tail, n - a.shape[0], axis=0)])


def run_reacquiring(filt, grid, dynamics, x0, p0, steps, ins, gravity, loose, *, gate, ratio,
                    sigma_pos, sigma_vel):
    """Run a Kalman filter over a voyage with the matcher's checks (see the module notes).

    Parameters
    ----------
    filt : Filter
        A Kalman filter whose state is :class:`~jaxgrav.filters.FilterState` (``ukf``,
        ``ekf``) over the 13 INS error states and the map-error states.
    grid : Grid or PreparedMap
        The map (the filter and the matcher read it; prepared once).
    dynamics : Dynamics
        One step of the error model.
    x0, p0 : Array, shapes ``(n,)``, ``(n, n)``
        The prior.
    steps : Step
        The filter's steps, shape ``(N, ...)`` per field.
    ins : Track
        The INS-indicated track, shape ``(N,)``.
    gravity : Array, shape ``(N,)``
        Raw readings (mGal; Eötvös not corrected).
    loose : LooseConfig
        The matcher and the segments (``n_fixes``, ``stride``, ``fix_every``,
        ``segment_error``, ``cell_error``, ``fix_cov_scale``, ``fix_sigma_floor_m``).
    gate : float or Array
        χ²(2) above which the fix resets the filter.
    ratio : float or Array
        The filter's position σ over the fix's (traces) above which the fix resets it.
    sigma_pos : float or Array, shape ``(K,)``
        The opening of the position covariance (m per axis), one per stage: the check
        is run ``K`` times in turn (e.g. a wide window to find a lost filter, then a
        narrow one to find a drifting one), each on the state the previous left.
    sigma_vel : float or Array
        The opening of the velocity covariance (m/s per axis).

    Returns
    -------
    infos : StepInfo
        Leading axis ``N``.
    checks : Reacquisition
    """
    lc = loose
    n = steps.z.shape[0]
    span, every = lc.n_fixes * lc.fix_every, lc.stride * lc.fix_every
    n_chunks = -(-n // every)
    n_pad = n_chunks * every
    steps_p = jax.tree.map(lambda a: _pad(a, n_pad), steps)
    steps_p = steps_p._replace(z=_pad(steps.z, n_pad, jnp.nan))
    ins_p = Track(*(_pad(a, max(n_pad, span)) for a in ins))
    grav_p = _pad(gravity, max(n_pad, span), jnp.nan)
    dt = dynamics.dt
    tables = error_kf_tables(lc.ins, jnp.mean(ins.lat), dt, every, span)
    # the state checked is after the reading of step end − 1: F^{-k} F = F^{-(k-1)}
    back = tables.backward @ dynamics.f[:13, :13]
    tables = tables._replace(backward=back, h_mean=jnp.mean(back[:, :2, :], axis=0))
    n_x = x0.shape[0]
    h_full = jnp.concatenate([tables.h_mean, jnp.zeros((2, n_x - 13), tables.h_mean.dtype)], 1)
    grid = prepare_map(grid)
    field = prepare_field(grid)
    state = filt.init(x0, p0)
    state = in_update_precision(filt, state, jax.tree.map(lambda a: a[0], steps), field,
                                dynamics)
    blocks = jax.tree.map(lambda a: a.reshape(n_chunks, every, *a.shape[1:]), steps_p)

    def check(end, state, sigma_p):
        """One stage of the check at ``end``: match, test, reset where lost."""
        x, p = state.x, state.p
        opened = open_covariance(p, p0, sigma_p, sigma_vel)
        res, reach, usable = fix_segment(lc, tables, grid, ins_p, grav_p, x[:13],
                                         opened[:13, :13], end)
        complete = end - span >= 0
        offset = jnp.stack([res.offset_north_m, res.offset_east_m])
        cov = res.covariance_m2
        if lc.cell_error:  # the cell's variance is in the likelihood already
            cell = jnp.clip(reach / lc.matcher.half_size, lc.min_spacing_m, lc.max_spacing_m)
            cov = less_cell(cov, cell**2 / 12.0)
        r = (cov * lc.fix_cov_scale + lc.fix_sigma_floor_m**2 * jnp.eye(2)).astype(p.dtype)
        good = complete & usable & res.accepted & jnp.all(jnp.isfinite(r))
        r = jnp.where(jnp.isfinite(r), r, jnp.eye(2, dtype=p.dtype))
        nu = jnp.where(good, -offset, 0.0).astype(p.dtype)
        nis = innovation_nis(p, nu, r, h_full)
        disagrees = nis > gate
        sharper = jnp.trace(h_full @ p @ h_full.T) > ratio**2 * jnp.trace(r)
        reset = good & (disagrees | sharper)
        x_open = x.at[13:].set(x0[13:])
        x_new, p_new, _ = fix_update(x_open, opened, nu, r, h_full, reset)
        if lc.shape_update:  # the segment's readings given the fix: velocity, tilt, bias
            lat, lon, g, v_e, v_n, _ = corrected_segment(lc, tables, ins_p, grav_p, x[:13], end)
            b = tables.backward[:, :4].reshape(lat.shape[0], lc.fix_every, 4, -1).mean(1)
            x13, p13, _ = shape_update(grid, lc.matcher, lat, lon,
                                       jnp.where(jnp.isfinite(g), g, 0.0), v_e, v_n, b,
                                       tables.h_mean, x[:13], x_new[:13], p_new[:13, :13],
                                       offset, 1.0, reset)
            x_new, p_new = x_new.at[:13].set(x13), p_new.at[:13, :13].set(p13)
        state = FilterState(jnp.where(reset, x_new, x), jnp.where(reset, p_new, p))
        event = jnp.select([~complete, ~usable, ~res.accepted, reset & disagrees, reset],
                           [1, 2, 3, 4, 5], 0)
        return state, (event, jnp.where(complete & usable, nis, jnp.nan), offset, r)

    stages = jnp.atleast_1d(jnp.asarray(sigma_pos, p0.dtype))

    def chunk(state, args):
        j, block = args
        state, infos = jax.lax.scan(lambda s, st: filt.update(s, st, field, dynamics), state,
                                    block)
        end = (j + 1) * every
        state, out = jax.lax.scan(lambda s, sig: check(end, s, sig), state, stages)
        return state, (infos, out)

    _, (infos, out) = jax.lax.scan(chunk, state, (jnp.arange(n_chunks), blocks))
    infos = jax.tree.map(lambda a: a.reshape(n_pad, *a.shape[2:])[:n], infos)
    time = ins_p.t[0] + ((jnp.arange(n_chunks) + 1) * every - 1) * dt
    return infos, Reacquisition(time, *out)
