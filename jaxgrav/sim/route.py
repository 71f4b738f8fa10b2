"""Routes: waypoints sailed with an autopilot, turning at a finite radius.

A voyage is not a straight line: a ship or submarine steers from waypoint to waypoint
along great-circle legs, turns at a radius set by its speed and rudder, and changes
speed between legs. :func:`sail` runs that autopilot as one ``lax.scan`` over the time
steps (a pure function of arrays, so a batch of routes is a ``vmap`` away):

- the heading is steered toward the current waypoint's great-circle bearing at the
  largest turn rate the radius allows (``speed / radius``);
- a waypoint is reached when the ship comes within the turn radius of it (the turn
  starts there, as an autopilot's acceptance circle does), and the next leg begins;
- speed changes toward the new leg's speed at a bounded acceleration;
- a cyclic route (a patrol) starts over after its last waypoint; an open route (a
  transit) holds its last heading once its last waypoint is reached.

Positions are dead-reckoned step by step with the WGS84 radii of curvature at each
step's mid-latitude, as :func:`~jaxgrav.sim.trajectory.track_from_heading` does.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.constants import DEG
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.sim.trajectory import Track

__all__ = ["Route", "great_circle", "sail"]


class Route(NamedTuple):
    """Waypoints and the speed on the leg toward each.

    Attributes
    ----------
    lat, lon : Array, shape ``(W,)``
        Waypoints (degrees); the voyage starts at the first.
    speed : Array, shape ``(W,)``
        Speed over ground (m/s) on the leg that ends at each waypoint (``speed[0]``: on
        the leg that ends at the first waypoint of a cyclic route, and at the start).
    turn_radius_m : Array
        Turn radius (m), scalar.
    cyclic : Array of bool
        Scalar: start over after the last waypoint (a patrol) rather than hold course.
    """

    lat: jax.Array
    lon: jax.Array
    speed: jax.Array
    turn_radius_m: jax.Array
    cyclic: jax.Array


def great_circle(lat1, lon1, lat2, lon2):
    """Great-circle distance (m, on the mean sphere) and initial bearing (degrees).

    Parameters
    ----------
    lat1, lon1, lat2, lon2 : Array
        From and to (degrees).

    Returns
    -------
    distance_m, bearing_deg : Array
        Bearing clockwise from north in (−180, 180].
    """
    p1, p2 = lat1 * DEG, lat2 * DEG
    dl = (lon2 - lon1) * DEG
    a = jnp.sin(0.5 * (p2 - p1)) ** 2 + jnp.cos(p1) * jnp.cos(p2) * jnp.sin(0.5 * dl) ** 2
    dist = 2.0 * 6371008.8 * jnp.arcsin(jnp.sqrt(jnp.clip(a, 0.0, 1.0)))
    bearing = jnp.arctan2(jnp.sin(dl) * jnp.cos(p2),
                          jnp.cos(p1) * jnp.sin(p2) - jnp.sin(p1) * jnp.cos(p2) * jnp.cos(dl))
    return dist, bearing / DEG


def _wrap_deg(a):
    """Angle in (−180, 180] degrees."""
    return a - 360.0 * jnp.ceil((a - 180.0) / 360.0)


def sail(route, n_steps, dt, *, max_accel=0.02):
    """Sail a route with an autopilot; the true trajectory at every step.

    Parameters
    ----------
    route : Route
    n_steps : int
        Number of samples (static), including the start.
    dt : float
        Step (s).
    max_accel : float
        Largest change of speed (m/s²) between legs.

    Returns
    -------
    track : Track
        ``n_steps`` samples from the first waypoint, heading first toward the second.
    leg : Array of int, shape ``(n_steps,)``
        Index of the waypoint being steered to (counting on past the last one of a
        cyclic route: ``leg // W`` is the lap).
    """
    lat_w, lon_w = jnp.asarray(route.lat, float), jnp.asarray(route.lon, float)
    speed_w = jnp.asarray(route.speed, lat_w.dtype)
    n_w = lat_w.shape[0]
    radius = jnp.asarray(route.turn_radius_m, lat_w.dtype)
    cyclic = jnp.asarray(route.cyclic)
    _, h0 = great_circle(lat_w[0], lon_w[0], lat_w[1], lon_w[1])

    def target(leg):
        i = jnp.where(cyclic, leg % n_w, jnp.minimum(leg, n_w - 1))
        return lat_w[i], lon_w[i], speed_w[i]

    def step(state, _):
        lat, lon, heading, speed, leg = state
        t_lat, t_lon, t_speed = target(leg)
        dist, _ = great_circle(lat, lon, t_lat, t_lon)
        leg = leg + ((dist <= radius) & (cyclic | (leg < n_w))).astype(leg.dtype)
        done = ~cyclic & (leg >= n_w)  # an open route past its last waypoint: hold course
        t_lat, t_lon, t_speed = target(leg)
        _, bearing = great_circle(lat, lon, t_lat, t_lon)
        err = jnp.where(done, 0.0, _wrap_deg(bearing - heading))
        max_turn = speed * dt / radius / DEG
        new_heading = _wrap_deg(heading + jnp.clip(err, -max_turn, max_turn))
        new_speed = speed + jnp.clip(t_speed - speed, -max_accel * dt, max_accel * dt)
        h_mid = heading + 0.5 * _wrap_deg(new_heading - heading)
        s_mid = 0.5 * (speed + new_speed)
        d_n = s_mid * dt * jnp.cos(h_mid * DEG)
        d_e = s_mid * dt * jnp.sin(h_mid * DEG)
        lat_mid = lat + 0.5 * d_n / meridian_radius(lat) / DEG
        new_lat = lat + d_n / meridian_radius(lat_mid) / DEG
        new_lon = lon + d_e / (prime_vertical_radius(lat_mid) * jnp.cos(lat_mid * DEG)) / DEG
        new = (new_lat, new_lon, new_heading, new_speed, leg)
        return new, new

    leg0 = jnp.asarray(1, jnp.int32)
    start = (lat_w[0], lon_w[0], h0, speed_w[1], leg0)
    _, (lats, lons, heads, speeds, legs) = jax.lax.scan(step, start, None, length=n_steps - 1)
    lat = jnp.concatenate([lat_w[:1], lats])
    lon = jnp.concatenate([lon_w[:1], lons])
    heading = jnp.concatenate([h0[None], heads]) * DEG
    speed = jnp.concatenate([speed_w[1:2], speeds])
    t = jnp.arange(n_steps, dtype=lat.dtype) * dt
    track = Track(t, lat, lon, speed * jnp.sin(heading), speed * jnp.cos(heading))
    return track, jnp.concatenate([leg0[None], legs])
