"""Methods the Monte Carlo runner knows by name: scenario + matcher/filter + errors per run.

Each entry of :data:`BUILDERS` maps a method name to a *builder*::

    builder(grid, *, drift_deg=None, noise=None, n_fixes=None) -> MethodSpec

``None`` means the method's own default; for ``grid`` that is the shipped ``ryukyu``
2.5′ map for the matchers and paper D's three point masses for the filters. The
spec's ``fn(key, *args)`` simulates and solves one run and returns a dict of per-run
metrics, at least :data:`METRICS`:

``ins_err_m``  horizontal error of the INS-indicated track (m): the mean distance from
               the truth for the matchers; the RMS over the second half of the run
               for the filters
``err_m``      the same for the method's estimated track (m)
``status``     the method's status bit field (0 = clean; int32)

Matchers: ``correlation`` (paper A, dense offsets), ``chains`` (paper A's iso-point
chains on the map refined to 0.005° nodes), ``entropy``, ``iccp`` and
``entropy+iccp`` (paper B, each stage alone and combined).

The paper-D filters (``ukf``, ``ekf``, ``gsf``, ``pmf`` and the guarded ``ukf-guard``,
``gsf-guard``) also return ``nees``, the mean position NEES over the second half of the
run (expected value 2); they run over paper D's point masses, or over a map (straight
tracks in random directions).

``fn`` must be a module-level function (not a fresh closure), so that repeated runs
reuse the compiled code; everything a user may sweep goes into ``args``.

Adding a method
---------------
One entry, ``BUILDERS["name"] = builder`` or ``register("name", builder)``;
``jaxgrav montecarlo --method`` lists the keys of :data:`BUILDERS`.
"""

import dataclasses
import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp

from jaxgrav.sim import DEG_ARC_M

__all__ = [
    "BUILDERS",
    "FILTER_METHODS",
    "METRICS",
    "MethodSpec",
    "build",
    "chains_run",
    "correlation_run",
    "default_grid",
    "ekf_run",
    "entropy_iccp_run",
    "entropy_run",
    "filter_builder",
    "gsf_guard_run",
    "gsf_run",
    "iccp_run",
    "pmf_run",
    "register",
    "ukf_guard_run",
    "ukf_run",
]

METRICS = ("ins_err_m", "err_m", "status")
"""Metrics every method returns per run."""


@dataclasses.dataclass(frozen=True)
class MethodSpec:
    """A method ready for :func:`jaxgrav.montecarlo.run`.

    Attributes
    ----------
    fn : callable
        ``fn(key, *args) -> dict`` of per-run metrics (at least :data:`METRICS`).
    args : tuple
        Extra arguments of ``fn`` (map, scenario, configurations).
    settings : dict
        The resolved scenario settings and a one-line description (for file attributes).
    status_bits : dict of int to str
        Meaning of the ``status`` bits.
    """

    fn: Callable
    args: tuple
    settings: dict
    status_bits: dict


def default_grid():
    """The shipped 2.5′ ``ryukyu`` gravity anomaly map (mGal), 24–36°N, 124–136°E."""
    from jaxgrav import datasets

    return datasets.load("ryukyu")["anomaly_2p5min"]


def _region(grid):
    w, e, s, n = grid.extent
    return (float(s), float(n), float(w), float(e))


# ------------------------------------------------------------------- correlation (A)
def correlation_run(key, grid, scenario, config):
    """One paper-A run: simulate (:func:`~jaxgrav.scenarios.matching_scenario`), match dense.

    Readings are Eötvös-corrected with the true velocity (as a user with an INS
    velocity would) and matched by :func:`~jaxgrav.match.dense.match_dense`.

    Returns
    -------
    dict
        ``ins_err_m``, ``err_m`` (m), ``status`` (int32), ``score`` (the matcher's),
        ``offset_north_m``, ``offset_east_m`` (estimated correction, m).
    """
    from jaxgrav.geodesy import eotvos
    from jaxgrav.match.dense import match_dense
    from jaxgrav.scenarios import matching_scenario

    run = matching_scenario(key, grid, scenario)
    g = run.readings + eotvos(run.ins_lat, run.truth.v_east, run.truth.v_north)
    r = match_dense(grid, run.ins_lat, run.ins_lon, g, config)
    return _matcher_record(run, r, **_offset(r))


def _matcher_record(run, r, **extra):
    """The per-run record of a matcher: mean-track errors of the INS and of the match
    (m), status, score, and ``extra``; paper A's matchers add the offset."""
    from jaxgrav.scenarios import track_error_m

    return dict(
        ins_err_m=track_error_m(run.ins_lat, run.ins_lon, run.truth),
        err_m=track_error_m(r.lat, r.lon, run.truth),
        status=jnp.asarray(r.status, jnp.int32),
        score=r.score,
        **extra,
    )


def _offset(r):
    return dict(offset_north_m=r.offset_north_m, offset_east_m=r.offset_east_m)


def correlation_builder(grid, *, drift_deg=None, noise=None, n_fixes=None):
    """Paper A, dense correlation matcher (the ``jaxgrav demo`` realistic setting).

    Defaults: INS drift 0.035° (fixed radius, random direction), 1 mGal noise, 30
    fixes 2 min apart at 10 kn east + 10 kn north; search radius 1.2 × the drift,
    bias prior σ 3 mGal.
    """
    from jaxgrav.match.api import config_for
    from jaxgrav.match.result import STATUS
    from jaxgrav.scenarios import MatchingScenario

    grid = default_grid() if grid is None else grid
    drift = 0.035 if drift_deg is None else float(drift_deg)
    noise = 1.0 if noise is None else float(noise)
    n = 30 if n_fixes is None else int(n_fixes)
    _check(drift, noise, n)
    scen = MatchingScenario(region=_region(grid), drift_deg=drift, noise_mgal=noise, n_fixes=n)
    cfg = config_for("dense", grid, 1.2 * drift * DEG_ARC_M, noise_mgal=max(noise, 0.1),
                     bias_sigma_mgal=3.0)
    settings = dict(description="paper A: dense correlation matcher, fixed INS drift",
                    drift_deg=drift, noise_mgal=noise, n_fixes=n, dt_s=scen.dt,
                    search_half_size=cfg.half_size, search_spacing_m=cfg.spacing_m)
    return MethodSpec(correlation_run, (grid, scen, cfg), settings, dict(STATUS))


# ------------------------------------------------------------------------ chains (A)
CHAIN_NODE_DEG = 0.005
"""Node spacing the chain matcher's map is refined to (degrees): paper A's 0.005°
(its 0.5° map refined ×100; the 2.5′ map refined ×8, as ``examples/paper_a_table1.py``)."""


def chains_run(key, grid, refined, scenario, config):
    """One paper-A run: simulate on ``grid``, match by iso-point chains on ``refined``.

    Readings are Eötvös-corrected with the true velocity and matched by
    :func:`~jaxgrav.match.correlation.match_chains`.

    Returns
    -------
    dict
        ``ins_err_m``, ``err_m`` (m), ``status`` (int32), ``score`` (the matcher's),
        ``offset_north_m``, ``offset_east_m`` (m), ``work_constrained`` (chains left
        after constraint elimination).
    """
    from jaxgrav.geodesy import eotvos
    from jaxgrav.match.correlation import match_chains
    from jaxgrav.scenarios import matching_scenario

    run = matching_scenario(key, grid, scenario)
    g = run.readings + eotvos(run.ins_lat, run.truth.v_east, run.truth.v_north)
    r = match_chains(refined, run.ins_lat, run.ins_lon, g, config)
    return _matcher_record(run, r, **_offset(r), work_constrained=r.work_constrained)


def chains_builder(grid, *, drift_deg=None, noise=None, n_fixes=None):
    """Paper A's pipeline: iso-point chains with constraint elimination.

    The readings come from ``grid``; the matcher searches ``grid`` refined (bilinear)
    to :data:`CHAIN_NODE_DEG` nodes (factor ``round(dlat / 0.005°)``, at least 1:
    ×8 for the 2.5′ map). Scenario as :func:`correlation_builder` (drift 0.035°,
    1 mGal, 30 fixes 2 min apart); search window and tolerances from
    :func:`~jaxgrav.match.api.config_for` ``("chains", ...)`` for 1.2 × the drift.
    """
    from jaxgrav.match.api import config_for
    from jaxgrav.match.result import STATUS
    from jaxgrav.scenarios import MatchingScenario

    grid = default_grid() if grid is None else grid
    drift = 0.035 if drift_deg is None else float(drift_deg)
    noise = 1.0 if noise is None else float(noise)
    n = 30 if n_fixes is None else int(n_fixes)
    _check(drift, noise, n)
    factor = max(1, round(min(grid.dlat, grid.dlon) / CHAIN_NODE_DEG))
    refined = grid.refine(factor) if factor > 1 else grid
    scen = MatchingScenario(region=_region(grid), drift_deg=drift, noise_mgal=noise, n_fixes=n)
    cfg = config_for("chains", refined, 1.2 * drift * DEG_ARC_M, noise_mgal=max(noise, 0.1),
                     step_m=scen.step_m)
    settings = dict(description=f"paper A: iso-point chains on the map refined x{factor}, "
                                "fixed INS drift",
                    drift_deg=drift, noise_mgal=noise, n_fixes=n, dt_s=scen.dt,
                    refine_factor=factor, search_half_size=cfg.half_size,
                    stencil_size=cfg.stencil_size)
    return MethodSpec(chains_run, (grid, refined, scen, cfg), settings, dict(STATUS))


# ----------------------------------------------------------------- entropy, ICCP (B)
def entropy_iccp_run(key, grid, scenario, entropy, iccp):
    """One paper-B run: simulate (:func:`~jaxgrav.match.entropy_iccp.paper_b_scenario`), match.

    Returns
    -------
    dict
        ``ins_err_m``, ``err_m`` (m), ``status`` (int32), ``score`` (mean squared
        misfit), ``rotation_deg`` (estimated heading correction).
    """
    from jaxgrav.match.entropy_iccp import match_entropy_iccp, paper_b_scenario

    run = paper_b_scenario(key, grid, scenario)
    r = match_entropy_iccp(grid, run.ins_lat, run.ins_lon, run.readings, entropy, iccp)
    return _b_metrics(run, r)


def entropy_run(key, grid, scenario, entropy):
    """One paper-B run matched by the entropy coarse stage alone; as :func:`entropy_iccp_run`
    (``rotation_deg`` is 0: the stage only shifts the track)."""
    from jaxgrav.match.entropy import match_entropy
    from jaxgrav.match.entropy_iccp import paper_b_scenario

    run = paper_b_scenario(key, grid, scenario)
    return _b_metrics(run, match_entropy(grid, run.ins_lat, run.ins_lon, run.readings, entropy))


def iccp_run(key, grid, scenario, iccp):
    """One paper-B run matched by ICCP alone from the INS track; as :func:`entropy_iccp_run`."""
    from jaxgrav.match.entropy_iccp import paper_b_scenario
    from jaxgrav.match.iccp import match_iccp

    run = paper_b_scenario(key, grid, scenario)
    return _b_metrics(run, match_iccp(grid, run.ins_lat, run.ins_lon, run.readings, iccp))


def _b_metrics(run, r):
    return _matcher_record(run, r, rotation_deg=r.rotation_deg)


_B_RUNS = {
    "entropy+iccp": (entropy_iccp_run, "entropy coarse + ICCP fine matching"),
    "entropy": (entropy_run, "entropy coarse matching alone"),
    "iccp": (iccp_run, "ICCP alone (from the INS track)"),
}


def paper_b_builder(grid, *, stage="entropy+iccp", drift_deg=None, noise=None, n_fixes=None):
    """Paper B: entropy coarse matching, ICCP, or both (``stage``).

    Defaults (SPEC §B, the example's ``gravity`` case): INS offset uniform in
    [⅔·drift, drift] with drift 0.03°, rotated ±1.5° about the start, 1 mGal noise,
    60 fixes a minute apart at 10 m/s in a random direction. The matchers are sized
    to the drift + 0.005° as ``examples/paper_b_entropy_iccp.py``: entropy offsets
    by :func:`~jaxgrav.match.entropy.entropy_config_for` (at most 20 a side), ICCP
    by :func:`~jaxgrav.match.entropy_iccp.iccp_config_for` with ``stage="alone"``
    (window over the whole error) or ``"fine"`` (after the entropy stage).

    Parameters
    ----------
    grid : Grid or None
        Map (mGal); None: :func:`default_grid`.
    stage : {"entropy+iccp", "entropy", "iccp"}
    drift_deg, noise, n_fixes : optional
        Offset bound (degrees of arc), reading noise σ (map units), fixes per track.

    Returns
    -------
    MethodSpec
    """
    from jaxgrav.match.entropy import entropy_config_for
    from jaxgrav.match.entropy_iccp import ALL_STATUS_B, PaperBScenario, iccp_config_for

    fn, label = _B_RUNS[stage]
    grid = default_grid() if grid is None else grid
    drift = 0.03 if drift_deg is None else float(drift_deg)
    noise = 1.0 if noise is None else float(noise)
    n = 60 if n_fixes is None else int(n_fixes)
    _check(drift, noise, n)
    scen = PaperBScenario(region=_region(grid), offset_min_deg=2.0 * drift / 3.0,
                          offset_max_deg=drift, noise=noise, n_fixes=n)
    reach_m = (drift + 0.005) * DEG_ARC_M
    settings = dict(description=f"paper B: {label}; offset and rotated INS track",
                    drift_deg=drift, offset_min_deg=scen.offset_min_deg, noise_mgal=noise,
                    n_fixes=n, dt_s=scen.dt, rotation_deg=scen.rotation_deg)
    args = (grid, scen)
    if stage != "iccp":
        ent = entropy_config_for(grid, reach_m, max_half_size=20)
        settings["entropy_half_size"] = ent.half_size
        args += (ent,)
    if stage != "entropy":
        icp = iccp_config_for(grid, reach_m, stage="alone" if stage == "iccp" else "fine",
                              noise=max(noise, 0.1))
        settings["iccp_window_m"] = float(icp.window_m)
        args += (icp,)
    return MethodSpec(fn, args, settings, dict(ALL_STATUS_B))


entropy_iccp_builder = functools.partial(paper_b_builder, stage="entropy+iccp")
"""Paper B, entropy coarse + ICCP fine matching (:func:`paper_b_builder`)."""


def _check(drift, noise, n):
    if not drift > 0:
        raise ValueError(f"drift must be a positive angle (degrees of arc); got {drift!r}")
    if not noise >= 0:
        raise ValueError(f"noise must be a non-negative standard deviation (mGal); got {noise!r}")
    if n < 5:
        raise ValueError(f"fixes must be at least 5 per track; got {n}")


# ----------------------------------------------------------------- paper-D filters (D)
def _kalman_run(key, field, scenario, filt, guard=False):
    from jaxgrav.match.filters import (
        GuardConfig,
        filter_scenario,
        guard_run,
        initial_state,
        run_filter,
        run_metrics,
        run_steps,
    )

    run = filter_scenario(key, field, scenario)
    dynamics, steps = run_steps(run, scenario)
    x0, p0 = initial_state(scenario)
    # readings sit on steps every-1, 2 every-1, …: update only there, predict in between
    _, infos = run_filter(filt, field, dynamics, x0, p0, steps, scenario.reading_every)
    if guard:
        infos = guard_run(infos, dynamics, p0, GuardConfig())
    return run_metrics(run, infos)


def ukf_run(key, field, scenario):
    """One paper-D run filtered by the UKF (default sigma points).

    Parameters
    ----------
    key : PRNG key
    field : PointMasses or Grid
        Anomaly field simulated and filtered (mGal).
    scenario : FilterScenario

    Returns
    -------
    dict
        ``ins_err_m``, ``err_m`` (RMS position error over the second half of the
        run, m), ``status`` (OR of the steps' :data:`~jaxgrav.match.filters.STATUS_FILTER`
        flags without ``no_reading``; int32), ``nees`` (mean position NEES over the
        second half; 2 for a consistent filter).
    """
    from jaxgrav.match.filters import ukf

    return _kalman_run(key, field, scenario, ukf())


def ekf_run(key, field, scenario):
    """One paper-D run filtered by the EKF (``jax.jacfwd`` Jacobian); as :func:`ukf_run`."""
    from jaxgrav.match.filters import ekf

    return _kalman_run(key, field, scenario, ekf())


def gsf_run(key, field, scenario):
    """One paper-D run filtered by a Gaussian sum of 3 × 3 UKFs; as :func:`ukf_run`."""
    from jaxgrav.match.filters import gaussian_sum, ukf

    return _kalman_run(key, field, scenario, gaussian_sum(ukf(), 3))


def ukf_guard_run(key, field, scenario):
    """One paper-D run filtered by the UKF, its output guarded; as :func:`ukf_run`.

    :func:`~jaxgrav.match.filters.guard_run` with the default
    :class:`~jaxgrav.match.filters.GuardConfig`: position corrections only in the
    directions whose variance fell below 0.2 of the free INS's.
    """
    from jaxgrav.match.filters import ukf

    return _kalman_run(key, field, scenario, ukf(), guard=True)


def gsf_guard_run(key, field, scenario):
    """One paper-D run filtered by the Gaussian sum of 3 × 3 UKFs, output guarded; as
    :func:`ukf_guard_run`."""
    from jaxgrav.match.filters import gaussian_sum, ukf

    return _kalman_run(key, field, scenario, gaussian_sum(ukf(), 3), guard=True)


def pmf_run(key, field, scenario):
    """One paper-D run filtered by the grid point-mass filter (61 × 61 cells of 200 m).

    The filter updates at every reading (``run_pmf`` with ``every =
    scenario.reading_every``); between readings the estimate is predicted. Returns as
    :func:`ukf_run`.
    """
    from jaxgrav.match.filters import (
        filter_scenario,
        initial_state,
        pmf,
        run_metrics,
        run_pmf,
        run_steps,
    )

    run = filter_scenario(key, field, scenario)
    _, steps = run_steps(run, scenario)
    x0, p0 = initial_state(scenario)
    every = scenario.reading_every
    t = steps.z.shape[0]
    pad = -t % every  # readings sit on steps every-1, 2 every-1, …; pad to a multiple
    steps = jax.tree.map(lambda a: jnp.concatenate([a, jnp.repeat(a[-1:], pad, 0)]), steps)
    _, infos = run_pmf(pmf(), field, scenario.dt, x0, p0, steps, every)
    return run_metrics(run, jax.tree.map(lambda a: a[:t], infos))


_FILTER_RUNS = {
    "ukf": (ukf_run, "UKF (scaled sigma points, alpha 0.5)"),
    "ekf": (ekf_run, "EKF (jacfwd Jacobian)"),
    "gsf": (gsf_run, "Gaussian sum of 3 x 3 UKFs"),
    "ukf-guard": (ukf_guard_run, "UKF, no-harm guard (corrections where variance < 0.2 of INS)"),
    "gsf-guard": (gsf_guard_run, "Gaussian sum of 3 x 3 UKFs, no-harm guard"),
    "pmf": (pmf_run, "grid point-mass filter, 61 x 61 cells of 200 m"),
}


def filter_builder(grid, *, kind, drift_deg=None, noise=None, n_fixes=None):
    """Paper D: gravity/INS filtering over ``paper_d()``'s three point masses or a map.

    The scenario is :class:`~jaxgrav.match.filters.FilterScenario` at 5 m/s, stepping
    at the reading rate: ``dt = 10 s``, a reading every step, 721 steps (2 h). This
    is the same physics as the paper's 2 s steps with a reading every 5th: the INS
    error model is discretised exactly (Van Loan), so five 2 s predictions equal
    one 10 s prediction, and the 2 s steps in between carry no reading — only the
    per-step diagnostics are lost, at a fifth of the cost. Over the point masses the
    geometry is ``"mixed"`` (east–west or north-then-east tracks across the masses);
    over a map it is ``"random"`` (straight tracks, uniform heading, as
    ``examples/paper_d_ukf.py --map ryukyu``) from starts at least the track length
    + 3 × the initial error + 10 km inside the map, so the truth, the INS track,
    the sigma points and the point-mass filter's grid stay on it.

    Parameters
    ----------
    grid : Grid or None
        Anomaly map (mGal), sampled bicubically; None: paper D's point masses
        (23.9–24.6°N, 122.6–123.3°E).
    kind : {"ukf", "ekf", "gsf", "pmf", "ukf-guard", "gsf-guard"}
    drift_deg : float, optional
        Size of the initial INS position error (degrees of arc; default 2 km =
        0.01797°); the velocity error is 0.2 m/s.
    noise : float, optional
        Reading noise σ (mGal, default 1), also the filters' reading noise.
    n_fixes : int, optional
        Steps (= readings) per run including the start (default 721).

    Returns
    -------
    MethodSpec

    Raises
    ------
    ValueError
        A map too small for the tracks (smaller than twice the margin above).
    """
    from jaxgrav.fields.pointmass import paper_d
    from jaxgrav.match.filters import STATUS_FILTER, FilterScenario

    fn, label = _FILTER_RUNS[kind]
    pos_error = 2000.0 if drift_deg is None else float(drift_deg) * DEG_ARC_M
    noise = 1.0 if noise is None else float(noise)
    n = 721 if n_fixes is None else int(n_fixes)
    _check(pos_error / DEG_ARC_M, noise, n)
    scen = FilterScenario(dt=10.0, reading_every=1, n_steps=n, pos_error=pos_error,
                          noise_mgal=noise)
    if grid is None:
        field, where, extra = paper_d(), "the 3 point masses", dict(field="paper-d point masses")
    else:
        margin_m = scen.speed * scen.dt * (n - 1) + 3.0 * pos_error + 10e3
        scen = dataclasses.replace(scen, geometry="random",
                                   region=_inner_region(grid, margin_m))
        field, where = grid, f"the map {grid.name or 'grid'}"
        extra = dict(field=f"grid {grid.name}".strip(),
                     region=",".join(f"{v:.4f}" for v in scen.region))
    settings = dict(description=f"paper D: {label} over {where}; errors RMS over the second "
                                "half of the run",
                    **extra, pos_error_m=pos_error,
                    vel_error_m_s=scen.vel_error, noise_mgal=noise, bias_mgal=scen.bias_mgal,
                    n_steps=n, dt_s=scen.dt, reading_every=scen.reading_every,
                    geometry=scen.geometry, speed_m_s=scen.speed)
    bits = {b: name for name, b in STATUS_FILTER.items() if b and name != "no_reading"}
    return MethodSpec(fn, (field, scen), settings, bits)


def _inner_region(grid, margin_m):
    """``(lat_min, lat_max, lon_min, lon_max)`` of ``grid`` shrunk by ``margin_m`` (m)."""
    import math

    w, e, s, n = (float(v) for v in grid.extent)
    dlat = margin_m / DEG_ARC_M
    dlon = margin_m / (DEG_ARC_M * math.cos(math.radians(min(max(abs(s), abs(n)), 89.0))))
    region = (s + dlat, n - dlat, w + dlon, e - dlon)
    if not (region[0] < region[1] and region[2] < region[3]):
        raise ValueError(
            f"the map (lat {s:g}..{n:g}, lon {w:g}..{e:g}) is too small for the filter runs: "
            f"starts must lie {margin_m / 1e3:.0f} km inside it (track length + 3 x the initial "
            "error + 10 km); use fewer --fixes, a smaller --drift or a larger map")
    return region


FILTER_METHODS = tuple(_FILTER_RUNS)
"""Names of the paper-D filters (errors are RMS over the second half of a run, with NEES)."""

BUILDERS = {
    "correlation": correlation_builder,
    "chains": chains_builder,
    "entropy": functools.partial(paper_b_builder, stage="entropy"),
    "iccp": functools.partial(paper_b_builder, stage="iccp"),
    "entropy+iccp": entropy_iccp_builder,
    **{k: functools.partial(filter_builder, kind=k) for k in _FILTER_RUNS},
}
"""Method name -> builder."""


def register(name, builder, *, replace=False):
    """Add a method builder under ``name`` (see the module docstring for the contract)."""
    if name in BUILDERS and not replace:
        raise ValueError(f"method {name!r} is already registered; pass replace=True")
    BUILDERS[name] = builder


def build(method, grid=None, **options):
    """The :class:`MethodSpec` of a registered method.

    Parameters
    ----------
    method : str
        A key of :data:`BUILDERS`.
    grid : Grid, optional
        Map simulated and matched (or filtered) against; None: the method's default
        (:func:`default_grid` for the matchers, paper D's point masses for the filters).
    **options
        ``drift_deg`` (degrees of arc), ``noise`` (map units), ``n_fixes``; None
        keeps the method's default.

    Returns
    -------
    MethodSpec
    """
    if method not in BUILDERS:
        raise ValueError(f"method must be one of {sorted(BUILDERS)}; got {method!r}")
    return BUILDERS[method](grid, **options)
