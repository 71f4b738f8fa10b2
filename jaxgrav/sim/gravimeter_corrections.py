"""Corrections of a gravimeter record: platform tilt and map-based Eötvös (mGal).

:func:`tilt_correction` is the tilt disturbance ``δg_θ`` of an estimated tilt (e.g.
from :mod:`jaxgrav.sim.tilt_filter`), to subtract; :func:`eotvos_from_map` estimates
the Eötvös effect as the mean difference between the map along the track and the
filtered measured anomaly, to add. The velocity-based Eötvös correction is
:func:`jaxgrav.eotvos`.
"""

import jax.numpy as jnp

from jaxgrav.constants import MGAL
from jaxgrav.sim.platform_model import G0

__all__ = ["eotvos_from_map", "tilt_correction"]


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
