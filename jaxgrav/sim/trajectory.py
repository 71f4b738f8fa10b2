"""Vehicle trajectories: fixes at a fixed interval on the WGS84 ellipsoid.

Positions are dead-reckoned from speed and heading with the radii of curvature of
each step's mid-latitude (exact to well below a metre over the tens of kilometres
between fixes of a matching track). Everything is JAX: a PRNG key can decide the
start point, and a batch of tracks is a ``vmap`` away.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.constants import DEG
from jaxgrav.geodesy import local_offsets_m, meridian_radius, prime_vertical_radius

__all__ = [
    "Track",
    "random_start",
    "straight_track",
    "track_error_m",
    "track_from_heading",
    "turning_track",
]


class Track(NamedTuple):
    """A sampled trajectory.

    Attributes
    ----------
    t : Array, shape ``(N,)``
        Time of each fix (s).
    lat, lon : Array, shape ``(N,)``
        Position (degrees).
    v_east, v_north : Array, shape ``(N,)``
        Velocity over ground (m/s).
    """

    t: jax.Array
    lat: jax.Array
    lon: jax.Array
    v_east: jax.Array
    v_north: jax.Array


def track_from_heading(lat0, lon0, speed, heading_deg, dt):
    """Dead-reckon a track from speed and heading at each fix.

    Parameters
    ----------
    lat0, lon0 : float
        Start position (degrees).
    speed : float or Array, shape ``(N,)``
        Speed over ground (m/s).
    heading_deg : Array, shape ``(N,)``
        Heading at each fix (degrees clockwise from north); sets N.
    dt : float
        Interval between fixes (s).

    Returns
    -------
    Track
        N fixes; step k uses the mean velocity of fixes k and k+1.
    """
    heading = jnp.asarray(heading_deg) * DEG
    speed = jnp.broadcast_to(jnp.asarray(speed, dtype=heading.dtype), heading.shape)
    ve = speed * jnp.sin(heading)
    vn = speed * jnp.cos(heading)
    dn = 0.5 * (vn[1:] + vn[:-1]) * dt
    de = 0.5 * (ve[1:] + ve[:-1]) * dt

    def step(pos, d):
        lat, lon = pos
        lat_mid = lat + 0.5 * d[0] / meridian_radius(lat) / DEG
        dlat = d[0] / meridian_radius(lat_mid) / DEG
        dlon = d[1] / (prime_vertical_radius(lat_mid) * jnp.cos(lat_mid * DEG)) / DEG
        new = (lat + dlat, lon + dlon)
        return new, new

    start = (jnp.asarray(lat0, dtype=heading.dtype), jnp.asarray(lon0, dtype=heading.dtype))
    _, (lats, lons) = jax.lax.scan(step, start, jnp.stack([dn, de], axis=-1))
    t = jnp.arange(heading.shape[0], dtype=heading.dtype) * dt
    return Track(
        t, jnp.concatenate([start[0][None], lats]), jnp.concatenate([start[1][None], lons]), ve, vn
    )


def straight_track(lat0, lon0, v_east, v_north, n, dt):
    """Constant-velocity track (a rhumb line) of ``n`` fixes ``dt`` seconds apart.

    Parameters
    ----------
    lat0, lon0 : float
        Start (degrees).
    v_east, v_north : float
        Velocity (m/s); paper A uses 10 kn each.
    n : int
        Number of fixes (static).
    dt : float
        Interval (s).

    Returns
    -------
    Track
    """
    speed = jnp.hypot(v_east, v_north)
    heading = jnp.rad2deg(jnp.arctan2(v_east, v_north))
    return track_from_heading(lat0, lon0, speed, jnp.full((n,), heading), dt)


def turning_track(lat0, lon0, speed, heading0_deg, turn_rate_deg_s, n, dt):
    """Constant-speed track turning at a constant rate (a circle arc; rate 0 is straight).

    Parameters
    ----------
    lat0, lon0 : float
        Start (degrees).
    speed : float
        Speed (m/s).
    heading0_deg : float
        Initial heading (degrees clockwise from north).
    turn_rate_deg_s : float
        Rate of turn (degrees per second, positive clockwise).
    n : int
        Number of fixes (static).
    dt : float
        Interval (s).

    Returns
    -------
    Track
    """
    t = jnp.arange(n) * dt
    return track_from_heading(lat0, lon0, speed, heading0_deg + turn_rate_deg_s * t, dt)


def random_start(key, region, margin_deg=0.0):
    """Uniformly random start point in a region, keeping a margin from its edges.

    Parameters
    ----------
    key : PRNG key
    region : tuple of float
        ``(lat_min, lat_max, lon_min, lon_max)`` in degrees.
    margin_deg : float or tuple of float
        Margin kept from each edge: one value, or ``(south, north, west, east)``.

    Returns
    -------
    tuple of Array
        ``(lat0, lon0)`` in degrees.
    """
    s, n, w, e = region
    m = jnp.broadcast_to(jnp.asarray(margin_deg, dtype=float), (4,))
    u = jax.random.uniform(key, (2,))
    return s + m[0] + u[0] * (n - s - m[0] - m[1]), w + m[2] + u[1] * (e - w - m[2] - m[3])


def track_error_m(lat, lon, truth):
    """Mean horizontal distance (m) between positions and the true track."""
    return jnp.mean(jnp.hypot(*local_offsets_m(lat, lon, truth.lat, truth.lon)))
