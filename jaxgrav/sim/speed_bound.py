"""Paper D's speed bound: the map detail a vehicle crosses must stay below the swell.

A vehicle crossing a map of node spacing ``n_d`` at speed ``v`` sees the map's finest
detail at ``f_t = v / n_d`` (:func:`signal_frequency`). The low-pass filter
(:mod:`jaxgrav.sim.fir`) separates it from the swell (0.05–0.5 Hz) only while
``f_t ≤ f_dist / factor`` (factor 2.5 in practice), which bounds the speed
(:func:`max_speed`) or, for a given speed, the map spacing (:func:`min_map_spacing`).
"""

import jax.numpy as jnp
import numpy as np

from jaxgrav._validate import concrete

__all__ = ["max_speed", "min_map_spacing", "signal_frequency"]


def signal_frequency(speed, map_spacing):
    """Temporal frequency ``f_t = v / n_d`` (Hz) of the map's finest detail at a speed.

    Parameters
    ----------
    speed : array_like
        Vehicle speed over ground (m/s).
    map_spacing : array_like
        Map node spacing ``n_d`` along the track (m).

    Returns
    -------
    Array
        ``f_t`` in Hz, broadcast shape.
    """
    _check_positive(map_spacing=map_spacing)
    return jnp.asarray(speed) / jnp.asarray(map_spacing)


def max_speed(map_spacing, disturbance_hz=0.05, factor=2.5):
    """Highest speed (m/s) keeping ``f_t = v / n_d ≤ f_dist / factor`` (paper D).

    Parameters
    ----------
    map_spacing : array_like
        Map node spacing ``n_d`` (m).
    disturbance_hz : array_like
        Lowest frequency of the disturbance band (Hz); swell starts at 0.05 Hz.
    factor : array_like
        Separation factor: 2 from Shannon, 2.5 in practice (paper D).

    Returns
    -------
    Array
        Speed bound in m/s (divide by :data:`jaxgrav.constants.KNOT` for knots).
        A 100 m map allows 2 m/s (3.9 kn); the 2.5′ (≈ 4 km) map 80 m/s.
    """
    _check_positive(map_spacing=map_spacing, disturbance_hz=disturbance_hz, factor=factor)
    return jnp.asarray(map_spacing) * jnp.asarray(disturbance_hz) / jnp.asarray(factor)


def min_map_spacing(speed, disturbance_hz=0.05, factor=2.5):
    """Finest map spacing (m) whose detail a vehicle at ``speed`` can still separate.

    The inverse of :func:`max_speed`: ``n_d ≥ factor · v / f_dist``.

    Parameters
    ----------
    speed : array_like
        Speed over ground (m/s).
    disturbance_hz, factor : array_like
        As in :func:`max_speed`.

    Returns
    -------
    Array
        Map spacing in m.
    """
    _check_positive(speed=speed, disturbance_hz=disturbance_hz, factor=factor)
    return jnp.asarray(factor) * jnp.asarray(speed) / jnp.asarray(disturbance_hz)


def _check_positive(**values):
    for name, val in values.items():
        arr = concrete(val)
        if arr is not None and not np.all(np.isfinite(arr) & (arr > 0)):
            raise ValueError(f"{name} must be positive and finite; got {val!r}")
