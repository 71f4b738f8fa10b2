"""Unscented and extended Kalman filters for one scalar gravity reading per step.

Both predict with the linear INS error model exactly (``x ← F x``, ``P ← F P Fᵀ + Q``;
the unscented transform of a linear map is exact, so sigma-point prediction would
give the same numbers at 2n+1 times the cost) and differ only in the update. A
step's known linear measurement part (:attr:`~jaxgrav.filters.model.Step.h_lin`) is
added to ``h`` at every sigma point (UKF) or to ``h`` and its Jacobian (EKF).

Updates:

* :func:`ukf` — scaled symmetric sigma points (Julier 2002; paper D):
  ``λ = α²(n + κ) − n``, ``W₀ᵐ = λ/(n+λ)``, ``W₀ᶜ = λ/(n+λ) + 1 − α² + β``,
  ``Wᵢ = 1/(2(n+λ))``, points ``x ± columns of chol((n+λ) P)``.
* :func:`ekf` — the Jacobian of the *same* measurement function by
  ``jax.jacfwd``: no hand-derived Jacobians (paper D's objection to the EKF).

With a :class:`~jaxgrav.filters.model.MapPlusBias` measurement (the default
:data:`~jaxgrav.filters.model.gravity_measurement`) the UKF evaluates the map
only at the ``2m + 1`` distinct sigma-point positions (m = 2 position states): the
other points share the mean position and differ only in the additive bias. The
numbers are those of the generic ``2n + 1``-point evaluation.

Covariance handling: ``P`` is symmetrised after every step and updated in Joseph
form (EKF) or as ``P − K S Kᵀ`` (UKF). Both factor the predicted ``P`` once per
update with :func:`~jaxgrav._linalg.modified_cholesky` (the UKF for its sigma
points, the EKF only as the check): a non-positive pivot within a relative jitter of
zero is clamped (``covariance_repaired``; the update goes on); a more negative or
non-finite one skips the update (``covariance_failed``). An innovation variance
``S`` that is not positive (a negative or zero reading variance, or the UKF's
negative centre weight ``W₀ᶜ`` with κ < 0 or β < 0) also sets ``covariance_failed``
and skips the update instead of dividing by it. A missing reading (NaN), a sigma
point off the map or a gated innovation skip the update and set a flag: the state
stays the prediction.

Both filters also have a ``predict`` (:class:`~jaxgrav.filters.model.Filter`)
for the steps between readings of ``run_filter(..., every=k)``: ``F x``, ``F P Fᵀ + Q``
and the per-step info, nothing else.
"""

import jax
import jax.numpy as jnp

from jaxgrav._linalg import modified_cholesky
from jaxgrav.filters.model import (
    STATUS_FILTER,
    Filter,
    FilterState,
    MapPlusBias,
    StepInfo,
    gravity_measurement,
)

__all__ = ["MIN_ALPHA_FLOAT32", "ekf", "predict", "sigma_weights", "ukf"]

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
    """One-pass modified Cholesky of ``p``; returns (L, repaired, failed)."""
    return modified_cholesky(p, _JITTER)


def _predict_step(state, step, field, dynamics):
    """A step known to have no reading: the prediction and its info."""
    del field
    pred = predict(state, dynamics.f, dynamics.q)
    sigma = jnp.sqrt(jnp.clip(jnp.diag(pred.p), 0.0, None))
    nan = jnp.full_like(step.z, jnp.nan)
    status = STATUS_FILTER["no_reading"] | jnp.where(
        jnp.isfinite(step.z), STATUS_FILTER["reading_ignored"], 0)
    return pred, StepInfo(pred.x, sigma, pred.p[:2, :2], nan, nan, status.astype(jnp.int32))


def _sigma_measurements(measurement, field, step, x, delta):
    """``h`` at the sigma points ``x``, ``x ± delta[j]`` (rows), shape ``(2n + 1,)``."""
    n = x.shape[0]
    if not isinstance(measurement, MapPlusBias):
        points = jnp.concatenate([x[None], x + delta, x - delta])
        return jax.vmap(lambda xi: measurement(field, xi, step.lat, step.lon))(points)
    # rows j >= m of delta (columns of the lower factor) do not move the position
    m, b = measurement.n_position, measurement.bias_index
    pos = jnp.concatenate([x[None, :m], x[:m] + delta[:m, :m], x[:m] - delta[:m, :m]])
    g = jax.vmap(lambda d: measurement.map_part(field, d, step.lat, step.lon))(pos)
    rest = jnp.broadcast_to(g[0], (n - m,))
    g = jnp.concatenate([g[:1], g[1 : m + 1], rest, g[m + 1 :], rest])
    lin = jnp.concatenate([x[b : b + 1], x[b] + delta[:, b], x[b] - delta[:, b]])
    for i in measurement.extra_indices:
        lin = lin + jnp.concatenate([x[i : i + 1], x[i] + delta[:, i], x[i] - delta[:, i]])
    return g + lin


def _finish(pred, x_new, p_new, nu, s, flags, skip):
    """Choose the update or the prediction, build the info."""
    x = jnp.where(skip, pred.x, x_new)
    p = jnp.where(skip, pred.p, 0.5 * (p_new + p_new.T))
    sigma = jnp.sqrt(jnp.clip(jnp.diag(p), 0.0, None))
    info = StepInfo(x, sigma, p[:2, :2], nu, s, flags.astype(jnp.int32))
    return FilterState(x, p), info


def _flags(z, s, nu, gate, off_map, repaired, failed):
    """Status bits and the skip decision of one update.

    ``failed`` (P not factorable) and a non-positive or NaN innovation variance ``s``
    set ``covariance_failed``; the gate is tested only on a usable ``s``.
    """
    no_reading = ~jnp.isfinite(z)
    bad_s = (~no_reading) & (~off_map) & ~(s > 0.0)
    failed = failed | bad_s
    gated = (~no_reading) & (~off_map) & (~failed) & (nu**2 > gate * s)
    flags = (
        jnp.where(no_reading, STATUS_FILTER["no_reading"], 0)
        | jnp.where(off_map & ~no_reading, STATUS_FILTER["off_map"], 0)
        | jnp.where(gated, STATUS_FILTER["gated"], 0)
        | jnp.where(repaired, STATUS_FILTER["covariance_repaired"], 0)
        | jnp.where(failed, STATUS_FILTER["covariance_failed"], 0)
    )
    return flags, no_reading | off_map | gated | failed


def _curvature_variance(measurement, field, step, x, p):
    """``½ tr((∇²h P)²)``: the variance of the map's second-order term over ``N(x, P)``.

    The Hessian is taken of the map part of a :class:`MapPlusBias` over its position
    states (of the whole measurement otherwise) at the mean; 0 where it is not finite
    (off the map).
    """
    if isinstance(measurement, MapPlusBias):
        m = measurement.n_position
        hess = jax.hessian(lambda d: measurement.map_part(field, d, step.lat, step.lon))(x[:m])
        pp = p[:m, :m]
    else:
        hess = jax.hessian(lambda xi: measurement(field, xi, step.lat, step.lon))(x)
        pp = p  # the step's linear part (h_lin) has no curvature
    hp = hess @ pp
    v = 0.5 * jnp.trace(hp @ hp)
    return jnp.where(jnp.isfinite(v), v, 0.0)


MIN_ALPHA_FLOAT32 = 0.1
"""Smallest UKF ``alpha`` in float32: on paper D's first update α = 0.1 is within 0.4 % of
float64 and α = 0.05 4 % off (review of 2026-12-06, helper-30)."""


def ukf(measurement=gravity_measurement, *, alpha=0.5, beta=2.0, kappa=0.0, gate=jnp.inf,
        curvature_count=0.0):
    """Unscented Kalman filter for a scalar reading.

    Parameters
    ----------
    measurement : callable
        ``h(field, x, lat, lon) -> ẑ`` (mGal); default :data:`gravity_measurement`.
        A :class:`~jaxgrav.filters.model.MapPlusBias` is evaluated at the
        distinct sigma-point positions only.
    alpha : float
        Sigma-point spread. The default 0.5 puts the position sigma points at
        ``α √(n+κ) σ = 1.8 σ`` from the mean for n = 13 — inside a local map and
        across the prior's extent, where the map's curvature matters. Paper D's
        range is ``1e-4 ≤ α < 1``; a small α samples the map close to the mean (a
        second-order filter in the limit, not the EKF: ``β`` keeps the map's
        curvature). In float32 ``α`` must be at least :data:`MIN_ALPHA_FLOAT32`: the
        sigma points then sit a few metres from the mean, closer than float32
        latitudes and longitudes resolve, and the update is wrong without a sign
        (α = 1e-3: innovation variance 70 × too large); ``update`` raises
        ValueError for such a state. Use float64 (``jax_enable_x64``) for smaller α.
    beta : float
        2 is optimal for a Gaussian prior.
    kappa : float
        Secondary scaling, 0 (paper D) or ``3 − n``.
    gate : float
        Skip updates whose normalised innovation squared exceeds this (default: never).
    curvature_count : float or Array
        Add ``curvature_count · ½ tr((∇²h P)²)`` to the reading variance: the map's
        second-order (linearisation) error over the predicted position covariance,
        counted as many times as consecutive readings share it (readings per map cell
        along the track; :func:`~jaxgrav.navigate.navigate_tight`). It vanishes when
        the position is known to much better than the map's curvature scale.
        Default 0: off.

    Returns
    -------
    Filter
        ``init(x0, P0)``, ``update(state, step, field, dynamics) -> (state, StepInfo)``,
        ``predict`` (same signature) for steps without a reading.
    """

    def init(x0, p0):
        return FilterState(jnp.asarray(x0), jnp.asarray(p0))

    def update(state, step, field, dynamics):
        pred = predict(state, dynamics.f, dynamics.q)
        n = pred.x.shape[0]
        if (pred.x.dtype == jnp.float32 and isinstance(alpha, int | float)
                and alpha < MIN_ALPHA_FLOAT32):
            raise ValueError(f"ukf(alpha={alpha!r}) in float32: alpha must be at least "
                             f"{MIN_ALPHA_FLOAT32} there (the sigma points would sit closer "
                             "to the mean than float32 positions resolve); enable float64 "
                             "(jax_enable_x64) or use a larger alpha")
        scale, wm, wc = sigma_weights(n, alpha, beta, kappa)
        chol, repaired, failed = _robust_cholesky(pred.p)
        delta = jnp.sqrt(scale) * chol.T  # rows are the sigma offsets
        points = jnp.concatenate([pred.x[None], pred.x + delta, pred.x - delta])
        zs = _sigma_measurements(measurement, field, step, pred.x, delta)
        if step.h_lin is not None:  # the step's known linear part, at every point
            zs = zs + points @ step.h_lin
        off_map = ~jnp.all(jnp.isfinite(zs))
        zs = jnp.where(jnp.isfinite(zs), zs, 0.0)  # double-where: no NaN into the algebra
        z_hat = wm @ zs
        dz = zs - z_hat
        r = step.r
        if not (isinstance(curvature_count, (int, float)) and curvature_count == 0):
            r = r + curvature_count * _curvature_variance(measurement, field, step, pred.x,
                                                          pred.p)
        s = wc @ dz**2 + r
        pxz = (wc * dz) @ (points - pred.x)
        z = jnp.where(jnp.isfinite(step.z), step.z, z_hat)
        nu = z - z_hat
        k = pxz / jnp.where(s > 0.0, s, 1.0)  # double-where: s <= 0 is a skipped update
        x_new = pred.x + k * nu
        p_new = pred.p - s * jnp.outer(k, k)
        flags, skip = _flags(step.z, s, nu, gate, off_map, repaired, failed)
        nu_out = jnp.where(jnp.isfinite(step.z) & ~off_map, nu, jnp.nan)  # none off map
        return _finish(pred, x_new, p_new, nu_out, s, flags, skip)

    return Filter(init, update, _predict_step)


def ekf(measurement=gravity_measurement, *, gate=jnp.inf, check_covariance=True):
    """Extended Kalman filter; ``H = jax.jacfwd`` of the measurement function.

    Parameters
    ----------
    measurement : callable
        ``h(field, x, lat, lon) -> ẑ`` (mGal).
    gate : float
        Skip updates whose normalised innovation squared exceeds this.
    check_covariance : bool
        Factor the predicted ``P`` with the UKF's modified Cholesky to set
        ``covariance_repaired`` / ``covariance_failed`` (the latter skipping the
        update), as the UKF does (static; default True). The EKF does not need the
        factor, so this is only the check; it costs about a third of the EKF's run
        time on paper D's runs. False: only a non-positive innovation variance is
        caught.

    Returns
    -------
    Filter
        As :func:`ukf`'s, with the same status flags; a non-positive innovation
        variance ``H P Hᵀ + R`` also sets ``covariance_failed`` and skips the update.
    """

    def init(x0, p0):
        return FilterState(jnp.asarray(x0), jnp.asarray(p0))

    def update(state, step, field, dynamics):
        pred = predict(state, dynamics.f, dynamics.q)
        if check_covariance:
            _, repaired, failed = _robust_cholesky(pred.p)  # the UKF's check, factor unused
        else:
            repaired = failed = jnp.zeros((), bool)
        z_hat = measurement(field, pred.x, step.lat, step.lon)
        h = jax.jacfwd(measurement, argnums=1)(field, pred.x, step.lat, step.lon)
        if step.h_lin is not None:  # the step's known linear part
            z_hat, h = z_hat + step.h_lin @ pred.x, h + step.h_lin
        off_map = ~(jnp.isfinite(z_hat) & jnp.all(jnp.isfinite(h)))
        z_hat = jnp.where(off_map, 0.0, z_hat)
        h = jnp.where(off_map, 0.0, h)
        ph = pred.p @ h
        s = h @ ph + step.r
        k = ph / jnp.where(s > 0.0, s, 1.0)  # double-where: s <= 0 is a skipped update
        z = jnp.where(jnp.isfinite(step.z), step.z, z_hat)
        nu = z - z_hat
        x_new = pred.x + k * nu
        ikh = jnp.eye(pred.x.shape[0], dtype=pred.p.dtype) - jnp.outer(k, h)
        p_new = ikh @ pred.p @ ikh.T + step.r * jnp.outer(k, k)  # Joseph form
        flags, skip = _flags(step.z, s, nu, gate, off_map, repaired, failed)
        nu_out = jnp.where(jnp.isfinite(step.z) & ~off_map, nu, jnp.nan)  # none off map
        return _finish(pred, x_new, p_new, nu_out, s, flags, skip)

    return Filter(init, update, _predict_step)
