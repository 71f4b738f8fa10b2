"""``jaxgrav simulate-filter``: a track CSV (and its truth) from paper D's filtering scenario.

Writes the input of ``jaxgrav filter`` (:mod:`jaxgrav.cli.filter`): raw readings (the
Eötvös effect of the true velocity taken off, as a gravimeter reads) from paper D's
scenario (:func:`~jaxgrav.scenarios.filter_scenario`) over its three point masses, or
over a map (``--map``) whose readings may see a drawn map error (``--map-error SIGMA
--map-error-length L``).
"""

import dataclasses

import jax
import numpy as np

from jaxgrav._io import check_outputs
from jaxgrav.cli.inputs import check_map_field, check_out_format, map_error_args, whole_number
from jaxgrav.cli.simulate import check_map_error_size, check_seed
from jaxgrav.cli.voyage import MAX_HOURS
from jaxgrav.datasets import load_map
from jaxgrav.fields.map_error import map_error
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.geodesy import eotvos
from jaxgrav.scenarios import FilterScenario, filter_scenario
from jaxgrav.sim import DEG_ARC_M
from jaxgrav.tracks import write_track_csv

__all__ = ["MAX_ROWS", "add_parser", "cmd_simulate_filter"]


def add_parser(subparsers):
    """Add the ``simulate-filter`` sub-command to an ``argparse`` sub-parser set."""
    s = subparsers.add_parser("simulate-filter",
                              help="write a track CSV from paper D's filtering scenario")
    s.add_argument("--out", required=True, help="track CSV for jaxgrav filter")
    s.add_argument("--truth", default=None,
                   help="also write the true track (t, lat, lon, v_east, v_north) here")
    s.add_argument("--geometry", choices=("east-west", "north-east"), default=None,
                   help="east-west across the masses (default) or north along the mass "
                        "line for half the run, then east")
    s.add_argument("--minutes", type=float, default=120.0, help="duration (default 120)")
    s.add_argument("--dt", type=float, default=2.0, help="row interval (s, default 2)")
    s.add_argument("--reading-every", type=whole_number, default=5,
                   help="a gravity reading every this many rows (default 5: every 10 s)")
    s.add_argument("--map", default=None,
                   help="simulate over this anomaly map (NetCDF or a shipped map, e.g. "
                        "ryukyu) instead of paper D's point masses: straight tracks from a "
                        "random start at least the track length + 16 km inside the map, "
                        "random heading (--geometry is then refused); missing (NaN) nodes "
                        "are refused only where the track crosses them")
    s.add_argument("--var", default=None, help="variable of --map when the file has several")
    s.add_argument("--map-error", type=float, default=0.0, metavar="SIGMA",
                   help="with --map: the readings see the map + a drawn error field of this "
                        "1-sigma (mGal), covariance s^2 (1 + r/L) e^(-r/L) (default 0)")
    s.add_argument("--map-error-length", type=float, default=None, metavar="L",
                   help="the map error's correlation length L (m, default 10000)")
    s.add_argument("--seed", type=int, default=0, help="PRNG seed")
    s.add_argument("--force", action="store_true", help="overwrite existing outputs")
    s.set_defaults(func=cmd_simulate_filter)


_simulate = jax.jit(filter_scenario)
"""Paper D's scenario, compiled once per process and scenario shape."""

_SIM_MARGIN_M = 16e3  # 3 x 2 km initial error + 10 km: the INS track stays on the map

MAX_ROWS = 1_000_000
"""Most rows ``simulate-filter`` writes: a million take about 0.5 GB and 20 s to simulate
and 70 MB of CSV, and ``jaxgrav filter`` then steps through every one."""


def _inner_region(grid, length_m, name, dt):
    """``(lat_min, lat_max, lon_min, lon_max)`` where a straight track of ``length_m`` (m)
    may start on ``grid``: the map shrunk by the length + the INS margin on every side."""
    w, e, s, n = (float(v) for v in grid.extent)
    margin_m = length_m + _SIM_MARGIN_M
    m_per_lon = DEG_ARC_M * np.cos(np.radians(min(max(abs(s), abs(n)), 89.0)))
    dlat, dlon = margin_m / DEG_ARC_M, margin_m / m_per_lon
    region = (s + dlat, n - dlat, w + dlon, e - dlon)
    if not (region[0] < region[1] and region[2] < region[3]):
        longest = min(0.5 * (n - s) * DEG_ARC_M, 0.5 * (e - w) * m_per_lon) - _SIM_MARGIN_M
        steps = np.floor(longest / (FilterScenario().speed * dt) * (1 - 1e-9)) if longest > 0 else 0
        minutes = np.floor(steps * dt / 6.0) / 10.0  # whole --dt steps, down to 0.1 min
        raise ValueError(
            f"--map {name} (lat {s:g}..{n:g}, lon {w:g}..{e:g}) is too small for the run: a "
            f"straight track of {length_m / 1e3:.0f} km in any direction must start "
            f"{margin_m / 1e3:.0f} km inside it (the track + {_SIM_MARGIN_M / 1e3:.0f} km for "
            "the INS error); "
            + (f"at most --minutes {minutes:g} fits at the scenario's "
               f"{FilterScenario().speed:g} m/s" if minutes > 0 else
               "the map is too small for any run")
            + " (or use a larger map)")
    return region


def _steps(args):
    """Rows of the run, ``--minutes`` at ``--dt`` (at least two)."""
    if not np.isfinite(args.minutes):
        raise ValueError(f"--minutes must be a finite duration (min); got {args.minutes!r}")
    n = round(args.minutes * 60.0 / args.dt) + 1
    if n < 2:
        raise ValueError(f"--minutes must cover at least one --dt step ({args.dt:g} s); got "
                         f"{args.minutes!r}")
    if args.map is None and args.minutes > 60 * MAX_HOURS:
        raise ValueError(f"--minutes must be at most {60 * MAX_HOURS:g} ({MAX_HOURS:g} h, the "
                         "longest INS run the simulators accept, as simulate-voyage --hours) "
                         f"over paper D's point masses; got {args.minutes:g}")
    return n


def _check_rows(args, n):
    """Refuse more than :data:`MAX_ROWS` rows, naming the longest ``--minutes`` at ``--dt``."""
    if n > MAX_ROWS:
        most = np.floor((MAX_ROWS - 1) * args.dt / 6.0) / 10.0  # down to 0.1 min
        least_dt = 60.0 * args.minutes / (MAX_ROWS - 1) * 1.001  # rounded up
        # "at this --dt at most --minutes 0" (below 0.1 min) named no usable value
        shorter = f"at most --minutes {most:g} at this --dt, or " if most > 0 else ""
        raise ValueError(f"--minutes {args.minutes:g} at --dt {args.dt:g} s makes {n} rows; at "
                         f"most {MAX_ROWS} (a million take about 0.5 GB and 20 s to simulate, "
                         f"70 MB of CSV): give {shorter}a --dt of at least {least_dt:.3g} s")


def _check_readings(args, run, grid):
    """Refuse a run whose due readings are NaN: the track crosses missing map nodes."""
    due = np.zeros(np.shape(run.readings), bool)
    due[::args.reading_every] = True
    bad = due & ~np.isfinite(np.asarray(run.readings))
    if not bad.any():
        return
    i = int(np.flatnonzero(bad)[0])
    lat, lon = float(run.truth.lat[i]), float(run.truth.lon[i])
    where = ("has missing (NaN) nodes along" if bool(np.asarray(grid.contains(lat, lon)))
             else "does not hold")
    raise ValueError(f"--map {args.map} {where} the simulated track: {int(bad.sum())} of "
                     f"{int(due.sum())} readings are missing, the first at row {i + 1} (lat "
                     f"{lat:.5g}, lon {lon:.5g}); give another --seed or a map complete there "
                     "(missing nodes away from the track are fine)")


def cmd_simulate_filter(args):
    """Run ``jaxgrav simulate-filter``: paper D's scenario over its three point masses."""
    check_seed(args.seed)
    # folders, inputs and repeats first; then every existing output named
    check_outputs([args.out, args.truth], force=args.force, names=["--out", "--truth"],
                  inputs={"--map": args.map})
    check_out_format(args.out, "CSV")
    if args.truth is not None:
        check_out_format(args.truth, "CSV", "--truth")
    if not (np.isfinite(args.dt) and args.dt > 0):
        raise ValueError(f"--dt must be a positive step (s); got {args.dt!r}")
    if args.reading_every < 1:
        raise ValueError(f"--reading-every must be a positive number of rows; got "
                         f"{args.reading_every}")
    n = _steps(args)
    if (n - 1) // args.reading_every + 1 < 2:  # one reading at the start: ran, exit 0
        raise ValueError(f"--reading-every {args.reading_every} leaves one reading in the {n} "
                         f"rows of --minutes {args.minutes:g} every --dt {args.dt:g} s; expected "
                         f"at most {n - 1} rows between readings")
    me_sigma, me_length = map_error_args(args)
    check_map_error_size(me_sigma)
    if args.map is None and args.var is not None:  # was ignored, silently
        raise ValueError(f"--var {args.var} names a variable of --map; without --map the "
                         "readings come from paper D's point masses: give --map or leave "
                         "--var out")
    if args.map is not None and args.geometry is not None:  # was dropped without a word
        raise ValueError(f"--geometry {args.geometry} shapes the track over paper D's point "
                         "masses; with --map the track is a straight line of random heading: "
                         "leave --geometry out")
    args.geometry = args.geometry or "east-west"
    if args.map is None:
        if me_sigma > 0:
            raise ValueError("--map-error needs --map (paper D's point masses have no grid to "
                             "draw the map error on)")
        _check_rows(args, n)
        scen = FilterScenario(dt=args.dt, reading_every=args.reading_every, n_steps=n,
                              geometry=args.geometry)
        run = _simulate(jax.random.key(args.seed), paper_d(), scen)
        over = f"{args.geometry} over paper D's point masses"
    else:
        grid = load_map(args.map, args.var, allow_nan=True)
        check_map_field(grid, "gravity", args.map)  # nT were written as gravity
        scen = FilterScenario(dt=args.dt, reading_every=args.reading_every, n_steps=n)
        scen = dataclasses.replace(scen, geometry="random", region=_inner_region(
            grid, scen.speed * args.dt * (n - 1), args.map, args.dt))
        _check_rows(args, n)
        me = map_error(me_sigma, me_length) if me_sigma > 0 else None
        run = _simulate(jax.random.key(args.seed), grid, scen, me)
        _check_readings(args, run, grid)
        over = f"a random straight track over --map {args.map}"
        if me is not None:
            over += f" (map error {me_sigma:g} mGal, L {me_length:g} m)"
    truth = run.truth
    err = np.asarray(run.errors)
    # the raw reading, as a gravimeter gives it: minus the Eötvös effect of the true velocity
    raw = np.asarray(run.readings) - np.asarray(eotvos(truth.lat, truth.v_east, truth.v_north))
    write_track_csv(args.out, {
        "t": truth.t, "lat": run.ins_lat, "lon": run.ins_lon,
        "v_east": np.asarray(truth.v_east) + err[:, 3],
        "v_north": np.asarray(truth.v_north) + err[:, 2],
        "gravity": raw,
    }, force=args.force, precision=12)
    if args.truth:
        write_track_csv(args.truth, {"t": truth.t, "lat": truth.lat, "lon": truth.lon,
                                     "v_east": truth.v_east, "v_north": truth.v_north},
                        force=args.force, precision=12)
    drift = np.hypot(err[:, 0], err[:, 1])
    also = f" and {args.truth}" if args.truth else ""
    print(f"wrote {args.out}{also}: {n} rows every {args.dt:g} s, "
          f"{int(np.isfinite(np.asarray(run.readings)).sum())} readings, {over}; INS error "
          f"{drift[0]:.0f} m at the start, RMS "
          f"{np.sqrt(np.mean(drift**2)):.0f} m")
