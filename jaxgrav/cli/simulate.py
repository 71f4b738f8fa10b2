"""``jaxgrav simulate``: write a track CSV from paper A's matching scenario.

Wire into :mod:`jaxgrav.cli` with ``add_parser(sub)``. The track is simulated by one
compiled program (:func:`jaxgrav.executables.call`, kept on disk like the other commands'
programs) rather than operation by operation (about 80 small programs compiled eagerly).
"""

import dataclasses
import math

import jax
import numpy as np

from jaxgrav import executables
from jaxgrav._io import check_outputs
from jaxgrav.cli.inputs import check_map_field, check_out_format, whole_number
from jaxgrav.cli.match_search import unresolved
from jaxgrav.constants import KNOT
from jaxgrav.datasets import load_map
from jaxgrav.fields.map_error import TruthGrid, map_error, truth_grid
from jaxgrav.match import MIN_FIXES
from jaxgrav.montecarlo.spec import region_of
from jaxgrav.scenarios import MatchingScenario, matching_scenario
from jaxgrav.scenarios.paper_a import check_region_covered, max_fixes, placement_region
from jaxgrav.sim import DEG_ARC_M, rayleigh_quantile
from jaxgrav.tracks import write_track_csv

__all__ = ["DEFAULT_MAP_ERROR_LENGTH_M", "MAX_BIAS_MGAL", "MAX_MAP_ERROR", "MAX_SEED",
           "add_map_error_options", "add_parser", "check_map_error_size", "check_seed",
           "describe_map_error", "map_error_from_args"]

DEFAULT_MAP_ERROR_LENGTH_M = 10000.0
"""Default correlation length of ``--map-error`` (m)."""

MAX_MAP_ERROR = 1000.0
"""Largest ``--map-error`` a simulator draws (map units): a marine gravity map is off by a
few mGal, a magnetic map by tens of nT; 1e9 was drawn and written (exit 0), readings that
every command then refused."""

MAX_SEED = 2**63 - 1
"""Largest ``--seed``: ``jax.random.key`` takes a signed 64-bit integer."""


def check_seed(seed):
    """ValueError naming ``--seed`` unless it is an integer in 0 .. :data:`MAX_SEED`.

    ``jax.random.key`` fails on 2**63 and beyond with an OverflowError, and a negative
    seed only repeats a large one (-1 draws what 2**64 - 1 would).
    """
    if not 0 <= seed <= MAX_SEED:
        raise ValueError(f"--seed must be an integer from 0 to {MAX_SEED} (2**63 - 1); "
                         f"got {seed}")


def check_map_error_size(sigma, option="--map-error"):
    """ValueError naming ``option`` for a map error above :data:`MAX_MAP_ERROR`, drawn by a
    simulator or told to a matcher or filter (``match``, ``filter``, ``navigate`` and
    ``montecarlo --told-map-error`` took 1e9 and ran every fix rejected); ``sigma`` None
    or at most that passes."""
    if sigma is not None and sigma > MAX_MAP_ERROR:
        raise ValueError(f"{option} must be at most {MAX_MAP_ERROR:g} (map units; a marine "
                         "gravity map's error is a few mGal, a magnetic map's tens of nT); "
                         f"got {sigma:g}")


def add_map_error_options(parser):
    """Add ``--map-error``, ``--map-error-length`` and ``--truth-map`` to a sub-parser."""
    parser.add_argument("--map-error", type=float, default=None, metavar="SIGMA",
                        help="the readings see the map plus a correlated error field of this "
                             "standard deviation (map units, e.g. mGal), drawn per run "
                             "(second-order Gauss-Markov); default 0 = a perfect map")
    parser.add_argument("--map-error-length", type=float, default=None, metavar="L",
                        help="correlation length of --map-error (m, default "
                             f"{DEFAULT_MAP_ERROR_LENGTH_M:.0f})")
    parser.add_argument("--truth-map", default=None, metavar="MAP",
                        help="the readings come from MAP (NetCDF grid or shipped map, e.g. "
                             "ryukyu, the 2.5' map) while --map is the map used; exclusive "
                             "with --map-error")


def map_error_from_args(args, grid, *, allow_nan=False, length_alone=False):
    """The map-error model of ``--map-error``/``--map-error-length``/``--truth-map``.

    Parameters
    ----------
    args : argparse.Namespace
        With ``map_error``, ``map_error_length``, ``truth_map`` (and ``var``).
    grid : Grid or None
        The map used; a ``--truth-map`` must cover its area.
    allow_nan : bool
        Keep a ``--truth-map``'s missing (NaN) nodes (for a command that then checks
        the readings along its track); by default such a map is refused.
    length_alone : bool
        ``--map-error-length`` may come without ``--map-error`` (montecarlo: the length
        of ``--told-map-error``); by default it is refused there (it was ignored).

    Returns
    -------
    CorrelatedMapError, TruthGrid or None
        None for a perfect map (``--map-error`` absent or 0 and no ``--truth-map``).

    Raises ValueError naming the option and the value for a negative, NaN or infinite
    σ or L, a σ above :data:`MAX_MAP_ERROR`, both ``--map-error`` and ``--truth-map``, a
    truth map that does not cover the map or that holds the map's own values.
    """
    sigma, length = args.map_error, args.map_error_length
    if sigma is not None and not (math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"--map-error must be a finite standard deviation >= 0 (map units, "
                         f"0 = perfect map); got {sigma!r}")
    if length is not None and not (math.isfinite(length) and length > 0):
        raise ValueError(f"--map-error-length must be a finite correlation length > 0 (m); "
                         f"got {length!r}")
    check_map_error_size(sigma)
    if length is not None and not sigma and not length_alone:  # was ignored, silently
        raise ValueError(f"--map-error-length {length:g} is the correlation length of the "
                         "drawn map error, and no --map-error is given: add --map-error "
                         "SIGMA, or leave it out")
    if args.truth_map is not None:
        if sigma is not None:
            raise ValueError(f"--truth-map {args.truth_map} and --map-error {sigma!r} exclude "
                             "each other: give the truth as a map or as an error model")
        if grid is None:
            raise ValueError(f"--truth-map {args.truth_map} needs a --map to compare with")
        truth = load_map(args.truth_map, None, allow_nan=allow_nan)
        check_region_covered(truth, region_of(grid), f"--truth-map {args.truth_map}")
        if _same_grid(truth, grid):  # ran as a map error ("truth map ryukyu"), with none
            raise ValueError(f"--truth-map {args.truth_map} holds the --map's own values: "
                             "the readings would see no map error; give another map (e.g. a "
                             "newer survey), or leave --truth-map out for a perfect map")
        return truth_grid(truth)
    if not sigma:
        return None
    return map_error(sigma, DEFAULT_MAP_ERROR_LENGTH_M if length is None else length)


def _same_grid(a, b):
    """Whether grids ``a`` and ``b`` have the same nodes and values (NaN equal to NaN)."""
    return all(np.shape(x) == np.shape(y) and np.array_equal(np.asarray(x), np.asarray(y),
                                                              equal_nan=True)
               for x, y in ((a.lat, b.lat), (a.lon, b.lon), (a.values, b.values)))


def describe_map_error(args):
    """One phrase for the map-error setting of ``args`` (summaries, titles)."""
    if args.truth_map is not None:
        return f"truth map {args.truth_map}"
    if not args.map_error:
        return "perfect map (no map error)"
    length = DEFAULT_MAP_ERROR_LENGTH_M if args.map_error_length is None else args.map_error_length
    return f"map error {args.map_error:g} (map units), L = {length / 1000:g} km"


def add_parser(sub):
    """Add the ``simulate`` sub-command to an ``argparse`` sub-parser set."""
    sim_p = sub.add_parser("simulate", help="write a track CSV from a matching scenario")
    sim_p.add_argument("--map", default="ryukyu",
                       help="map the readings are simulated from (plus --map-error; or the region "
                            "of --truth-map): NetCDF grid or shipped map (default ryukyu, "
                            "2.5'); missing (NaN) nodes are refused only where the track "
                            "crosses them")
    sim_p.add_argument("--var", default=None)
    sim_p.add_argument("--out", required=True, help="track CSV (INS fixes and readings)")
    sim_p.add_argument("--truth", default=None, help="also write the true track here")
    sim_p.add_argument("--n", type=whole_number, default=30,
                       help=f"fixes (default 30, at least {MIN_FIXES}: the fewest match takes)")
    sim_p.add_argument("--dt", type=float, default=120.0, help="interval (s, default 120)")
    sim_p.add_argument("--v-east", type=float, default=10.0, help="knots (default 10)")
    sim_p.add_argument("--v-north", type=float, default=10.0, help="knots (default 10)")
    sim_p.add_argument("--drift", type=float, default=0.035,
                       help="INS drift (degrees of arc, default 0.035)")
    sim_p.add_argument("--drift-law", choices=("fixed", "rayleigh"), default="fixed",
                       help="fixed: the drift is --drift; rayleigh: --drift is the Rayleigh "
                            "scale and the search radius its --probability quantile")
    sim_p.add_argument("--probability", type=float, default=None,
                       help="with --drift-law rayleigh: the quantile written as "
                            "drift_radius (default 0.99)")
    sim_p.add_argument("--noise", type=float, default=1.0, help="reading noise (mGal)")
    sim_p.add_argument("--bias", type=float, default=0.0, help="gravimeter bias (mGal)")
    sim_p.add_argument("--seed", type=int, default=0)
    sim_p.add_argument("--force", action="store_true")
    add_map_error_options(sim_p)
    sim_p.set_defaults(func=_cmd_simulate)
    return sim_p


MAX_BIAS_MGAL = 1000.0
"""Largest ``--bias`` magnitude (mGal): a gravimeter tied to a base station is off by a
few mGal, and the largest free-air anomalies on Earth are a few hundred mGal; a bias
beyond this makes readings that are no longer an anomaly."""


@jax.jit
def _matching_program(key_data, grid, scenario, model):
    """:func:`~jaxgrav.scenarios.matching_scenario` from raw key data, one compiled program."""
    return matching_scenario(jax.random.wrap_key_data(key_data), grid, scenario, model)


def _check_simulate_args(args):
    """Range-check every numeric option of ``simulate`` before anything runs."""
    def finite(name, value, ok, expected):
        if not (math.isfinite(value) and ok(value)):
            raise ValueError(f"{name} must be {expected}; got {value!r}")
    check_seed(args.seed)
    if args.n < MIN_FIXES:  # jaxgrav match refuses a shorter track
        raise ValueError(f"--n must be at least {MIN_FIXES} fixes (the fewest jaxgrav match "
                         f"takes); got {args.n}")
    finite("--dt", args.dt, lambda v: v > 0, "a positive interval between fixes (s)")
    finite("--v-east", args.v_east, lambda v: abs(v) <= 100, "a speed within ±100 knots")
    finite("--v-north", args.v_north, lambda v: abs(v) <= 100, "a speed within ±100 knots")
    if math.hypot(args.v_east, args.v_north) == 0:
        raise ValueError("--v-east and --v-north are both 0; a matching track must move")
    finite("--drift", args.drift, lambda v: 0 < v <= 5,
           "a positive INS drift of at most 5 degrees of arc")
    if args.probability is not None:
        finite("--probability", args.probability, lambda v: 0 < v < 1,
               "a probability strictly between 0 and 1")
        if args.drift_law == "fixed":  # was not used, without a word
            raise ValueError(f"--probability {args.probability:g} is the Rayleigh quantile of "
                             "--drift-law rayleigh; with --drift-law fixed the search radius "
                             "is 1.2 x --drift: give --drift-law rayleigh or leave it out")
    args.probability = 0.99 if args.probability is None else args.probability
    # 1e30 was written (exit 0), readings that every command then refuses
    finite("--noise", args.noise, lambda v: 0 <= v <= MAX_BIAS_MGAL,
           f"a reading noise >= 0 and at most {MAX_BIAS_MGAL:g} mGal (a marine gravimeter's "
           "is about 1)")
    finite("--bias", args.bias, lambda v: abs(v) <= MAX_BIAS_MGAL,
           f"a finite gravimeter bias within ±{MAX_BIAS_MGAL:g} mGal (a tied gravimeter is "
           "off by a few mGal; free-air anomalies stay within a few hundred)")


def _check_track_fits(args, scen, grid):
    """Refuse an ``--n`` whose track cannot fit on the map (its readings would be NaN)."""
    w, e, s, n = (float(v) for v in grid.extent)
    where = f"--map {args.map} (lat {s:g}..{n:g}, lon {w:g}..{e:g})"
    fit = max_fixes(scen)
    if fit >= args.n:
        return
    if fit < MIN_FIXES:
        raise ValueError(f"{where} is too small for a track of {MIN_FIXES} fixes "
                         f"{scen.step_m / 1000:.3g} km apart kept 1.5 x --drift "
                         f"({args.drift:g} degrees) from each edge; use a larger map, a "
                         "shorter --dt or a smaller --drift")
    span = (args.n - 1) * args.dt
    dlat = abs(scen.v_north) * span / DEG_ARC_M
    north = placement_region(scen)[1]  # the northern edge where tracks start (±89° at most)
    dlon = abs(scen.v_east) * span / (DEG_ARC_M * math.cos(math.radians(north)))
    raise ValueError(
        f"--n {args.n} fixes every {args.dt:g} s at {math.hypot(args.v_east, args.v_north):.3g} "
        f"kn make a track of {scen.step_m * (args.n - 1) / 1000:.0f} km ({dlat:.4g} degrees "
        f"north-south, {dlon:.4g} east-west) that does not fit in {where} with 1.5 x --drift "
        f"from each edge; at most --n {fit} fits (or give a shorter --dt or a lower speed)")


def _drift_radius(args):
    """The ``drift_radius`` written in the track (degrees of arc)."""
    return (1.2 * args.drift if args.drift_law == "fixed"
            else float(rayleigh_quantile(args.drift, args.probability)))


def _check_resolved(args, scen, grid):
    """Refuse a track, or a search radius, shorter than ``--n`` readings of ``--noise``
    can tell on the map (``--dt 1e-9``, ``--drift 1e-12`` were written, exit 0; jaxgrav
    match refuses such a radius)."""
    length = scen.step_m * (args.n - 1)
    text, least_m = unresolved(grid, length, args.n, args.noise)
    if text is not None:
        raise ValueError(f"--n {args.n} fixes every {args.dt:g} s make a track of "
                         f"{length:.3g} m, along which {text}: it would tell no position; "
                         f"expected a --dt of at least {args.dt * least_m / length:.2g} s")
    radius = _drift_radius(args)
    text, least_m = unresolved(grid, 2.0 * radius * DEG_ARC_M, args.n, args.noise)
    if text is None:
        return
    least_deg = least_m / 2.0 / DEG_ARC_M
    if args.drift_law == "rayleigh" and rayleigh_quantile(args.drift, 0.99) >= least_deg:
        # --probability 1e-300 was blamed on --drift ("at least 4e+144 degrees")
        p = -math.expm1(-0.5 * (least_deg / args.drift) ** 2)
        raise ValueError(f"--probability {args.probability:g} (the quantile of the Rayleigh "
                         f"drift of --drift {args.drift:g}) gives the track a drift radius of "
                         f"{radius * DEG_ARC_M:.3g} m, across whose search region {text}: "
                         f"jaxgrav match would refuse it; expected a --probability of at "
                         f"least {p:.2g}")
    raise ValueError(f"--drift {args.drift:g} degrees of arc gives the track a drift "
                     f"radius of {radius * DEG_ARC_M:.3g} m, across whose search region "
                     f"{text}: jaxgrav match would refuse it; expected a --drift of at "
                     f"least {args.drift * least_deg / radius:.2g} degrees of arc")


def _check_readings(args, run, grid):
    """Refuse a simulated track whose readings are NaN: off the map, or on missing nodes."""
    bad = ~np.isfinite(np.asarray(run.readings))
    if not bad.any():
        return
    lat, lon = np.asarray(run.truth.lat), np.asarray(run.truth.lon)
    i = int(np.flatnonzero(bad)[0])
    at = f"the first at fix {i + 1} of {args.n} (lat {lat[i]:.5g}, lon {lon[i]:.5g})"
    source = f"--truth-map {args.truth_map}" if args.truth_map else f"--map {args.map}"
    if not bool(np.asarray(grid.contains(lat[i], lon[i]))):
        raise ValueError(f"the simulated track leaves {source} ({int(bad.sum())} readings off "
                         f"it, {at}); give another --seed or fewer --n")
    raise ValueError(f"{source} has missing (NaN) nodes along the simulated track: "
                     f"{int(bad.sum())} of {args.n} readings fall in a cell with a missing "
                     f"node, {at}; give another --seed or a map complete there (missing "
                     "nodes away from the track are fine)")


def _cmd_simulate(args):
    _check_simulate_args(args)
    check_outputs([args.out, args.truth], force=args.force, names=["--out", "--truth"],
                  inputs={"--map": args.map, "--truth-map": args.truth_map})
    check_out_format(args.out, "CSV")
    if args.truth is not None:
        check_out_format(args.truth, "CSV", "--truth")
    grid = load_map(args.map, args.var, allow_nan=True)
    check_map_field(grid, "gravity", args.map)  # nT were written as gravity
    w, e, s, n = grid.extent
    scen = MatchingScenario(
        region=(s, n, w, e), v_east=args.v_east * KNOT, v_north=args.v_north * KNOT,
        dt=args.dt, drift_deg=args.drift, noise_mgal=args.noise, bias_mgal=args.bias,
        n_fixes=args.n, drift_law=args.drift_law,
    )
    _check_track_fits(args, scen, grid)
    _check_resolved(args, scen, grid)
    scen = dataclasses.replace(scen, region=placement_region(scen))
    model = map_error_from_args(args, grid, allow_nan=True)
    run = executables.call(_matching_program, jax.random.key_data(jax.random.key(args.seed)),
                           grid, scen, model)
    _check_readings(args, run, model.grid if isinstance(model, TruthGrid) else grid)
    truth = run.truth
    write_track_csv(args.out, {
        "t": truth.t, "lat": run.ins_lat, "lon": run.ins_lon, "gravity": run.readings,
        "v_east": truth.v_east, "v_north": truth.v_north,
        "drift_radius": np.full(args.n, _drift_radius(args)),
    }, force=args.force)
    if args.truth:
        write_track_csv(args.truth, {"t": truth.t, "lat": truth.lat, "lon": truth.lon},
                        force=args.force)
    drift_m = float(np.hypot(run.drift_north_m, run.drift_east_m).mean())
    also = f" and {args.truth}" if args.truth else ""
    print(f"wrote {args.out}{also}: {args.n} fixes, INS drift {drift_m:.0f} m, "
          f"{describe_map_error(args)}")
