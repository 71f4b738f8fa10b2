"""Paper B's simulated experiment and its metrics.

A straight track at constant speed in a random direction; the INS track is the true
one rotated about its start by ±``rotation_deg`` (1.5°) and offset by a random vector
of 0.02–0.03° (the accuracy goal: entropy + ICCP at most half the INS error); readings
are the field at the true positions plus white noise. :func:`paper_b_errors` matches
one such run by entropy, ICCP and entropy + ICCP and returns the track errors.
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav import sim
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match.combined import match_entropy_iccp
from jaxgrav.match.iccp import iccp_result
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios.paper_a import (
    MatchingRun,
    check_start_tries,
    first_clear_draw,
    scenario_truth,
)
from jaxgrav.sim import track_error_m

__all__ = ["PaperBErrors", "PaperBScenario", "paper_b_errors", "paper_b_scenario"]


@pytree_dataclass
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
    start_tries : int
        Starts (and headings) tried per run (static, default 1): the first whose true
        track reads no missing (NaN) node of the truth field is taken, the first draw
        being the one of a single try (so runs on a complete map are the same for any
        value); for maps with land masked
        (:func:`~jaxgrav.scenarios.paper_a.first_clear_draw`). A run none of whose tries
        is clear keeps the first, and its NaN readings say so.
    """

    region: tuple = static_field((39.0, 41.0, 115.0, 117.0))
    speed: float = 10.0
    dt: float = 60.0
    offset_min_deg: float = 0.02
    offset_max_deg: float = 0.03
    rotation_deg: float = 1.5
    noise: float = 1.0
    n_fixes: int = static_field(60)
    start_tries: int = static_field(1)

    def __post_init__(self):
        check_start_tries(self.start_tries)


def paper_b_scenario(key, truth_field, scenario=PaperBScenario(), map_error=None):  # noqa: B008
    """Simulate one run of :class:`PaperBScenario`.

    Parameters
    ----------
    key : PRNG key
    truth_field : Grid or callable
        Field sensed (nT or mGal), sampled bicubically if a Grid; with ``map_error``,
        the map the truth is drawn from.
    scenario : PaperBScenario
    map_error : CorrelatedMapError, TruthGrid or None, optional
        As :func:`~jaxgrav.scenarios.paper_a.matching_scenario` (drawn per run from
        ``map_error_key(key)``; a TruthGrid must cover ``scenario.region``; None:
        today's readings, bit for bit; a per-batch draw: pass the drawn truth Grid as
        ``truth_field``).

    Returns
    -------
    MatchingRun
        ``drift_north_m``/``drift_east_m`` are the INS errors at each fix (m).
    """
    s = scenario
    truth_field = scenario_truth(key, truth_field, map_error, s.region)
    k_start, k_head, k_off, k_dir, k_sign, k_noise = jax.random.split(key, 6)
    length_m = (s.n_fixes - 1) * s.dt * s.speed
    m_lat = (length_m + s.offset_max_deg * sim.DEG_ARC_M) / sim.DEG_ARC_M * 1.05
    m_lon = m_lat / math.cos(math.radians(max(abs(s.region[0]), abs(s.region[1]))))
    margin = (m_lat, m_lat, m_lon, m_lon)

    def track(lat0, lon0, heading):
        return sim.track_from_heading(lat0, lon0, s.speed, jnp.full((s.n_fixes,), heading),
                                      s.dt)

    def draw(k):  # one more try: a start and a heading
        k_s, k_h = jax.random.split(k)
        return (*sim.random_start(k_s, s.region, margin),
                jax.random.uniform(k_h, (), minval=0.0, maxval=360.0))

    def clear(start):
        t = track(*start)
        return jnp.all(jnp.isfinite(sim.field_along(truth_field, t.lat, t.lon, "bicubic")))

    first = (*sim.random_start(k_start, s.region, margin),
             jax.random.uniform(k_head, (), minval=0.0, maxval=360.0))
    lat0, lon0, heading = first_clear_draw(k_start, first, draw, clear, s.start_tries)
    truth = track(lat0, lon0, heading)
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


class PaperBErrors(NamedTuple):
    """Mean-track errors (m) of one run, rotations (degrees) and misfits (map units²).

    ``misfit_*`` are mean squared differences of the readings and the map along the
    true, the entropy and the entropy + ICCP tracks: a matched track that fits better
    than the truth is an ambiguity no data criterion can resolve.
    """

    ins_m: jax.Array
    entropy_m: jax.Array
    iccp_m: jax.Array
    combined_m: jax.Array
    true_rotation_deg: jax.Array
    iccp_rotation_deg: jax.Array
    combined_rotation_deg: jax.Array
    status_iccp: jax.Array
    status_combined: jax.Array
    misfit_truth: jax.Array
    misfit_entropy: jax.Array
    misfit_combined: jax.Array


def paper_b_errors(key, truth_field, grid, scenario, entropy, iccp_alone, iccp_fine):
    """Simulate one run and match it by entropy, ICCP and entropy + ICCP (vmap over keys).

    Parameters
    ----------
    key : PRNG key
    truth_field : Grid or callable
        Field sensed.
    grid : Grid or PreparedMap
        Map matched against (prepared here once for all three matchers).
    scenario : PaperBScenario
    entropy : EntropyConfig
    iccp_alone, iccp_fine : IccpConfig
        ICCP configurations alone (window covering the drift) and after the coarse stage.

    Returns
    -------
    PaperBErrors
    """
    pm = prepare_map(grid)
    run = paper_b_scenario(key, truth_field, scenario)
    lat, lon, z = run.ins_lat, run.ins_lon, run.readings
    alone = iccp_result(pm.patches(), pm.grid, lat, lon, z, iccp_alone)
    both = match_entropy_iccp(pm, lat, lon, z, entropy, iccp_fine)
    c_lat, c_lon = both.topk_lat[0], both.topk_lon[0]  # the coarse (entropy) track
    # true rotation: of the truth relative to the INS track (what a matcher should return)
    tn, te = local_offsets_m(run.truth.lat, run.truth.lon, run.truth.lat[0], run.truth.lon[0])
    in_, ie = local_offsets_m(lat, lon, lat[0], lon[0])
    true_rot = jnp.rad2deg(jnp.arctan2(te[-1], tn[-1]) - jnp.arctan2(ie[-1], in_[-1]))
    true_rot = (true_rot + 180.0) % 360.0 - 180.0
    err = lambda la, lo: track_error_m(la, lo, run.truth)  # noqa: E731
    misfit_truth = jnp.mean((z - pm.sample(run.truth.lat, run.truth.lon, "bicubic")) ** 2)
    return PaperBErrors(
        err(lat, lon), err(c_lat, c_lon), err(alone.lat, alone.lon),
        err(both.lat, both.lon), true_rot, alone.rotation_deg, both.rotation_deg,
        alone.status, both.status, misfit_truth, both.topk_score[0], both.score,
    )
