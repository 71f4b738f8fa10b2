"""Paper B combined: entropy coarse match, then ICCP fine match; validated entry point.

:func:`match_entropy_iccp` runs both stages on one map sampler (spline coefficients
computed once). ICCP starts from the coarse offset; its result replaces the coarse
one only if it is finite and its mean squared misfit along the track is not larger
(otherwise status bit 128 is raised and the coarse track is kept), so the combined
match is never worse than the coarse one *in misfit*.

:func:`match_track_b` is the checked public entry point for one track with
``method`` in :data:`METHODS_B`; :func:`paper_b_scenario` simulates the experiment of
SPEC §B (and the issue's accuracy goal): a straight track, an INS track offset by a
random vector and rotated about its start, readings of a field with white noise.
"""

import dataclasses
import math
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav import sim
from jaxgrav._pytree import static_field
from jaxgrav.grid import make_sampler
from jaxgrav.match.entropy import (
    ENTROPY_STATUS,
    EntropyConfig,
    coarse_offsets,
    entropy_config_for,
    match_entropy,
)
from jaxgrav.match.iccp import ICCP_STATUS, IccpConfig, _iccp_result, match_iccp
from jaxgrav.match.result import STATUS, MatchResult
from jaxgrav.scenarios import MatchingRun, track_error_m

__all__ = [
    "COMBINED_STATUS",
    "METHODS_B",
    "PaperBErrors",
    "PaperBScenario",
    "iccp_config_for",
    "match_entropy_iccp",
    "match_track_b",
    "paper_b_errors",
    "paper_b_scenario",
]

METHODS_B = ("entropy", "iccp", "entropy+iccp")

COMBINED_STATUS = {
    128: "entropy+ICCP: the ICCP result fitted worse than the coarse match; coarse track kept",
}
"""Status bit of the combined matcher (with :data:`ENTROPY_STATUS` and :data:`ICCP_STATUS`)."""

ALL_STATUS_B = {**STATUS, **ENTROPY_STATUS, **ICCP_STATUS, **COMBINED_STATUS}



_DEFAULT_ENTROPY = EntropyConfig()
_DEFAULT_ICCP = IccpConfig()


@jax.jit
def match_entropy_iccp(grid, lat, lon, readings, entropy=_DEFAULT_ENTROPY, iccp=_DEFAULT_ICCP):
    """Entropy coarse match followed by ICCP fine match, for one track (jitted).

    Parameters
    ----------
    grid : Grid
        Map (nT or mGal).
    lat, lon : Array, shape ``(N,)``
        INS-indicated fixes (degrees).
    readings : Array, shape ``(N,)``
        Measured values (map units), bias-free.
    entropy : EntropyConfig
    iccp : IccpConfig
        ``window_m`` should cover the coarse stage's error (a few offset spacings
        to a map cell), not the whole INS drift.

    Returns
    -------
    MatchResult
        ``score`` is the mean squared misfit (map units²); ``topk_*`` hold the coarse
        and the fine track (in that order), ``chosen`` which one was returned.
    """
    sample = make_sampler(grid, "bicubic")
    coarse_sample = sample if entropy.method == "bicubic" else make_sampler(grid, entropy.method)
    coarse, d_n, d_e = coarse_offsets(coarse_sample, lat, lon, readings, entropy)
    fine = _iccp_result(sample, lat, lon, readings, iccp, d_n, d_e)
    coarse_misfit = jnp.mean((jnp.asarray(readings) - sample(coarse.lat, coarse.lon)) ** 2)
    use_fine = jnp.isfinite(fine.score) & ~(fine.score > coarse_misfit)
    pick = lambda a, b: jnp.where(use_fine, a, b)  # noqa: E731
    status = (
        (coarse.status & ~1)
        | jnp.where(jnp.isfinite(fine.score) | jnp.isfinite(coarse_misfit), 0, 1)
        | (fine.status & 16 & jnp.where(use_fine, 16, 0))
        | (fine.status & 64)
        | jnp.where(use_fine, 0, 128)
    ).astype(jnp.int32)
    return MatchResult(
        lat=pick(fine.lat, coarse.lat),
        lon=pick(fine.lon, coarse.lon),
        offset_north_m=pick(fine.offset_north_m, coarse.offset_north_m),
        offset_east_m=pick(fine.offset_east_m, coarse.offset_east_m),
        rotation_deg=pick(fine.rotation_deg, coarse.rotation_deg),
        score=pick(fine.score, coarse_misfit),
        bias=coarse.bias,
        topk_lat=jnp.stack([coarse.lat, fine.lat]),
        topk_lon=jnp.stack([coarse.lon, fine.lon]),
        topk_score=jnp.stack([coarse_misfit, fine.score]),
        chosen=use_fine.astype(jnp.int32),
        n_candidates=fine.n_candidates,
        work_unconstrained=coarse.work_unconstrained,
        work_constrained=coarse.work_constrained + fine.work_constrained,
        work_pairs=coarse.work_pairs + fine.work_pairs,
        status=status,
    )


def iccp_config_for(grid, drift_radius_m, *, stage="alone", noise=1.0, **kw):
    """An :class:`IccpConfig` sized to the expected error.

    Parameters
    ----------
    grid : Grid
    drift_radius_m : float
        Largest expected INS error (m).
    stage : {"alone", "fine"}
        ``"alone"``: the window covers 1.2 × the drift; ``"fine"`` (after the entropy
        stage, whose error can still reach the drift: entropy is a weak criterion):
        the larger of that and one map cell diagonal.
    noise : float
        Reading noise σ (map units); contour points must match their value within 3σ.
    **kw
        Other :class:`IccpConfig` fields.

    Returns
    -------
    IccpConfig
    """
    if not drift_radius_m > 0:
        raise ValueError(f"drift_radius_m must be positive (m); got {drift_radius_m!r}")
    if stage not in ("alone", "fine"):
        raise ValueError(f"stage must be 'alone' or 'fine'; got {stage!r}")
    dy, dx = grid.spacing_m()
    cell = math.hypot(dy, dx)
    window = 1.2 * float(drift_radius_m) if stage == "alone" else max(cell, 1.2 * drift_radius_m)
    kw.setdefault("window_m", window)
    kw.setdefault("max_step_m", max(cell / 2.0, 200.0))
    kw.setdefault("contour_tol", 3.0 * float(noise) + 1e-6)
    return IccpConfig(**kw)


def match_track_b(grid, lat, lon, readings, *, method="entropy+iccp", drift_radius_m=5000.0,
                  noise=1.0, entropy=None, iccp=None, warn=True):
    """Match one track with paper B's methods, with input checks (public entry point).

    Parameters
    ----------
    grid : Grid
        Map: magnetic total intensity or anomaly (nT), or gravity anomaly (mGal).
    lat, lon : array_like, shape ``(N,)``
        INS-indicated fixes (degrees), N ≥ :data:`~jaxgrav.match.MIN_FIXES`.
    readings : array_like, shape ``(N,)``
        Measured values in the map's units, corrected for any known bias (Eötvös for
        gravity): neither stage estimates a bias.
    method : {"entropy", "iccp", "entropy+iccp"}
    drift_radius_m : float
        Largest expected INS error (m); sizes the entropy offsets and ICCP's window.
    noise : float
        Reading noise σ (map units).
    entropy : EntropyConfig, optional
        Replaces the sizing from ``drift_radius_m``.
    iccp : IccpConfig, optional
        Replaces the sizing from ``drift_radius_m`` and ``noise``.
    warn : bool
        Emit a ``RuntimeWarning`` per status flag raised.

    Returns
    -------
    MatchResult

    Raises
    ------
    ValueError
        Unknown method, mismatched lengths, too short a track, NaN values, a track
        off the map, non-positive drift radius.
    """
    from jaxgrav.match.api import _validate

    if method not in METHODS_B:
        raise ValueError(f"method must be one of {METHODS_B}; got {method!r}")
    if not noise >= 0:
        raise ValueError(f"noise must be a non-negative standard deviation; got {noise!r}")
    lat, lon, readings = _validate(grid, lat, lon, readings)
    if method != "iccp" and entropy is None:
        entropy = entropy_config_for(grid, drift_radius_m)
    if iccp is None:
        stage = "alone" if method == "iccp" else "fine"
        iccp = iccp_config_for(grid, drift_radius_m, stage=stage, noise=noise)
    if method == "entropy":
        result = match_entropy(grid, lat, lon, readings, entropy)
    elif method == "iccp":
        result = match_iccp(grid, lat, lon, readings, iccp)
    else:
        result = match_entropy_iccp(grid, lat, lon, readings, entropy, iccp)
    if warn:
        for bit, msg in ALL_STATUS_B.items():
            if int(result.status) & bit:
                warnings.warn(msg, RuntimeWarning, stacklevel=2)
    return result


def status_messages_b(status):
    """Messages of a paper-B status bit field (a Python int)."""
    return [msg for bit, msg in ALL_STATUS_B.items() if int(status) & bit]


__all__ += ["ALL_STATUS_B", "status_messages_b"]


# ---------------------------------------------------------------------- simulation
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
    from jaxgrav.match.candidates import local_offsets_m

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
    """Mean-track errors (m) of one run and the rotations estimated (degrees)."""

    ins_m: jax.Array
    entropy_m: jax.Array
    iccp_m: jax.Array
    combined_m: jax.Array
    true_rotation_deg: jax.Array
    iccp_rotation_deg: jax.Array
    combined_rotation_deg: jax.Array
    status_iccp: jax.Array
    status_combined: jax.Array


def paper_b_errors(key, truth_field, grid, scenario, entropy, iccp_alone, iccp_fine):
    """Simulate one run and match it by entropy, ICCP and entropy + ICCP (vmap over keys).

    Parameters
    ----------
    key : PRNG key
    truth_field : Grid or callable
        Field sensed.
    grid : Grid
        Map matched against.
    scenario : PaperBScenario
    entropy : EntropyConfig
    iccp_alone, iccp_fine : IccpConfig
        ICCP configurations alone (window covering the drift) and after the coarse stage.

    Returns
    -------
    PaperBErrors
    """
    run = paper_b_scenario(key, truth_field, scenario)
    lat, lon, z = run.ins_lat, run.ins_lon, run.readings
    alone = _iccp_result(make_sampler(grid, "bicubic"), lat, lon, z, iccp_alone)
    both = match_entropy_iccp(grid, lat, lon, z, entropy, iccp_fine)
    c_lat, c_lon = both.topk_lat[0], both.topk_lon[0]  # the coarse (entropy) track
    # true rotation: of the truth relative to the INS track (what a matcher should return)
    from jaxgrav.match.candidates import local_offsets_m

    tn, te = local_offsets_m(run.truth.lat, run.truth.lon, run.truth.lat[0], run.truth.lon[0])
    in_, ie = local_offsets_m(lat, lon, lat[0], lon[0])
    true_rot = jnp.rad2deg(jnp.arctan2(te[-1], tn[-1]) - jnp.arctan2(ie[-1], in_[-1]))
    true_rot = (true_rot + 180.0) % 360.0 - 180.0
    err = lambda la, lo: track_error_m(la, lo, run.truth)  # noqa: E731
    return PaperBErrors(
        err(lat, lon), err(c_lat, c_lon), err(alone.lat, alone.lon),
        err(both.lat, both.lon), true_rot, alone.rotation_deg, both.rotation_deg,
        alone.status, both.status,
    )
