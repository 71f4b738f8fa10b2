"""``jaxgrav match``: one track against a map.

Wire into :mod:`jaxgrav.cli` with ``add_parsers(sub)`` (which adds ``jaxgrav sample``,
:mod:`jaxgrav.cli.sample`, too).
"""

import json
import math
import sys

import numpy as np

from jaxgrav._io import atomic_output, check_outputs
from jaxgrav.cli import sample
from jaxgrav.cli.filter_checks import check_velocity_columns, speed_course_warning
from jaxgrav.cli.inputs import (
    FIELD_UNITS,
    add_map_error_var_option,
    add_track_option,
    check_map_field,
    check_out_format,
    fill_map_error_length,
    read_track,
    track_map,
    track_time_units,
    whole_number,
)
from jaxgrav.cli.match_missing import missing_counts, missing_message
from jaxgrav.cli.match_search import check_radius_resolved, check_search, check_track_moves
from jaxgrav.cli.match_size import check_fixes_memory
from jaxgrav.cli.match_status import status_text
from jaxgrav.cli.positions import check_velocity_units
from jaxgrav.cli.sanity import check_readings, fit_check, time_gap_warning
from jaxgrav.cli.simulate import check_map_error_size
from jaxgrav.fields.map_error import map_error
from jaxgrav.geodesy import eotvos_jit
from jaxgrav.grid_values import map_units
from jaxgrav.match import (
    ENTROPY_HALF_SIZE,
    IMPLAUSIBLE_FIT,
    METHODS,
    MIN_FIXES,
    STATUS,
    match_track,
)
from jaxgrav.match.api import MAP_ERROR_METHODS, MASKED, missing_reading
from jaxgrav.sim import DEG_ARC_M
from jaxgrav.track_units import unit_of

__all__ = ["CONTOUR_METHODS", "ENTROPY_HALF_SIZE", "add_parsers", "check_search"]

CONTOUR_METHODS = ("entropy", "iccp", "entropy+iccp")
"""Methods that match magnetic as well as gravity tracks (they estimate no bias)."""


def add_parsers(sub):
    """Add the ``match`` and ``sample`` sub-commands to an ``argparse`` set."""
    m = sub.add_parser("match", help="match a track CSV against a map (papers A and B)")
    m.add_argument("--map", required=True,
                   help="NetCDF grid with lat/lon coordinates, or a shipped map (ryukyu, "
                        "ryukyu:anomaly_0p5deg)")
    m.add_argument("--var", default=None, help="variable to read when the file has several")
    add_track_option(m, "CSV: t (s), lat, lon (INS, degrees), gravity (mGal) or magnetic "
                        "(nT); optional v_east, v_north (m/s), drift_radius (degrees)")
    m.add_argument("--out", required=True, help="result JSON")
    m.add_argument("--method", choices=METHODS, default="dense",
                   help="dense (default, most accurate), chains (paper A's constrained "
                        "iso-point chains), or paper B's entropy, iccp, entropy+iccp")
    m.add_argument("--drift-radius", type=float, default=None,
                   help="largest INS drift (degrees of arc); default: the track's "
                        "drift_radius column, else 0.05")
    m.add_argument("--noise", type=float, default=1.0,
                   help="reading noise sigma (mGal, or nT for a magnetic track)")
    m.add_argument("--bias-sigma", type=float, default=None,
                   help="dense, chains: prior sigma of the reading bias (mGal, > 0; inf: "
                        "estimated freely); default 3 with velocities, else free")
    m.add_argument("--max-rotation", type=float, default=None, metavar="DEG",
                   help="iccp, entropy+iccp: largest INS heading error (degrees, 0-180), the "
                        "bound on ICCP's rotation (library max_rotation_deg); default 90, "
                        "i.e. no bound that matters. The README's paper B numbers use 2 with "
                        "--drift-radius 0.035")
    m.add_argument("--entropy-half-size", type=whole_number, default=ENTROPY_HALF_SIZE, metavar="N",
                   help="entropy, entropy+iccp: at most N offsets per side, (2N+1)^2 in all "
                        f"(default {ENTROPY_HALF_SIZE}, as the README's numbers); on fine maps "
                        "the offset spacing grows instead")
    m.add_argument("--refine", type=whole_number, default=1,
                   help="refine the map by this factor first (chains: paper A used 100)")
    m.add_argument("--map-error", type=float, default=0.0, metavar="SIGMA",
                   help="dense, chains, entropy+iccp: σ of the map's error (map units, default "
                        "0 = white-noise score); "
                        "> 0 scores by GLS, returns the posterior fix and tests its integrity")
    m.add_argument("--map-error-length", type=float, default=None, metavar="L",
                   help="dense, chains, entropy+iccp: correlation length of the map's error "
                        "(m, default 10000)")
    add_map_error_var_option(m)
    m.add_argument("--missing", choices=("auto", "land", "gaps"), default="auto",
                   help="what missing (NaN) map nodes are: land (candidates touching them are "
                        "dropped) or, dense only, survey gaps (each candidate is scored on its "
                        "fixes over present cells); auto (default): gaps for dense when the "
                        "INS track itself crosses a missing cell, else land")
    m.add_argument("--eotvos-corrected", "--no-eotvos", dest="no_eotvos", action="store_true",
                   help="the gravity column is already Eötvös-corrected (with velocities "
                        "v_east, v_north the column is otherwise taken as raw and corrected "
                        "here; the rule of match, filter and navigate); --no-eotvos is its "
                        "older name")
    m.add_argument("--force", action="store_true", help="overwrite an existing output")
    m.set_defaults(func=_cmd_match)

    sample.add_parser(sub)


def _check_out(args, writes):
    """``--out`` before anything is computed: not a folder, not an input, no clobbering,
    its suffix fits ``writes`` (``"JSON"`` or ``"CSV"``)."""
    check_outputs([args.out], force=args.force, names=["--out"],
                  inputs={"--track": args.track, "--map": args.map})
    check_out_format(args.out, writes)


def _drift_radius(args, track):
    """The search radius (degrees of arc): ``--drift-radius``, else the largest value of
    the track's ``drift_radius`` column (each must be > 0), else 0.05."""
    if args.drift_radius is not None:
        return args.drift_radius
    if "drift_radius" not in track or not np.isfinite(track["drift_radius"]).any():
        return 0.05
    radius = np.asarray(track["drift_radius"], float)
    bad = np.flatnonzero(np.isfinite(radius) & ~(radius > 0))
    if bad.size:
        i = int(bad[0])
        column = track.renamed.get("drift_radius", "drift_radius")
        raise ValueError(f"--track {str(args.track)!r}, line {track.line(i)}, column "
                         f"{column!r}: drift radius {radius[i]:g} is not a positive angle in "
                         f"degrees of arc ({bad.size} such row(s)); fix the column or give "
                         "--drift-radius")
    return float(np.nanmax(radius))


def _cmd_match(args):
    _check_match_args(args)
    _check_out(args, "JSON")
    track = read_track(args, required=("t", "lat", "lon"))
    n_rows = len(track["lat"])
    if n_rows < MIN_FIXES:  # was the library's "the track is too short: 1 fixes", no file
        raise ValueError(f"--track {str(args.track)!r} has {n_rows} row{'s' * (n_rows != 1)}; "
                         f"match needs at least {MIN_FIXES} fixes")
    check_fixes_memory(args.method, n_rows, f"--track {str(args.track)!r}")
    fields = [f for f in FIELD_UNITS if f in track]
    radius_deg = _drift_radius(args, track)
    if not fields:
        raise ValueError(_no_readings(args, track, radius_deg))
    grid, sigma_var = track_map(args, track, radius_deg * DEG_ARC_M,
                                sigma_given=args.map_error > 0, field=None)
    # a survey file with both columns is matched on the one the map's units name (a map
    # without units: gravity); it was matched on the magnetic column against any map
    field = (fields[0] if len(fields) == 1
             else "magnetic" if grid.units == FIELD_UNITS["magnetic"] else "gravity")
    check_map_field(grid, field, args.map)
    if field == "gravity" and not args.no_eotvos:  # a lone v_east: raw taken as corrected
        check_velocity_columns(track, f"--track {str(args.track)!r}")
        if "v_east" in track and "v_north" in track:  # knots: a +42 mGal bias, exit 0
            check_velocity_units(track, where=f"--track {str(args.track)!r}")
        speed_course = speed_course_warning(track, f"--track {str(args.track)!r}")
        if speed_course is not None:
            print(f"warning: {speed_course}", file=sys.stderr)
    if sigma_var is not None:
        if args.method not in MAP_ERROR_METHODS:
            raise ValueError(f"--map-error-var is used by --method {', '.join(MAP_ERROR_METHODS)}"
                             f"; got --method {args.method}")
        args.map_error = sigma_var
    has_v = (field == "gravity" and "v_east" in track and "v_north" in track
             and not args.no_eotvos)
    unit = "nT" if field == "magnetic" else "mGal"
    # compared with the map as the matcher will: Eötvös-corrected (bilinear: levels and
    # spreads need no spline, and the gap check compiled that program already)
    correction = (np.asarray(eotvos_jit(track["lat"], track["v_east"], track["v_north"]))
                  if has_v else 0.0)
    check_readings(track[field], np.asarray(grid.sample(track["lat"], track["lon"], "bilinear")),
                   args.noise, column=field, where=f"--track {str(args.track)!r}", unit=unit,
                   correction=correction, missing_skipped=False, line=track.line)
    source = ("--drift-radius" if args.drift_radius is not None else
              f"column 'drift_radius' of --track {str(args.track)!r}" if
              "drift_radius" in track and np.isfinite(track["drift_radius"]).any() else
              "the default drift radius")
    check_search(args, grid, radius_deg, track["lat"], source=source)
    check_radius_resolved(grid, radius_deg, n_rows, args.noise, source)
    check_track_moves(grid, track["lat"], track["lon"], args.noise, f"--track {str(args.track)!r}")
    if args.refine > 1:
        grid = grid.refine(args.refine)
    if field != "gravity" and args.method not in CONTOUR_METHODS:
        raise ValueError(f"--method {args.method} matches gravity; use entropy, iccp or "
                         "entropy+iccp for a magnetic track")
    max_rotation = 90.0 if args.max_rotation is None else args.max_rotation
    kw = {}  # the options each method takes (_check_match_args refuses the others)
    if args.method in ("dense", "chains"):
        kw["bias_sigma_mgal"] = args.bias_sigma
    if args.method == "dense":
        kw["missing"] = args.missing
    if args.map_error > 0:
        kw["map_error"] = map_error(args.map_error, args.map_error_length)
    if args.method in ("iccp", "entropy+iccp"):
        kw["max_rotation_deg"] = max_rotation
    if args.method in ("entropy", "entropy+iccp"):
        kw["entropy_half_size"] = args.entropy_half_size
    result = match_track(
        grid, track["lat"], track["lon"], track[field], method=args.method,
        drift_radius_m=radius_deg * DEG_ARC_M, noise=args.noise,
        v_east=track["v_east"] if has_v else None,
        v_north=track["v_north"] if has_v else None, warn=False, **kw,
    )
    n_fix = len(track["lat"])
    p_fit, fit_warning = fit_check(result.chi2_per_dof, n_fix - 3, args.noise)
    # with velocities the bias prior is 3 mGal (match_track): a gravimeter offset far
    # beyond it shows as a bad fit, which the advice above would blame on noise
    sigma_b = args.bias_sigma if args.bias_sigma is not None else 3.0 if has_v else math.inf
    bias = float(result.bias)
    if (fit_warning is not None and args.method in ("dense", "chains") and math.isfinite(sigma_b)
            and abs(bias) > 3.0 * sigma_b):
        fit_warning += (f"; the fitted bias {bias:+.3g} mGal is {abs(bias) / sigma_b:.1f} sigma "
                        f"of the bias prior ({sigma_b:g} mGal): a gravimeter offset? give "
                        "--bias-sigma inf to estimate it freely")
    read_as = missing_reading(grid, track["lat"], track["lon"], args.method, args.missing,
                              radius_deg * DEG_ARC_M)
    gap = missing_counts(grid, track, result, radius_deg * DEG_ARC_M)
    # the implausible-fit bit's message is the fit check's own line, with its numbers; the
    # missing-node bit's says how many nodes and fixes met missing nodes and what was done
    messages = [missing_message(args, n_fix, gap, read_as, bool(result.accepted))
                if bit == MASKED else status_text(bit) for bit in STATUS
                if int(result.status) & bit and bit != IMPLAUSIBLE_FIT]
    if fit_warning is not None:
        messages = [*messages, fit_warning]
    if has_v and args.method in ("dense", "chains"):
        twice = _eotvos_twice(bias, correction, args.noise)
        messages = messages if twice is None else [*messages, twice]
    time_gap = time_gap_warning(track["t"], where=f"--track {str(args.track)!r}",
                                line=track.line)
    messages = messages if time_gap is None else [*messages, time_gap]
    r = {"t": np.asarray(track["t"], float).tolist()}
    t_units, t_first = track_time_units(track)  # Unix times were labelled "s"
    if track.time_origin is not None:  # ISO times: t counts from the first; both kept
        r.update(time=[str(c) for c in track.text[track.time_text]],
                 time_origin=track.time_origin)
    elif t_first is not None:  # Unix times kept as given; the first one as a date
        r.update(time_start=t_first)
    r.update({k: np.asarray(v).tolist() for k, v in result._asdict().items()})
    r.update(status_messages=messages, fit_p_value=p_fit,
             fit_plausible=None if math.isnan(p_fit) else fit_warning is None,
             units=_units(args.method, unit))
    r["units"]["t"] = t_units
    cov = np.asarray(result.covariance_m2, float)
    r.update(accepted=bool(result.accepted), covariance_m2=cov.tolist(),
             sigma_north_m=float(np.sqrt(cov[0, 0])), sigma_east_m=float(np.sqrt(cov[1, 1])),
             **{f"map_error_{_unit_key(unit)}": args.map_error},  # nT was map_error_mgal
             map_error_length_m=args.map_error_length,
             map_error_var=args.map_error_var)
    r.update(method=args.method, missing=args.missing, missing_read_as=read_as, **gap,
             field=field, map=str(args.map),
             track=str(args.track), drift_radius_deg=radius_deg, eotvos_applied_here=has_v,
             eotvos=_eotvos_note(args, field, track, has_v))
    if args.method in CONTOUR_METHODS:
        r.update(max_rotation_deg=max_rotation, entropy_half_size=args.entropy_half_size)
    with atomic_output(args.out, force=args.force) as tmp:
        tmp.write_text(json.dumps(_strict_json(r), indent=1, allow_nan=False))
    score_unit = "" if args.method == "entropy" else f" {unit}^2"
    print(f"wrote {args.out}: {args.method} match of {n_fix} fixes, offset "
          f"{float(result.offset_north_m):.0f} m north, {float(result.offset_east_m):.0f} m "
          f"east, rotation {float(result.rotation_deg):.2f} deg, score "
          f"{float(result.score):.3g}{score_unit}")
    for msg in r["status_messages"]:
        print(f"warning: {msg}", file=sys.stderr)


def _no_readings(args, track, radius_deg):
    """The message for a track without a gravity or magnetic column: the ``--columns`` to
    give names the column whose header declares a field's unit (``RMI (nT)``), else the
    field of the map's units (it said ``--columns gravity=COLUMN`` on an nT map)."""
    declared = [(name, kind) for name in track.order if unit_of(name)[1]
                for kind in [map_units(np.ones(1), unit_of(name)[1])[1]]
                if kind in FIELD_UNITS.values()]
    field = {u: f for f, u in FIELD_UNITS.items()}
    if declared:
        name, kind = declared[0]
        hint = (f"column {name!r} declares {kind}: if it holds the readings, give "
                f"--columns {field[kind]}='{name}'")
    else:
        try:
            units = track_map(args, track, radius_deg * DEG_ARC_M, field=None)[0].units
        except ValueError:
            units = None
        which = field.get(units, "gravity")
        hint = ((f"--map {str(args.map)!r} is in {units}: " if which != "gravity" else "")
                + f"name the readings' column with --columns {which}=COLUMN")
    return (f"track file {str(args.track)!r} needs a 'gravity' (mGal) or 'magnetic' (nT) "
            f"column; it has {', '.join(track.order)} ({hint})")


def _eotvos_twice(bias, correction, noise):
    """A warning when the fitted bias is the Eötvös correction applied here (within 20 %,
    over 10 mGal and 3 noise): readings corrected already, then again; else None."""
    applied = float(np.mean(correction))
    if abs(applied) > max(10.0, 3.0 * noise) and abs(bias - applied) < 0.2 * abs(applied):
        return (f"the fitted bias {bias:+.3g} mGal is the Eötvös correction applied here "
                f"with v_east, v_north (mean {applied:+.3g} mGal): were the readings "
                "corrected already? then give --eotvos-corrected")
    return None


def _eotvos_note(args, field, track, has_v):
    """What was done about Eötvös, for the JSON (``eotvos_applied_here`` alone read as
    "the input was corrected" beside the option ``--eotvos-corrected``)."""
    if field != "gravity":
        return "not applicable (magnetic readings)"
    if has_v:
        return "corrected here with the track's v_east, v_north"
    if "v_east" in track and "v_north" in track:
        return "given corrected (--eotvos-corrected): readings used as they are"
    return "no velocity columns: readings taken as Eötvös-corrected"


def _strict_json(value):
    """``value`` with every NaN or infinite float as None: strict JSON (``null``: not
    computed, e.g. the covariance of ``entropy`` alone or the p-value without a χ²)."""
    if isinstance(value, dict):
        return {k: _strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict_json(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _units(method, unit):
    """The units block of the JSON result."""
    return {"t": "s", "lat": "degrees_north", "lon": "degrees_east",
            "offset_north_m": "m", "offset_east_m": "m", "rotation_deg": "degrees",
            "score": ("nats (entropy of the readings-minus-map differences)"
                      if method == "entropy" else f"{unit}^2 (weighted mean squared residual)"),
            "bias": unit, "covariance_m2": "m^2 (north, east)", "sigma_north_m": "m",
            "sigma_east_m": "m", "chi2_per_dof": "1", "drift_radius_deg": "degrees of arc",
            f"map_error_{_unit_key(unit)}": unit, "map_error_length_m": "m"}


def _unit_key(unit):
    """A unit as a key suffix: ``mgal`` or ``nt`` (``map_error_nt`` on a magnetic map)."""
    return unit.lower()


def _check_match_args(args):
    """Numeric options of ``match``: one clear error naming the option and the value."""
    def bad(option, value, expected):
        raise ValueError(f"{option} must be {expected}; got {value!r}")

    if args.drift_radius is not None and not (math.isfinite(args.drift_radius)
                                              and args.drift_radius > 0):
        bad("--drift-radius", args.drift_radius, "a positive number of degrees of arc")
    if not (math.isfinite(args.noise) and args.noise > 0):
        # 0 weights every reading infinitely: χ² of 1e306 and a meaningless covariance
        bad("--noise", args.noise, "a finite standard deviation > 0 (mGal or nT)")
    if args.bias_sigma is not None:
        if args.method not in ("dense", "chains"):
            raise ValueError(f"--bias-sigma is the bias prior of --method dense and chains; "
                             f"--method {args.method} estimates no bias (correct the readings "
                             "instead)")
        # 0 (a bias known to be zero) divides by zero in the score: no candidate survives
        if not args.bias_sigma > 0:
            bad("--bias-sigma", args.bias_sigma, "a standard deviation > 0 (mGal; inf: the "
                "bias estimated freely; for a bias known to be near zero give a small sigma "
                "such as 0.01)")
    if args.refine < 1:
        bad("--refine", args.refine, "an integer factor >= 1")
    if not (math.isfinite(args.map_error) and args.map_error >= 0):
        bad("--map-error", args.map_error, "a finite standard deviation >= 0 (mGal)")
    check_map_error_size(args.map_error)
    fill_map_error_length(args, args.map_error != 0 or args.map_error_var is not None)
    if not (math.isfinite(args.map_error_length) and args.map_error_length > 0):
        bad("--map-error-length", args.map_error_length, "a finite correlation length > 0 (m)")
    if args.map_error > 0 and args.method not in MAP_ERROR_METHODS:
        raise ValueError(f"--map-error is used by --method {', '.join(MAP_ERROR_METHODS)} "
                         f"only; got --method {args.method}")
    if args.missing == "gaps" and args.method != "dense":
        raise ValueError(f"--missing gaps (survey gaps scored per fix) is built for --method "
                         f"dense only; got --method {args.method} (use --missing land or auto)")
    if args.max_rotation is not None:
        if args.method not in ("iccp", "entropy+iccp"):
            raise ValueError(f"--max-rotation bounds ICCP's rotation; it has no effect with "
                             f"--method {args.method} (use iccp or entropy+iccp)")
        if not (math.isfinite(args.max_rotation) and 0 <= args.max_rotation <= 180):
            bad("--max-rotation", args.max_rotation,
                "the INS heading-error bound in degrees, between 0 and 180")
    if args.entropy_half_size != ENTROPY_HALF_SIZE and args.method not in ("entropy",
                                                                       "entropy+iccp"):
        raise ValueError(f"--entropy-half-size sizes the entropy stage; it has no effect with "
                         f"--method {args.method} (use entropy or entropy+iccp)")
    if not 1 <= args.entropy_half_size <= 100:
        bad("--entropy-half-size", args.entropy_half_size, "an integer between 1 and 100")
