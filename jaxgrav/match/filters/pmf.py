"""Grid point-mass filter over the INS position error, with the gravimeter bias marginalised.

The standard terrain-navigation baseline (Bergman 1999): the posterior of the
horizontal position error ``(d_n, d_e)`` lives on a fixed ``G × G`` grid of cells
centred on zero error. Each cell also carries a Gaussian for the gravimeter bias
δg_a (a one-state Kalman filter per cell, Rao–Blackwellised), so an unknown bias
does not have to be gridded.

Prediction between readings is diffusion: a random walk of the position error
with density ``q_pos`` (m²/s), applied as the exact-variance three-point stencil
``[v/2, 1 − v, v/2]`` along each axis, ``v = q_pos Δt / cell²`` (requires
``v ≤ 1``, checked by :func:`pmf`'s caller through ``grid_edge``/``status``). The
bias moments are mixed with the weights (moment matching). The update multiplies
each cell by the likelihood of the reading given that cell's map value and bias
``N(z − Δg_M(cell) − b_c; 0, s_c + r)``. A missing reading or a cell off the map
skips the update (off-map cells keep their weight only if the whole grid is off).

The estimate is the posterior mean; its covariance is the posterior covariance of
the grid (plus the cell's own variance ``cell²/12``), so NEES can be computed.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._linalg import inv_2x2
from jaxgrav.match.filters.model import STATUS_FILTER, Filter, StepInfo, gravity_measurement

__all__ = ["PMFState", "pmf", "run_pmf"]


class PMFState(NamedTuple):
    """Point-mass filter state.

    Attributes
    ----------
    w : Array, shape ``(G, G)``
        Normalised cell weights (north index first).
    bias_mean, bias_var : Array, shape ``(G, G)``
        Per-cell Gaussian of the gravimeter bias (mGal, mGal²).
    """

    w: jax.Array
    bias_mean: jax.Array
    bias_var: jax.Array


def _diffuse(a, v):
    """Three-point stencil along both axes, zero flux at the edges (mass conserving)."""

    def along(x, axis):
        lo = jnp.concatenate([jnp.take(x, jnp.array([0]), axis), jnp.delete(x, -1, axis)], axis)
        hi = jnp.concatenate([jnp.delete(x, 0, axis), jnp.take(x, jnp.array([-1]), axis)], axis)
        return (1.0 - v) * x + 0.5 * v * (lo + hi)

    return along(along(a, 0), 1)


def pmf(n_cells=61, cell_m=200.0, *, q_pos=4.0, measurement=gravity_measurement):
    """Grid point-mass filter.

    Parameters
    ----------
    n_cells : int
        Cells per axis ``G`` (static, odd so that zero error is a cell centre).
    cell_m : float
        Cell size (m). The grid spans ``±(G−1)/2 · cell`` (default ±6 km, 3σ of a
        2 km error).
    q_pos : float
        Random-walk density of the position error (m²/s): covers the Schuler
        wander of the velocity error that the grid does not model (default: a
        0.2 m/s error wanders ~160 m in a quarter Schuler period).
    measurement : callable
        ``h(field, x, lat, lon)``, evaluated with ``x`` holding a cell's offset and
        zero bias.

    Returns
    -------
    Filter
        ``init(x0, P0)`` takes the Gaussian prior of the 13-state error model (uses
        its position and bias blocks); ``update(state, step, field, dynamics)``
        ignores ``dynamics`` except for the step length implied by ``q_pos``:
        pass ``dynamics=dt`` (s) as a scalar.
    """
    half = (n_cells - 1) / 2
    offsets = (jnp.arange(n_cells) - half) * cell_m
    dn, de = jnp.meshgrid(offsets, offsets, indexing="ij")

    def init(x0, p0):
        d = jnp.stack([dn - x0[0], de - x0[1]], -1)
        info = inv_2x2(p0[:2, :2])
        logw = -0.5 * jnp.einsum("...i,ij,...j->...", d, info, d)
        w = jnp.exp(logw - logw.max())
        shape = (n_cells, n_cells)
        return PMFState(w / w.sum(), jnp.full(shape, x0[12]), jnp.full(shape, p0[12, 12]))

    def _cell_values(field, step):
        x = jnp.zeros(13)

        def one(a, b):
            return measurement(field, x.at[0].set(a).at[1].set(b), step.lat, step.lon)

        return jax.vmap(jax.vmap(one))(dn, de)

    def update(state, step, field, dt):
        v = q_pos * dt / cell_m**2
        w = _diffuse(state.w, v)
        safe_w = jnp.where(w > 0, w, 1.0)
        m = jnp.where(w > 0, _diffuse(state.w * state.bias_mean, v) / safe_w, state.bias_mean)
        m2 = _diffuse(state.w * (state.bias_var + state.bias_mean**2), v) / safe_w
        s = jnp.where(w > 0, jnp.clip(m2 - m**2, 1e-12, None), state.bias_var)

        has = jnp.isfinite(step.z)
        g = _cell_values(field, step)
        on_map = jnp.isfinite(g)
        nu = jnp.where(has & on_map, step.z - g - m, 0.0)
        var = s + step.r
        loglik = jnp.where(on_map, -0.5 * (nu**2 / var + jnp.log(var)), -jnp.inf)
        any_on = jnp.any(on_map)
        loglik = loglik - jnp.max(jnp.where(on_map, loglik, -jnp.inf))
        do = has & any_on
        w_new = jnp.where(do, w * jnp.exp(loglik), w)
        total = w_new.sum()
        do = do & (total > 0)
        w_new = jnp.where(do, w_new / jnp.where(total > 0, total, 1.0), w)
        gain = s / var
        m_new = jnp.where(do, m + gain * nu, m)
        s_new = jnp.where(do, s - gain * s, s)
        state = PMFState(w_new, m_new, s_new)

        mean_n = jnp.sum(w_new * dn)
        mean_e = jnp.sum(w_new * de)
        cn, ce = dn - mean_n, de - mean_e
        cov = jnp.array([[jnp.sum(w_new * cn * cn), jnp.sum(w_new * cn * ce)],
                         [jnp.sum(w_new * cn * ce), jnp.sum(w_new * ce * ce)]])
        cov = cov + jnp.eye(2) * cell_m**2 / 12.0
        bias = jnp.sum(w_new * m_new)
        bias_var = jnp.sum(w_new * (s_new + (m_new - bias) ** 2))
        x = jnp.zeros(13).at[0].set(mean_n).at[1].set(mean_e).at[12].set(bias)
        sigma = jnp.zeros(13).at[0].set(jnp.sqrt(cov[0, 0])).at[1].set(jnp.sqrt(cov[1, 1]))
        sigma = sigma.at[12].set(jnp.sqrt(bias_var))
        edge = (w_new[0].sum() + w_new[-1].sum() + w_new[:, 0].sum() + w_new[:, -1].sum()) > 1e-3
        z_hat = jnp.sum(w * (g + m))
        flags = (
            jnp.where(~has, STATUS_FILTER["no_reading"], 0)
            | jnp.where(has & ~jnp.all(on_map), STATUS_FILTER["off_map"], 0)
            | jnp.where(edge, STATUS_FILTER["grid_edge"], 0)
        )
        info = StepInfo(x, sigma, cov, jnp.where(has, step.z - z_hat, jnp.nan),
                        jnp.where(has, jnp.sum(w * (var + (g + m - z_hat) ** 2)), jnp.nan),
                        flags.astype(jnp.int32))  # fmt: skip
        return state, info

    return Filter(init, update)


def run_pmf(filt, field, dt, x0, p0, steps, every=1):
    """Run a point-mass filter, updating only on every ``every``-th step.

    The grid filter is costly per update (``G²`` map values), and a prediction
    over ``k`` steps is one diffusion with ``k`` times the variance; so the filter
    steps at the reading rate. Readings must sit on steps ``every−1, 2·every−1,
    …`` (index into ``steps``), as in :func:`~jaxgrav.match.filters.paper_d.filter_scenario`;
    others are ignored. Between updates the estimate is held (causal).

    Parameters
    ----------
    filt : Filter
        From :func:`pmf`.
    field : Grid, PointMasses or callable
    dt : float
        Step length (s).
    x0, p0 : Array
        Gaussian prior of the 13-state model.
    steps : Step
        Leading axis ``T``, a multiple of ``every``.
    every : int
        Steps per update (static).

    Returns
    -------
    final : PMFState
    infos : StepInfo
        Leading axis ``T``; the info of each update repeated over its block (the
        first block's leading steps hold the update's values too).
    """
    sub = jax.tree.map(lambda a: a[every - 1 :: every], steps)
    state = filt.init(x0, p0)

    def body(state, step):
        return filt.update(state, step, field, dt * every)

    final, infos = jax.lax.scan(body, state, sub)
    return final, jax.tree.map(lambda a: jnp.repeat(a, every, axis=0), infos)
