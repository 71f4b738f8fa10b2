"""Matchers as Monte Carlo methods: paper A's dense and chain matchers, paper B's stages.

Each ``*_run(key, ...)`` simulates one run and matches it; each builder returns the
:class:`~jaxgrav.montecarlo.spec.MethodSpec` that :mod:`jaxgrav.montecarlo.methods`
registers by name. :func:`paper_a_match` and :func:`matcher_record` are the one
definition of a paper-A run and of the per-run metrics, shared with
:mod:`jaxgrav.montecarlo.paper_a_table1`.
"""

import functools
import warnings

import jax.numpy as jnp

from jaxgrav.geodesy import eotvos
from jaxgrav.match.combined import match_entropy_iccp
from jaxgrav.match.correlation import match_chains
from jaxgrav.match.dense import match_dense
from jaxgrav.match.entropy import entropy_config_for, match_entropy
from jaxgrav.match.iccp import match_iccp
from jaxgrav.match.result import CORRELATION_STATUS
from jaxgrav.match.result import STATUS as ALL_STATUS
from jaxgrav.match.sizing import chain_grid, config_for, iccp_config_for
from jaxgrav.montecarlo.draws import scenario_draws
from jaxgrav.montecarlo.fix_metrics import fix_metrics
from jaxgrav.montecarlo.spec import (
    MethodSpec,
    check_map_error,
    check_settings,
    default_grid,
    map_error_settings,
    region_of,
    told_map_error,
    told_settings,
)
from jaxgrav.prepared import PreparedMap, as_grid, prepare_map
from jaxgrav.scenarios import MatchingScenario, matching_scenario
from jaxgrav.scenarios.paper_b import PaperBScenario, paper_b_scenario
from jaxgrav.sim import DEG_ARC_M, track_error_m

__all__ = [
    "DEPRECATED_NAMES",
    "MISSING_MAP_START_TRIES",
    "chains_builder",
    "chains_run",
    "dense_builder",
    "dense_run",
    "entropy_iccp_builder",
    "entropy_iccp_run",
    "entropy_run",
    "iccp_run",
    "ins_error_m",
    "matcher_record",
    "paper_a_match",
    "paper_b_builder",
]


MISSING_MAP_START_TRIES = 16
"""Random starts (true tracks) a run tries on a map with missing nodes: the builders' (A, B,
D) ``start_tries`` then (:func:`~jaxgrav.scenarios.paper_a.first_clear_draw`)."""


# ------------------------------------------------------------ metrics of every matcher
def ins_error_m(run):
    """Mean horizontal INS error of a run (m, scalar): the mean length of the scenario's
    north/east INS offsets at the fixes (``run.drift_north_m``, ``run.drift_east_m``,
    shape ``(n_fixes,)``).

    For paper A's fixed drift this is exactly the drift radius on the mean sphere
    (``drift_deg · DEG_ARC_M``); for paper B the offsets are measured from the true
    track, so it equals ``track_error_m(ins_lat, ins_lon, truth)``."""
    return jnp.mean(jnp.hypot(run.drift_north_m, run.drift_east_m))


def matcher_record(run, r, **extra):
    """The per-run record of a matcher.

    Parameters
    ----------
    run : MatchingRun
        The simulated run (truth, INS track, INS offsets).
    r : MatchResult
        The matcher's result for it.
    **extra
        More per-run values to include.

    Returns
    -------
    dict
        ``ins_err_m`` (:func:`ins_error_m`, m), ``err_m`` (mean distance of the
        returned track from the truth, m; a rejected fix returns the INS track),
        ``status`` (int32), ``score`` (the matcher's), the fix metrics ``accepted``,
        ``sigma_max_m``, ``covered95``
        (:func:`~jaxgrav.montecarlo.fix_metrics.fix_metrics`), the run's draws
        (:func:`~jaxgrav.montecarlo.draws.scenario_draws`: start and INS offset),
        ``readings_on_map`` (every reading finite: the true track read no missing map
        node) and ``extra``.
    """
    return dict(
        ins_err_m=ins_error_m(run),
        readings_on_map=jnp.all(jnp.isfinite(run.readings)),
        err_m=track_error_m(r.lat, r.lon, run.truth),
        status=jnp.asarray(r.status, jnp.int32),
        score=r.score,
        **fix_metrics(run, r),
        **scenario_draws(run.truth.lat, run.truth.lon, run.ins_lat, run.ins_lon),
        **extra,
    )


def _offset(r):
    return dict(offset_north_m=r.offset_north_m, offset_east_m=r.offset_east_m)


# -------------------------------------------------------------------------- paper A
def paper_a_match(matcher, key, truth_field, match_map, scenario, config, map_error=None):
    """One paper-A run: simulate on ``truth_field``, correct Eötvös, match on ``match_map``.

    Parameters
    ----------
    matcher : callable
        :func:`~jaxgrav.match.dense.match_dense` or
        :func:`~jaxgrav.match.correlation.match_chains`.
    key : PRNG key
    truth_field : Grid
        Field the gravimeter senses (mGal).
    match_map : Grid
        Map matched against (mGal).
    scenario : MatchingScenario
    config : DenseConfig or ChainConfig
        ``matcher``'s settings.
    map_error : CorrelatedMapError, TruthGrid or None, optional
        Map error of the readings (drawn per run on ``truth_field`` from the run's key;
        :func:`~jaxgrav.scenarios.matching_scenario`); the matcher still uses
        ``match_map``. None: readings from ``truth_field`` itself.

    Returns
    -------
    run : MatchingRun
        :func:`~jaxgrav.scenarios.matching_scenario`'s run.
    readings : Array, shape ``(n_fixes,)``
        The readings corrected for the Eötvös effect with the true velocity (mGal), as a
        user with an INS velocity would.
    result : MatchResult
    """
    run = matching_scenario(key, truth_field, scenario, map_error)
    g = run.readings + eotvos(run.ins_lat, run.truth.v_east, run.truth.v_north)
    return run, g, matcher(match_map, run.ins_lat, run.ins_lon, g, config)


# ------------------------------------------------------------------------- dense (A)
def dense_run(key, grid, scenario, config, map_error=None):
    """One paper-A run on ``grid`` matched by :func:`~jaxgrav.match.dense.match_dense`.

    As :func:`paper_a_match` with ``grid`` the map and, with ``map_error`` None, also
    the truth (else the truth is drawn per run by ``map_error``).

    Returns
    -------
    dict
        :func:`matcher_record` (``ins_err_m``, ``err_m``, ``status``, ``score``) and
        ``offset_north_m``, ``offset_east_m`` (estimated correction, m).
    """
    run, _, r = paper_a_match(match_dense, key, grid, grid, scenario, config, map_error)
    return matcher_record(run, r, **_offset(r))


def _paper_a_settings(grid, drift_deg, noise, n_fixes, map_error):
    """The paper-A builders' defaults and checks: map, map error, drift, noise, fixes, scenario."""
    grid = default_grid() if grid is None else grid
    map_error = check_map_error(map_error, grid)
    drift = 0.035 if drift_deg is None else float(drift_deg)
    noise = 1.0 if noise is None else float(noise)
    n = 30 if n_fixes is None else int(n_fixes)
    check_settings(drift, noise, n)
    # land masked on the map: a run's start is drawn again (up to 16 times) until its
    # true track reads no missing node (a complete map: the same runs as one try)
    tries = MISSING_MAP_START_TRIES if grid.n_missing else 1
    scen = MatchingScenario(region=region_of(grid), drift_deg=drift, noise_mgal=noise, n_fixes=n,
                            start_tries=tries)
    return grid, map_error, drift, noise, n, scen


def dense_builder(grid, *, drift_deg=None, noise=None, n_fixes=None, map_error=None,
                  map_error_told="auto"):
    """Paper A, dense-offset matcher (the ``jaxgrav demo`` realistic setting).

    Defaults: INS drift 0.035° (fixed radius, random direction), 1 mGal noise, 30
    fixes 2 min apart at 10 kn east + 10 kn north; search radius 1.2 × the drift,
    bias prior σ 3 mGal; a perfect map (``map_error`` None).

    ``map_error`` (every matcher builder): a
    :class:`~jaxgrav.fields.map_error.CorrelatedMapError` (drawn once per run from the
    run's key on ``grid``; σ = 0 is the perfect map, exactly as None) or a
    :class:`~jaxgrav.fields.map_error.TruthGrid` (the readings come from its grid,
    which must cover ``grid``'s area). The matcher always uses ``grid``; the spec's
    settings record σ and L (``map_error_sigma``, ``map_error_length_m``) or the truth
    grid's name (``truth_map``).

    ``map_error_told``: the map-error model the *matcher* is told
    (:func:`~jaxgrav.match.sizing.config_for`'s ``map_error``: GLS score, posterior-mean
    fix, fixes with a 1-σ above 3 km rejected). ``"auto"`` (default): the readings'
    CorrelatedMapError itself (the user knows their map's error level); for a
    TruthGrid its ``error`` if stated, else
    :func:`~jaxgrav.fields.map_error_estimate.estimate_map_error` of ``grid`` (from the
    map alone, never the truth); none for a perfect map. None or σ = 0: the
    white-noise matcher (exactly the runs without this option). A CorrelatedMapError:
    that model, which may differ from the truth's (mis-told studies). The settings
    record ``told_map_error_sigma``, ``told_map_error_length_m`` and
    ``told_map_error_source``.
    """
    grid, map_error, drift, noise, n, scen = _paper_a_settings(grid, drift_deg, noise, n_fixes,
                                                             map_error)
    told, source = told_map_error(map_error_told, map_error, grid)
    cfg = config_for("dense", grid, 1.2 * drift * DEG_ARC_M, noise_mgal=max(noise, 0.1),
                     bias_sigma_mgal=3.0, map_error=told)
    settings = dict(description="paper A: dense-offset matcher, fixed INS drift"
                                + ("" if told is None else ", told the map error (GLS)"),
                    drift_deg=drift, noise_mgal=noise, n_fixes=n, dt_s=scen.dt,
                    search_half_size=cfg.half_size, search_spacing_m=cfg.spacing_m,
                    search_region=cfg.region, max_sigma_m=float(cfg.max_sigma_m),
                    max_sigma_ratio=float(cfg.max_sigma_ratio),
                    **map_error_settings(map_error), **told_settings(told, source))
    return MethodSpec(dense_run, (grid, scen, cfg, map_error), settings,
                      dict(CORRELATION_STATUS))


# ------------------------------------------------------------------------ chains (A)
def chains_run(key, grid, refined, scenario, config, map_error=None):
    """One paper-A run: simulate on ``grid``, match by iso-point chains on ``refined``.

    As :func:`paper_a_match` with
    :func:`~jaxgrav.match.correlation.match_chains` (``map_error`` as :func:`dense_run`).

    Returns
    -------
    dict
        :func:`matcher_record` (``ins_err_m``, ``err_m``, ``status``, ``score``),
        ``offset_north_m``, ``offset_east_m`` (m), ``work_constrained`` (chains left
        after constraint elimination).
    """
    run, _, r = paper_a_match(match_chains, key, grid, refined, scenario, config, map_error)
    return matcher_record(run, r, **_offset(r), work_constrained=r.work_constrained)


def chains_builder(grid, *, drift_deg=None, noise=None, n_fixes=None, map_error=None,
                   map_error_told="auto"):
    """Paper A's pipeline: iso-point chains with constraint elimination.

    The readings come from ``grid``; the matcher searches ``grid`` refined (bilinear)
    to :data:`~jaxgrav.match.sizing.CHAIN_NODE_DEG` nodes
    (:func:`~jaxgrav.match.sizing.chain_grid`: ×8 for the 2.5′ map). Scenario as
    :func:`dense_builder` (drift 0.035°, 1 mGal, 30 fixes 2 min apart); search window
    and tolerances from :func:`~jaxgrav.match.api.config_for` ``("chains", ...)`` for
    1.2 × the drift.
    ``map_error`` as :func:`dense_builder` (drawn on ``grid``, not the refined map);
    ``map_error_told`` as :func:`dense_builder` (told: the GLS posterior over the
    chains' nodes, fixes with a 1-σ above 3 km rejected,
    :data:`~jaxgrav.match.sizing.CHAIN_MAP_ERROR_INTEGRITY`).
    """
    grid, map_error, drift, noise, n, scen = _paper_a_settings(grid, drift_deg, noise, n_fixes,
                                                             map_error)
    told, source = told_map_error(map_error_told, map_error, grid)
    refined = chain_grid(grid)
    factor = round(grid.dlat / refined.dlat)
    cfg = config_for("chains", refined, 1.2 * drift * DEG_ARC_M, noise_mgal=max(noise, 0.1),
                     step_m=scen.step_m, map_error=told)
    settings = dict(description=f"paper A: iso-point chains on the map refined x{factor}, "
                                "fixed INS drift"
                                + ("" if told is None else ", told the map error (GLS)"),
                    drift_deg=drift, noise_mgal=noise, n_fixes=n, dt_s=scen.dt,
                    refine_factor=factor, search_half_size=cfg.half_size,
                    stencil_size=cfg.stencil_size, **map_error_settings(map_error),
                    **told_settings(told, source))
    return MethodSpec(chains_run, (grid, refined, scen, cfg, map_error), settings,
                      dict(CORRELATION_STATUS))


# ----------------------------------------------------------------- entropy, ICCP (B)
def _paper_b_truth(grid, map_error):
    """The field a paper-B run's readings sample: the map (a PreparedMap's bicubic
    sampler, not prepared again) or, with a map error, the Grid the error is drawn on."""
    if map_error is None and isinstance(grid, PreparedMap):
        return grid.sampler("bicubic")
    return as_grid(grid)


def entropy_iccp_run(key, grid, scenario, entropy, iccp, map_error=None):
    """One paper-B run: simulate (:func:`~jaxgrav.match.entropy_iccp.paper_b_scenario`), match.

    ``grid``: a Grid or the PreparedMap :func:`paper_b_builder` passes. ``map_error`` as
    :func:`dense_run`: the readings' truth, drawn per run; the matchers use ``grid``.

    Returns
    -------
    dict
        ``ins_err_m``, ``err_m`` (m), ``status`` (int32), ``score`` (mean squared
        misfit), ``rotation_deg`` (estimated heading correction).
    """
    run = paper_b_scenario(key, _paper_b_truth(grid, map_error), scenario, map_error)
    r = match_entropy_iccp(grid, run.ins_lat, run.ins_lon, run.readings, entropy, iccp)
    return _b_metrics(run, r)


def entropy_run(key, grid, scenario, entropy, map_error=None):
    """One paper-B run matched by the entropy coarse stage alone; as :func:`entropy_iccp_run`
    (``rotation_deg`` is 0: the stage only shifts the track)."""
    run = paper_b_scenario(key, _paper_b_truth(grid, map_error), scenario, map_error)
    return _b_metrics(run, match_entropy(grid, run.ins_lat, run.ins_lon, run.readings, entropy))


def iccp_run(key, grid, scenario, iccp, map_error=None):
    """One paper-B run matched by ICCP alone from the INS track; as :func:`entropy_iccp_run`."""
    run = paper_b_scenario(key, _paper_b_truth(grid, map_error), scenario, map_error)
    return _b_metrics(run, match_iccp(grid, run.ins_lat, run.ins_lon, run.readings, iccp))


def _b_metrics(run, r):
    return matcher_record(run, r, rotation_deg=r.rotation_deg)


_B_RUNS = {
    "entropy+iccp": (entropy_iccp_run, "entropy coarse + ICCP fine matching"),
    "entropy": (entropy_run, "entropy coarse matching alone"),
    "iccp": (iccp_run, "ICCP alone (from the INS track)"),
}


def paper_b_builder(grid, *, stage="entropy+iccp", drift_deg=None, noise=None, n_fixes=None,
                    map_error=None, map_error_told="auto"):
    """Paper B: entropy coarse matching, ICCP, or both (``stage``).

    Defaults (paper B's gravity case, as ``examples/paper_b_entropy_iccp.py``): INS
    offset uniform in [⅔·drift, drift] with drift 0.03°, rotated ±1.5° about the
    start, 1 mGal noise, 60 fixes a minute apart at 10 m/s in a random direction. The
    matchers are sized to the drift + 0.005° as the example: entropy offsets by
    :func:`~jaxgrav.match.entropy.entropy_config_for` (at most 20 a side), ICCP by
    :func:`~jaxgrav.match.entropy_iccp.iccp_config_for` with ``stage="alone"``
    (window over the whole error) or ``"fine"`` (after the entropy stage).

    Parameters
    ----------
    grid : Grid or None
        Map (mGal); None: :func:`default_grid`.
    stage : {"entropy+iccp", "entropy", "iccp"}
    drift_deg, noise, n_fixes : optional
        Offset bound (degrees of arc), reading noise σ (map units), fixes per track.
    map_error : CorrelatedMapError, TruthGrid or None, optional
        The readings' map error, as :func:`dense_builder`.
    map_error_told : "auto", CorrelatedMapError or None, optional
        The map error ``entropy+iccp`` is told, as :func:`dense_builder`'s (told: the
        GLS posterior over the entropy stage's offsets in the searched disc, its
        informativeness and no-harm tests,
        :data:`~jaxgrav.match.sizing.ICCP_MAP_ERROR_INTEGRITY`). The stages alone
        (``entropy``, ``iccp``) have no told form: anything but "auto" or None is an
        error for them, and they run the white-noise matcher.

    Returns
    -------
    MethodSpec
        Its ``args`` start with the :class:`~jaxgrav.prepared.PreparedMap` of ``grid``
        (spline coefficients computed once, not in every chunk's program: 22 of
        entropy+iccp's 346 kernels). On a ``grid`` with missing nodes its scenario's
        ``start_tries`` is :data:`MISSING_MAP_START_TRIES` (a run's start and heading
        drawn until its track reads no missing node; ``readings_on_map``), else 1.
    """
    fn, label = _B_RUNS[stage]
    grid = default_grid() if grid is None else grid
    map_error = check_map_error(map_error, grid)
    if stage != "entropy+iccp" and not (map_error_told is None
                                        or isinstance(map_error_told, str)):
        raise ValueError(f"map_error_told: the {stage} stage alone has no told form (its "
                         f"fixes carry no covariance); got {map_error_told!r}")
    told, source = (told_map_error(map_error_told, map_error, grid)
                    if stage == "entropy+iccp" else told_map_error(None, None, grid))
    drift = 0.03 if drift_deg is None else float(drift_deg)
    noise = 1.0 if noise is None else float(noise)
    n = 60 if n_fixes is None else int(n_fixes)
    check_settings(drift, noise, n)
    # land masked: a run's start and heading are drawn again, as paper A's (dense_builder)
    scen = PaperBScenario(region=region_of(grid), offset_min_deg=2.0 * drift / 3.0,
                          offset_max_deg=drift, noise=noise, n_fixes=n,
                          start_tries=MISSING_MAP_START_TRIES if grid.n_missing else 1)
    reach_m = (drift + 0.005) * DEG_ARC_M
    settings = dict(description=f"paper B: {label}; offset and rotated INS track"
                                + ("" if told is None else ", told the map error (GLS)"),
                    drift_deg=drift, offset_min_deg=scen.offset_min_deg, noise_mgal=noise,
                    n_fixes=n, dt_s=scen.dt, rotation_deg=scen.rotation_deg,
                    **map_error_settings(map_error), **told_settings(told, source))
    args = (prepare_map(grid), scen)  # the spline coefficients once, not in every chunk
    if stage != "iccp":
        ent = entropy_config_for(grid, reach_m, max_half_size=20)
        settings["entropy_half_size"] = ent.half_size
        args += (ent,)
    if stage != "entropy":
        icp = iccp_config_for(grid, reach_m, stage="alone" if stage == "iccp" else "fine",
                              noise=max(noise, 0.1), map_error=told)
        settings["iccp_window_m"] = float(icp.window_m)
        args += (icp,)
    return MethodSpec(fn, (*args, map_error), settings, dict(ALL_STATUS))


entropy_iccp_builder = functools.partial(paper_b_builder, stage="entropy+iccp")
"""Paper B, entropy coarse + ICCP fine matching (:func:`paper_b_builder`)."""



DEPRECATED_NAMES = {"correlation_run": "dense_run", "correlation_builder": "dense_builder"}
"""Old name -> new name of the paper-A dense matcher's functions (kept for one release)."""


def __getattr__(name):
    if name in DEPRECATED_NAMES:
        new = DEPRECATED_NAMES[name]
        warnings.warn(f"jaxgrav.montecarlo.matcher_runs.{name} is deprecated; use {new} (the "
                      "registry method 'correlation' is now 'dense')", DeprecationWarning,
                      stacklevel=2)
        return globals()[new]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
