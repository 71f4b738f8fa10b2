"""``jaxgrav filter`` and ``jaxgrav simulate-filter``: gravity/INS filtering of a track (paper D).

Wire into :mod:`jaxgrav.cli` with ``cli_filter.add_parsers(sub)``.

``filter`` reads a track CSV with the INS-indicated position and the gravimeter's
anomaly readings, runs a filter of :mod:`jaxgrav.filters` over the 13-state
INS error model of :mod:`jaxgrav.sim.ins` and writes the filtered track::

    TRACK.csv  t (s, uniform step), lat, lon (INS, degrees), gravity (the
               gravimeter's anomaly, mGal; empty where there is no reading),
               optional v_east, v_north (INS, m/s)
    OUT.csv    t, lat, lon (INS position − estimated INS error, degrees),
               sigma_north, sigma_east (posterior 1-σ of the position, m),
               cov_north_east (m²), v_east, v_north (INS velocity − estimated error,
               m/s; only when the track has them), v_north_error, v_east_error and
               their sigma_v_north, sigma_v_east (m/s), gravimeter_bias and
               sigma_gravimeter_bias (mGal), map_error and sigma_map_error (mGal; with
               --map-error), innovation and innovation_sigma (reading − prediction
               and its predicted 1-σ, mGal; empty without a reading), status (bit
               flags of jaxgrav.filters.STATUS_FILTER, 0 = a normal update)

Eötvös, the one rule of ``match``, ``filter`` and ``navigate``: with ``v_east`` and
``v_north`` the gravity column is the **raw** reading, which the command corrects with
the INS velocity (``--eotvos-corrected``: it already was, with that velocity); the
UKF, EKF and Gaussian sum then carry the Eötvös error of the INS velocity error,
``∂E/∂v · δv``, in their measurement (the point-mass filter does not, and says so).
Without velocity columns the gravity column must be Eötvös-corrected already.

The prior is the INS error at one step before the first row (zero mean, the
``--sigma-*`` standard deviations); every row's reading updates the estimate, and
row ``k`` of the output is the causal posterior after row ``k``.

The map is a NetCDF grid (``--map``), paper D's three masses (``--point-masses
paper-d``) or a fitted point-mass model file (``--point-masses MODEL.json``, see
:func:`~jaxgrav.fields.pointmass_fit.save_point_masses`; its offset is taken off the
readings).

``simulate-filter`` writes such a track (raw readings: the Eötvös effect of the true
velocity taken off, as a gravimeter reads) from paper D's scenario
(:func:`~jaxgrav.scenarios.filter_scenario`) over its three point masses, or over a
map (``--map``) whose readings may see a drawn map error (``--map-error SIGMA
--map-error-length L``). ``filter --map-error SIGMA --map-error-length L`` tells the
filter the map is wrong (:mod:`jaxgrav.filters.map_state`; ``--map-error-order 2``: a
second-order Gauss–Markov state, matched to the default map-error model).
"""

import dataclasses
import sys
from pathlib import Path

import jax
import numpy as np

from jaxgrav.cli.inputs import add_columns_option, read_track, track_map
from jaxgrav.datasets import load_map
from jaxgrav.fields.map_error import map_error
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.fields.pointmass_fit import load_point_masses
from jaxgrav.filters import STATUS_FILTER, status_messages_filter
from jaxgrav.filters.api import FILTER_METHODS, PMF_SPAN_SIGMA, filter_track, reading_stride
from jaxgrav.filters.map_state import map_error_state
from jaxgrav.geodesy import eotvos, eotvos_jacobian
from jaxgrav.scenarios import FilterScenario, filter_scenario
from jaxgrav.sim import DEG_ARC_M
from jaxgrav.tracks import csv_line, write_track_csv

__all__ = ["add_parsers", "cmd_filter", "cmd_simulate_filter"]

DT_RTOL = 1e-3
"""Relative tolerance of a uniform time step."""

_WARN = {
    "off_map": "the estimate or its sigma points left the map, update skipped (pmf: grid "
               "cells off the map, left out of the update)",
    "covariance_repaired": "the covariance was not positive definite; jitter added",
    "covariance_failed": "the covariance could not be repaired, or the innovation variance "
                         "was not positive; update skipped",
    "gated": "innovation outside the gate; update skipped",
    "grid_edge": "posterior mass at the edge of the point-mass grid; raise --sigma-pos",
}


def add_parsers(subparsers):
    """Add the ``filter`` and ``simulate-filter`` sub-commands to an ``argparse`` set."""
    f = subparsers.add_parser("filter", help="gravity/INS filtering of a track CSV (paper D)")
    f.add_argument("--map", default=None,
                   help="anomaly map: NetCDF grid with lat/lon coordinates (mGal) or a "
                        "shipped map (ryukyu); give --map or --point-masses")
    f.add_argument("--point-masses", default=None, metavar="paper-d|MODEL.json",
                   help="use a point-mass anomaly model: paper-d (paper D's three masses) "
                        "or a fitted model file written by "
                        "jaxgrav.fields.pointmass_fit.save_point_masses (e.g. by "
                        "examples/paper_d_pointmass_fit.py --out-model)")
    f.add_argument("--var", default=None, help="variable to read when the file has several")
    f.add_argument("--track", required=True,
                   help="CSV: t (s, uniform step), lat, lon (INS, degrees), gravity "
                        "(mGal; empty where no reading; raw when v_east, v_north are given, "
                        "else Eötvös-corrected); optional v_east, v_north (INS, m/s)")
    add_columns_option(f)
    f.add_argument("--method", choices=FILTER_METHODS, default="ukf",
                   help="ukf (default), ekf (jacfwd Jacobian), gsf (Gaussian sum of 3 x 3 "
                        "UKFs, for multi-modal priors), pmf (grid point-mass filter)")
    f.add_argument("--out", required=True,
                   help="output CSV: t, lat, lon, sigma_north, sigma_east (m), covariance, "
                        "velocity, biases, innovations and status per row")
    f.add_argument("--sigma-pos", type=float, default=1414.2,
                   help="initial INS position error, 1-σ per axis (m); default 1414 m, "
                        "i.e. 2 km RMS horizontal")
    f.add_argument("--sigma-vel", type=float, default=0.1414,
                   help="initial INS velocity error, 1-σ per axis (m/s); default 0.14, "
                        "i.e. 0.2 m/s RMS horizontal (navigation-grade INS)")
    f.add_argument("--sigma-gravity", type=float, default=1.0,
                   help="reading noise, 1-σ (mGal); default 1 (marine gravimeter)")
    f.add_argument("--guard", type=float, nargs="?", const=0.2, default=None,
                   metavar="RATIO",
                   help="no-harm guard (ukf, ekf, gsf): apply the position correction only "
                        "in directions whose variance fell below RATIO times the free INS's "
                        "(default 0.2 when given without a value; chosen on paper D's "
                        "experiment); elsewhere the output stays the INS with its own 1-σ")
    f.add_argument("--map-error", type=float, default=0.0, metavar="SIGMA",
                   help="the map's error, 1-sigma (mGal): ukf, ekf, gsf add a Gauss-Markov "
                        "map-error state over the distance travelled (--map-error-order); pmf "
                        "a first-order one per grid cell. Default 0: the map is the truth")
    f.add_argument("--map-error-length", type=float, default=10e3, metavar="L",
                   help="correlation length of that state over the distance travelled (m, "
                        "default 10000; time constant L / ground speed). For a map error "
                        "with covariance s^2 (1 + r/L) e^(-r/L) use order 2 with L, or order "
                        "1 with 2 L")
    f.add_argument("--map-error-order", type=int, default=1, choices=(1, 2),
                   help="order of the map-error state: 1 first-order Gauss-Markov (default), "
                        "2 second-order (value and rate; covariance s^2 (1 + r/L) e^(-r/L), "
                        "the model of simulate-filter --map-error); pmf: 1 only")
    f.add_argument("--eotvos-corrected", action="store_true",
                   help="the gravity column is already Eötvös-corrected with the INS velocity "
                        "of v_east, v_north (default: raw, corrected here)")
    f.add_argument("--force", action="store_true", help="overwrite an existing output")
    f.set_defaults(func=cmd_filter)

    s = subparsers.add_parser("simulate-filter",
                              help="write a track CSV from paper D's filtering scenario")
    s.add_argument("--out", required=True, help="track CSV for jaxgrav filter")
    s.add_argument("--truth", default=None,
                   help="also write the true track (t, lat, lon, v_east, v_north) here")
    s.add_argument("--geometry", choices=("east-west", "north-east"), default="east-west",
                   help="east-west across the masses (default) or north along the mass "
                        "line for half the run, then east")
    s.add_argument("--minutes", type=float, default=120.0, help="duration (default 120)")
    s.add_argument("--dt", type=float, default=2.0, help="row interval (s, default 2)")
    s.add_argument("--reading-every", type=int, default=5,
                   help="a gravity reading every this many rows (default 5: every 10 s)")
    s.add_argument("--map", default=None,
                   help="simulate over this anomaly map (NetCDF or a shipped map, e.g. "
                        "ryukyu) instead of paper D's point masses: straight tracks from a "
                        "random start at least the track length + 16 km inside the map, "
                        "random heading (--geometry is then not used)")
    s.add_argument("--var", default=None, help="variable of --map when the file has several")
    s.add_argument("--map-error", type=float, default=0.0, metavar="SIGMA",
                   help="with --map: the readings see the map + a drawn error field of this "
                        "1-sigma (mGal), covariance s^2 (1 + r/L) e^(-r/L) (default 0)")
    s.add_argument("--map-error-length", type=float, default=10e3, metavar="L",
                   help="the map error's correlation length L (m, default 10000)")
    s.add_argument("--seed", type=int, default=0, help="PRNG seed")
    s.add_argument("--force", action="store_true", help="overwrite existing outputs")
    s.set_defaults(func=cmd_simulate_filter)
    return f, s


# ------------------------------------------------------------------------ checks
def _uniform_dt(t, where):
    """The step of a uniform time column, or a ValueError naming the first bad row."""
    if t.size < 2:
        raise ValueError(f"{where} has {t.size} row; the filter needs at least 2 "
                         "(the time step is taken from column t)")
    d = np.diff(t)
    dt = float(np.median(d))
    if not dt > 0:
        raise ValueError(f"{where}: column t must increase; median step {dt:g} s")
    bad = np.flatnonzero(np.abs(d - dt) > DT_RTOL * dt)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{where}: column t must have a uniform step; t goes {t[i]:g} -> {t[i + 1]:g} s "
            f"(step {d[i]:g} s) on lines {csv_line(i)}-{csv_line(i + 1)}, expected {dt:g} s "
            f"(the median) within {DT_RTOL:.1%}; {bad.size} bad step(s)")
    return dt


def _map_error_args(args):
    """Validated ``--map-error`` / ``--map-error-length`` (a ValueError naming the option)."""
    if not (np.isfinite(args.map_error) and args.map_error >= 0):
        raise ValueError(f"--map-error must be a finite map-error sigma >= 0 (mGal); got "
                         f"{args.map_error!r}")
    if not (np.isfinite(args.map_error_length) and args.map_error_length > 0):
        raise ValueError(f"--map-error-length must be a finite correlation length > 0 (m); "
                         f"got {args.map_error_length!r}")
    order = getattr(args, "map_error_order", 1)
    if order not in (1, 2):
        raise ValueError(f"--map-error-order must be 1 or 2; got {order!r}")
    if order == 2 and getattr(args, "method", None) == "pmf":
        raise ValueError("--map-error-order 2 is not available with --method pmf (its per-cell "
                         "map-error state is first order); use --map-error-order 1 with 2 L")
    return args.map_error, args.map_error_length


def _output_columns(t, track, res):
    """The output CSV's columns: position and its covariance, velocity, biases, status."""
    cols = {"t": t, "lat": res["lat"], "lon": res["lon"]}
    cols.update({k: res[k] for k in ("sigma_north", "sigma_east", "cov_north_east")})
    if "v_east" in track and "v_north" in track:  # the INS velocity, corrected
        cols.update(v_east=track["v_east"] - res["v_east_error"],
                    v_north=track["v_north"] - res["v_north_error"])
    keys = ["v_north_error", "v_east_error", "sigma_v_north", "sigma_v_east",
            "gravimeter_bias", "sigma_gravimeter_bias"]
    keys += ["map_error", "sigma_map_error"] if "map_error" in res else []
    cols.update({k: res[k] for k in (*keys, "innovation", "innovation_sigma", "status")})
    return cols


def _check_sigma(name, value):
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive, finite standard deviation; got {value!r}")


_FILTER_MARGIN_M = 20e3
"""Reach of a filter beyond its point-mass grid (m): the INS drift over a few hours."""


def _field(args, track):
    """The map (cut to the track's reach), its name for messages, and the model's offset."""
    if args.point_masses == "paper-d":
        return paper_d(), "point masses paper-d", 0.0
    if args.point_masses is not None:
        masses, offset = load_point_masses(args.point_masses)
        return (masses, f"point masses {args.point_masses} (K = {masses.size}, offset "
                f"{offset:+.3f} mGal)", offset)
    margin_m = PMF_SPAN_SIGMA * args.sigma_pos + _FILTER_MARGIN_M
    return track_map(args, track, margin_m), f"map {args.map}", 0.0


def _eotvos(args, track, g):
    """The readings Eötvös-corrected by the one rule (module notes), the filter's ``∂E/∂v``
    (None: not carried) and a note for the summary line."""
    if "v_east" not in track or "v_north" not in track:
        if args.eotvos_corrected:
            raise ValueError(f"--eotvos-corrected needs the INS velocity columns v_east, "
                             f"v_north in --track {str(args.track)!r}")
        return g, None, "no velocity columns: gravity taken as Eötvös-corrected"
    lat, ve, vn = (np.asarray(track[k]) for k in ("lat", "v_east", "v_north"))
    if not args.eotvos_corrected:
        g = g + np.asarray(eotvos(lat, ve, vn))
    how = "given corrected" if args.eotvos_corrected else "Eötvös-corrected here"
    if args.method == "pmf":
        return g, None, f"readings {how} with the INS velocity (pmf: its error not modelled)"
    jac = np.asarray(eotvos_jacobian(lat, ve, vn))
    return g, jac, f"readings {how} with the INS velocity, its error in the filter"


def _check_on_map(grid, lat, lon, where, name):
    inside = np.asarray(grid.contains(lat, lon))
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        w, e, s, n = grid.extent
        raise ValueError(
            f"{where}: {int((~inside).sum())} of {lat.size} positions are off the map --map "
            f"{name} (lat {s:g}..{n:g}, lon {w:g}..{e:g}), first on line {csv_line(i)} "
            f"(lat {lat[i]:g}, lon {lon[i]:g})")


def cmd_filter(args):
    """Run ``jaxgrav filter`` (x64 is enabled by the CLI entry point)."""
    if (args.map is None) == (args.point_masses is None):
        given = "both" if args.map is not None else "neither"
        raise ValueError(f"give exactly one of --map MAP.nc and --point-masses "
                         f"paper-d|MODEL.json; got {given}")
    if Path(args.out).exists() and not args.force:
        raise FileExistsError(f"--out {str(args.out)!r} exists; pass --force to overwrite it")
    for name, value in (("--sigma-pos", args.sigma_pos), ("--sigma-vel", args.sigma_vel),
                        ("--sigma-gravity", args.sigma_gravity)):
        _check_sigma(name, value)
    where = f"--track {str(args.track)!r}"
    track = read_track(args, required=("t", "lat", "lon", "gravity"), allow_nan=("gravity",))
    t, lat, lon, g = (track[k] for k in ("t", "lat", "lon", "gravity"))
    _uniform_dt(t, where)
    if np.any(np.abs(lat) > 90):
        i = int(np.flatnonzero(np.abs(lat) > 90)[0])
        raise ValueError(f"{where}: latitude {lat[i]:g} on line {csv_line(i)} is outside "
                         "[-90, 90] degrees")
    if not np.isfinite(g).any():
        raise ValueError(f"{where}: column 'gravity' has no readings (all {g.size} cells "
                         "empty or NaN); the filter needs at least one (mGal)")
    if args.guard is not None:
        if args.method == "pmf":
            raise ValueError("--guard applies to ukf, ekf and gsf; got --method pmf")
        if not (np.isfinite(args.guard) and args.guard > 0):
            raise ValueError(f"--guard must be a positive variance ratio (posterior / free "
                             f"INS, e.g. 0.2); got {args.guard!r}")
    if args.method == "pmf":
        reading_stride(np.flatnonzero(np.isfinite(g)), where)
    me_sigma, me_length = _map_error_args(args)
    fogm = (map_error_state(me_sigma, me_length, args.map_error_order) if me_sigma > 0
            else None)
    field, field_name, offset = _field(args, track)
    if args.map is not None:
        _check_on_map(field, lat, lon, where, args.map)
    g, jac, eotvos_note = _eotvos(args, track, g)
    # the model is masses + offset: z − (masses + offset + bias) = (z − offset) − (masses + bias)
    res = filter_track(field, t, lat, lon, g - offset, args.method, sigma_pos=args.sigma_pos,
                       sigma_vel=args.sigma_vel, sigma_gravity=args.sigma_gravity,
                       guard=args.guard, map_error=fogm, eotvos_velocity=jac, where=where)
    write_track_csv(args.out, _output_columns(t, track, res), force=args.force, precision=12)
    n_read = int(np.isfinite(g).sum())
    stride = f", updates every {res['pmf_every']} rows" if args.method == "pmf" else ""
    stride += f", no-harm guard {args.guard:g}" if args.guard is not None else ""
    if fogm is not None:
        stride += (f", map-error state {me_sigma:g} mGal over {me_length:g} m"
                   + (" per cell" if args.method == "pmf" else "")
                   + (", second order" if args.map_error_order == 2 else ""))
    print(f"wrote {args.out}: {args.method} over {t.size} rows ({n_read} readings{stride}) "
          f"on {field_name}; final 1-sigma {res['sigma_north'][-1]:.0f} m north, "
          f"{res['sigma_east'][-1]:.0f} m east; {eotvos_note}")
    status = res["status"]
    for name in status_messages_filter(int(np.bitwise_or.reduce(status))):
        if name == "no_reading":
            continue
        count = int(np.count_nonzero(status & STATUS_FILTER[name]))
        print(f"warning: {name} on {count} of {t.size} rows: {_WARN.get(name, name)}",
              file=sys.stderr)


# ---------------------------------------------------------------------- simulate
_simulate = jax.jit(filter_scenario)
_SIM_MARGIN_M = 16e3  # 3 x 2 km initial error + 10 km: the INS track stays on the map


def _inner_region(grid, margin_m, name):
    """``(lat_min, lat_max, lon_min, lon_max)`` of ``grid`` shrunk by ``margin_m`` (m)."""
    w, e, s, n = (float(v) for v in grid.extent)
    dlat = margin_m / DEG_ARC_M
    dlon = margin_m / (DEG_ARC_M * np.cos(np.radians(min(max(abs(s), abs(n)), 89.0))))
    region = (s + dlat, n - dlat, w + dlon, e - dlon)
    if not (region[0] < region[1] and region[2] < region[3]):
        raise ValueError(f"--map {name} (lat {s:g}..{n:g}, lon {w:g}..{e:g}) is too small for "
                         f"the run: starts must lie {margin_m / 1e3:.0f} km inside it; use "
                         "fewer --minutes or a larger map")
    return region
"""Paper D's scenario, compiled once per process and scenario shape."""


def cmd_simulate_filter(args):
    """Run ``jaxgrav simulate-filter``: paper D's scenario over its three point masses."""
    outs = [p for p in (args.out, args.truth) if p is not None]
    existing = [str(p) for p in outs if Path(p).exists()]
    if existing and not args.force:
        raise FileExistsError(f"{existing} exist(s); pass --force to overwrite")
    if args.truth is not None and Path(args.truth).resolve() == Path(args.out).resolve():
        raise ValueError(f"--truth must differ from --out; both are {args.out!r}")
    if not (np.isfinite(args.dt) and args.dt > 0):
        raise ValueError(f"--dt must be a positive step (s); got {args.dt!r}")
    if args.reading_every < 1:
        raise ValueError(f"--reading-every must be a positive number of rows; got "
                         f"{args.reading_every}")
    n = round(args.minutes * 60.0 / args.dt) + 1 if np.isfinite(args.minutes) else 0
    if n < 2:
        raise ValueError(f"--minutes must cover at least one --dt step ({args.dt:g} s); got "
                         f"{args.minutes!r}")
    me_sigma, me_length = _map_error_args(args)
    if args.map is None:
        if me_sigma > 0:
            raise ValueError("--map-error needs --map (paper D's point masses have no grid to "
                             "draw the map error on)")
        scen = FilterScenario(dt=args.dt, reading_every=args.reading_every, n_steps=n,
                              geometry=args.geometry)
        run = _simulate(jax.random.key(args.seed), paper_d(), scen)
        over = f"{args.geometry} over paper D's point masses"
    else:
        grid = load_map(args.map, args.var)
        scen = FilterScenario(dt=args.dt, reading_every=args.reading_every, n_steps=n)
        margin = scen.speed * args.dt * (n - 1) + _SIM_MARGIN_M
        scen = dataclasses.replace(scen, geometry="random",
                                   region=_inner_region(grid, margin, args.map))
        me = map_error(me_sigma, me_length) if me_sigma > 0 else None
        run = _simulate(jax.random.key(args.seed), grid, scen, me)
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
