"""INS drift for matching scenarios (paper A): a slowly varying horizontal position error.

Over the few tens of minutes of a matching track the INS error is nearly a constant
offset ("the INS track is parallel to the true track"). Its size is random with a
Rayleigh law whose σ grows with the time since the last fix (:func:`drift_sigma`:
linearly, ``σ = σ0 + rate·t``); its direction is uniform. The search radius is a
Rayleigh quantile of it (:func:`rayleigh_quantile`). To keep tracks from being
exactly parallel the offset may also grow and rotate slowly along the track.

Distances are in metres on the ground; :data:`DEG_ARC_M` converts the papers'
"degrees" of drift (degrees of arc of the mean Earth sphere) to metres.
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.constants import DEG, WGS84_MEAN_RADIUS
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius

__all__ = [
    "DEG_ARC_M",
    "Drift",
    "apply_drift",
    "drift_offsets",
    "drift_sigma",
    "rayleigh_quantile",
    "rayleigh_sigma",
    "sample_drift",
]

DEG_ARC_M = WGS84_MEAN_RADIUS * DEG
"""Metres per degree of arc on the mean Earth sphere (≈ 111 195 m)."""


def drift_sigma(elapsed_s, sigma_rate_m_per_s, sigma0_m=0.0):
    """Rayleigh scale σ of the drift radius after ``elapsed_s`` since the last fix.

    The INS position error grows from the error of the last fix: ``σ = σ0 + rate·t``
    (linear growth, the first-order behaviour of a velocity error; e.g. a rate of
    0.5 m/s gives σ = 1.8 km an hour after a perfect fix). Pass the result to
    :func:`sample_drift` (``law="rayleigh"``) or :func:`rayleigh_quantile`.

    Parameters
    ----------
    elapsed_s : float or Array
        Time since the last position fix (s), ≥ 0.
    sigma_rate_m_per_s : float or Array
        Growth rate of σ (m/s).
    sigma0_m : float or Array
        σ right after the fix (m).

    Returns
    -------
    Array
        σ (m), broadcast shape of the inputs.
    """
    elapsed = jnp.asarray(elapsed_s, dtype=float)
    return sigma0_m + sigma_rate_m_per_s * elapsed


def rayleigh_quantile(sigma, p):
    """Radius r with P(R ≤ r) = p for a Rayleigh law of scale σ: ``σ √(−2 ln(1 − p))``."""
    return sigma * jnp.sqrt(-2.0 * jnp.log1p(-jnp.asarray(p)))


def rayleigh_sigma(radius, p):
    """Scale σ of the Rayleigh law whose p-quantile is ``radius`` (inverse of the above)."""
    return radius / math.sqrt(-2.0 * math.log1p(-p))


class Drift(NamedTuple):
    """Parameters of one track's INS drift.

    Attributes
    ----------
    radius_m : Array
        Drift radius at the last fix (m).
    direction_rad : Array
        Direction of the offset at the last fix (rad, clockwise from north).
    growth : Array
        Fractional growth of the radius from the first to the last fix (0 = constant).
    rotation_rad : Array
        Rotation of the offset from the first to the last fix (rad).
    """

    radius_m: jax.Array
    direction_rad: jax.Array
    growth: jax.Array
    rotation_rad: jax.Array


def sample_drift(key, sigma_m, *, growth=0.0, rotation_deg=0.0, law="rayleigh"):
    """Draw one track's drift.

    Parameters
    ----------
    key : PRNG key
    sigma_m : float or Array
        ``law="rayleigh"``: Rayleigh scale σ of the radius (m). ``law="fixed"``: the
        radius itself (m), as in a table of fixed drift levels.
    growth : float
        Fractional growth of the radius along the track (e.g. 0.2).
    rotation_deg : float
        Maximum rotation of the offset along the track (degrees); the actual
        rotation is uniform in ±rotation_deg.
    law : {"rayleigh", "fixed"}
        Radius law (static).

    Returns
    -------
    Drift
    """
    k_r, k_d, k_rot = jax.random.split(key, 3)
    sigma_m = jnp.asarray(sigma_m, dtype=float)
    if law == "rayleigh":
        radius = sigma_m * jnp.sqrt(-2.0 * jnp.log1p(-jax.random.uniform(k_r)))
    elif law == "fixed":
        radius = sigma_m
    else:
        raise ValueError(f"law must be 'rayleigh' or 'fixed'; got {law!r}")
    direction = jax.random.uniform(k_d, minval=0.0, maxval=2.0 * jnp.pi)
    rotation = jax.random.uniform(k_rot, minval=-1.0, maxval=1.0) * rotation_deg * DEG
    return Drift(radius, direction, jnp.asarray(growth, dtype=float), rotation)


def drift_offsets(drift, n):
    """North and east offsets (m) of the drift at ``n`` equally spaced fixes.

    The radius grows linearly from ``radius/(1+growth)`` to ``radius`` and the
    direction turns linearly by ``rotation_rad`` from the first fix to the last.

    Returns
    -------
    tuple of Array
        ``(d_north, d_east)``, each ``(n,)`` in metres.
    """
    s = jnp.linspace(0.0, 1.0, n)
    r = drift.radius_m * (1.0 + drift.growth * s) / (1.0 + drift.growth)
    a = drift.direction_rad + drift.rotation_rad * (s - 1.0)
    return r * jnp.cos(a), r * jnp.sin(a)


def apply_drift(lat, lon, d_north, d_east):
    """Shift positions (degrees) by north/east offsets (m) on the WGS84 ellipsoid."""
    lat = jnp.asarray(lat)
    dlat = d_north / meridian_radius(lat) / DEG
    dlon = d_east / (prime_vertical_radius(lat) * jnp.cos(lat * DEG)) / DEG
    return lat + dlat, lon + dlon
