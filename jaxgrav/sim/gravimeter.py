"""Marine gravimeter signal chain of paper D: disturbances, platform tilt filter, Eötvös.

A gravimeter on a stabilised platform aboard a moving vehicle reads, after normal
gravity is removed (all terms in mGal)::

    reading = Δg + a_v + δg_θ − E + bias + noise

* ``a_v`` — periodic vertical acceleration from swell, 5–10 cm/s² (5 000–10 000
  mGal) at 0.05–0.5 Hz: a sum of sinusoids with random phases;
* ``δg_θ = g_v (cos θ − 1) + a_h sin θ`` — platform tilt θ coupling the horizontal
  acceleration ``a_h`` into the sensitive axis (``g_sen = g_v cos θ + a_h sin θ``).
  The platform is a damped second-order system forced by ``a_h/g``
  (:class:`PlatformModel`), so δg_θ has a constant part (not removed by low-pass
  filtering) and a part at twice the swell frequency;
* ``E`` — the Eötvös effect (:func:`jaxgrav.eotvos`, positive moving east).

The chain: estimate θ with the 2-state Kalman filter (state θ, θ̇; the gyro measures
θ̇, ``C = [0 1]``; the measured ``a_h`` drives the model) and subtract
:func:`tilt_correction`; correct Eötvös from the velocity (:func:`jaxgrav.eotvos`)
or from the map (:func:`eotvos_from_map`); low-pass filter
(:func:`jaxgrav.sim.fir.apply_fir`) to remove the swell.

This module simulates the raw record (:func:`simulate_gravimeter`) and re-exports the
chain's other pieces: the platform (:mod:`jaxgrav.sim.platform_model`), the tilt
Kalman filter (:mod:`jaxgrav.sim.tilt_filter`) and the tilt and Eötvös corrections
(:mod:`jaxgrav.sim.gravimeter_corrections`).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import check_finite, check_latitude, concrete
from jaxgrav.constants import MGAL
from jaxgrav.geodesy import eotvos, normal_gravity
from jaxgrav.sim.gravimeter_corrections import eotvos_from_map, tilt_correction
from jaxgrav.sim.platform_model import (
    G0,
    PlatformModel,
    platform_discrete,
    platform_response,
)
from jaxgrav.sim.tilt_filter import TiltKF, TiltKFState, run_tilt_kf, tilt_kalman

__all__ = [
    "G0",
    "Disturbances",
    "GravimeterConfig",
    "GravimeterRecord",
    "PlatformModel",
    "TiltKF",
    "TiltKFState",
    "eotvos_from_map",
    "platform_discrete",
    "platform_response",
    "run_tilt_kf",
    "simulate_gravimeter",
    "tilt_correction",
    "tilt_kalman",
]


@pytree_dataclass
class GravimeterConfig:
    """Disturbance and sensor settings of :func:`simulate_gravimeter` (all sweepable).

    Attributes
    ----------
    vertical_amp, vertical_freq : tuple or Array, shape ``(K,)``
        Swell components of the vertical acceleration: amplitude (m/s²) and
        frequency (Hz). Paper D: 5–10 cm/s² at 0.05–0.5 Hz.
    horizontal_amp, horizontal_freq : tuple or Array, shape ``(J,)``
        Components of the horizontal acceleration forcing the platform (m/s², Hz).
    platform : PlatformModel
    noise_mgal : float
        White noise of the gravimeter (mGal, per sample).
    bias_mgal : float
        Constant gravimeter bias (mGal).
    accel_noise : float
        White noise of the horizontal accelerometer (m/s², per sample).
    gyro_noise : float
        White noise of the platform gyro (rad/s, per sample).
    height : float
        Sensor height above the ellipsoid (m; negative when submerged).
    eotvos_form : {"full", "simple"}
        Form of :func:`jaxgrav.eotvos` (static).
    """

    vertical_amp: tuple = (0.08, 0.06, 0.05)
    vertical_freq: tuple = (0.07, 0.12, 0.25)
    horizontal_amp: tuple = (0.1, 0.05)
    horizontal_freq: tuple = (0.09, 0.16)
    platform: PlatformModel = PlatformModel()
    noise_mgal: float = 1.0
    bias_mgal: float = 0.0
    accel_noise: float = 0.01
    gyro_noise: float = 2e-5
    height: float = 0.0
    eotvos_form: str = static_field("full")


class Disturbances(NamedTuple):
    """True disturbance terms of a simulated record, each shape ``(N,)``.

    Attributes
    ----------
    vertical, tilt, eotvos : Array
        ``a_v``, ``δg_θ`` and ``E`` (mGal); the reading holds ``+a_v + δg_θ − E``.
    theta, theta_rate : Array
        Platform tilt (rad) and tilt rate (rad/s).
    accel_h : Array
        True horizontal acceleration (m/s²).
    """

    vertical: jax.Array
    tilt: jax.Array
    eotvos: jax.Array
    theta: jax.Array
    theta_rate: jax.Array
    accel_h: jax.Array


class GravimeterRecord(NamedTuple):
    """A simulated raw record sampled at the track's epochs.

    Attributes
    ----------
    t : Array, shape ``(N,)``
        Time (s).
    reading : Array, shape ``(N,)``
        Gravimeter output minus normal gravity (mGal).
    accel_h : Array, shape ``(N,)``
        Measured horizontal acceleration (m/s²).
    gyro : Array, shape ``(N,)``
        Measured platform tilt rate (rad/s).
    truth : Disturbances
    """

    t: jax.Array
    reading: jax.Array
    accel_h: jax.Array
    gyro: jax.Array
    truth: Disturbances


def _sinusoids(t, amp, freq, phase):
    amp, freq = jnp.asarray(amp, dtype=t.dtype), jnp.asarray(freq, dtype=t.dtype)
    return amp, freq, 2 * jnp.pi * freq * t[:, None] + phase  # (N, K) arguments


def simulate_gravimeter(key, track, anomaly, config=GravimeterConfig()):  # noqa: B008 (frozen)
    """Simulate the raw gravimeter record along a track (sampled at the track's epochs).

    Parameters
    ----------
    key : PRNG key
        Decides the swell phases and the sensor noises.
    track : Track
        True trajectory, ``N`` fixes uniformly spaced in time (sample rate
        ``1/(t[1] − t[0])``, e.g. 1 Hz); velocities give the Eötvös effect.
    anomaly : array_like, shape ``(N,)``
        True gravity anomaly at the fixes (mGal), e.g.
        :func:`jaxgrav.sim.field_along` of a fine map.
    config : GravimeterConfig

    Returns
    -------
    GravimeterRecord

    Raises
    ------
    ValueError
        (concrete inputs) mismatched lengths, fewer than 2 fixes, non-uniform
        sampling, a non-finite anomaly, or a disturbance frequency at or above
        Nyquist (it would alias into the gravity band).
    """
    t = jnp.asarray(track.t, dtype=jnp.result_type(track.t, float))
    anomaly = jnp.asarray(anomaly, dtype=t.dtype)
    if anomaly.shape != t.shape or t.ndim != 1 or t.shape[0] < 2:
        raise ValueError(
            f"anomaly must have one value per track fix (N ≥ 2); got anomaly shape "
            f"{anomaly.shape}, track.t shape {t.shape}"
        )
    check_finite(anomaly, "anomaly")
    check_latitude(track.lat, "track.lat")
    _check_sampling(track.t, config)
    return _simulate(key, track._replace(t=t), anomaly, config)


@jax.jit
def _simulate(key, track, anomaly, config):
    t = track.t
    nv, nh = len(config.vertical_amp), len(config.horizontal_amp)
    kp, kn = jax.random.split(key)
    phase = jax.random.uniform(kp, (nv + nh,), dtype=t.dtype, maxval=2 * jnp.pi)
    white = jax.random.normal(kn, (3, t.shape[0]), dtype=t.dtype)
    amp, freq, arg = _sinusoids(t, config.vertical_amp, config.vertical_freq, phase[:nv])
    a_v = jnp.sum(amp * jnp.sin(arg), axis=-1)
    amp, freq, arg = _sinusoids(t, config.horizontal_amp, config.horizontal_freq, phase[nv:])
    a_h = jnp.sum(amp * jnp.sin(arg), axis=-1)
    h = platform_response(config.platform, freq)
    th_amp = amp / config.platform.g * jnp.abs(h)
    theta = jnp.sum(th_amp * jnp.sin(arg + jnp.angle(h)), axis=-1)
    rate = jnp.sum(th_amp * 2 * jnp.pi * freq * jnp.cos(arg + jnp.angle(h)), axis=-1)
    g_v = normal_gravity(track.lat, config.height) * MGAL + a_v
    tilt = g_v * (jnp.cos(theta) - 1.0) + a_h * jnp.sin(theta)
    e = eotvos(track.lat, track.v_east, track.v_north, config.height, form=config.eotvos_form)
    reading = anomaly + (a_v + tilt) / MGAL - e + config.bias_mgal + config.noise_mgal * white[0]
    acc = a_h + config.accel_noise * white[1]
    gyro = rate + config.gyro_noise * white[2]
    truth = Disturbances(a_v / MGAL, tilt / MGAL, e, theta, rate, a_h)
    return GravimeterRecord(t, reading, acc, gyro, truth)


def _check_sampling(t, config):
    tc = concrete(t)
    if tc is None:
        return
    steps = np.diff(tc.astype(float))
    dt = steps[0]
    if not (dt > 0 and np.allclose(steps, dt, rtol=1e-6, atol=0)):
        raise ValueError(
            f"track.t must be uniformly increasing (one sample rate); got steps from "
            f"{steps.min()!r} to {steps.max()!r} s"
        )
    for name in ("vertical_freq", "horizontal_freq"):
        f = concrete(getattr(config, name))
        if f is not None and np.any(np.asarray(f) >= 0.5 / dt):
            raise ValueError(
                f"config.{name} must stay below the Nyquist frequency {0.5 / dt:g} Hz of "
                f"the {1 / dt:g} Hz record; got {np.max(f)!r} Hz"
            )
