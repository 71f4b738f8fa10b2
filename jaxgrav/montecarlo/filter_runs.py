"""Filters as Monte Carlo methods: paper D's Kalman, point-mass and particle filters.

Each ``*_run(key, field, scenario)`` simulates one run of
:func:`~jaxgrav.scenarios.filter_scenario` and filters it; :func:`filter_builder`
returns the :class:`~jaxgrav.montecarlo.spec.MethodSpec` that
:mod:`jaxgrav.montecarlo.methods` registers by name.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp

from jaxgrav._pytree import pytree_dataclass
from jaxgrav.fields.map_error import CorrelatedMapError, TruthGrid
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.filters import (
    PARTICLES,
    STATUS_FILTER,
    GuardConfig,
    ekf,
    gaussian_sum,
    gravity_measurement,
    guard_run,
    pad_to_stride,
    pcrlb,
    pf,
    pmf,
    rbpf,
    run_filter,
    ukf,
)
from jaxgrav.filters.map_state import ORDERS, MapErrorState, augment, matched_state

__all__ = [
    "FILTER_METHODS",
    "MAP_ERROR_TOLD",
    "ToldMapError",
    "ekf_run",
    "filter_builder",
    "gsf_guard_run",
    "gsf_run",
    "pf_run",
    "pmf_run",
    "rbpf_run",
    "ukf_guard_run",
    "ukf_run",
]

from jaxgrav.montecarlo.draws import scenario_draws
from jaxgrav.montecarlo.matcher_runs import MISSING_MAP_START_TRIES
from jaxgrav.montecarlo.spec import MethodSpec, check_settings, cpu_options_for
from jaxgrav.navigate import implausible_block_count
from jaxgrav.scenarios import (
    FilterScenario,
    filter_scenario,
    initial_state,
    run_metrics,
    run_steps,
)
from jaxgrav.sim import DEG_ARC_M

_FILTER_KEY = 1
"""``fold_in(run key, _FILTER_KEY)`` seeds a particle filter."""


# ----------------------------------------------------------------- paper-D filters (D)
@pytree_dataclass
class ToldMapError:
    """What a filter is told about the map error (all data; None fields are off).

    Attributes
    ----------
    white_var : Array, scalar
        Added to the reading noise variance (mGal²): the map error told as white noise.
    state : MapErrorState or None
        The FOGM map-error state (:mod:`jaxgrav.filters.map_state`); None: no state.
    """

    white_var: jax.Array
    state: MapErrorState | None = None


def _told_steps(run, scenario, told):
    dynamics, steps = run_steps(run, scenario)
    x0, p0 = initial_state(scenario)
    if told is None:
        return dynamics, steps, x0, p0, gravity_measurement
    steps = steps._replace(r=steps.r + told.white_var)
    dynamics, x0, p0, meas = augment(told.state, dynamics, x0, p0, scenario.speed)
    return dynamics, steps, x0, p0, meas


def _with_bound(metrics, run, field, dynamics, steps, p0, meas, every):
    """``metrics`` plus ``bound_m``: the PCRLB of the horizontal position error, RMS over
    the second half of the run (as ``err_m``), of the model the filter is told
    (``dynamics, steps, p0, meas`` from :func:`_told_steps`); ``readings_on_map`` (every
    reading, one each ``every`` steps, finite: the true track read no missing map node);
    and the run's draws (:func:`~jaxgrav.montecarlo.draws.scenario_draws`)."""
    rms = pcrlb(field, dynamics, p0, steps, run.errors[1:, :2], meas).position_rms
    half = rms.shape[0] // 2
    between = jnp.arange(run.readings.shape[0]) % every != 0
    return dict(metrics, bound_m=jnp.sqrt(jnp.mean(rms[half:] ** 2)),
                readings_on_map=jnp.all(jnp.isfinite(run.readings) | between),
                **scenario_draws(run.truth.lat, run.truth.lon, run.ins_lat, run.ins_lon))


def _flag_innovations(metrics, infos):
    """``metrics`` plus ``implausible_blocks`` (blocks of the run's innovations that fail
    :func:`~jaxgrav.navigate.innovation_blocks`' χ² test, the rule ``jaxgrav filter``
    flags a log's rows with), its ``implausible_fit`` bit OR-ed into ``status``."""
    blocks = implausible_block_count(infos.innovation, jnp.sqrt(infos.innovation_var))
    status = metrics["status"] | jnp.where(blocks > 0, STATUS_FILTER["implausible_fit"], 0)
    return dict(metrics, status=status.astype(jnp.int32), implausible_blocks=blocks)


def _kalman_run(key, field, scenario, make, guard=False, map_error=None, told=None,
                particles=False):
    run = filter_scenario(key, field, scenario, map_error)
    dynamics, steps, x0, p0, meas = _told_steps(run, scenario, told)
    # a particle filter's own random numbers: a key apart from the run's simulation
    fkey = jax.random.fold_in(key, _FILTER_KEY) if particles else None
    # readings sit on steps every-1, 2 every-1, …: update only there, predict in between
    _, infos = run_filter(make(meas), field, dynamics, x0, p0, steps, scenario.reading_every,
                          key=fkey)
    if guard:
        infos = guard_run(infos, dynamics, p0, GuardConfig())
    return _with_bound(_flag_innovations(run_metrics(run, infos), infos), run, field, dynamics,
                       steps, p0, meas, scenario.reading_every)


def ukf_run(key, field, scenario, map_error=None, told=None):
    """One paper-D run filtered by the UKF (default sigma points).

    Parameters
    ----------
    key : PRNG key
    field : PointMasses or Grid
        Anomaly map filtered (mGal); also the truth when ``map_error`` is None.
    scenario : FilterScenario
    map_error : CorrelatedMapError, TruthGrid or None
        Truth = ``truth_field(map_error_key(key), field, map_error)``
        (:func:`~jaxgrav.scenarios.filter_scenario`); needs a Grid.
    told : ToldMapError or None
        What the filter is told about the map error (None: nothing, today's filter).

    Returns
    -------
    dict
        ``ins_err_m``, ``err_m`` (RMS position error over the second half of the
        run, m), ``status`` (OR of the steps' :data:`~jaxgrav.filters.STATUS_FILTER`
        flags without ``no_reading``, with ``implausible_fit`` when a block of 60
        innovations fails the χ² test of :func:`~jaxgrav.navigate.innovation_blocks`;
        int32), ``implausible_blocks`` (the number of such blocks), ``nees`` (mean
        position NEES over the second half; 2 for a consistent filter), ``bound_m`` (the posterior
        Cramér–Rao bound of the position error, :func:`~jaxgrav.filters.pcrlb` with the
        model the filter is told, RMS over the second half, m), ``readings_on_map``
        (bool: every reading finite, the true track read no missing map node) and the
        run's draws (``start_lat``, ``start_lon``, ``ins_offset_north_m``,
        ``ins_offset_east_m``).
    """
    return _kalman_run(key, field, scenario, ukf, False, map_error, told)


def ekf_run(key, field, scenario, map_error=None, told=None):
    """One paper-D run filtered by the EKF (``jax.jacfwd`` Jacobian); as :func:`ukf_run`."""
    return _kalman_run(key, field, scenario, ekf, False, map_error, told)


def _gsf(meas):
    return gaussian_sum(ukf(meas), 3)


def gsf_run(key, field, scenario, map_error=None, told=None):
    """One paper-D run filtered by a Gaussian sum of 3 × 3 UKFs; as :func:`ukf_run`."""
    return _kalman_run(key, field, scenario, _gsf, False, map_error, told)


def pf_run(key, field, scenario, map_error=None, told=None):
    """One paper-D run filtered by the SIR particle filter (2000 particles); as :func:`ukf_run`.

    The filter's key is ``fold_in(key, 1)``: apart from the simulation's.
    """
    return _kalman_run(key, field, scenario, lambda m: pf(PARTICLES["pf"], m), False, map_error,
                       told, particles=True)


def rbpf_run(key, field, scenario, map_error=None, told=None):
    """One paper-D run filtered by the Rao–Blackwellised particle filter (1000 particles in
    position, a shared Kalman covariance for the other states); as :func:`pf_run`."""
    return _kalman_run(key, field, scenario, lambda m: rbpf(PARTICLES["rbpf"], m), False,
                       map_error, told, particles=True)


def ukf_guard_run(key, field, scenario, map_error=None, told=None):
    """One paper-D run filtered by the UKF, its output guarded; as :func:`ukf_run`.

    :func:`~jaxgrav.filters.guard_run` with the default
    :class:`~jaxgrav.filters.GuardConfig`: position corrections only in the
    directions whose variance fell below 0.2 of the free INS's.
    """
    return _kalman_run(key, field, scenario, ukf, True, map_error, told)


def gsf_guard_run(key, field, scenario, map_error=None, told=None):
    """One paper-D run filtered by the Gaussian sum of 3 × 3 UKFs, output guarded; as
    :func:`ukf_guard_run`."""
    return _kalman_run(key, field, scenario, _gsf, True, map_error, told)


def pmf_run(key, field, scenario, map_error=None, told=None):
    """One paper-D run filtered by the grid point-mass filter (61 × 61 cells of 200 m).

    The filter updates at every reading (``run_filter`` with ``every =
    scenario.reading_every``, the run padded to whole strides); between readings the
    estimate is predicted. Its error model is taken at the mean INS latitude of the
    padded run. Map error: ``told.white_var`` is added to the reading variance;
    ``told.state`` (first order only) is the per-cell Rao–Blackwellised map-error
    state of :func:`~jaxgrav.filters.pmf`. Returns as :func:`ukf_run`.
    """
    run = filter_scenario(key, field, scenario, map_error)
    _, steps = run_steps(run, scenario)
    if told is not None:
        steps = steps._replace(r=steps.r + told.white_var)
    x0, p0 = initial_state(scenario)
    every = scenario.reading_every
    padded, _ = pad_to_stride(steps, every)  # readings already on steps every-1, 2 every-1, …
    filt = pmf()
    dynamics = filt.dynamics(jnp.mean(padded.lat), scenario.dt)
    if told is not None:
        dynamics, x0, p0, _ = augment(told.state, dynamics, x0, p0, scenario.speed)
    _, infos = run_filter(filt, field, dynamics, x0, p0, padded, every)
    t = steps.z.shape[0]
    # the bound is of the 13-state model the other filters are told, not the PMF's grid
    bound_dyn, bound_steps, _, bound_p0, meas = _told_steps(run, scenario, told)
    infos = jax.tree.map(lambda a: a[:t], infos)
    return _with_bound(_flag_innovations(run_metrics(run, infos), infos), run, field,
                       bound_dyn, bound_steps, bound_p0, meas, every)


_FILTER_RUNS = {
    "ukf": (ukf_run, "UKF (scaled sigma points, alpha 0.5)"),
    "ekf": (ekf_run, "EKF (jacfwd Jacobian)"),
    "gsf": (gsf_run, "Gaussian sum of 3 x 3 UKFs"),
    "ukf-guard": (ukf_guard_run, "UKF, no-harm guard (corrections where variance < 0.2 of INS)"),
    "gsf-guard": (gsf_guard_run, "Gaussian sum of 3 x 3 UKFs, no-harm guard"),
    "pmf": (pmf_run, "grid point-mass filter, 61 x 61 cells of 200 m"),
    "pf": (pf_run, f"SIR particle filter, {PARTICLES['pf']} particles"),
    "rbpf": (rbpf_run, f"Rao-Blackwellised particle filter, {PARTICLES['rbpf']} particles"),
}


MAP_ERROR_TOLD = ("none", "white", "state", "fogm", "sogm")
"""What :func:`filter_builder`'s filters are told about the map error: nothing, white
noise, a Gauss–Markov state of ``map_error_order`` (default the model's own), or the
state of order 1 (``"fogm"``) or 2 (``"sogm"``)."""


def _told(map_error, told, kind, order=None):
    """The :class:`ToldMapError` of a builder's map-error settings (None: told nothing)."""
    if order is not None and (isinstance(order, bool) or order not in ORDERS):
        raise ValueError(f"map_error_order must be 1 (FOGM), 2 (SOGM) or None (the map-error "
                         f"model's own order); got {order!r}")
    if told is None:
        told = "state"
        if isinstance(map_error, TruthGrid) and map_error.error is None:
            told = "none"
    if told not in MAP_ERROR_TOLD:
        raise ValueError(f"map_error_told must be one of {MAP_ERROR_TOLD}; got {told!r}")
    if told in ("fogm", "sogm"):
        forced = 1 if told == "fogm" else 2
        if order is not None and order != forced:
            raise ValueError(f"map_error_told={told!r} contradicts map_error_order={order!r}")
        told, order = "state", forced
    if map_error is None or told == "none":
        return None, "none"
    model = map_error.error if isinstance(map_error, TruthGrid) else map_error
    if model is None:
        raise ValueError("map_error is a TruthGrid without an error description (sigma, L), so "
                         "the filter cannot be told it: use map_error_told='none' or "
                         "truth_grid(grid, error=map_error(sigma, length_m))")
    if told == "white":
        return ToldMapError(jnp.square(model.sigma)), told
    if kind == "pmf":
        order = 1 if order is None else order
        if order != 1:
            raise ValueError("the point-mass filter's per-cell map-error state is first order "
                             "only: use map_error_order=1 (a FOGM of length 2 L for a markov2 "
                             f"map error), 'white' or 'none'; got map_error_order={order!r}")
    state = matched_state(model, order)
    return ToldMapError(jnp.zeros_like(model.sigma), state), f"{told} order {state.order}"


def filter_builder(grid, *, kind, drift_deg=None, noise=None, n_fixes=None, map_error=None,
                   map_error_told=None, map_error_order=None):
    """Paper D: gravity/INS filtering over ``paper_d()``'s three point masses or a map.

    The scenario is :class:`~jaxgrav.scenarios.FilterScenario` at 5 m/s, stepping
    at the reading rate: ``dt = 10 s``, a reading every step, 721 steps (2 h). This
    is the same physics as the paper's 2 s steps with a reading every 5th: the INS
    error model is discretised exactly (Van Loan), so five 2 s predictions equal
    one 10 s prediction, and the 2 s steps in between carry no reading — only the
    per-step diagnostics are lost, at a fifth of the cost. Over the point masses the
    geometry is ``"mixed"`` (east–west or north-then-east tracks across the masses);
    over a map it is ``"random"`` (straight tracks, uniform heading, as
    ``examples/paper_d_ukf.py --map ryukyu``) from starts at least the track length
    + 3 × the initial error + 10 km inside the map, so the truth, the INS track,
    the sigma points and the point-mass filter's grid stay on it. On a map with
    missing (NaN, land-masked) nodes a run's true track is drawn again, up to
    :data:`~jaxgrav.montecarlo.matcher_runs.MISSING_MAP_START_TRIES` times
    (``FilterScenario.start_tries``), until it reads none; the filters read the missing
    nodes near it as a mask (``off_map`` rows), and ``readings_on_map`` records
    whether the run found such a track.

    Parameters
    ----------
    grid : Grid or None
        Anomaly map (mGal), sampled bicubically; None: paper D's point masses
        (23.9–24.6°N, 122.6–123.3°E).
    kind : {"ukf", "ekf", "gsf", "pmf", "pf", "rbpf", "ukf-guard", "gsf-guard"}
    drift_deg : float, optional
        Size of the initial INS position error (degrees of arc; default 2 km =
        0.01797°); the velocity error is 0.2 m/s.
    noise : float, optional
        Reading noise σ (mGal, default 1), also the filters' reading noise.
    n_fixes : int, optional
        Steps (= readings) per run including the start (default 721).
    map_error : CorrelatedMapError, TruthGrid or None
        The map is not the truth: each run's readings come from
        ``truth_field(map_error_key(key), grid, map_error)`` (one error field per run);
        needs a ``grid``. None: the map is the truth (today).
    map_error_told : {"state", "fogm", "sogm", "white", "none"}, optional
        What the filters are told: ``"state"`` (default) a Gauss–Markov map-error
        state with the model's σ (:func:`~jaxgrav.filters.map_state.matched_state`) of
        order ``map_error_order``; ``"fogm"`` / ``"sogm"`` the same with order 1 / 2;
        ``"white"`` σ² added to the reading variance; ``"none"`` nothing.
    map_error_order : {1, 2}, optional
        Order of the state: 1 FOGM (length L for ``markov1``, 2 L for ``markov2``),
        2 SOGM (length L; exact for ``markov2``); default the model's own order
        (matched: 2 for the default ``markov2`` map error). ``pmf``: per-cell FOGM
        only (default 1; 2 is a ValueError).

    Returns
    -------
    MethodSpec

    Raises
    ------
    ValueError
        A map too small for the tracks (smaller than twice the margin above); a
        ``map_error`` without a map; an unknown ``map_error_told``; a
        ``map_error_order`` not 1, 2 or None, or 2 for ``pmf``.
    TypeError
        A ``map_error`` that is not a CorrelatedMapError, TruthGrid or None.
    """
    fn, label = _FILTER_RUNS[kind]
    if map_error is not None:
        if not isinstance(map_error, CorrelatedMapError | TruthGrid):
            raise TypeError("map_error must be a CorrelatedMapError (map_error(sigma, length_m)), "
                            f"a TruthGrid or None; got {type(map_error).__name__}")
        if grid is None:
            raise ValueError("map_error needs a map (grid): paper D's point masses have no grid "
                             "to draw the map error on")
    told, told_name = _told(map_error, map_error_told, kind, map_error_order)
    pos_error = 2000.0 if drift_deg is None else float(drift_deg) * DEG_ARC_M
    noise = 1.0 if noise is None else float(noise)
    n = 721 if n_fixes is None else int(n_fixes)
    check_settings(pos_error / DEG_ARC_M, noise, n)
    scen = FilterScenario(dt=10.0, reading_every=1, n_steps=n, pos_error=pos_error,
                          noise_mgal=noise)
    if grid is None:
        field, where, extra = paper_d(), "the 3 point masses", dict(field="paper-d point masses")
    else:
        margin_m = scen.speed * scen.dt * (n - 1) + 3.0 * pos_error + 10e3
        # land masked on the map: a run's track is drawn again (up to 16 times) until it
        # reads no missing node (a complete map: the same runs as one try)
        scen = dataclasses.replace(scen, geometry="random",
                                   region=_innerregion_of(grid, margin_m),
                                   start_tries=MISSING_MAP_START_TRIES if grid.n_missing else 1)
        field, where = grid, f"the map {grid.name or 'grid'}"
        extra = dict(field=f"grid {grid.name}".strip(),
                     region=",".join(f"{v:.4f}" for v in scen.region))
    settings = dict(description=f"paper D: {label} over {where}; errors RMS over the second "
                                "half of the run",
                    **extra, pos_error_m=pos_error,
                    vel_error_m_s=scen.vel_error, noise_mgal=noise, bias_mgal=scen.bias_mgal,
                    n_steps=n, dt_s=scen.dt, reading_every=scen.reading_every,
                    geometry=scen.geometry, speed_m_s=scen.speed)
    if map_error is not None:
        me = map_error.error if isinstance(map_error, TruthGrid) else map_error
        settings.update(map_error="truth grid" if isinstance(map_error, TruthGrid) else
                        f"{me.family} sigma {float(me.sigma):g} mGal, L {float(me.length_m):g} m",
                        map_error_told=told_name)
    bits = {b: name for name, b in STATUS_FILTER.items() if b and name != "no_reading"}
    args = (field, scen) if map_error is None else (field, scen, map_error, told)
    return MethodSpec(fn, args, settings, bits, cpu_options_for(kind))


def _innerregion_of(grid, margin_m):
    """``(lat_min, lat_max, lon_min, lon_max)`` of ``grid`` shrunk by ``margin_m`` (m)."""
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
