"""The 2-state linear Kalman filter of paper D for the gravimeter platform's tilt.

State ``(θ, θ̇)``, propagated by the platform model (:func:`platform_discrete`) driven
by the measured horizontal acceleration, corrected with the gyro's tilt rate
(``C = [0 1]``). :func:`tilt_kalman` gives an optax-style ``init``/``update`` pair,
:func:`run_tilt_kf` runs it over a record with ``lax.scan``; subtract
:func:`jaxgrav.sim.gravimeter_corrections.tilt_correction` of the estimate.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._validate import check_finite
from jaxgrav.sim.platform_model import platform_discrete

__all__ = ["TiltKF", "TiltKFState", "run_tilt_kf", "tilt_kalman"]


class TiltKFState(NamedTuple):
    """Posterior of the tilt Kalman filter after a sample.

    Attributes
    ----------
    x : Array, shape ``(2,)``
        Tilt θ (rad) and tilt rate θ̇ (rad/s).
    P : Array, shape ``(2, 2)``
        Covariance of ``x``.
    u : Array, scalar
        Last measured horizontal acceleration (m/s²), the start of the next step's
        input ramp.
    count : Array, int scalar
        Samples processed; 0 means ``x``, ``P`` are the prior of the first sample.
    """

    x: jax.Array
    P: jax.Array
    u: jax.Array
    count: jax.Array


class TiltKF(NamedTuple):
    """An ``init``/``update`` pair (optax style) for the platform tilt filter.

    ``init(theta_std=1e-2, rate_std=1e-3, x0=(0, 0)) -> TiltKFState`` and
    ``update(state, gyro, accel_h) -> TiltKFState``: predict one sample with the
    measured horizontal accelerations (m/s²) of the previous and this sample, then
    correct with this sample's gyro rate (rad/s).
    """

    init: callable
    update: callable


def tilt_kalman(platform, dt, accel_noise, gyro_noise):
    """The 2-state linear Kalman filter of paper D for the platform tilt.

    Model ``x_{k+1} = F x_k + G0 a_h[k] + G1 a_h[k+1]`` (:func:`platform_discrete`)
    driven by the *measured* ``a_h``, whose white noise (``accel_noise``) becomes
    process noise ``Q = σ_a² (G0 G0ᵀ + G1 G1ᵀ)``; measurement ``z = C x + v`` with
    ``C = [0 1]`` (the gyro) and ``R = σ_g²``. θ is observable through the
    platform's restoring term.

    Parameters
    ----------
    platform : PlatformModel
    dt : float or Array
        Sample interval (s).
    accel_noise : float or Array
        Accelerometer noise σ_a (m/s²).
    gyro_noise : float or Array
        Gyro noise σ_g (rad/s).

    Returns
    -------
    TiltKF
    """
    f, g0, g1 = platform_discrete(platform, dt)
    q = accel_noise**2 * (jnp.outer(g0, g0) + jnp.outer(g1, g1))
    r = jnp.asarray(gyro_noise, dtype=f.dtype) ** 2

    def init(theta_std=1e-2, rate_std=1e-3, x0=(0.0, 0.0)):
        return _kf_init(jnp.asarray(x0, f.dtype), jnp.asarray(theta_std, f.dtype),
                        jnp.asarray(rate_std, f.dtype))

    def update(state, gyro, accel_h):
        return _kf_update((f, g0, g1, q, r), state, gyro, accel_h)

    return TiltKF(init, update)


@jax.jit
def _kf_init(x0, theta_std, rate_std):
    p = jnp.diag(jnp.stack([theta_std, rate_std]) ** 2)
    return TiltKFState(x0, p, jnp.zeros((), x0.dtype), jnp.zeros((), jnp.int32))


@jax.jit
def _kf_update(model, state, gyro, accel_h):
    f, g0, g1, q, r = model
    first = state.count == 0
    x = jnp.where(first, state.x, f @ state.x + g0 * state.u + g1 * accel_h)
    p = jnp.where(first, state.P, f @ state.P @ f.T + q)
    k = p[:, 1] / (p[1, 1] + r)
    x = x + k * (gyro - x[1])
    ikc = jnp.eye(2, dtype=p.dtype) - jnp.outer(k, jnp.array([0.0, 1.0], dtype=p.dtype))
    p = ikc @ p @ ikc.T + r * jnp.outer(k, k)  # Joseph form
    return TiltKFState(x, p, jnp.asarray(accel_h, f.dtype), state.count + 1)


def run_tilt_kf(platform, dt, gyro, accel_h, accel_noise, gyro_noise, *, theta_std=1e-2,
                rate_std=1e-3):
    """Run the tilt filter over a record with ``lax.scan``.

    Parameters
    ----------
    platform : PlatformModel
    dt : float or Array
        Sample interval (s).
    gyro : array_like, shape ``(N,)``
        Measured tilt rate (rad/s).
    accel_h : array_like, shape ``(N,)``
        Measured horizontal acceleration (m/s²).
    accel_noise, gyro_noise : float or Array
        Their noise standard deviations (m/s², rad/s).
    theta_std, rate_std : float or Array
        Prior standard deviations of θ (rad) and θ̇ (rad/s); prior mean zero.

    Returns
    -------
    TiltKFState
        Posterior at every sample: ``x`` ``(N, 2)``, ``P`` ``(N, 2, 2)``, ``u``,
        ``count`` ``(N,)``. The tilt estimate is ``x[:, 0]``.
    """
    gyro, accel_h = jnp.asarray(gyro), jnp.asarray(accel_h)
    if gyro.ndim != 1 or gyro.shape != accel_h.shape:
        raise ValueError(
            f"gyro and accel_h must be 1-D of equal length; got shapes {gyro.shape} and "
            f"{accel_h.shape}"
        )
    check_finite(gyro, "gyro")
    check_finite(accel_h, "accel_h")
    return _run_tilt_kf(platform, dt, gyro, accel_h, accel_noise, gyro_noise, theta_std,
                        rate_std)


@jax.jit
def _run_tilt_kf(platform, dt, gyro, accel_h, accel_noise, gyro_noise, theta_std, rate_std):
    kf = tilt_kalman(platform, dt, accel_noise, gyro_noise)

    def step(state, zu):
        new = kf.update(state, *zu)
        return new, new

    _, states = jax.lax.scan(step, kf.init(theta_std, rate_std), (gyro, accel_h))
    return states
