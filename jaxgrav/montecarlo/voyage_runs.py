"""Monte Carlo methods over voyages: simulate a patrol, navigate it, measure against the truth.

``voyage-dense``, ``voyage-chains`` and ``voyage-entropy+iccp`` are the loosely coupled
loop (:func:`~jaxgrav.navigate.navigate_loose`, hourly fixes of the dense matcher, of
paper A's chains on the map refined to 0.005° nodes, or of the entropy+ICCP matcher,
:func:`~jaxgrav.navigate.loose_config`); ``voyage-ukf``,
``voyage-ekf``, ``voyage-gsf``, ``voyage-rbpf`` and ``voyage-pmf`` the tightly coupled filters
(:func:`~jaxgrav.navigate.navigate_tight`; the particle filter's key is
``fold_in(run key, 1)``, apart from the simulation's, as for the filter methods). Each
run draws a ``patrol-12h`` voyage (:func:`~jaxgrav.scenarios.voyage_scenario`;
navigation-grade INS unless told
otherwise) whose readings see the map plus the run's map error, and returns, besides
:data:`~jaxgrav.montecarlo.spec.METRICS`:

``ins_err_m``, ``err_m``   RMS radial error of the free INS and of the navigation solution
                           over the last whole hour (m; the last bin of the hourly RMS, a
                           partial hour at the end left out as there)
``nees``                   mean position NEES over the voyage (2 expected)
``hourly_err_m``, ``hourly_ins_err_m``   RMS per hour (m), shape ``(H,)``
``err_series_m``, ``ins_err_series_m``, ``sigma_series_m``   every 10 min: radial error
                           of the solution, of the free INS, and the stated radial 1-σ (m)
``readings_on_map``        every reading finite: the voyage's true track read no missing
                           map node (on a map with missing nodes the route is drawn again,
                           :data:`~jaxgrav.montecarlo.matcher_runs.MISSING_MAP_START_TRIES`
                           times, until it reads none)
``status``                 tightly coupled: the filter's status bits OR-ed over the voyage,
                           with ``implausible_fit`` set when a block of its innovations is
                           implausible (:func:`~jaxgrav.navigate.innovation_blocks`, the
                           rule ``jaxgrav navigate`` flags a real log's rows with);
                           loosely coupled: bit ``k`` set when a fix event ``k`` of
                           :data:`~jaxgrav.navigate.FIX_EVENTS` happened (bit 0: accepted)
``implausible_blocks``     tightly coupled: the number of those blocks (a consistent filter
                           fails one in 1000)
"""

import functools

import jax
import jax.numpy as jnp

from jaxgrav.fields.map_error import CorrelatedMapError
from jaxgrav.filters import STATUS_FILTER, matched_state
from jaxgrav.montecarlo.draws import scenario_draws
from jaxgrav.montecarlo.matcher_runs import MISSING_MAP_START_TRIES
from jaxgrav.montecarlo.spec import (
    MethodSpec,
    check_map_error,
    cpu_options_for,
    default_grid,
    map_error_settings,
    region_of,
)
from jaxgrav.navigate import (
    FIX_EVENTS,
    LOOSE_MATCHERS,
    SEGMENT_ERRORS,
    TIGHT_METHODS,
    LooseConfig,
    TightConfig,
    hourly_rms,
    implausible_block_count,
    loose_config,
    loose_map,
    navigate_loose,
    navigate_tight,
    voyage_errors,
)
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import NAVIGATION_GRADE, voyage_preset, voyage_scenario
from jaxgrav.scenarios.paper_a import check_region_covered

__all__ = ["SERIES_EVERY_S", "VOYAGE_METHODS", "voyage_builder", "voyage_dense_run",
           "voyage_tight_run", "voyage_tracks"]

VOYAGE_METHODS = tuple(f"voyage-{m}" for m in (*LOOSE_MATCHERS, *TIGHT_METHODS))
"""The voyage methods of :data:`~jaxgrav.montecarlo.methods.BUILDERS`."""

SERIES_EVERY_S = 600.0
"""Spacing of the error series kept per run (s)."""

TOLD = ("state", "none")
"""What a voyage method may be told of the map error: the matched model (a map-error
state for the filters, the GLS score for the matcher) or nothing."""


def _metrics(voyage, nav, cov, dt, status):
    err = voyage_errors(voyage, nav, cov)
    every = round(SERIES_EVERY_S / dt)
    sigma = jnp.sqrt(jnp.trace(cov, axis1=1, axis2=2))
    hourly_nav, hourly_free = hourly_rms(err.nav_m, dt), hourly_rms(err.free_m, dt)
    if hourly_nav.shape[-1]:  # the last whole hour, as the hourly figures (a partial one
        last_nav, last_free = hourly_nav[-1], hourly_free[-1]  # at the end is left out)
    else:  # a voyage shorter than an hour: all of it
        last_nav, last_free = (jnp.sqrt(jnp.mean(e[1:] ** 2)) for e in (err.nav_m, err.free_m))
    return dict(
        ins_err_m=last_free, err_m=last_nav,
        status=status.astype(jnp.int32), nees=jnp.mean(err.nees),
        hourly_err_m=hourly_nav, hourly_ins_err_m=hourly_free,
        err_series_m=err.nav_m[::every], ins_err_series_m=err.free_m[::every],
        sigma_series_m=sigma[::every], readings_on_map=jnp.all(jnp.isfinite(voyage.gravity)),
        **scenario_draws(voyage.truth.lat, voyage.truth.lon, voyage.ins.lat, voyage.ins.lon))


def voyage_tight_run(key, pm, grid, scenario, model, config):
    """One voyage navigated by the tightly coupled filter (see the module notes).

    Parameters
    ----------
    key : PRNG key
    pm : PreparedMap
        The map as the filter samples it.
    grid : Grid
        The same map, for the truth (map + the run's error).
    scenario : VoyageScenario
    model : CorrelatedMapError or TruthGrid or None
        The readings' map error.
    config : TightConfig
    """
    voyage = voyage_scenario(key, grid, scenario, model)
    res = navigate_tight(pm, voyage, config, jax.random.fold_in(key, 1))
    blocks = implausible_block_count(res.innovation, jnp.sqrt(res.innovation_var))
    status = jax.lax.reduce(res.status, jnp.int32(0), jax.lax.bitwise_or, (0,)) | jnp.where(
        blocks > 0, STATUS_FILTER["implausible_fit"], 0)
    out = _metrics(voyage, res.nav, res.cov_north_east, scenario.dt, status)
    return {**out, "implausible_blocks": blocks}


def voyage_dense_run(key, pm, grid, scenario, model, config):
    """One voyage navigated by the loosely coupled loop (arguments as :func:`voyage_tight_run`,
    ``config`` a :class:`~jaxgrav.navigate.LooseConfig`); also returns ``fix_event`` (per
    segment end, :data:`~jaxgrav.navigate.FIX_EVENTS`) and ``fix_time_s`` (the segment
    ends, s from the voyage's start)."""
    voyage = voyage_scenario(key, grid, scenario, model)
    res = navigate_loose(pm, voyage, config)
    bits = jnp.sum(jnp.stack([jnp.any(res.fix_event == k) * (1 << k) for k in FIX_EVENTS]))
    out = _metrics(voyage, res.nav, res.cov_north_east, scenario.dt, bits)
    return {**out, "fix_event": res.fix_event, "fix_time_s": res.fix_time - voyage.ins.t[0]}


def voyage_tracks(key, pm, grid, scenario, model, config):
    """The tracks of one voyage as a voyage method runs it (arguments as
    :func:`voyage_tight_run`; ``config`` a TightConfig or a LooseConfig).

    Returns
    -------
    dict of str to (lat, lon)
        ``truth``, ``free INS`` and ``navigation`` (the corrected track), each a pair of
        arrays of shape ``(N,)`` in degrees, for :func:`~jaxgrav.plot.plot_map`.
    """
    voyage = voyage_scenario(key, grid, scenario, model)
    if isinstance(config, TightConfig):
        nav = navigate_tight(pm, voyage, config, jax.random.fold_in(key, 1)).nav
    else:
        nav = navigate_loose(pm, voyage, config).nav
    return {"truth": (voyage.truth.lat, voyage.truth.lon),
            "free INS": (voyage.ins.lat, voyage.ins.lon),
            "navigation": (nav.lat, nav.lon)}


def voyage_builder(grid=None, *, kind, drift_deg=None, noise=None, n_fixes=None, map_error=None,
                   map_error_told="state", map_error_order=None, hours=None,
                   ins=NAVIGATION_GRADE, segment_error=None, fix_prior=None,
                   first_n_fixes=None, shape_update=None, reacquire_after=None,
                   reacquire_inflation=None):
    """The :class:`~jaxgrav.montecarlo.spec.MethodSpec` of a voyage method.

    Parameters
    ----------
    grid : Grid, optional
        The map (default the shipped 2.5′ ``ryukyu``). The preset's region (25–35° N,
        125–135° E) is used if the map covers it, else the map's own extent.
    kind : {"voyage-dense", "voyage-chains", "voyage-entropy+iccp", "voyage-ukf",
            "voyage-ekf", "voyage-gsf", "voyage-rbpf", "voyage-pmf"}
    drift_deg : float, optional
        Initial INS position error (degrees of arc; default 500 m).
    noise : float, optional
        Reading noise 1-σ (mGal, default 1).
    n_fixes : None
        Not a voyage setting (ValueError otherwise; see ``hours``).
    map_error : CorrelatedMapError, TruthGrid or None
        The readings' map error, drawn per run.
    map_error_told : {"state", "none"}
        ``state``: the filters carry a map-error state matched to ``map_error`` (of
        order ``map_error_order``, default 2), the dense matcher is told its σ and L;
        ``none``: neither is told.
    map_error_order : {1, 2}, optional
        Order of the filters' map-error state.
    hours : float, optional
        Length of each voyage (default 12).
    ins : INSErrorModel
        The INS (simulated and told to the navigator); default navigation grade.
    segment_error : {"markov", "linear", "conditional"}, optional
        ``voyage-dense`` only: how the loop tells the matcher the filter's own error
        (:attr:`~jaxgrav.navigate.LooseConfig.segment_error`); default
        :func:`~jaxgrav.navigate.loose_config`'s (conditional, with the rest of
        :data:`~jaxgrav.navigate.DENSE_LOOP`; ``"markov"``: the old loop).
    fix_prior : bool, optional
        ``voyage-dense`` only: the offsets weighed by the filter's prior
        (:attr:`~jaxgrav.navigate.LooseConfig.fix_prior`); default ``loose_config``'s.
    first_n_fixes : int, optional
        ``voyage-dense`` only: the segment ends before a whole segment match the last
        that many fixes (:attr:`~jaxgrav.navigate.LooseConfig.first_n_fixes`); default
        none.
    shape_update : bool, optional
        ``voyage-dense`` only: the segment's readings update the rest of the state given
        each accepted fix (:attr:`~jaxgrav.navigate.LooseConfig.shape_update`); default
        ``loose_config``'s.
    reacquire_after, reacquire_inflation : int or None, float, optional
        ``voyage-dense`` only: widen the filter's covariance after that many failed
        fixes in a row (:attr:`~jaxgrav.navigate.LooseConfig.reacquire_after`; None
        given here keeps ``loose_config``'s default, pass 0 for never) and by what
        factor; default ``loose_config``'s.

    Returns
    -------
    MethodSpec
        On a ``grid`` (or a TruthGrid ``map_error``) with missing (NaN, land-masked)
        nodes its scenario's ``start_tries`` is
        :data:`~jaxgrav.montecarlo.matcher_runs.MISSING_MAP_START_TRIES` (each run's route
        drawn again until its true track reads no missing node; ``readings_on_map`` per
        run), else 1 (the voyages of a single try).
    """
    if kind not in VOYAGE_METHODS:
        raise ValueError(f"kind must be one of {', '.join(VOYAGE_METHODS)}; got {kind!r}")
    if n_fixes is not None:
        raise ValueError("fixes per track is not a voyage setting: a voyage method runs over "
                         f"--hours (default 12); got {n_fixes}")
    if map_error_told not in TOLD:
        raise ValueError(f"map_error_told must be one of {', '.join(TOLD)} for {kind}; got "
                         f"{map_error_told!r}")
    if map_error_order not in (None, 1, 2):
        raise ValueError(f"map_error_order must be 1 or 2; got {map_error_order!r}")
    loop = {k: v for k, v in (("segment_error", segment_error), ("fix_prior", fix_prior),
                              ("first_n_fixes", first_n_fixes), ("shape_update", shape_update),
                              ("reacquire_after", reacquire_after),
                              ("reacquire_inflation", reacquire_inflation))
            if v is not None}
    if loop.get("reacquire_after") == 0:
        loop["reacquire_after"] = None  # never
    if loop and kind != "voyage-dense":
        raise ValueError(f"{' and '.join(loop)} are settings of voyage-dense's loop; got {kind}")
    if segment_error is not None and segment_error not in SEGMENT_ERRORS:
        raise ValueError(f"segment_error must be one of {', '.join(SEGMENT_ERRORS)}; got "
                         f"{segment_error!r}")
    grid = default_grid() if grid is None else grid
    # land masked (the map's or a truth grid's): a run's route is drawn again (up to 16
    # times) until it reads no missing node (a complete map: the same voyages as one try)
    missing = grid.n_missing or getattr(getattr(map_error, "grid", None), "n_missing", 0)
    changes = {"ins": ins, "start_tries": MISSING_MAP_START_TRIES if missing else 1}
    if hours is not None:
        changes["hours"] = float(hours)
    if noise is not None:
        if not noise > 0:
            raise ValueError(f"noise must be a positive reading 1-σ (mGal); got {noise!r}")
        changes["noise_mgal"] = float(noise)
    if drift_deg is not None:
        if not drift_deg > 0:
            raise ValueError(f"drift must be a positive initial position error (degrees of "
                             f"arc); got {drift_deg!r}")
        changes["pos_error_m"] = float(drift_deg) * 111_195.0
    scenario = voyage_preset("patrol-12h", **changes)
    try:
        check_region_covered(grid, scenario.region, "the map")
    except ValueError:
        scenario = voyage_preset("patrol-12h", region=region_of(grid), **changes)
    model = check_map_error(map_error, grid)
    told = model if isinstance(model, CorrelatedMapError) and map_error_told == "state" else None
    sigma_pos = scenario.pos_error_m / 2**0.5
    name = kind.removeprefix("voyage-")
    loose = name in LOOSE_MATCHERS
    # the map the navigator reads (chains: the nodes of the map refined)
    pm = loose_map(grid, name) if loose else prepare_map(grid)
    if loose:
        sigma = 0.0 if told is None else float(told.sigma)
        length = 10000.0 if told is None else float(told.length_m)
        step = scenario.speed * LooseConfig.fix_every * scenario.dt  # between fixes (m)
        config = loose_config(scenario.ins, sigma, length, scenario.noise_mgal,
                              matcher=name, grid=pm, step_m=step, sigma_pos_m=sigma_pos, **loop)
        fn, bits = voyage_dense_run, {1 << k: v for k, v in FIX_EVENTS.items()}
    else:
        default = 1 if name == "pmf" else told.order if told is not None else None
        state = None if told is None else matched_state(told, map_error_order or default)
        config = TightConfig(ins=scenario.ins, sigma_pos_m=sigma_pos,
                             noise_mgal=scenario.noise_mgal, map_error=state,
                             method=kind.removeprefix("voyage-"))
        fn, bits = voyage_tight_run, {v: k for k, v in STATUS_FILTER.items() if v}
    settings = dict(description=f"{scenario.hours:g} h patrols, navigated "
                    + (f"loosely coupled (hourly {name} fixes, {config.segment_error} segment "
                       "error" + (", the filter's prior" if config.fix_prior else "")
                       + (", the segment's shape" if config.shape_update else "")
                       + (", re-acquiring" if config.reacquire_after else "") + ")"
                       if loose else
                       f"tightly coupled ({name})"),
                    hours=scenario.hours, dt=scenario.dt, noise_mgal=scenario.noise_mgal,
                    pos_error_m=scenario.pos_error_m, map_error_told=map_error_told,
                    series_every_s=SERIES_EVERY_S, **map_error_settings(model),
                    **({"segment_error": config.segment_error, "fix_prior": int(config.fix_prior),
                        "fixes_per_segment": config.n_fixes, "fixes_between_ends": config.stride,
                        "first_segment_fixes": config.first_n_fixes or 0,
                        "shape_update": int(config.shape_update),
                        "reacquire_after": config.reacquire_after or 0,
                        "reacquire_inflation": float(config.reacquire_inflation)}
                       if loose else {}))
    return MethodSpec(fn, (pm, grid, scenario, model, config), settings, bits,
                      cpu_options_for(kind))


BUILDERS = {k: functools.partial(voyage_builder, kind=k) for k in VOYAGE_METHODS}
"""Voyage method name -> builder (merged into :data:`~jaxgrav.montecarlo.methods.BUILDERS`)."""
