"""Paper D's filtering experiment: a ship crossing a point-mass anomaly with a drifting INS.

One PRNG key in, one run out (``vmap`` for Monte Carlo). The ship sails 2 h at
5 m/s over paper D's three-mass area, either straight east or west across the
masses' latitude band (``"east-west"``) or north along the mass line for the
first hour and then east (``"north-east"``). The INS error follows
:mod:`jaxgrav.sim.ins` from a 2 km position and 0.2 m/s velocity error (fixed
sizes, random directions). The gravimeter reads the true anomaly + a 1 mGal bias +
1 mGal white noise every 10 s (NaN in between); Eötvös is taken as corrected.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._linalg import inv_2x2
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.constants import DEG
from jaxgrav.fields.map_error import map_error_key, truth_field
from jaxgrav.filters.model import STATUS_FILTER, Dynamics, Step, map_anomaly
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.grid import Grid
from jaxgrav.scenarios.paper_a import check_start_tries, first_clear_draw
from jaxgrav.sim.ins import (
    INSErrorModel,
    initial_covariance,
    sample_initial_error,
    simulate_errors,
    transition,
)
from jaxgrav.sim.trajectory import Track, track_from_heading

__all__ = [
    "FilterRun",
    "FilterScenario",
    "filter_scenario",
    "initial_state",
    "run_metrics",
    "run_steps",
]

_DEFAULT_INS = INSErrorModel()
MASS_LON = 122.918751
"""Longitude of paper D's mass line (degrees)."""


@pytree_dataclass
class FilterScenario:
    """Paper D's filtering experiment (numbers are sweepable arrays; shapes static).

    Attributes
    ----------
    speed : float
        Ship speed (m/s).
    dt : float
        Filter step (s).
    reading_every : int
        A reading every this many steps (static); NaN in between.
    pos_error, vel_error : float
        Size of the initial INS position (m) and velocity (m/s) error.
    noise_mgal, bias_mgal : float
        Reading noise σ and gravimeter bias (mGal).
    n_steps : int
        Steps per run including the start (static): 2 h at 2 s is 3601.
    geometry : {"east-west", "north-east", "mixed", "random"}
        Track family (static); ``"mixed"`` draws one of the two per run;
        ``"random"`` is a straight track from a uniform start in ``region`` with a
        uniform heading (for maps other than paper D's masses).
    region : tuple of float
        ``(lat_min, lat_max, lon_min, lon_max)`` of ``"random"`` starts (static).
    ins : INSErrorModel
        Sensor error parameters.
    start_tries : int
        True tracks tried per run (static, default 1): the first that reads no missing
        (NaN) node of the truth field is taken, the first draw being the one of a single
        try (so runs on a complete map are the same for any value); for maps with land
        masked (:func:`~jaxgrav.scenarios.paper_a.first_clear_draw`). A run none of whose
        tries is clear keeps the first, and its NaN readings say so.
    """

    speed: float = 5.0
    dt: float = 2.0
    reading_every: int = static_field(5)
    pos_error: float = 2000.0
    vel_error: float = 0.2
    noise_mgal: float = 1.0
    bias_mgal: float = 1.0
    n_steps: int = static_field(3601)
    geometry: str = static_field("mixed")
    region: tuple = static_field((24.5, 35.5, 124.5, 135.5))
    ins: INSErrorModel = _DEFAULT_INS
    start_tries: int = static_field(1)

    def __post_init__(self):
        check_start_tries(self.start_tries)


class FilterRun(NamedTuple):
    """One simulated run.

    Attributes
    ----------
    truth : Track
        True trajectory, ``T`` states.
    ins_lat, ins_lon : Array, shape ``(T,)``
        INS-indicated position (degrees).
    readings : Array, shape ``(T,)``
        Gravimeter readings (mGal), NaN between readings.
    errors : Array, shape ``(T, 13)``
        True INS error states (:mod:`jaxgrav.sim.ins`).
    """

    truth: Track
    ins_lat: jax.Array
    ins_lon: jax.Array
    readings: jax.Array
    errors: jax.Array


def _true_track(key, s):
    """East–west or north-then-east track over the masses."""
    k_geo, k_lat, k_dir, k_lon = jax.random.split(key, 4)
    n = s.n_steps
    span_deg = s.speed * s.dt * (n - 1) / (111.32e3 * jnp.cos(24.3 * DEG))
    # east-west: a random latitude in the masses' band, centred on the mass line
    lat_ew = jax.random.uniform(k_lat, (), minval=24.10, maxval=24.45)
    east = jax.random.bernoulli(k_dir)
    lon_ew = MASS_LON + jnp.where(east, -0.5, 0.5) * span_deg
    head_ew = jnp.full(n, jnp.where(east, 90.0, 270.0))
    # north then east: start south of the masses, near the mass line
    lat_ne = jax.random.uniform(k_lat, (), minval=24.03, maxval=24.10)
    lon_ne = MASS_LON + jax.random.uniform(k_lon, (), minval=-0.05, maxval=0.05)
    head_ne = jnp.where(jnp.arange(n) < n // 2, 0.0, 90.0)
    if s.geometry == "random":
        k_a, k_b, k_c = jax.random.split(k_geo, 3)
        lat0 = jax.random.uniform(k_a, (), minval=s.region[0], maxval=s.region[1])
        lon0 = jax.random.uniform(k_b, (), minval=s.region[2], maxval=s.region[3])
        heading = jnp.full(n, jax.random.uniform(k_c, (), minval=0.0, maxval=360.0))
        return track_from_heading(lat0, lon0, s.speed, heading, s.dt)
    if s.geometry == "east-west":
        use_ew = True
    elif s.geometry == "north-east":
        use_ew = False
    else:
        use_ew = jax.random.bernoulli(k_geo)
    lat0 = jnp.where(use_ew, lat_ew, lat_ne)
    lon0 = jnp.where(use_ew, lon_ew, lon_ne)
    heading = jnp.where(use_ew, head_ew, head_ne)
    return track_from_heading(lat0, lon0, s.speed, heading, s.dt)


def filter_scenario(key, field, scenario=None, map_error=None):
    """Simulate one run of paper D's experiment.

    Parameters
    ----------
    key : PRNG key
    field : Grid, PointMasses or callable
        The anomaly map (mGal); the truth when ``map_error`` is None.
    scenario : FilterScenario, optional
        Default ``FilterScenario()``.
    map_error : CorrelatedMapError, TruthGrid or None
        The map is not the truth: the readings are simulated from
        :func:`~jaxgrav.fields.map_error.truth_field` ``(map_error_key(key), field,
        map_error)`` (one error field per run, drawn from a key folded off ``key``, so
        every other draw is the same as without map error). Needs ``field`` to be a
        Grid (TypeError otherwise: a point-mass model has no grid to draw the error
        on). None: the readings come from ``field`` (bit-identical to no argument).

    Returns
    -------
    FilterRun
    """
    s = FilterScenario() if scenario is None else scenario
    if map_error is not None:
        if not isinstance(field, Grid):
            raise TypeError(
                "map_error needs the map (field) to be a Grid; got "
                f"{type(field).__name__} (a point-mass model has no grid to draw the map "
                "error on: pass the truth as the field instead)")
        field = truth_field(map_error_key(key), field, map_error)
    k_track, k_err0, k_err, k_noise = jax.random.split(key, 4)
    truth = first_clear_draw(
        k_track, _true_track(k_track, s), lambda k: _true_track(k, s),
        lambda t: jnp.all(jnp.isfinite(map_anomaly(field, t.lat, t.lon))), s.start_tries)
    f, q = transition(s.ins, jnp.mean(truth.lat), s.dt)
    x0 = sample_initial_error(k_err0, s.ins, s.pos_error, s.vel_error).at[12].set(s.bias_mgal)
    errors = simulate_errors(k_err, f, q, x0, s.n_steps)
    ins_lat = truth.lat + errors[:, 0] / meridian_radius(truth.lat) / DEG
    east_radius = prime_vertical_radius(truth.lat) * jnp.cos(truth.lat * DEG)
    ins_lon = truth.lon + errors[:, 1] / east_radius / DEG
    anomaly = map_anomaly(field, truth.lat, truth.lon)
    noise = s.noise_mgal * jax.random.normal(k_noise, anomaly.shape)
    has_reading = (jnp.arange(s.n_steps) % s.reading_every) == 0
    readings = jnp.where(has_reading, anomaly + errors[:, 12] + noise, jnp.nan)
    return FilterRun(truth, ins_lat, ins_lon, readings, errors)


def initial_state(scenario=None):
    """The filter's prior: zero error, covariance matching the scenario's error sizes.

    Position and velocity errors of size ``a`` in a random direction have
    ``E[d_n²] = E[d_e²] = a²/2``; the gravimeter bias prior is the model's σ.

    Parameters
    ----------
    scenario : FilterScenario, optional
        Default ``FilterScenario()``.

    Returns
    -------
    x0 : Array, shape ``(13,)``
    p0 : Array, shape ``(13, 13)``
    """
    s = FilterScenario() if scenario is None else scenario
    p0 = initial_covariance(s.ins, s.pos_error / jnp.sqrt(2.0), s.vel_error / jnp.sqrt(2.0))
    return jnp.zeros(p0.shape[0]), p0


def run_steps(run, scenario=None):
    """Filter inputs for a simulated run: one :class:`Step` per state after the first.

    Parameters
    ----------
    run : FilterRun
    scenario : FilterScenario, optional
        The scenario the run was simulated with; default ``FilterScenario()``.

    Returns
    -------
    dynamics : Dynamics
        The INS error model over ``scenario.dt`` at the run's mean INS latitude, with
        ``dt`` filled in.
    steps : Step
        Leading axis ``T − 1``.
    """
    s = FilterScenario() if scenario is None else scenario
    f, q = transition(s.ins, jnp.mean(run.ins_lat), s.dt)
    t = run.ins_lat.shape[0] - 1
    r = jnp.full(t, jnp.square(s.noise_mgal))
    dyn = Dynamics(f, q, jnp.asarray(s.dt, f.dtype))
    return dyn, Step(run.ins_lat[1:], run.ins_lon[1:], run.readings[1:], r)


def run_metrics(run, infos):
    """Paper D's scores of one filtered run, over the second half of the run (the second hour).

    Parameters
    ----------
    run : FilterRun
    infos : StepInfo
        Leading axis ``T − 1``: ``infos[k]`` is the posterior at state ``k + 1``.

    Returns
    -------
    dict of str to Array
        ``ins_err_m`` and ``err_m``: RMS horizontal position error of the INS and of
        the filter (m); ``status``: OR of the steps' flags without ``no_reading``
        (int32); ``nees``: mean position NEES (2 for honest 1-σ bounds).
    """
    truth = run.errors[1:, :2]
    half = truth.shape[0] // 2
    e_ins = truth[half:]
    e_filt = e_ins - infos.x[half:, :2]
    info = jax.vmap(inv_2x2)(infos.p_pos[half:])  # closed form: no batched LAPACK (deadlocks)
    nees = jnp.einsum("ti,tij,tj->t", e_filt, info, e_filt)
    status = jnp.bitwise_or.reduce(infos.status) & ~STATUS_FILTER["no_reading"]
    return dict(
        ins_err_m=jnp.sqrt(jnp.mean(jnp.sum(e_ins**2, -1))),
        err_m=jnp.sqrt(jnp.mean(jnp.sum(e_filt**2, -1))),
        status=jnp.asarray(status, jnp.int32),
        nees=jnp.mean(nees),
    )
