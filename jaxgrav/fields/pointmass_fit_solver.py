"""Optimiser of the point-mass fit: linear start, Adam, Levenberg–Marquardt, restarts.

For each of ``n_restarts`` random starts (positions uniform in the inner 90 % of the
box, depths uniform in the inner 80 % of the bounds, :func:`initial_positions`), the
masses and offset are first solved by ridge-regularised linear least squares (the
model is linear in them, :func:`_linear_solve`), then ``steps`` Adam iterations
(optax, cosine-decayed learning rate) update all parameters, then ``polish_steps``
Levenberg–Marquardt (damped Gauss–Newton, :func:`_lm_step`) steps finish the descent.
The restarts are ``jax.vmap``-ed and the iterations are ``lax.scan``-ned
(:func:`fit_batch`): one compiled call runs them all (one compilation per ``K``,
window size and iteration counts). Parameters and loss are those of
:mod:`jaxgrav.fields.pointmass_fit_model`. Package-internal: :func:`fit_batch` and
:func:`initial_positions` serve :func:`jaxgrav.fields.fit_point_masses`.
"""

import functools
import math

import jax
import jax.numpy as jnp
import optax
from jax.flatten_util import ravel_pytree

from jaxgrav.fields.pointmass_fit_model import (
    RawParams,
    mass_positions,
    misfit_loss,
    predict_scaled,
    unit_anomalies,
)


def _linear_solve(raw_lat, raw_lon, raw_depth, p, fit_offset):
    """Masses (and offset) minimising the misfit at fixed positions (ridge 1e-3)."""
    a = unit_anomalies(*mass_positions(RawParams(raw_lat, raw_lon, raw_depth, None, None), p), p)
    if fit_offset:
        a = jnp.concatenate([a, jnp.ones_like(a[:, :1])], axis=1)
    ata = a.T @ a
    lam = 1e-3 * jnp.trace(ata) / ata.shape[0]
    chol = jax.scipy.linalg.cho_factor(ata + lam * jnp.eye(ata.shape[0], dtype=ata.dtype))
    x = jax.scipy.linalg.cho_solve(chol, a.T @ p.target)
    k = raw_lat.shape[0]
    return x[:k], (x[k] if fit_offset else jnp.zeros((), x.dtype))


def _lm_step(x, mu, nu, loss, resid):
    """One Levenberg–Marquardt step on flat parameters; returns (x, mu, nu, loss).

    Marquardt scaling: the normal equations are solved for the column-normalised
    Jacobian, ``(ĴᵀĴ + μI) δ̂ = −Ĵᵀr``, by Cholesky. The damping follows Nielsen
    (1999): on a step with gain ratio ``ρ > 0`` it is accepted and
    ``μ ← μ·max(1/3, 1 − (2ρ − 1)³)``; otherwise it is rejected and ``μ ← μν``,
    ``ν ← 2ν``.
    """
    r = resid(x)
    jac = jax.jacfwd(resid)(x)  # (N, P)
    norm = jnp.sqrt(jnp.sum(jac**2, axis=0))
    norm = jnp.where(norm > 0, norm, 1.0)
    js = jac / norm
    eye = jnp.eye(x.shape[0], dtype=x.dtype)
    chol = jax.scipy.linalg.cho_factor(js.T @ js + mu * eye)
    step = -jax.scipy.linalg.cho_solve(chol, js.T @ r)
    x_new = x + step / norm
    loss_new = jnp.sum(resid(x_new) ** 2)
    predicted = loss - jnp.sum((r + js @ step) ** 2)
    rho = (loss - loss_new) / jnp.where(predicted > 0, predicted, jnp.inf)
    accept = jnp.isfinite(loss_new) & (loss_new < loss) & (rho > 0)
    x = jnp.where(accept, x_new, x)
    loss = jnp.where(accept, loss_new, loss)
    mu = jnp.where(accept, mu * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), mu * nu)
    nu = jnp.where(accept, 2.0, 2.0 * nu)
    mu = jnp.clip(mu, 100.0 * jnp.finfo(x.dtype).eps, 1e8)
    return x, mu, jnp.minimum(nu, 1e8), loss


def _fit_one(raw_pos, p, learning_rate, rtol, *, fit_offset, steps, polish_steps):
    """Fit from one start; raw_pos (3, K) raw lat/lon/depth.

    Returns (RawParams, loss, converged).
    """
    mass, offset = _linear_solve(raw_pos[0], raw_pos[1], raw_pos[2], p, fit_offset)
    raw = RawParams(raw_pos[0], raw_pos[1], raw_pos[2], mass, offset)
    history = []
    if steps > 0:
        schedule = optax.cosine_decay_schedule(learning_rate, steps, alpha=0.02)
        opt = optax.adam(schedule)
        value_and_grad = jax.value_and_grad(misfit_loss)

        def adam_step(carry, _):
            raw, state = carry
            loss, g = value_and_grad(raw, p, fit_offset)
            upd, state = opt.update(g, state, raw)
            return (optax.apply_updates(raw, upd), state), loss

        (raw, _), adam_hist = jax.lax.scan(adam_step, (raw, opt.init(raw)), None, length=steps)
        history.append(adam_hist)
    flat, unravel = ravel_pytree(raw)
    n = p.target.shape[0]

    def resid(x):
        return (predict_scaled(unravel(x), p, fit_offset) - p.target) / math.sqrt(n)

    loss = loss_start = jnp.sum(resid(flat) ** 2)
    if polish_steps > 0:

        def lm(carry, _):
            carry = _lm_step(*carry, resid)
            return carry, carry[-1]

        init = (flat, jnp.asarray(1e-3, flat.dtype), jnp.asarray(2.0, flat.dtype), loss)
        (flat, _, _, loss), lm_hist = jax.lax.scan(lm, init, None, length=polish_steps)
        window = max(1, polish_steps // 4)
        before = lm_hist[-window - 1] if polish_steps > window else loss_start
    else:
        window = max(1, steps // 10)
        before = history[0][-window]
    # converged: stalled, or at the dtype's resolution (RMS <= sqrt(eps)·scale)
    stalled = (before - loss <= rtol * loss) | (loss <= jnp.finfo(flat.dtype).eps)
    converged = jnp.isfinite(loss) & stalled
    return unravel(flat), loss, converged


@functools.partial(jax.jit, static_argnames=("fit_offset", "steps", "polish_steps"))
def fit_batch(raw_pos, p, learning_rate, rtol, *, fit_offset, steps, polish_steps):
    """vmap of :func:`_fit_one` over restarts; raw_pos (R, 3, K)."""
    one = functools.partial(
        _fit_one, fit_offset=fit_offset, steps=steps, polish_steps=polish_steps
    )
    return jax.vmap(one, in_axes=(0, None, None, None))(raw_pos, p, learning_rate, rtol)


def initial_positions(key, n_restarts, k, dtype):
    """Raw (R, 3, K) starts: positions in the inner 90 %, depths in the inner 80 %."""
    u = jax.random.uniform(key, (n_restarts, 3, k), dtype=dtype)
    lo = jnp.asarray([0.05, 0.05, 0.1], dtype)[None, :, None]
    hi = jnp.asarray([0.95, 0.95, 0.9], dtype)[None, :, None]
    q = lo + (hi - lo) * u
    return jnp.log(q) - jnp.log1p(-q)
