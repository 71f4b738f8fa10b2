"""Grid point-mass filter over the INS position error, with the other error states marginalised.

The terrain-navigation baseline (Bergman 1999) with the INS error model in it. The
posterior of the position error ``(d_n, d_e)`` is on ``G × G`` cells; the rest is Gaussian:

* each cell carries a Gaussian for the gravimeter bias δg_a (a one-state Kalman
  filter per cell, Rao–Blackwellised), so an unknown bias is not gridded;
* the velocity, attitude and sensor-bias errors are one Gaussian conditional on
  the position, ``x_o | d ~ N(m_o + K (d − d̄), C)``: a linear regression on the
  position shared by all cells (one ``13 × 13`` mean and covariance in the state,
  whose position block is the grid's mean and covariance).

Prediction, from the linear error model ``x ← F x + w`` (each step moves the
origin and adds to the pending spread; ``settle`` applies the spread to the cells, below):

1. **Drift**: the grid is translated by the mean drift the error model predicts,
   ``s = (F x̄ − x̄)_pos`` (the INS error's Schuler-coupled drift from the estimated
   velocity and attitude errors). The grid's origin is a continuous state, so the
   translation is exact and adds no numerical diffusion.
2. **Diffusion**: each cell's mass spreads by the growth of the position
   variance the error model predicts, ``D = diag(F P Fᵀ + Q − P)_pos`` (clipped at
   0) ``+ q_pos Δt`` — the conditional noise ``F_po C F_poᵀ + Q_pp`` plus the
   coherent growth from the velocity error (the exact model's shear
   ``Δt·K (d − d̄)`` of the grid, matched in variance as a blur); the north–east
   correlation of ``D`` is dropped. The spread is the exact solution of the diffusion
   equation on the cells, ``w ← A_n w A_eᵀ`` with ``A = exp(v/2 · L)``, ``L`` the
   second-difference matrix and ``v = D/cell²``: non-negative, mass-conserving, of
   variance exactly ``v`` (away from the edges) for any ``v`` (closed form in the
   cosine basis that diagonalises ``L``). **Boundary**: zero-flux (reflecting) edges,
   no mass lost; ``status`` flags ``grid_edge`` when more than 1e-3 of the mass sits
   in the outermost cells, and the estimate is then unreliable.
3. **Re-centring** (applied before the spread, folded into ``A``): when the mean is
   half a cell or more from the grid's centre, the weights are shifted by whole cells,
   provided the cells pushed off the far edge hold less than 1e-5 of the mass.

**Pending between readings.** Spreads compose (``A(v₁) A(v₂) = A(v₁ + v₂)``) and the
per-cell models are affine and the same in every cell, so ``predict`` only moves the
centre, predicts the Gaussian part and adds to :attr:`PMFState.pending`; the cells are
spread once (re-centred, re-sized if adaptive), when a reading comes (``update``) or on
``settle``. ``predict``'s reported moments are the settled grid's plus the pending drift
and spread, without the edges' reflection, the re-centring loss or a re-gridding (tested
against the settled grid); its ``grid_edge`` flag is the last settled grid's, so a grid
spreading into its edges between readings is flagged at the next reading. With a
reading every ``k`` steps (``run_filter(..., every=k)``) the cells are spread once per
reading, not ``k`` times.

The Gaussian part is predicted with the Kalman equations, and the per-cell bias
moments are mixed through the same kernel (moment matching). The update
multiplies each cell by the likelihood of the reading given the cell's map value
and bias, ``N(z − Δg_M(cell) − b_c; 0, s_c + r)``; then the Gaussian states move
by the regression, ``m_o ← m_o + K (d̄⁺ − d̄⁻)``, ``C`` unchanged (with a known linear
part of the reading, :attr:`Step.h_lin`, each cell's Gaussian takes the reading too and
the state is the mixture's moments: :mod:`~jaxgrav.filters.pmf_linear`). A missing
reading skips the update; a cell whose map value is unknown (off a Grid map, or a NaN
node within the interpolation's reach) gets the known cells' mean likelihood, so the
reading moves no mass between known and unknown cells, and keeps its bias and linear
part (no cell on the map: no update); with ``missing="land"`` a cell whose nearest
node is NaN gets none: the vehicle cannot be there. The estimate is the posterior
mean; its position covariance is the grid's plus the cell's own ``cell²/12`` (for NEES;
after a ``predict``, plus the pending spread).

**Map-error state** (Rao–Blackwellised, like the bias). When the prior and the
dynamics carry one more state after the 13 INS error states — a first-order
Gauss–Markov map error appended by :func:`~jaxgrav.filters.map_state.augment` with
``order=1`` — each cell carries a joint Gaussian of (bias, map error): means, variances
and their covariance. The reading's likelihood in a cell is
``N(z − Δg_M(cell) − b_c − ε_c; 0, s_b + s_ε + 2 c_bε + r)`` with the cell's predicted
moments, then each cell's pair takes its own two-state Kalman update. The prediction
takes each cell's ``ε ← Φ ε + w`` (from the dynamics' last row) and mixes the pair's
moments through the kernel. Order 2 is refused (ValueError); 13 states: as above.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp

from jaxgrav._linalg import inv_2x2
from jaxgrav._validate import concrete
from jaxgrav.filters.model import (
    STATUS_FILTER,
    Dynamics,
    StepInfo,
    gravity_measurement,
)
from jaxgrav.filters.pmf_cells import (
    MISSING,
    PMFState,
    cell_fields,
    cell_summary,
    cell_values,
    grid_moments,
    mix_cells,
    sync_gaussian,
    weigh_cells,
    with_cells,
)
from jaxgrav.filters.pmf_grid import REGRID_RATIO, check_adaptive, resize_cells, resolving_cell
from jaxgrav.filters.pmf_linear import conditional_reading, mixture_update
from jaxgrav.filters.pmf_predict import (
    affine_cells,
    compose_pending,
    diffusion_kernel,
    no_pending,
    shifted_kernel,
    staying_cells,
)
from jaxgrav.sim.ins import GRAV, N_STATES, INSErrorModel, transition

__all__ = ["PMFFilter", "PMFState", "diffusion_kernel", "pmf"]

EDGE_MASS = 1e-3
"""``grid_edge`` is flagged when the outermost cells hold more than this mass."""
KEEP_WEIGHT = 1e-3
"""An adaptive grid always spans the cells weighing more than this (a distant mode stays)."""
RECENTRE_LOSS = 1e-5
"""Re-centring may push at most this mass off the grid."""
_DEFAULT_INS = INSErrorModel()
_TINY = 1e-13  # cells below this fraction of the total weight take the global bias moments


class PMFFilter(NamedTuple):
    """The point-mass filter: a :class:`~jaxgrav.filters.model.Filter` plus its error model.

    ``init``, ``update`` and ``predict`` follow the ``Filter`` protocol, so
    :func:`~jaxgrav.filters.model.run_filter` runs it: ``init(x0, P0) -> PMFState``;
    ``update(state, step, field, dynamics) -> (state, StepInfo)`` (predict, then the
    reading); ``predict(state, step, field, dynamics) -> (state, StepInfo)`` (no
    reading, no map evaluation; ``step`` only for the ``reading_ignored`` flag).
    ``dynamics(lat, dt) -> Dynamics`` is the error model over a step of ``dt`` seconds at a
    latitude, with ``dt`` filled in (the filter's random-walk spread needs it). The
    ``dynamics`` argument of ``update`` and ``predict`` may also be a scalar ``dt``: a
    pure random walk of density ``q_pos``, no error model. ``settle(state) -> state``
    applies a pending prediction to the cells (``predict`` leaves it pending; ``update``
    settles before the reading).
    """

    init: Callable
    update: Callable
    predict: Callable
    dynamics: Callable
    settle: Callable | None = None


def pmf(n_cells=61, cell_m=200.0, *, q_pos=4.0, ins=_DEFAULT_INS,
        measurement=gravity_measurement, adapt_span=None, min_cell_m=None, max_cell_m=None,
        resolve=None, missing="gaps", spread_dtype=None):
    """Grid point-mass filter with the INS error model's drift.

    Parameters
    ----------
    n_cells : int
        Cells per axis ``G`` (static, odd so that the centre is a cell centre).
    cell_m : float
        Cell size (m). The grid spans ``±(G−1)/2 · cell`` about its centre
        (default ±6 km, 3σ of a 2 km error).
    q_pos : float
        Extra random-walk density of the position error (m²/s) on top of the
        error model's own spread (model mismatch, grid discretisation); the only
        diffusion when ``ins`` is None or ``dynamics`` is a scalar.
    ins : INSErrorModel or None
        Error model of the filter's ``dynamics(lat, dt)``; None: position random walk
        only (no drift), the classic PMF.
    measurement : callable
        ``h(field, x, lat, lon)``, evaluated with ``x`` holding a cell's offset and
        zero bias.
    adapt_span : float, optional
        An adaptive grid, first cell ``cell_m``: whenever the prediction is settled (each
        ``update`` or ``settle``) it is re-centred, and re-sized when it spans fewer than
        ``±adapt_span`` σ of the weights on an axis or more than ``±REGRID_RATIO ·
        adapt_span`` σ, to span the latter (cells within ``[min_cell_m, max_cell_m]``,
        default ``cell_m/4`` and ``8·cell_m``; :mod:`~jaxgrav.filters.pmf_grid`). None
        (default): the fixed grid.
    resolve : float, optional
        An adaptive grid's cells are also kept small enough that the map changes from one
        cell to the next by at most ``resolve`` times the reading's predictive 1-σ where
        the weights are (measured at each reading,
        :func:`~jaxgrav.filters.pmf_grid.resolving_cell`), even if the grid then spans
        less than ``±adapt_span`` σ (its ``grid_edge`` flag says so). None (default): no
        such bound.
    missing : {"gaps", "land"}
        A cell on a missing (NaN) node of a Grid map: a survey gap (default) or land,
        where the vehicle cannot be (:data:`~jaxgrav.filters.pmf_cells.MISSING`).
    spread_dtype : dtype, optional
        Of the spread's two matrix products (:func:`~jaxgrav.filters.pmf_cells.mix_cells`),
        e.g. ``jnp.float32``: ~2 × faster on a CPU, weights and moments still in the
        state's dtype. None (default): the state's dtype.

    Returns
    -------
    PMFFilter
        ``init(x0, P0)`` takes the Gaussian prior of the 13-state error model; the
        grid starts centred on zero error. Run it with
        ``run_filter(filt, field, filt.dynamics(lat, dt), x0, p0, steps, every=k)``.
    """
    if missing not in MISSING:
        raise ValueError(f"missing must be one of {MISSING}; got {missing!r}")
    if n_cells % 2 != 1 or n_cells < 3:
        raise ValueError(f"n_cells must be an odd integer >= 3; got {n_cells!r}")
    half = (n_cells - 1) / 2
    base = (jnp.arange(n_cells) - half) * cell_m
    if adapt_span is not None:
        min_cell_m = cell_m / 4 if min_cell_m is None else min_cell_m
        max_cell_m = cell_m * 8 if max_cell_m is None else max_cell_m
        check_adaptive(adapt_span, min_cell_m, max_cell_m, resolve)
    # the cells' largest extent (an adaptive grid starts at cell_m, then stays in [min, max]);
    # None when a size is traced: the cells are then sampled one by one on a map
    sizes = [concrete(v) for v in ((cell_m,) if adapt_span is None else (cell_m, max_cell_m))]
    span_m = None if any(v is None for v in sizes) else (n_cells - 1) * max(map(float, sizes))

    def _size(state):
        return cell_m if state.cell is None else state.cell

    def cells(centre, c=None):
        """Cell position errors (m) of a grid centred at ``centre`` (cell ``c``, or cell_m)."""
        if c is None:
            return jnp.meshgrid(centre[0] + base, centre[1] + base, indexing="ij")
        i = jnp.arange(n_cells) - half
        return jnp.meshgrid(centre[0] + i * c[0], centre[1] + i * c[1], indexing="ij")

    def init(x0, p0):
        x0, p0 = jnp.asarray(x0, float), jnp.asarray(p0, float)
        centre = jnp.zeros(2, x0.dtype)
        dn, de = cells(centre)
        d = jnp.stack([dn - x0[0], de - x0[1]], -1)
        logw = -0.5 * jnp.einsum("...i,ij,...j->...", d, inv_2x2(p0[:2, :2]), d)
        w = jnp.exp(logw - logw.max())
        w = w / w.sum()
        shape = (n_cells, n_cells)
        n = _n_map_states(x0.shape[0])
        extra = () if not n else tuple(jnp.full(shape, v) for v in (
            x0[N_STATES], p0[N_STATES, N_STATES], p0[GRAV, N_STATES]))
        size = None if adapt_span is None else jnp.full(2, cell_m, x0.dtype)
        cap = None if adapt_span is None or resolve is None else jnp.full(2, jnp.inf, x0.dtype)
        state = PMFState(w, jnp.full(shape, x0[GRAV]), jnp.full(shape, p0[GRAV, GRAV]), centre,
                         x0[:N_STATES], p0[:N_STATES, :N_STATES], *extra, cell=size,
                         pending=no_pending(x0.dtype), cell_cap=cap)
        state = state._replace(summary=cell_summary(w, cell_fields(state)))
        return sync_gaussian(state, *grid_moments(w, dn, de, cell_m))

    def _n_map_states(n):
        if n == N_STATES:
            return 0
        if n == N_STATES + 1:
            return 1
        raise ValueError(f"the point-mass filter takes the {N_STATES} INS error states, plus "
                         "one first-order map-error state (augment with map_error_state(..., "
                         f"order=1)); got {n} states (a second-order map-error state is not "
                         "available in the point-mass filter)")

    def dynamics(lat, dt):
        if ins is None:
            return _random_walk(dt)
        f, q = transition(ins, lat, dt)
        return Dynamics(f, q, jnp.asarray(dt, f.dtype))

    def _random_walk(dt):
        dt = jnp.asarray(dt, float)
        return Dynamics(jnp.eye(N_STATES, dtype=dt.dtype), jnp.zeros((N_STATES,) * 2, dt.dtype),
                        dt)

    def _advance(state, dyn):
        """The prediction over a step, left pending on the cells (no grid work).

        Returns the state and the step's spread variance (m², north and east).
        """
        if not isinstance(dyn, Dynamics):
            dyn = _random_walk(dyn)
        if dyn.dt is None:
            raise ValueError("the point-mass filter needs the step length: pass "
                             "Dynamics(f, q, dt), e.g. from its dynamics(lat, dt)")
        has_err = state.err_mean is not None
        if _n_map_states(dyn.f.shape[0]) != int(has_err):
            raise ValueError(f"the point-mass filter's dynamics have {dyn.f.shape[0]} states "
                             f"but its state {N_STATES + int(has_err)}: augment the dynamics "
                             "and the prior with the same map-error state")
        e = N_STATES
        x, p = state.x, state.p
        f, q = dyn.f[:N_STATES, :N_STATES], dyn.q[:N_STATES, :N_STATES]
        x_new = f @ x
        p_new = f @ p @ f.T + q
        # the grid spreads by the growth of the position variance that the error model
        # predicts (conditional noise plus the coherent growth from the velocity error)
        spread = jnp.maximum(jnp.diagonal(p_new[:2, :2] - p[:2, :2]), 0.0) + q_pos * dyn.dt
        pending = no_pending(x.dtype) if state.pending is None else state.pending
        err = (dyn.f[e, e], dyn.q[e, e]) if has_err else ()
        pending = compose_pending(pending, spread, f[GRAV, GRAV], q[GRAV, GRAV], *err)
        state = state._replace(centre=state.centre + (x_new[:2] - x[:2]), x=x_new,
                               p=0.5 * (p_new + p_new.T), pending=pending)
        return state, spread

    def settle(state):
        """Apply the pending prediction: re-centre, spread, the per-cell models; re-size;
        then the position moments of ``x``, ``p`` are the grid's."""
        state = _settle(state)
        return state._replace(summary=cell_summary(state.w, cell_fields(state)))

    def _settle(state):  # without the summary (update takes its own after the reading)
        if state.pending is None:
            return state
        pending = state.pending
        size = jnp.broadcast_to(jnp.asarray(_size(state), state.x.dtype), (2,))
        # re-centre on the mean by whole cells, unless the cells pushed off hold mass
        k = jnp.round((state.x[:2] - state.centre) / size).astype(jnp.int32)
        k = jnp.clip(k, -(n_cells - 1), n_cells - 1)
        kept = [staying_cells(n_cells, k[a]).astype(state.w.dtype) for a in (0, 1)]
        ok = kept[0] @ state.w @ kept[1] > 1.0 - RECENTRE_LOSS
        k = jnp.where(ok, k, 0)
        a_n, a_e = (shifted_kernel(n_cells, pending[a] / size[a] ** 2, k[a]) for a in (0, 1))
        w, cell = mix_cells(a_n, a_e, state.w, affine_cells(cell_fields(state), pending),
                            _TINY, spread_dtype)
        state = state._replace(w=w, centre=state.centre + k * size,
                               pending=no_pending(pending.dtype))
        state = with_cells(state, cell)
        if adapt_span is not None:  # cells to span ±adapt_span σ (see pmf_grid)
            state = resize_cells(state, cells(state.centre, state.cell), adapt_span,
                                 (min_cell_m, max_cell_m), KEEP_WEIGHT, REGRID_RATIO, _TINY)
        # the Gaussian part's position block := the spread grid's moments, as predicted
        mean, cov = grid_moments(state.w, *cells(state.centre, state.cell), _size(state))
        return sync_gaussian(state, mean, cov, mean)

    def _info(state, mean, cov, innovation, innovation_var, flags):
        glob = affine_cells(list(state.summary[:-1]), state.pending)  # the settled grid's
        x = state.x.at[GRAV].set(glob[0])
        sigma = jnp.sqrt(jnp.maximum(jnp.diagonal(state.p), 0.0)).at[GRAV].set(
            jnp.sqrt(glob[1]))
        if state.err_mean is not None:  # the map error appended, as the Kalman filters do
            x = jnp.append(x, glob[2])
            sigma = jnp.append(sigma, jnp.sqrt(glob[3]))
        flags = flags | jnp.where(state.summary[-1] > EDGE_MASS, STATUS_FILTER["grid_edge"], 0)
        return StepInfo(x, sigma, cov, innovation, innovation_var, flags.astype(jnp.int32))

    def predict(state, step, field, dynamics):
        del field
        cov = state.p[:2, :2]  # the grid's covariance, as the last step left it
        state, spread = _advance(state, dynamics)
        # the pending spread keeps the weights' mean (moved with the centre) and adds its
        # variance: the grid's moments without touching the grid (edge effects aside)
        mean, cov = state.x[:2], cov + jnp.diag(spread)
        state = sync_gaussian(state, mean, cov, mean)
        nan = jnp.full((), jnp.nan, state.x.dtype)
        flags = STATUS_FILTER["no_reading"] | jnp.where(
            jnp.isfinite(step.z), STATUS_FILTER["reading_ignored"], 0)
        return state, _info(state, mean, cov, nan, nan, flags)

    def update(state, step, field, dynamics):
        state = _settle(_advance(state, dynamics)[0])
        w, m, s = state.w, state.bias_mean, state.bias_var
        dn, de = cells(state.centre, state.cell)
        prior_mean = state.x[:2]  # the settled grid's mean

        has = jnp.isfinite(step.z)
        g = cell_values(field, step, dn, de, measurement, span_m)
        on_map = jnp.isfinite(g)
        has_err = state.err_mean is not None
        if has_err:
            em, ev, ec = state.err_mean, state.err_var, state.err_cross
            pred_m, pred_v, cross_b, cross_e = m + em, s + ev + 2.0 * ec, s + ec, ec + ev
        else:
            pred_m, pred_v, cross_b = m, s, s
        lin = (None if step.h_lin is None  # e.g. the Eötvös effect of the velocity error
               else conditional_reading(state.x.at[:2].set(prior_mean), state.p,
                                        step.h_lin, dn, de))
        if lin is not None:
            pred_m, pred_v = pred_m + lin[0], pred_v + lin[1]
        nu = jnp.where(has & on_map, step.z - g - pred_m, 0.0)
        var = pred_v + step.r
        # the likelihood over its largest exponential factor: exp(−ν²/2s) · √(s_min/s), no
        # log per cell (XLA's float64 log costs four times a square root on CPU)
        inv = 1.0 / var
        expo = jnp.where(on_map, -0.5 * nu**2 * inv, -jnp.inf)
        any_on = jnp.any(on_map)
        s_min = jnp.min(jnp.where(on_map, var, jnp.inf))
        lik = jnp.exp(expo - jnp.max(expo)) * jnp.sqrt(s_min * inv)
        # a gap's cell takes the known cells' mean likelihood (zero piled the mass onto a
        # NaN hole's rim: 10 km off with a 450 m σ); land's, zero
        do = has & any_on
        w_new = jnp.where(do, weigh_cells(w, lik, on_map, field, step, dn, de, missing), w)
        total = w_new.sum()
        do = do & (total > 0)
        w_new = jnp.where(do, w_new / jnp.where(total > 0, total, 1.0), w)
        took = do & on_map  # the cells that took the reading
        gain = cross_b / var
        m_new = jnp.where(took, m + gain * nu, m)
        s_new = jnp.where(took, s - gain * cross_b, s)
        state = state._replace(w=w_new, bias_mean=m_new, bias_var=s_new)
        if state.cell_cap is not None:  # the map's resolution where the weights were
            cap = resolving_cell(w, g, var, state.cell, resolve)  # g: NaN off the map
            state = state._replace(cell_cap=jnp.where(do, cap, state.cell_cap))
        if has_err:
            gain_e = cross_e / var
            state = state._replace(err_mean=jnp.where(took, em + gain_e * nu, em),
                                   err_var=jnp.where(took, ev - gain_e * cross_e, ev),
                                   err_cross=jnp.where(took, ec - gain * cross_e, ec))
        mean, cov = grid_moments(w_new, dn, de, _size(state))
        if lin is None:
            state = sync_gaussian(state, mean, cov, prior_mean)
        else:  # each cell's Gaussian updated by the reading, then the mixture's moments
            x, p = mixture_update(w_new, *lin[2:], jnp.where(took, nu / var, 0.0),
                                  jnp.sum(jnp.where(took, w_new / var, 0.0)), mean, cov)
            state = state._replace(x=x, p=p)

        # the predictive moments of the reading: the known cells' (an unknown cell predicts
        # what the known ones do, as in its likelihood)
        w_on = jnp.where(on_map, w, 0.0)
        w_known = w_on / jnp.maximum(jnp.sum(w_on), jnp.finfo(w.dtype).tiny)
        pred = jnp.where(on_map, g + pred_m, 0.0)
        z_hat = jnp.sum(w_known * pred)
        z_var = jnp.sum(w_known * (var + (pred - z_hat) ** 2))
        flags = (jnp.where(~has, STATUS_FILTER["no_reading"], 0)
                 | jnp.where(has & ~jnp.all(on_map), STATUS_FILTER["off_map"], 0))
        used = has & any_on  # no cell on the map: the reading was not used, no innovation
        state = state._replace(summary=cell_summary(state.w, cell_fields(state)))
        return state, _info(state, mean, cov, jnp.where(used, step.z - z_hat, jnp.nan),
                            jnp.where(used, z_var, jnp.nan), flags)

    return PMFFilter(init, update, predict, dynamics, settle)
