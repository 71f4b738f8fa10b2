"""The gravimeter's stabilised platform: a damped oscillator forced by ``a_h / g``.

:class:`PlatformModel` (natural frequency, damping, gravity scale), its frequency
response (:func:`platform_response`) and its exact discretisation with a
first-order-hold input (:func:`platform_discrete`), used to simulate the tilt
(:mod:`jaxgrav.sim.gravimeter`) and by the tilt Kalman filter
(:mod:`jaxgrav.sim.tilt_filter`).
"""


import jax
import jax.numpy as jnp

from jaxgrav._linalg import expm
from jaxgrav._pytree import pytree_dataclass

__all__ = ["G0", "PlatformModel", "platform_discrete", "platform_response"]

G0 = 9.80665
"""Nominal gravity (m/s²) scaling the platform's input ``a_h / g``."""


@pytree_dataclass
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
