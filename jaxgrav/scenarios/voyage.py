"""Voyage scenarios: hours-long routes with a navigation-grade INS, one key in, one voyage out.

Two presets (:data:`PRESETS`), both at 10 kn with a reading every 10 s (1 mGal noise)
and a navigation-grade INS whose gyro (0.01 °/h) and accelerometer (25 µg) biases are
random constants, started 500 m and 0.05 m/s off in random directions:

- ``patrol-12h``: 12 h round a square of four 55.6 km legs (one lap), at a random place
  and orientation in the region;
- ``transit-24h``: 24 h along four 111 km legs, each turning up to 40° from the last.

The route is drawn from the key (start, orientation, turns), placed so that it stays
``margin_deg`` inside ``region`` (room for the INS drift and the matcher's search);
the readings see the map plus a correlated map error drawn per voyage when one is
given (:func:`~jaxgrav.scenarios.paper_a.scenario_truth`). On a map with missing (NaN,
land-masked) nodes ``start_tries`` routes are drawn at once and the first whose sailed
track reads none is kept (:func:`~jaxgrav.scenarios.paper_a.first_clear_draw`).
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.constants import DEG, KNOT
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.scenarios.paper_a import check_start_tries, first_clear_draw, scenario_truth
from jaxgrav.sim.ins import INSErrorModel
from jaxgrav.sim.readings import field_along
from jaxgrav.sim.route import Route, sail
from jaxgrav.sim.voyage import simulate_voyage

__all__ = ["INS_GRADES", "NAVIGATION_GRADE", "PRESETS", "VoyageScenario", "voyage_preset",
           "voyage_route", "voyage_scenario"]

NAVIGATION_GRADE = INSErrorModel(gyro_sigma=0.01 * DEG / 3600.0, gyro_tau=float("inf"),
                                 accel_sigma=25 * 9.80665e-6, accel_tau=float("inf"))
"""A navigation-grade INS: 0.01 °/h gyro and 25 µg accelerometer biases, random constants
(the voyage issue's goal setting); the rest as :class:`~jaxgrav.sim.ins.INSErrorModel`."""

INS_GRADES = {"navigation": NAVIGATION_GRADE, "strategic": INSErrorModel()}
"""The INS grades the voyage commands and examples name (``--ins``): navigation grade, and
the strategic grade of the default :class:`~jaxgrav.sim.ins.INSErrorModel`."""


@pytree_dataclass
class VoyageScenario:
    """A family of voyages.

    Attributes
    ----------
    region : tuple of float
        ``(lat_min, lat_max, lon_min, lon_max)`` the routes are drawn in (degrees); static.
    hours : float
        Length of the voyage (h); static (decides the number of steps).
    dt : float
        INS and gravimeter step (s); static.
    route : {"patrol", "transit"}
        A closed square patrolled round, or an open chain of legs (static).
    n_legs : int
        Legs of the route (static).
    leg_m : float
        Length of each leg (m).
    max_turn_deg : float
        Largest change of course between transit legs (degrees).
    speed : float
        Speed over ground (m/s).
    turn_radius_m : float
    margin_deg : float
        Room kept between the route and the region's edges (degrees).
    ins : INSErrorModel
    pos_error_m, vel_error : float
        Size of the initial INS position (m) and velocity (m/s) errors.
    noise_mgal : float
        Reading noise (mGal).
    start_tries : int
        Routes tried per voyage (static, default 1): the first whose sailed true track
        reads no missing (NaN) node of the truth field is taken, the first draw being the
        one of a single try (so voyages on a complete map are the same for any value); for
        maps with land masked (:func:`~jaxgrav.scenarios.paper_a.first_clear_draw`). A
        voyage none of whose tries is clear keeps the first, and its NaN readings say so.
    """

    region: tuple = static_field((25.0, 35.0, 125.0, 135.0))
    hours: float = static_field(12.0)
    dt: float = static_field(10.0)
    route: str = static_field("patrol")
    n_legs: int = static_field(4)
    leg_m: float = 55560.0
    max_turn_deg: float = 40.0
    speed: float = 10 * KNOT
    turn_radius_m: float = 500.0
    margin_deg: float = 0.6
    ins: INSErrorModel = NAVIGATION_GRADE
    pos_error_m: float = 500.0
    vel_error: float = 0.05
    noise_mgal: float = 1.0
    start_tries: int = static_field(1)

    def __post_init__(self):
        check_start_tries(self.start_tries)
        if self.route not in ("patrol", "transit"):
            raise ValueError(f"route must be 'patrol' or 'transit'; got {self.route!r}")
        if not (isinstance(self.n_legs, int) and self.n_legs >= 2):
            raise ValueError(f"n_legs must be an integer >= 2; got {self.n_legs!r}")
        if not self.hours * 3600.0 >= 2 * self.dt > 0:
            raise ValueError(f"hours must cover at least two steps of dt = {self.dt} s; got "
                             f"hours={self.hours}")

    @property
    def n_steps(self):
        """Samples of one voyage, the start included."""
        return round(self.hours * 3600.0 / self.dt) + 1


PRESETS = {
    "patrol-12h": {},
    "transit-24h": {"hours": 24.0, "route": "transit", "leg_m": 111120.0},
}
"""The named voyages (``jaxgrav simulate-voyage --preset``): overrides of VoyageScenario."""


def voyage_preset(name, **changes):
    """The named scenario of :data:`PRESETS`, with fields changed.

    Raises ValueError naming the presets for an unknown name.
    """
    if name not in PRESETS:
        raise ValueError(f"preset must be one of {sorted(PRESETS)}; got {name!r}")
    return dataclasses.replace(VoyageScenario(**PRESETS[name]), **changes)


def voyage_route(key, scenario):
    """Draw one route of the scenario (start, orientation and turns from ``key``).

    Returns
    -------
    Route
        ``n_legs`` waypoints for a patrol (cyclic), ``n_legs + 1`` for a transit.
    """
    s = scenario
    k_head, k_turn, k_start = jax.random.split(key, 3)
    h0 = jax.random.uniform(k_head, (), minval=0.0, maxval=360.0)
    if s.route == "patrol":
        course = h0 + (360.0 / s.n_legs) * jnp.arange(s.n_legs - 1)
    else:
        turns = jax.random.uniform(k_turn, (s.n_legs - 1,), minval=-1.0, maxval=1.0)
        course = h0 + jnp.concatenate([jnp.zeros(1), jnp.cumsum(turns * s.max_turn_deg)])
    north = jnp.concatenate([jnp.zeros(1), jnp.cumsum(s.leg_m * jnp.cos(course * DEG))])
    east = jnp.concatenate([jnp.zeros(1), jnp.cumsum(s.leg_m * jnp.sin(course * DEG))])
    lat_s, lat_n, lon_w, lon_e = (float(v) for v in s.region)
    lat_ref = 0.5 * (lat_s + lat_n)
    dlat = north / meridian_radius(lat_ref) / DEG
    dlon = east / (prime_vertical_radius(lat_ref) * np.cos(lat_ref * DEG)) / DEG
    lo = jnp.array([lat_s, lon_w]) + s.margin_deg - jnp.array([dlat.min(), dlon.min()])
    hi = jnp.array([lat_n, lon_e]) - s.margin_deg - jnp.array([dlat.max(), dlon.max()])
    start = lo + jax.random.uniform(k_start, (2,)) * (hi - lo)
    speed = jnp.full(dlat.shape, s.speed)
    return Route(start[0] + dlat, start[1] + dlon, speed, jnp.asarray(s.turn_radius_m),
                 jnp.asarray(s.route == "patrol"))


def voyage_scenario(key, field, scenario=VoyageScenario(), map_error=None):  # noqa: B008
    """Simulate one voyage of the scenario.

    Parameters
    ----------
    key : PRNG key
    field : Grid or callable
        The map (a Grid when ``map_error`` is a CorrelatedMapError), or the truth.
    scenario : VoyageScenario
    map_error : CorrelatedMapError, TruthGrid or None
        How the truth the gravimeter sees differs from ``field``
        (:func:`~jaxgrav.scenarios.paper_a.scenario_truth`): drawn per voyage from the key.

    Returns
    -------
    Voyage
        ``gravity`` NaN where the route reads a missing map node (none of
        ``scenario.start_tries`` routes was clear).
    """
    s = scenario
    truth = scenario_truth(key, field, map_error, s.region)
    k_route, k_voyage = jax.random.split(key)

    def clear(route):  # the true track, sailed as simulate_voyage sails it, reads no NaN
        track, _ = sail(route, s.n_steps, s.dt)
        return jnp.all(jnp.isfinite(field_along(truth, track.lat, track.lon, "bicubic")))

    route = first_clear_draw(k_route, voyage_route(k_route, s),
                             lambda k: voyage_route(k, s), clear, s.start_tries)
    return simulate_voyage(k_voyage, truth, route, scenario.n_steps, scenario.dt, scenario.ins,
                           pos_error_m=scenario.pos_error_m, vel_error=scenario.vel_error,
                           noise_mgal=scenario.noise_mgal)
