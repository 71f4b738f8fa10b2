"""``jaxgrav navigate``: map-aided navigation of a user's INS log (loosely or tightly coupled).

Wire into :mod:`jaxgrav.cli` with ``add_parser(sub)``.

::

    LOG.csv   t (s, a regular step), lat, lon (INS, degrees), v_east, v_north (INS,
              m/s), gravity (the gravimeter's anomaly, mGal, RAW: Eötvös not corrected,
              unless --eotvos-corrected says it was, with the INS velocity; empty where
              there is no reading: skipped and counted)
    NAV.csv   t, lat, lon (corrected, degrees), sigma_north, sigma_east (1-σ, m),
              cov_north_east (m²), v_east, v_north (corrected, m/s), fix_event (at the
              rows that end a segment: 0 accepted, 1 first segment incomplete, 2 not
              matched: missing reading or off the map, 3 rejected by the matcher's
              integrity test, 4 rejected by the innovation gate; empty elsewhere),
              fix_status (the matcher's status bits), fix_north, fix_east (the fix's
              correction of the segment, m); with ``--method ukf|ekf|gsf|rbpf|pmf``
              instead: status (the filter's bits of jaxgrav.filters.STATUS_FILTER: 0
              the reading was used, 1 no reading, 2 off the map, 16 gated, 128 the
              row's block of 60 readings has implausible innovations ...),
              innovation and innovation_sigma (mGal), gravimeter_bias and
              sigma_gravimeter_bias (mGal)

``--method dense|chains|entropy+iccp`` (loosely coupled): every ``--stride`` fixes the
last ``--n-fixes`` fixes (each the mean of ``--fix-every`` rows) are matched with the
dense matcher (or paper A's iso-point chains on the map refined to 0.005° nodes, or
paper B's entropy coarse search and ICCP fine match, the reading bias marginalised) on
the filter-corrected track (:mod:`jaxgrav.cli.navigate_loose`); accepted fixes update
the 13-state INS error Kalman filter (:func:`jaxgrav.navigate.navigate_loose`).
``dense`` runs :data:`jaxgrav.navigate.DENSE_LOOP` by default: 2 h segments (60 fixes)
every hour (the first fix after 2 h; ``--first-n-fixes 30``: after 1 h, on the last 30
fixes), the matcher told the segment's Eötvös and stretch errors given its offset
(``--segment-error conditional``), its offsets weighed by the filter's prior
(``--fix-prior``) and its lattice's cell; ``--segment-error markov`` is the old loop
(1 h segments, the Eötvös error told as a Markov error). A log too short for its first
segment is written as the INS with the filter's growing σ, and a warning says that no
fix could be made (so does one on which no fix was accepted). The readings are
Eötvös-corrected with the filter's velocity, the one rule of the navigation loop. Where
the log leaves the map, the fixes stop (event 2) and the solution continues on the INS
with a growing σ.

The default is ``--method ukf``: it aids from the first reading and predicts through
gaps. On the documented 12 h patrols with a 3 mGal map error (``docs/voyages.md``, 1000
patrols, seeds 0 / 1) it ends the last hour at 0.105 / 0.121 × the free INS's error;
``--method dense`` ends it at 0.088 / 0.083 and holds the error flat from hour to hour,
but makes its first fix only after 2 h (``--first-n-fixes 30``: 1 h) and needs every row.

``--method ukf|ekf|gsf|rbpf|pmf`` (tightly coupled, :func:`jaxgrav.navigate.navigate_tight`):
every reading updates the INS error filter; the readings are Eötvös-corrected with the
INS velocity and the Eötvös effect of its velocity error is part of the measurement;
``--map-error`` adds a second-order Gauss–Markov map-error state of that σ and L
(``pmf``: first order, per grid cell).
``rbpf`` is the Rao–Blackwellised particle filter (``--particles``, default 500;
``--seed`` for its draws); ``pmf`` the point-mass filter on an adaptive grid
(over-confident with a navigation-grade INS: one Gaussian velocity for the whole grid
cannot hold what each cell's Eötvös residual says; see ``docs/voyages.md``).
Readings that are missing or off the map are skipped and flagged row by row.

Times (:mod:`jaxgrav.time_steps`): jitter up to 10 % of the step is absorbed; the tight
filters predict through gaps up to ``--max-gap`` s (the INS interpolated, no reading),
the loose loop needs every row. The output has the log's own rows.
"""

import sys

import jax
import numpy as np

from jaxgrav import executables
from jaxgrav._io import check_outputs
from jaxgrav.cli.filter_checks import (
    MIN_PARTICLES,
    check_particles,
    check_positive,
    check_sigma_pos,
    check_sigma_vel,
    extent_text,
    gradient_at_ins,
    information_warning,
    offset_warning,
)
from jaxgrav.cli.inputs import (
    add_map_error_var_option,
    add_missing_option,
    add_track_option,
    check_missing_option,
    check_out_format,
    kept_columns,
    read_track,
    track_map,
    whole_number,
)
from jaxgrav.cli.navigate_loose import add_dense_loop_options, check_fix_blocks, run_loose
from jaxgrav.cli.sanity import (
    check_positions,
    check_readings,
    implausible_rows,
    innovation_check,
)
from jaxgrav.cli.simulate import check_map_error_size, check_seed
from jaxgrav.filters import STATUS_FILTER, map_error_state, status_messages_filter
from jaxgrav.geodesy import eotvos_jit
from jaxgrav.navigate import (
    DENSE_LOOP,
    LOOSE_MATCHERS,
    TIGHT_METHODS,
    TightConfig,
    navigate_tight,
)
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import INS_GRADES
from jaxgrav.sim.ins import GRAV
from jaxgrav.sim.trajectory import Track
from jaxgrav.sim.voyage_log import Voyage
from jaxgrav.time_steps import at_rows, on_steps, time_steps
from jaxgrav.tracks import write_track_csv

__all__ = ["DEFAULT_PARTICLES", "LOOSE_DEFAULTS", "METHODS", "PMF_WARNING", "add_parser",
           "check_log", "cmd_navigate", "nis_warning"]

METHODS = (*LOOSE_MATCHERS, *TIGHT_METHODS)
"""Navigation methods of the command: loosely coupled with a matcher of
:data:`jaxgrav.navigate.LOOSE_MATCHERS`, or tightly coupled with a filter of
:data:`jaxgrav.navigate.TIGHT_METHODS`."""

_MAP_MARGIN_M = 50e3
"""Map kept around the INS log (m): the navigation error and the matchers' searches."""

DEFAULT_PARTICLES = 500
"""Particles of ``--method rbpf`` without ``--particles``."""

LOOSE_DEFAULTS = {"fix_every": 12, "n_fixes": 30}
"""``--fix-every`` and ``--n-fixes`` of the loosely coupled methods when not given
(``--stride`` defaults to ``--n-fixes``); ``--method dense`` takes
:data:`~jaxgrav.navigate.DENSE_LOOP`'s segments unless ``--segment-error markov``."""


def add_parser(sub):
    """Add the ``navigate`` sub-command to an ``argparse`` sub-parser set."""
    p = sub.add_parser("navigate",
                       help="map-aided navigation of an INS log (loosely or tightly coupled)")
    p.add_argument("--map", default="ryukyu", help="anomaly map: NetCDF grid or shipped map")
    p.add_argument("--var", default=None)
    add_track_option(p, "INS log CSV: t, lat, lon, v_east, v_north, gravity (raw, mGal)")
    p.add_argument("--method", choices=METHODS, default="ukf",
                   help="ukf (default), ekf, gsf, rbpf, pmf: every reading into the INS error "
                        "filter (tightly coupled; pmf's 1-sigma is over-confident with the "
                        "navigation INS); dense, chains, entropy+iccp: hourly fixes of "
                        "that "
                        "matcher into the filter (loosely coupled; --fix-every, --n-fixes, "
                        "--stride)")
    p.add_argument("--particles", type=whole_number, default=None,
                   help=f"particles of --method rbpf, at least {MIN_PARTICLES} (default "
                        f"{DEFAULT_PARTICLES})")
    p.add_argument("--seed", type=int, default=None, help="seed of --method rbpf's draws")
    p.add_argument("--out", required=True, help="navigation CSV (see jaxgrav navigate docs)")
    p.add_argument("--eotvos-corrected", action="store_true",
                   help="the gravity column is already Eötvös-corrected with the INS velocity")
    p.add_argument("--ins", choices=sorted(INS_GRADES), default="navigation",
                   help="the filter's INS error model: navigation (0.01 deg/h, 25 ug, "
                        "default) or strategic (0.001 deg/h, 10 ug)")
    p.add_argument("--sigma-pos", type=float, default=354.0,
                   help="initial position error, 1-σ per axis (m)")
    p.add_argument("--sigma-vel", type=float, default=0.035,
                   help="initial velocity error, 1-σ per axis (m/s)")
    p.add_argument("--noise", type=float, default=1.0, help="reading noise, 1-σ (mGal)")
    p.add_argument("--map-error", type=float, default=None, metavar="SIGMA",
                   help="the map's error told to the matcher or filter, 1-σ (mGal, default 3 "
                        "unless --map-error-var)")
    p.add_argument("--map-error-length", type=float, default=10000.0, metavar="L",
                   help="its correlation length (m, default 10000)")
    add_map_error_var_option(p)
    p.add_argument("--fix-every", type=whole_number, default=None,
                   help=f"loosely coupled methods: rows per fix (default "
                        f"{LOOSE_DEFAULTS['fix_every']})")
    p.add_argument("--n-fixes", type=whole_number, default=None,
                   help=f"loosely coupled methods: fixes per segment (>= 5, default "
                        f"{LOOSE_DEFAULTS['n_fixes']}; dense {DENSE_LOOP['n_fixes']})")
    p.add_argument("--stride", type=whole_number, default=None,
                   help="loosely coupled methods: fixes between segment ends (default = "
                        f"--n-fixes: consecutive; dense {DENSE_LOOP['stride']})")
    p.add_argument("--first-n-fixes", type=whole_number, default=None,
                   help="loosely coupled methods: the segment ends before --n-fixes fixes "
                        "exist match the last N fixes (5 to --n-fixes; default none: the "
                        "first fix waits for a whole segment, 2 h with dense)")
    add_dense_loop_options(p, "dense")
    add_missing_option(p)
    p.add_argument("--max-gap", type=float, default=60.0,
                   help="longest gap between rows (s) the tightly coupled filters predict "
                        "through, the INS interpolated over the missing rows (default 60); "
                        "the loosely coupled methods need every row")
    p.add_argument("--max-speed", type=float, default=30.0,
                   help="largest plausible speed of the platform (m/s, default 30)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=cmd_navigate)
    return p


def check_log(track, grid, max_gap, max_speed, gaps=None, map_name="map"):
    """Check an INS log for navigation; returns ``(steps, n_missing, n_off_map)``.

    ``steps`` is the log's :class:`~jaxgrav.time_steps.TimeSteps`. Raises ValueError
    naming the file, the line and the value: times not on a regular step (jitter up to
    10 % of it, :func:`~jaxgrav.time_steps.time_steps`), a gap longer than
    ``max_gap`` or, when ``gaps`` gives the reason, any gap; a speed above
    ``max_speed``, a position jump (:func:`~jaxgrav.cli.sanity.check_positions`), a log
    with no row on the map (``map_name``, e.g. ``--map 'M.nc'``).
    """
    label = f"track file {track.path!r}"
    t = np.asarray(track["t"])
    if t.size < 2:
        raise ValueError(f"{label} has {t.size} row; navigation needs at least 2")
    steps = time_steps(t, label, max_gap=max_gap, max_step=max_gap, gaps=gaps, line=track.line)
    speed = np.hypot(track["v_east"], track["v_north"])
    fast = np.flatnonzero(~(speed <= max_speed))
    if fast.size:
        i = int(fast[0])
        raise ValueError(f"{label}, line {track.line(i)}: speed {speed[i]:.3g} m/s is "
                         f"implausible for the platform (--max-speed {max_speed:g} m/s; "
                         f"{fast.size} such row(s))")
    on_map = np.isfinite(np.asarray(grid.sample(track["lat"], track["lon"])))
    if not on_map.any():
        raise ValueError(f"{label}: no row lies on the {map_name} ({extent_text(grid)})")
    check_positions(track, where=label)
    return steps, int(np.sum(~np.isfinite(track["gravity"]))), int(np.sum(~on_map))


def _method_options(args):
    """Options that the method does not use: ``--particles`` (rbpf only) is refused;
    returns the warning for ``--fix-every``, ``--n-fixes``, ``--stride`` given to a
    tightly coupled method (None if not). Fills in the defaults."""
    for name in ("particles", "seed"):  # an unused --seed was dropped without a word
        if getattr(args, name) is not None and args.method != "rbpf":
            raise ValueError(f"--{name} is for --method rbpf; got --method {args.method}")
    check_missing_option(args)
    for name in ("segment_error", "fix_prior", "shape_update", "reacquire_after",
                 "reacquire_inflation"):
        if getattr(args, name) is not None and args.method != "dense":
            raise ValueError(f"--{name.replace('_', '-')} is for --method dense; got --method "
                             f"{args.method}")
    loose = [f"--{k.replace('_', '-')}" for k in ("fix_every", "n_fixes", "stride",
                                                   "first_n_fixes")
             if getattr(args, k) is not None]
    warning = None
    if loose and args.method in TIGHT_METHODS:
        warning = (f"warning: {', '.join(loose)} set the fixes of the loosely coupled methods "
                   f"({', '.join(LOOSE_MATCHERS)}); --method {args.method} uses every reading "
                   "and ignores them")
    args.particles = DEFAULT_PARTICLES if args.particles is None else args.particles
    args.seed = 0 if args.seed is None else args.seed
    # dense: DENSE_LOOP's segments (2 h every hour) unless markov or --n-fixes is given
    dense = args.method == "dense" and args.segment_error != "markov" and args.n_fixes is None
    for k, v in LOOSE_DEFAULTS.items():
        v = DENSE_LOOP.get(k, v) if dense else v
        setattr(args, k, v if getattr(args, k) is None else getattr(args, k))
    if args.stride is None:
        args.stride = DENSE_LOOP["stride"] if dense else args.n_fixes
    return warning


def cmd_navigate(args):
    """Run ``navigate`` (see the module notes)."""
    unused = _method_options(args)
    check_positive("--sigma-pos", args.sigma_pos, "m")
    check_sigma_pos(args.sigma_pos)
    check_positive("--sigma-vel", args.sigma_vel, "m/s")
    check_sigma_vel(args.sigma_vel)
    check_positive("--noise", args.noise, "mGal")
    if args.map_error is not None:
        check_positive("--map-error", args.map_error, "mGal", allow_zero=True)
        check_map_error_size(args.map_error)
    check_positive("--map-error-length", args.map_error_length, "m")
    check_positive("--max-gap", args.max_gap, "s")
    check_positive("--max-speed", args.max_speed, "m/s")
    check_seed(args.seed)
    check_particles(args.particles)
    for name, value in (("--fix-every", args.fix_every), ("--n-fixes", args.n_fixes),
                        ("--stride", args.stride)):
        if value < 1:
            raise ValueError(f"{name} must be a positive number of fixes/rows; got {value}")
    if args.n_fixes < 5:
        raise ValueError(f"--n-fixes must be at least 5 (a shorter segment cannot be matched "
                         f"reliably); got {args.n_fixes}")
    if args.stride > args.n_fixes:
        raise ValueError(f"--stride must be at most --n-fixes {args.n_fixes}; got {args.stride}")
    if args.first_n_fixes is not None and not 5 <= args.first_n_fixes <= args.n_fixes:
        raise ValueError(f"--first-n-fixes must be from 5 to --n-fixes {args.n_fixes}; got "
                         f"{args.first_n_fixes}")
    check_outputs([args.out], force=args.force, names=["--out"],
                  inputs={"--track": args.track, "--map": args.map})
    check_out_format(args.out, "CSV")
    if unused is not None:
        print(unused, file=sys.stderr)
    track = read_track(args, ("t", "lat", "lon", "v_east", "v_north", "gravity"),
                       allow_nan=("gravity",))
    if not np.isfinite(track["gravity"]).any():  # ran, exit 0: the INS written back, no aid
        raise ValueError(f"--track {track.path!r}: column "
                         f"{track.renamed.get('gravity', 'gravity')!r} has no readings (all "
                         f"{track['gravity'].size} cells empty or NaN); navigate needs at "
                         "least one (mGal)")
    grid, sigma_var = track_map(args, track, _MAP_MARGIN_M,  # missing nodes kept as a mask
                                sigma_given=args.map_error is not None)
    args.map_error = (sigma_var if sigma_var is not None
                      else 3.0 if args.map_error is None else args.map_error)
    steps, n_missing, n_off = check_log(
        track, grid, args.max_gap, args.max_speed, map_name=f"map --map {str(args.map)!r}",
        gaps=f"--method {args.method} needs every row (a tightly coupled --method, e.g. ukf, "
             "predicts through gaps)" if args.method in LOOSE_MATCHERS else None)
    log = Track(*(np.asarray(track[k]) for k in ("t", "lat", "lon", "v_east", "v_north")))
    gravity = np.asarray(track["gravity"])
    if args.method in LOOSE_MATCHERS:
        check_fix_blocks(gravity, args.fix_every, track.path)
    e_ins = np.asarray(eotvos_jit(log.lat, log.v_east, log.v_north))
    expected = np.asarray(grid.sample(log.lat, log.lon, "bicubic"))
    check_readings(gravity, expected, args.noise, column="gravity", line=track.line,
                   where=f"--track {track.path!r}",
                   correction=0.0 if args.eotvos_corrected else e_ins)
    if args.method in TIGHT_METHODS:  # its bias state allows a constant offset of σ_b
        level = offset_warning(gravity + (0.0 if args.eotvos_corrected else e_ins), expected,
                               INS_GRADES[args.ins].gravimeter_sigma, args.map_error, args.noise)
        if level is not None:
            print(f"warning: {level}", file=sys.stderr)
    if args.eotvos_corrected:  # back to the raw reading: the loop corrects it itself
        gravity = gravity - e_ins
    # the log on its regular step: jitter gone, gaps (tight filters) interpolated
    ins = Track(log.t[0] + steps.dt * np.arange(steps.n_steps), on_steps(steps, log.lat),
                on_steps(steps, log.lon, period=360.0), on_steps(steps, log.v_east),
                on_steps(steps, log.v_north))
    voyage = Voyage(ins, on_steps(steps, gravity, fill=np.nan))
    if args.method in TIGHT_METHODS:
        _tight(args, voyage, grid, n_missing, n_off, track, steps)
    else:
        run_loose(args, log, voyage, grid, track, steps, n_missing, n_off)


@jax.jit
def _tight_program(grid, voyage, cfg, key):
    """The tightly coupled filter as one program, the map's spline prepared inside it."""
    return navigate_tight(prepare_map(grid), voyage, cfg, key)


def _tight(args, voyage, grid, n_missing, n_off, track, steps):
    """Tightly coupled: the filter on every reading, and its CSV."""
    order = 1 if args.method == "pmf" else 2  # the point-mass filter's is per cell
    told = (map_error_state(args.map_error, args.map_error_length, order=order)
            if args.map_error > 0 else None)
    missing = check_missing_option(args)
    cfg = TightConfig(ins=INS_GRADES[args.ins], sigma_pos_m=args.sigma_pos,
                      sigma_vel=args.sigma_vel, noise_mgal=args.noise, map_error=told,
                      method=args.method, n_particles=args.particles, pmf_missing=missing)
    res = executables.call(_tight_program, grid, voyage, cfg, jax.random.PRNGKey(args.seed))
    cov = np.asarray(res.cov_north_east)
    sd = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    x, sigma = np.asarray(res.error_estimate), np.asarray(res.sigma)
    innovation_sigma = np.sqrt(np.asarray(res.innovation_var))
    # the rows of every block of readings whose innovations fail chi-squared, as filter does
    status = np.asarray(res.status) | np.where(
        implausible_rows(res.innovation, innovation_sigma), STATUS_FILTER["implausible_fit"], 0)
    # the log's rows (not the gaps' predicted ones), with the log's own times
    out = at_rows(steps, {
        "lat": res.nav.lat, "lon": res.nav.lon, "sigma_north": sd[:, 0],
        "sigma_east": sd[:, 1], "cov_north_east": cov[:, 0, 1], "v_east": res.nav.v_east,
        "v_north": res.nav.v_north, "status": status, "innovation": res.innovation,
        "innovation_sigma": innovation_sigma,
        "gravimeter_bias": x[:, GRAV], "sigma_gravimeter_bias": sigma[:, GRAV]})
    write_track_csv(args.out, kept_columns(track, {"t": np.asarray(track["t"]), **out}),
                    force=args.force)
    status, innovation, innovation_sigma = (out[k] for k in ("status", "innovation",
                                                             "innovation_sigma"))
    flags = np.bitwise_or.reduce(status)
    skipped = STATUS_FILTER["gated"] | STATUS_FILTER["covariance_failed"]
    used = np.isfinite(innovation) & (status & skipped == 0)
    print(f"wrote {args.out}: {status.size} rows, {int(used.sum())} reading(s) used "
          f"by the {args.method} filter; {n_missing} missing reading(s) skipped, {n_off} "
          f"row(s) without a map value at the INS position; "
          + (f"missing map nodes read as {missing}; " if args.method == "pmf"
             and grid.n_missing else "") + "flags seen: "
          f"{', '.join(status_messages_filter(flags)) or 'none'}"
          f"; {steps.describe()}")
    fit_warning = nis_warning(innovation, innovation_sigma)
    read = np.isfinite(np.asarray(voyage.gravity))
    lat, lon = np.asarray(voyage.ins.lat)[read], np.asarray(voyage.ins.lon)[read]
    flat = information_warning(*gradient_at_ins(grid, lat, lon),
                               float(np.hypot(args.noise, args.map_error)),
                               max(args.sigma_pos, float(np.max(sd))))
    pmf = PMF_WARNING if args.method == "pmf" and args.ins == "navigation" else None
    for warning in (flat, fit_warning, pmf):
        if warning is not None:
            print(f"warning: {warning}", file=sys.stderr)


PMF_WARNING = ("pmf's 1-sigma is over-confident with a navigation-grade INS (position NEES 21 "
               "on the documented 100 patrols, 2 expected: one Gaussian velocity for the "
               "whole grid); use --method ukf or rbpf for a 1-sigma to trust")  # docs/voyages.md


def nis_warning(innovation, innovation_sigma):
    """The tight filter's innovation check (:func:`~jaxgrav.cli.sanity.innovation_check`)
    as navigate's warning, its advice naming ``--noise``; None when the fit is plausible."""
    return innovation_check(innovation, innovation_sigma, noise_option="--noise")[2]
