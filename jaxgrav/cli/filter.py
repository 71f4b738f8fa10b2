"""``jaxgrav filter``: gravity/INS filtering of a track (paper D).

Wire into :mod:`jaxgrav.cli` with ``cli_filter.add_parser(sub)``.

``filter`` reads a track CSV with the INS-indicated position and the gravimeter's
anomaly readings, runs a filter of :mod:`jaxgrav.filters` over the 13-state
INS error model of :mod:`jaxgrav.sim.ins` and writes the filtered track::

    TRACK.csv  t (s, a regular step), lat, lon (INS, degrees), gravity (the
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

Times: the filters run on a regular step (:mod:`jaxgrav.time_steps`): clock jitter
of up to 10 % of a step is absorbed, and a gap of whole steps up to ``--max-gap``
seconds is predicted through (positions interpolated, no reading). The output has the
log's own rows. ``--method pmf`` updates on the stride all its readings sit on (the
greatest common divisor of the rows between them: a missing reading is an update
without one) and predicts between.

The prior is the INS error at one step before the first row (zero mean, the
``--sigma-*`` standard deviations); every row's reading updates the estimate, and
row ``k`` of the output is the causal posterior after row ``k``. The INS error model is
paper D's (``--ins strategic``, the default) or the navigation grade of ``jaxgrav
simulate-voyage`` logs (``--ins navigation``; :data:`jaxgrav.scenarios.INS_GRADES`): a
model better than the log's INS leaves the 1-σ over-confident, and the readings' fit does
not show it.

The map is a NetCDF grid (``--map``), paper D's three masses (``--point-masses
paper-d``) or a fitted point-mass model file (``--point-masses MODEL.json``, see
:func:`~jaxgrav.fields.pointmass_fit.save_point_masses`; its offset is taken off the
readings).

``filter --map-error SIGMA --map-error-length L`` tells the filter the map is wrong
(:mod:`jaxgrav.filters.map_state`; ``--map-error-order 2``: a second-order
Gauss–Markov state, matched to the default map-error model). Tracks to try it on:
``jaxgrav simulate-filter`` (:mod:`jaxgrav.cli.simulate_filter`).
"""

import sys

import numpy as np

from jaxgrav._io import check_outputs
from jaxgrav.cli.filter_checks import (
    MIN_PARTICLES,
    check_on_map,
    check_particles,
    check_pmf_span,
    check_sigma,
    check_sigma_pos,
    check_sigma_vel,
    check_velocity_columns,
    gradient_at_ins,
    information_warning,
    ins_label,
    map_at_ins,
    offset_warning,
    speed_course_warning,
)
from jaxgrav.cli.inputs import (
    add_map_error_var_option,
    add_missing_option,
    add_track_option,
    check_missing_option,
    check_out_format,
    kept_columns,
    map_error_args,
    read_track,
    track_map,
    whole_number,
)
from jaxgrav.cli.sanity import (
    check_positions,
    check_readings,
    implausible_rows,
    innovation_check,
)
from jaxgrav.cli.simulate import check_map_error_size, check_seed
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.fields.pointmass_fit import load_point_masses
from jaxgrav.filters import STATUS_FILTER, status_messages_filter
from jaxgrav.filters.api import (
    FILTER_METHODS,
    PARTICLES,
    PMF_SPAN_SIGMA,
    filter_track,
)
from jaxgrav.filters.map_state import map_error_state
from jaxgrav.geodesy import eotvos_jacobian_jit, eotvos_jit
from jaxgrav.scenarios import INS_GRADES
from jaxgrav.time_steps import at_rows, on_steps, time_steps
from jaxgrav.tracks import write_track_csv

__all__ = ["add_parser", "cmd_filter"]

_WARN = {
    "off_map": "the estimate or its sigma points (ukf, ekf, gsf) left the map or met a "
               "missing (NaN) map cell: update skipped; pf and rbpf particles and pmf cells "
               "without a map value take the others' mean likelihood (pmf --missing land: "
               "none where the nearest node is missing), the update is skipped only when "
               "none has one",
    "covariance_repaired": "the covariance was not positive definite; jitter added",
    "covariance_failed": "the covariance could not be repaired, or the innovation variance "
                         "was not positive; update skipped",
    "gated": "innovation outside the gate; update skipped",
    "grid_edge": "posterior mass at the edge of the point-mass grid; raise --sigma-pos",
    "implausible_fit": "the innovations of the rows' block of readings are implausible for "
                       "their predicted variance (chi-squared p < 1e-3); the 1-sigma there is "
                       "not trustworthy",
}


def add_parser(subparsers):
    """Add the ``filter`` sub-command to an ``argparse`` sub-parser set."""
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
    add_track_option(f, "CSV: t (s, a regular step; jitter up to 10 %% of it absorbed, gaps "
                        "up to --max-gap predicted through), lat, lon (INS, degrees), gravity "
                        "(mGal; empty where no reading; raw when v_east, v_north are given, "
                        "else Eötvös-corrected); optional v_east, v_north (INS, m/s)")
    f.add_argument("--method", choices=FILTER_METHODS, default="ukf",
                   help="ukf (default), ekf (jacfwd Jacobian), gsf (Gaussian sum of 3 x 3 "
                        "UKFs, for multi-modal priors), pmf (grid point-mass filter), pf (SIR "
                        "particle filter), rbpf (Rao-Blackwellised particle filter: particles "
                        "in position, a Kalman filter for the rest)")
    f.add_argument("--particles", type=whole_number, default=None, metavar="N",
                   help=f"pf, rbpf: number of particles, at least {MIN_PARTICLES} (default "
                        "2000 for pf, 1000 for rbpf; pf's 1-sigma is over-confident below "
                        "about 1000)")
    f.add_argument("--seed", type=int, default=None,
                   help="pf, rbpf: seed of the particles' random numbers (default 0)")
    f.add_argument("--out", required=True,
                   help="output CSV: t, lat, lon, sigma_north, sigma_east (m), covariance, "
                        "velocity, biases, innovations and status per row")
    f.add_argument("--sigma-pos", type=float, default=1414.2,
                   help="initial INS position error, 1-σ per axis (m); default 1414 m, "
                        "i.e. 2 km RMS horizontal")
    f.add_argument("--sigma-vel", type=float, default=0.1414,
                   help="initial INS velocity error, 1-σ per axis (m/s); default 0.14, "
                        "i.e. 0.2 m/s RMS horizontal (navigation-grade INS)")
    f.add_argument("--ins", choices=sorted(INS_GRADES), default="strategic",
                   help=f"the filter's INS error model: strategic, the {ins_label('strategic')}"
                        " of paper D and simulate-filter (default), or navigation, the "
                        f"{ins_label('navigation')} of simulate-voyage logs; a model better "
                        "than the log's INS leaves the 1-sigma over-confident")
    f.add_argument("--sigma-gravity", type=float, default=1.0,
                   help="reading noise, 1-σ (mGal); default 1 (marine gravimeter)")
    f.add_argument("--guard", type=float, nargs="?", const=0.2, default=None,
                   metavar="RATIO",
                   help="no-harm guard (ukf, ekf, gsf, pf, rbpf; not pmf): apply the position "
                        "correction only "
                        "in directions whose variance fell below RATIO (0 < RATIO <= 1) times the "
                        "free INS's "
                        "(default 0.2 when given without a value; chosen on paper D's "
                        "experiment); elsewhere the output stays the INS with its own 1-σ")
    f.add_argument("--map-error", type=float, default=0.0, metavar="SIGMA",
                   help="the map's error, 1-sigma (mGal): ukf, ekf, gsf add a Gauss-Markov "
                        "map-error state over the distance travelled (--map-error-order); pmf "
                        "a first-order one per grid cell. Default 0: the map is the truth")
    f.add_argument("--map-error-length", type=float, default=None, metavar="L",
                   help="correlation length of that state over the distance travelled (m, "
                        "default 10000; time constant L / the mean ground speed). For a map "
                        "error with covariance s^2 (1 + r/L) e^(-r/L) use order 2 with L, or "
                        "order 1 with 2 L")
    add_map_error_var_option(f)
    f.add_argument("--map-error-order", type=int, default=None, choices=(1, 2),
                   help="order of the map-error state: 1 first-order Gauss-Markov (default), "
                        "2 second-order (value and rate; covariance s^2 (1 + r/L) e^(-r/L), "
                        "the model of simulate-filter --map-error); pmf: 1 only")
    f.add_argument("--eotvos-corrected", action="store_true",
                   help="the gravity column is already Eötvös-corrected with the INS velocity "
                        "of v_east, v_north (default: raw, corrected here)")
    add_missing_option(f)
    f.add_argument("--max-gap", type=float, default=60.0, metavar="S",
                   help="longest gap between rows (s) the filter predicts through, the "
                        "missing rows' positions interpolated (default 60)")
    f.add_argument("--force", action="store_true", help="overwrite an existing output")
    f.set_defaults(func=cmd_filter)
    return f


# ------------------------------------------------------------------------ checks
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


_FILTER_MARGIN_M = 20e3
"""Reach of a filter beyond its point-mass grid (m): the INS drift over a few hours."""


def _field(args, track, sigma_given):
    """The map (cut to the track's reach), its name for messages, the model's offset and
    ``--map-error-var``'s σ (None without it)."""
    if args.point_masses == "paper-d":
        return paper_d(), "point masses paper-d", 0.0, None
    if args.point_masses is not None:
        masses, offset = load_point_masses(args.point_masses)
        return (masses, f"point masses {args.point_masses} (K = {masses.size}, offset "
                f"{offset:+.3f} mGal)", offset, None)
    margin_m = PMF_SPAN_SIGMA * args.sigma_pos + _FILTER_MARGIN_M
    grid, sigma_var = track_map(args, track, margin_m, error_reach_m=_FILTER_MARGIN_M,
                                sigma_given=sigma_given)
    return grid, f"map {args.map}", 0.0, sigma_var


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
        g = g + np.asarray(eotvos_jit(lat, ve, vn))
    how = "given corrected" if args.eotvos_corrected else "Eötvös-corrected here"
    jac = np.asarray(eotvos_jacobian_jit(lat, ve, vn))
    return g, jac, f"readings {how} with the INS velocity, its error in the filter"


def _particle_options(args):
    """``filter_track``'s particle settings from the arguments (empty for other methods)."""
    if args.method not in PARTICLES:
        return {}
    opts = dict(seed=args.seed)
    if args.particles is not None:
        opts["n_particles"] = args.particles
    return opts


def cmd_filter(args):
    """Run ``jaxgrav filter`` (x64 is enabled by the CLI entry point)."""
    if (args.map is None) == (args.point_masses is None):
        given = "both" if args.map is not None else "neither"
        raise ValueError(f"give exactly one of --map MAP.nc and --point-masses "
                         f"paper-d|MODEL.json; got {given}")
    if args.point_masses is not None and args.var is not None:  # was ignored, silently
        raise ValueError(f"--var {args.var} names a variable of a --map file; --point-masses "
                         f"{args.point_masses} has none: leave --var out")
    if args.point_masses is not None and args.missing is not None and args.method == "pmf":
        raise ValueError(f"--missing {args.missing} says how pmf reads a --map's missing (NaN) "
                         f"nodes; --point-masses {args.point_masses} is a field with no "
                         "nodes: leave --missing out")
    check_outputs([args.out], force=args.force, names=["--out"],
                  inputs={"--track": args.track, "--map": args.map,
                          "--point-masses": args.point_masses})
    check_out_format(args.out, "CSV")
    for name, value in (("--sigma-pos", args.sigma_pos), ("--sigma-vel", args.sigma_vel),
                        ("--sigma-gravity", args.sigma_gravity)):
        check_sigma(name, value)
    check_sigma_pos(args.sigma_pos)
    check_sigma_vel(args.sigma_vel)
    if args.seed is not None and args.method not in PARTICLES:  # was not used, no word
        raise ValueError(f"--seed is for --method pf or rbpf (their particles' draws); got "
                         f"--method {args.method}")
    args.seed = 0 if args.seed is None else args.seed
    check_seed(args.seed)
    where = f"--track {str(args.track)!r}"
    track = read_track(args, required=("t", "lat", "lon", "gravity"), allow_nan=("gravity",))
    t, lat, lon, g = (track[k] for k in ("t", "lat", "lon", "gravity"))
    check_velocity_columns(track, where)
    speed_course = speed_course_warning(track, where)  # raw readings read as corrected
    if speed_course is not None and not args.eotvos_corrected:
        print(f"warning: {speed_course}", file=sys.stderr)
    if not (np.isfinite(args.max_gap) and args.max_gap > 0):
        raise ValueError(f"--max-gap must be a finite time > 0 (s); got {args.max_gap!r}")
    steps = time_steps(t, where, max_gap=args.max_gap, line=track.line)
    if np.any(np.abs(lat) > 90):
        i = int(np.flatnonzero(np.abs(lat) > 90)[0])
        raise ValueError(f"{where}: latitude {lat[i]:g} on line {track.line(i)} is outside "
                         "[-90, 90] degrees")
    if "v_east" in track and "v_north" in track:
        check_positions(track, where=where)
    if not np.isfinite(g).any():
        raise ValueError(f"{where}: column 'gravity' has no readings (all {g.size} cells "
                         "empty or NaN); the filter needs at least one (mGal)")
    if args.guard is not None:
        if args.method == "pmf":
            raise ValueError("--guard applies to ukf, ekf, gsf, pf and rbpf; got --method pmf")
        # the posterior / free variance ratio is at most 1: --guard 1e9 held nothing back
        # while the summary said "no-harm guard 1e+09" (1 is the filter itself, tested)
        if not (np.isfinite(args.guard) and 0 < args.guard <= 1):
            raise ValueError(f"--guard must be a positive variance ratio of at most 1 "
                             f"(posterior / free INS, e.g. 0.2; at 1 the guard holds nothing "
                             f"back, and no ratio exceeds 1); got {args.guard:g}")
    missing = check_missing_option(args)
    if args.particles is not None:
        if args.method not in PARTICLES:
            raise ValueError(f"--particles is for --method pf or rbpf; got --method "
                             f"{args.method}")
        check_particles(args.particles)
    me_sigma, me_length = map_error_args(args)
    check_map_error_size(me_sigma)
    if args.map_error_var is not None and args.map is None:
        raise ValueError("--map-error-var needs --map (a point-mass model has no uncertainty "
                         "grid)")
    field, field_name, offset, sigma_var = _field(args, track, sigma_given=me_sigma > 0)
    if args.method == "pmf":  # a point-mass model ran "final 1-sigma 0 m" with 1e-9
        check_pmf_span(field, args.sigma_pos, lat, lon, g, args.sigma_gravity)
    if sigma_var is not None:
        me_sigma = sigma_var
    fogm = (map_error_state(me_sigma, me_length, args.map_error_order) if me_sigma > 0
            else None)
    if args.map is not None:
        check_on_map(field, lat, lon, where, args.map, line=track.line)
    g_raw = g
    g, jac, eotvos_note = _eotvos(args, track, g)
    expected = map_at_ins(field, lat, lon) + offset
    check_readings(g_raw, expected, args.sigma_gravity, column="gravity", where=where,
                   line=track.line, noise_option="--sigma-gravity",
                   correction=g - g_raw)
    level = offset_warning(g, expected, INS_GRADES[args.ins].gravimeter_sigma, me_sigma,
                           args.sigma_gravity)
    # the model is masses + offset: z − (masses + offset + bias) = (z − offset) − (masses + bias)
    # on the regular step: the log's rows, and interpolated positions without a reading
    # in its gaps; the result at the log's rows
    res = filter_track(field, t[0] + steps.dt * np.arange(steps.n_steps),
                       on_steps(steps, lat), on_steps(steps, lon, period=360.0),
                       on_steps(steps, g - offset, fill=np.nan), args.method,
                       sigma_pos=args.sigma_pos, sigma_vel=args.sigma_vel,
                       sigma_gravity=args.sigma_gravity, guard=args.guard, map_error=fogm,
                       eotvos_velocity=None if jac is None else on_steps(steps, jac, fill=0.0),
                       where=where, ins=INS_GRADES[args.ins], missing=missing,
                       **_particle_options(args))
    every = res.pop("pmf_every")
    res = at_rows(steps, res)
    res["status"] = res["status"] | np.where(
        implausible_rows(res["innovation"], res["innovation_sigma"]),
        STATUS_FILTER["implausible_fit"], 0)
    write_track_csv(args.out, kept_columns(track, _output_columns(t, track, res)),
                    force=args.force)
    n_read = int(np.isfinite(g).sum())
    stride = f", updates every {every} rows" if args.method == "pmf" else ""
    stride += f", no-harm guard {args.guard:g}" if args.guard is not None else ""
    if args.method in PARTICLES:
        opts = _particle_options(args)
        stride += (f", {opts.get('n_particles', PARTICLES[args.method])} particles, "
                   f"seed {args.seed}")
    if args.method == "pmf" and getattr(field, "n_missing", 0):
        stride += f", missing map nodes read as {missing}"
    if fogm is not None:
        stride += (f", map-error state {me_sigma:g} mGal over {me_length:g} m"
                   + (" per cell" if args.method == "pmf" else "")
                   + (", second order" if args.map_error_order == 2 else ""))
    print(f"wrote {args.out}: {args.method} over {t.size} rows ({n_read} readings{stride}) "
          f"on {field_name}, {ins_label(args.ins)}; final 1-sigma "
          f"{res['sigma_north'][-1]:.0f} m north, {res['sigma_east'][-1]:.0f} m east; "
          f"{eotvos_note}; {steps.describe()}")
    _, _, fit_warning = innovation_check(res["innovation"], res["innovation_sigma"])
    read = np.isfinite(g)
    flat = information_warning(
        *gradient_at_ins(field, lat[read], lon[read]), float(np.hypot(args.sigma_gravity,
                                                                      me_sigma)),
        max(args.sigma_pos, float(np.max(np.maximum(res["sigma_north"], res["sigma_east"])))))
    for warning in (flat, level, fit_warning):
        if warning is not None:
            print(f"warning: {warning}", file=sys.stderr)
    status = res["status"]
    for name in status_messages_filter(int(np.bitwise_or.reduce(status))):
        if name == "no_reading":
            continue
        count = int(np.count_nonzero(status & STATUS_FILTER[name]))
        print(f"warning: {name} on {count} of {t.size} rows: {_WARN.get(name, name)}",
              file=sys.stderr)
