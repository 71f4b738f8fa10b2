"""The posterior Cramér–Rao lower bound (PCRLB) of the gravity/INS problem along a track.

Tichavský, Muravchik & Nehorai (1998)'s recursion for the Fisher information ``J`` of the
state, for linear dynamics with additive Gaussian noise (``x ← F x + w``, ``w ~ N(0, Q)``)
and a scalar reading ``z = h(x) + v``, ``v ~ N(0, r)``:

    J_{k+1} = (Q + F J_k⁻¹ Fᵀ)⁻¹ + E[H_{k+1}ᵀ H_{k+1}] / r,   H = ∂h/∂x at the truth.

Written for the covariance bound ``B = J⁻¹`` it is the Kalman covariance recursion with
the measurement row taken at the **true** state (no estimate enters), so no matrix is
inverted: ``B⁻ = F B Fᵀ + Q``, then per reading the rank-one update
``B = B⁻ − B⁻ Hᵀ H B⁻ / (H B⁻ Hᵀ + r)``. The expectation over the truth is the Monte
Carlo average over runs (each run's bound is conditional on its own true trajectory,
the usual practice in terrain- and gravity-aided navigation); ``B`` bounds the mean
squared error of any unbiased estimator of that run. The measurement row is
``jax.jacfwd`` of the filters' own measurement (:mod:`jaxgrav.filters.model`) at the
true error state: the map gradient at the true position, the bias and map-error rows,
and the step's known linear part (:attr:`~jaxgrav.filters.model.Step.h_lin`).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._validate import concrete
from jaxgrav.filters.model import gravity_measurement, prepare_field

__all__ = ["PCRLBResult", "pcrlb"]


class PCRLBResult(NamedTuple):
    """The bound per step.

    Attributes
    ----------
    cov : Array, shape ``(T, n, n)``
        Bound on the error covariance after each step's reading.
    position_rms : Array, shape ``(T,)``
        ``√(B_nn + B_ee)``: the horizontal position error bound (m, RMS).
    off_map : Array, shape ``(T,)``, bool
        A reading at a true position off the map (its value or gradient not finite):
        it adds no information to the bound.
    """

    cov: jax.Array
    position_rms: jax.Array
    off_map: jax.Array


def _value_and_row(measurement, field, x, step):
    """``h`` and ``∂h/∂x`` at ``x`` (off a map the value is NaN, the row may not be)."""
    def h(xi):
        return measurement(field, xi, step.lat, step.lon)

    value, pullback = jax.vjp(h, x)
    return value, pullback(jnp.ones_like(value))[0]


def pcrlb(field, dynamics, p0, steps, true_error, measurement=gravity_measurement):
    """Posterior Cramér–Rao bound of the error state along one run.

    Parameters
    ----------
    field : Grid, PointMasses or callable
        The map the readings are modelled with (mGal).
    dynamics : Dynamics
        ``f``, ``q`` of shape ``(n, n)``.
    p0 : Array, shape ``(n, n)``
        Prior covariance (the bound's start; ``J₀ = P₀⁻¹``).
    steps : Step
        Leading axis ``T``: INS positions, readings (only whether they are finite is
        used), reading variances ``r`` (≥ 0; a concrete negative one is a ValueError, a
        traced one is skipped; ``r = 0``, a perfect reading, counts) and optional
        ``h_lin``.
    true_error : Array, shape ``(T, m)``, ``m ≤ n``
        The true error state at each step, at least its position part (the measurement
        row depends on the position error only; the other states enter linearly). Zero
        is used for the states not given.
    measurement : callable
        ``h(field, x, lat, lon)``; default :data:`~jaxgrav.filters.gravity_measurement`
        (pass :func:`~jaxgrav.filters.augment`'s measurement with its dynamics and prior
        for the map-error state).

    Returns
    -------
    PCRLBResult

    Notes
    -----
    Differentiable and batchable like the filters: ``jax.vmap`` over runs, ``jax.grad``
    of the bound with respect to the map or the noise.
    """
    r = concrete(steps.r)
    if r is not None and r.dtype != object and np.any(r < 0):
        raise ValueError(f"steps.r must be >= 0 (reading variances, mGal²); got "
                         f"{np.min(r)!r} ({int(np.sum(r < 0))} negative)")
    field = prepare_field(field)
    n = p0.shape[0]
    t = steps.z.shape[0]
    x_true = jnp.zeros((t, n), p0.dtype).at[:, : true_error.shape[1]].set(true_error)

    def body(b, inputs):
        step, x = inputs
        b = dynamics.f @ b @ dynamics.f.T + dynamics.q
        value, h = _value_and_row(measurement, field, x, step)
        if step.h_lin is not None:
            h = h + step.h_lin
        off = ~(jnp.isfinite(value) & jnp.all(jnp.isfinite(h)))
        # a perfect reading (r = 0) carries information too; nothing to learn only where
        # the innovation variance vanishes (r = 0 on a flat map); r < 0 is refused
        # above when concrete and skipped when traced
        use = jnp.isfinite(step.z) & ~off & (step.r >= 0.0)
        h = jnp.where(use, h, 0.0)
        bh = b @ h
        use = use & (h @ bh + jnp.where(use, step.r, 0.0) > 0.0)
        s = h @ bh + jnp.where(use, step.r, 1.0)
        b = b - jnp.where(use, 1.0, 0.0) * jnp.outer(bh, bh) / s
        b = 0.5 * (b + b.T)
        return b, (b, off & jnp.isfinite(step.z))

    _, (cov, off) = jax.lax.scan(body, jnp.asarray(p0), (steps, x_true))
    rms = jnp.sqrt(jnp.clip(cov[:, 0, 0] + cov[:, 1, 1], 0.0, None))
    return PCRLBResult(cov, rms, off)
