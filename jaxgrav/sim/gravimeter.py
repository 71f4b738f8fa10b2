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
"""

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._linalg import expm
from jaxgrav._pytree import static_field
from jaxgrav._validate import check_finite, check_latitude, concrete
from jaxgrav.constants import MGAL
from jaxgrav.geodesy import eotvos, normal_gravity

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

G0 = 9.80665
"""Nominal gravity (m/s²) scaling the platform's input ``a_h / g``."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PlatformModel:
    """Stabilised platform as a damped oscillator forced by horizontal acceleration.

    ``θ̈ + 2ζω₀ θ̇ + ω₀² θ = ω₀² a_h / g``: at low frequency the platform follows the
    apparent vertical, above ``f₀`` it lags and its response falls as ``(f₀/f)²``.

    Attributes
    ----------
    natural_freq_hz : float or Array
        Natural frequency ``f₀ = ω₀/2π`` (Hz).
    damping : float or Array
        Damping ratio ζ (√2/2 minimises the tilt's constant disturbance, paper D).
    g : float or Array
        Gravity scaling the input (m/s²).
    """

    natural_freq_hz: float = 0.02
    damping: float = 0.5**0.5
    g: float = G0


def platform_response(platform, freq_hz):
    """Complex frequency response ``θ / (a_h/g)`` of the platform.

    Parameters
    ----------
    platform : PlatformModel
    freq_hz : array_like
        Frequencies (Hz).

    Returns
    -------
    Array (complex)
        ``H(f) = ω₀² / (ω₀² − ω² + 2jζω₀ω)``, shape of ``freq_hz``.
    """
    w0 = 2 * jnp.pi * jnp.asarray(platform.natural_freq_hz)
    w = 2 * jnp.pi * jnp.asarray(freq_hz)
    return w0**2 / (w0**2 - w**2 + 2j * platform.damping * w0 * w)


@jax.jit
def platform_discrete(platform, dt):
    """Exact discretisation of the platform with a first-order-hold input.

    With ``a_h`` linear between samples,
    ``x_{k+1} = F x_k + G0 a_h[k] + G1 a_h[k+1]`` for ``x = (θ, θ̇)``.

    Parameters
    ----------
    platform : PlatformModel
    dt : float or Array
        Sample interval (s).

    Returns
    -------
    tuple of Array
        ``F`` (2, 2), ``G0`` (2,), ``G1`` (2,) with ``a_h`` in m/s², θ in rad.
    """
    w0 = 2 * jnp.pi * jnp.asarray(platform.natural_freq_hz, dtype=float)
    a = jnp.array([[0.0, 1.0], [-(w0**2), -2 * platform.damping * w0]])
    b = jnp.stack([0.0 * w0, w0**2 / platform.g])
    m = jnp.zeros((4, 4), dtype=a.dtype)
    m = m.at[:2, :2].set(a).at[:2, 2].set(b).at[2, 3].set(1.0)
    e = expm(m * dt)
    gam, lam = e[:2, 2], e[:2, 3] / dt  # ∫e^{Aτ}B dτ and ∫e^{A(dt−s)}B s/dt ds
    return e[:2, :2], gam - lam, lam


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
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


def simulate_gravimeter(key, track, anomaly, config=GravimeterConfig()):
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


def tilt_correction(theta, accel_h, g=G0):
    """Tilt disturbance ``δg_θ = g (cos θ − 1) + a_h sin θ`` in mGal (subtract it).

    Parameters
    ----------
    theta : array_like
        Platform tilt (rad), e.g. the Kalman estimate.
    accel_h : array_like
        Horizontal acceleration (m/s²).
    g : array_like
        Vertical gravity (m/s²).

    Returns
    -------
    Array
        δg_θ (mGal), broadcast shape.
    """
    theta = jnp.asarray(theta)
    return (g * (jnp.cos(theta) - 1.0) + jnp.asarray(accel_h) * jnp.sin(theta)) / MGAL


# ------------------------------------------------------------ platform tilt filter
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


# ------------------------------------------------------------------------ Eötvös
def eotvos_from_map(measured, map_along, valid=None):
    """Map-based Eötvös estimate: mean of the map minus mean of the measured anomaly.

    At constant speed and heading the Eötvös effect ``E`` is nearly constant, and
    after low-pass filtering it is what remains between the measured anomaly
    sequence and the map along the (INS-indicated) track (paper D). Any other
    constant (gravimeter bias, the tilt's constant part) is absorbed too.

    Parameters
    ----------
    measured : array_like, shape ``(N,)``
        Filtered measured anomaly (mGal), e.g. ``apply_fir(...).values``.
    map_along : array_like, shape ``(N,)``
        Map anomaly at the indicated positions (mGal).
    valid : array_like of bool, shape ``(N,)``, optional
        Samples to use (e.g. the FIR ``valid`` mask); non-finite samples of either
        input are always skipped.

    Returns
    -------
    Array, scalar
        Estimated ``E`` (mGal), same sign as :func:`jaxgrav.eotvos`: add it to the
        measured anomaly. NaN if no sample is usable.
    """
    measured, map_along = jnp.asarray(measured), jnp.asarray(map_along)
    if measured.ndim != 1 or measured.shape != map_along.shape:
        raise ValueError(
            f"measured and map_along must be 1-D of equal length; got shapes "
            f"{measured.shape} and {map_along.shape}"
        )
    use = jnp.isfinite(measured) & jnp.isfinite(map_along)
    if valid is not None:
        valid = jnp.asarray(valid, dtype=bool)
        if valid.shape != measured.shape:
            raise ValueError(f"valid must have shape {measured.shape}; got {valid.shape}")
        use = use & valid
    diff = jnp.where(use, map_along, 0.0) - jnp.where(use, measured, 0.0)  # NaN-safe grads
    return jnp.sum(diff) / jnp.where(jnp.any(use), jnp.sum(use), jnp.nan)

