"""Unscented and extended Kalman filters for one scalar gravity reading per step.

Both predict with the linear INS error model exactly (``x ← F x``, ``P ← F P Fᵀ + Q``;
the unscented transform of a linear map is exact, so sigma-point prediction would
give the same numbers at 2n+1 times the cost) and differ only in the update:

* :func:`ukf` — scaled symmetric sigma points (Julier 2002; paper D):
  ``λ = α²(n + κ) − n``, ``W₀ᵐ = λ/(n+λ)``, ``W₀ᶜ = λ/(n+λ) + 1 − α² + β``,
  ``Wᵢ = 1/(2(n+λ))``, points ``x ± columns of chol((n+λ) P)``.
* :func:`ekf` — the Jacobian of the *same* measurement function by
  ``jax.jacfwd``: no hand-derived Jacobians (paper D's objection to the EKF).

Covariance handling: ``P`` is symmetrised after every step and updated in Joseph
form (EKF) or as ``P − K S Kᵀ`` (UKF); when its Cholesky factor fails, jitter is
added and the ``covariance_repaired`` flag set; if that fails too the update is
skipped (``covariance_failed``). A missing reading (NaN), a sigma point off the
map or a gated innovation skip the update and set a flag: the state stays the
prediction.
"""

import jax
import jax.numpy as jnp

from jaxgrav._linalg import cholesky
from jaxgrav.match.filters.model import (
    STATUS_FILTER,
    Filter,
    FilterState,
    StepInfo,
    gravity_measurement,
)

__all__ = ["ekf", "predict", "sigma_weights", "ukf"]

_JITTER = 1e-9


def predict(state, f, q):
    """Linear prediction ``x ← F x``, ``P ← F P Fᵀ + Q`` (symmetrised)."""
    p = f @ state.p @ f.T + q
    return FilterState(f @ state.x, 0.5 * (p + p.T))


def sigma_weights(n, alpha, beta, kappa):
    """Scaled unscented weights.

    Parameters
    ----------
    n : int
        State dimension (static).
    alpha, beta, kappa : float
        Spread, prior-knowledge and secondary scaling parameters.

    Returns
    -------
    scale : Array, shape ``()``
        ``n + λ``; sigma points are ``x ± √(n+λ) Lᵢ``.
    wm, wc : Array, shape ``(2n + 1,)``
        Mean and covariance weights.
    """
    lam = alpha**2 * (n + kappa) - n
    scale = n + lam
    wi = 0.5 / scale
    rest = jnp.full(2 * n, wi)
    wm = jnp.concatenate([jnp.atleast_1d(lam / scale), rest])
    wc = jnp.concatenate([jnp.atleast_1d(lam / scale + 1.0 - alpha**2 + beta), rest])
    return scale, wm, wc


def _robust_cholesky(p):
    """Cholesky of ``p``, retried with relative jitter; returns (L, repaired, failed)."""
    n = p.shape[0]
    chol = cholesky(p)
    bad = ~jnp.all(jnp.isfinite(chol))
    jitter = _JITTER * (jnp.trace(p) / n + 1e-300)
    chol_j = cholesky(p + jitter * jnp.eye(n, dtype=p.dtype))
    chol = jnp.where(bad, chol_j, chol)
    failed = ~jnp.all(jnp.isfinite(chol))
    return jnp.where(failed, 0.0, chol), bad, failed


def _finish(pred, x_new, p_new, nu, s, flags, skip):
    """Choose the update or the prediction, build the info."""
    x = jnp.where(skip, pred.x, x_new)
    p = jnp.where(skip, pred.p, 0.5 * (p_new + p_new.T))
    sigma = jnp.sqrt(jnp.clip(jnp.diag(p), 0.0, None))
    info = StepInfo(x, sigma, p[:2, :2], nu, s, flags.astype(jnp.int32))
    return FilterState(x, p), info


def _flags(z, s, nu, gate, off_map):
    no_reading = ~jnp.isfinite(z)
    gated = (~no_reading) & (~off_map) & (nu**2 > gate * s)
    flags = (
        jnp.where(no_reading, STATUS_FILTER["no_reading"], 0)
        | jnp.where(off_map & ~no_reading, STATUS_FILTER["off_map"], 0)
        | jnp.where(gated, STATUS_FILTER["gated"], 0)
    )
    return flags, no_reading | off_map | gated


def ukf(measurement=gravity_measurement, *, alpha=0.5, beta=2.0, kappa=0.0, gate=jnp.inf):
    """Unscented Kalman filter for a scalar reading.

    Parameters
    ----------
    measurement : callable
        ``h(field, x, lat, lon) -> ẑ`` (mGal); default :func:`gravity_measurement`.
    alpha : float
        Sigma-point spread. The default 0.5 puts the position sigma points at
        ``α √(n+κ) σ = 1.8 σ`` from the mean for n = 13 — inside a local map and
        across the prior's extent, where the map's curvature matters. Paper D's
        range is ``1e-4 ≤ α < 1``; small α approaches the EKF.
    beta : float
        2 is optimal for a Gaussian prior.
    kappa : float
        Secondary scaling, 0 (paper D) or ``3 − n``.
    gate : float
        Skip updates whose normalised innovation squared exceeds this (default: never).

    Returns
    -------
    Filter
        ``init(x0, P0)``, ``update(state, step, field, dynamics) -> (state, StepInfo)``.
    """

    def init(x0, p0):
        return FilterState(jnp.asarray(x0), jnp.asarray(p0))

    def update(state, step, field, dynamics):
        pred = predict(state, dynamics.f, dynamics.q)
        n = pred.x.shape[0]
        scale, wm, wc = sigma_weights(n, alpha, beta, kappa)
        chol, repaired, failed = _robust_cholesky(pred.p)
        delta = jnp.sqrt(scale) * chol.T  # rows are the sigma offsets
        points = jnp.concatenate([pred.x[None], pred.x + delta, pred.x - delta])
        zs = jax.vmap(lambda xi: measurement(field, xi, step.lat, step.lon))(points)
        off_map = ~jnp.all(jnp.isfinite(zs))
        zs = jnp.where(jnp.isfinite(zs), zs, 0.0)  # double-where: no NaN into the algebra
        z_hat = wm @ zs
        dz = zs - z_hat
        s = wc @ dz**2 + step.r
        pxz = (wc * dz) @ (points - pred.x)
        z = jnp.where(jnp.isfinite(step.z), step.z, z_hat)
        nu = z - z_hat
        k = pxz / s
        x_new = pred.x + k * nu
        p_new = pred.p - s * jnp.outer(k, k)
        flags, skip = _flags(step.z, s, nu, gate, off_map)
        flags = flags | jnp.where(repaired, STATUS_FILTER["covariance_repaired"], 0)
        flags = flags | jnp.where(failed, STATUS_FILTER["covariance_failed"], 0)
        nu_out = jnp.where(jnp.isfinite(step.z), nu, jnp.nan)
        return _finish(pred, x_new, p_new, nu_out, s, flags, skip | failed)

    return Filter(init, update)


def ekf(measurement=gravity_measurement, *, gate=jnp.inf):
    """Extended Kalman filter; ``H = jax.jacfwd`` of the measurement function.

    Parameters
    ----------
    measurement : callable
        ``h(field, x, lat, lon) -> ẑ`` (mGal).
    gate : float
        Skip updates whose normalised innovation squared exceeds this.

    Returns
    -------
    Filter
    """

    def init(x0, p0):
        return FilterState(jnp.asarray(x0), jnp.asarray(p0))

    def update(state, step, field, dynamics):
        pred = predict(state, dynamics.f, dynamics.q)
        z_hat = measurement(field, pred.x, step.lat, step.lon)
        h = jax.jacfwd(measurement, argnums=1)(field, pred.x, step.lat, step.lon)
        off_map = ~(jnp.isfinite(z_hat) & jnp.all(jnp.isfinite(h)))
        z_hat = jnp.where(off_map, 0.0, z_hat)
        h = jnp.where(off_map, 0.0, h)
        ph = pred.p @ h
        s = h @ ph + step.r
        k = ph / s
        z = jnp.where(jnp.isfinite(step.z), step.z, z_hat)
        nu = z - z_hat
        x_new = pred.x + k * nu
        ikh = jnp.eye(pred.x.shape[0], dtype=pred.p.dtype) - jnp.outer(k, h)
        p_new = ikh @ pred.p @ ikh.T + step.r * jnp.outer(k, k)  # Joseph form
        flags, skip = _flags(step.z, s, nu, gate, off_map)
        nu_out = jnp.where(jnp.isfinite(step.z), nu, jnp.nan)
        return _finish(pred, x_new, p_new, nu_out, s, flags, skip)

    return Filter(init, update)
