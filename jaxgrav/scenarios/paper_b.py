"""Paper B's simulated experiment (SPEC §B and the issue's accuracy goal).

A straight track at constant speed in a random direction; the INS track is the true
one rotated about its start by ±``rotation_deg`` and offset by a random vector;
readings are the field at the true positions plus white noise.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp

from jaxgrav import sim
from jaxgrav._pytree import static_field
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.scenarios.paper_a import MatchingRun

__all__ = ["PaperBScenario", "paper_b_scenario"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PaperBScenario:
    """Paper B's experiment: a straight track, an INS offset and rotated about its start.

    Attributes
    ----------
    region : tuple of float
        ``(lat_min, lat_max, lon_min, lon_max)`` the whole run stays in (degrees); static.
    speed : float
        Speed (m/s); the heading is uniform in [0, 360°).
    dt : float
        Interval between fixes (s).
    offset_min_deg, offset_max_deg : float
        INS offset radius, uniform between these (degrees of arc); direction uniform.
    rotation_deg : float
        INS track rotated about its start by ±rotation_deg (sign random).
    noise : float
        Reading noise σ (field units).
    n_fixes : int
        Fixes per track (static).
    """

    region: tuple = static_field((39.0, 41.0, 115.0, 117.0))
    speed: float = 10.0
    dt: float = 60.0
    offset_min_deg: float = 0.02
    offset_max_deg: float = 0.03
    rotation_deg: float = 1.5
    noise: float = 1.0
    n_fixes: int = static_field(60)


def paper_b_scenario(key, truth_field, scenario=PaperBScenario()):
    """Simulate one run of :class:`PaperBScenario`.

    Parameters
    ----------
    key : PRNG key
    truth_field : Grid or callable
        Field sensed (nT or mGal), sampled bicubically if a Grid.
    scenario : PaperBScenario

    Returns
    -------
    MatchingRun
        ``drift_north_m``/``drift_east_m`` are the INS errors at each fix (m).
    """
    s = scenario
    k_start, k_head, k_off, k_dir, k_sign, k_noise = jax.random.split(key, 6)
    length_m = (s.n_fixes - 1) * s.dt * s.speed
    m_lat = (length_m + s.offset_max_deg * sim.DEG_ARC_M) / sim.DEG_ARC_M * 1.05
    m_lon = m_lat / math.cos(math.radians(max(abs(s.region[0]), abs(s.region[1]))))
    lat0, lon0 = sim.random_start(k_start, s.region, (m_lat, m_lat, m_lon, m_lon))
    heading = jax.random.uniform(k_head, (), minval=0.0, maxval=360.0)
    truth = sim.track_from_heading(lat0, lon0, s.speed, jnp.full((s.n_fixes,), heading), s.dt)
    north, east = local_offsets_m(truth.lat, truth.lon, lat0, lon0)
    theta = jnp.deg2rad(s.rotation_deg) * jnp.where(jax.random.bernoulli(k_sign), 1.0, -1.0)
    radius = jax.random.uniform(k_off, (), minval=s.offset_min_deg, maxval=s.offset_max_deg)
    radius = radius * sim.DEG_ARC_M
    direction = jax.random.uniform(k_dir, (), minval=0.0, maxval=2 * jnp.pi)
    c, sn = jnp.cos(theta), jnp.sin(theta)
    rn = c * north - sn * east + radius * jnp.cos(direction)
    re = sn * north + c * east + radius * jnp.sin(direction)
    ins_lat, ins_lon = sim.apply_drift(jnp.full_like(north, lat0), jnp.full_like(east, lon0),
                                       rn, re)
    err_n, err_e = local_offsets_m(ins_lat, ins_lon, truth.lat, truth.lon)
    value = sim.field_along(truth_field, truth.lat, truth.lon, "bicubic")
    readings = value + s.noise * jax.random.normal(k_noise, value.shape, value.dtype)
    return MatchingRun(truth, ins_lat, ins_lon, readings, err_n, err_e)
