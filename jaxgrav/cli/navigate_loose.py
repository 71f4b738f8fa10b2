"""``jaxgrav navigate``'s loosely coupled methods (``dense``, ``chains``, ``entropy+iccp``):
the loop on the log, its CSV and its summary line (see :mod:`jaxgrav.cli.navigate`).

``chains`` searches the nodes of the map refined to
:data:`~jaxgrav.match.sizing.CHAIN_NODE_DEG` (:func:`~jaxgrav.match.sizing.chain_grid`),
its displacement stencil sized for the log's fastest row between fixes and its window
fixed at :data:`~jaxgrav.navigate.CHAIN_REACH_M` about each fix.
"""

import argparse
import math
import sys

import jax
import numpy as np

from jaxgrav.cli.inputs import kept_columns, whole_number
from jaxgrav.match.sizing import chain_grid
from jaxgrav.navigate import FIX_EVENTS, SEGMENT_ERRORS, loose_config, navigate_loose
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import INS_GRADES
from jaxgrav.tracks import write_track_csv

__all__ = ["add_dense_loop_options", "check_fix_blocks", "first_fix_rows", "no_fix_warning",
           "reacquire_options", "run_loose"]


def add_dense_loop_options(parser, method):
    """``--segment-error``, ``--[no-]fix-prior``, ``--[no-]shape-update``,
    ``--reacquire-after`` and ``--reacquire-inflation``: the dense loop's settings, as
    ``navigate --method dense`` and ``montecarlo --method voyage-dense`` (the ``method``
    their help names) take them."""
    parser.add_argument("--segment-error", choices=SEGMENT_ERRORS, default=None,
                        help=f"{method}: how the loop tells the matcher the filter's own error: "
                             "conditional (default: the segment's Eotvos and stretch errors "
                             "given its offset, 2 h segments every hour), linear, or markov "
                             "(the old loop: 1 h segments, a Markov error at the Schuler length)")
    parser.add_argument("--fix-prior", action=argparse.BooleanOptionalAction, default=None,
                        help=f"{method}: weigh the offsets by the filter's prior (default on, "
                             "off with --segment-error markov)")
    parser.add_argument("--shape-update", action=argparse.BooleanOptionalAction, default=None,
                        help=f"{method}: after an accepted fix the segment's readings update the "
                             "rest of the INS error state given the fix (default on, off with "
                             "--segment-error markov)")
    parser.add_argument("--reacquire-after", type=whole_number, default=None, metavar="N",
                        help=f"{method}: after N fixes in a row rejected on the window's edge or "
                             "for not fitting the segment, widen the filter's covariance by "
                             "--reacquire-inflation at each further one until a fix is "
                             "accepted (default 1; 0: never; never with --segment-error markov)")
    parser.add_argument("--reacquire-inflation", type=float, default=None, metavar="X",
                        help=f"{method}: the covariance's factor of --reacquire-after (>= 1, "
                             "default 16; no wider than the matcher's widest window)")


def reacquire_options(args, never=None):
    """The re-acquisition settings of ``--reacquire-after`` / ``--reacquire-inflation`` as
    :class:`~jaxgrav.navigate.LooseConfig` fields (only those given; ``--reacquire-after
    0`` becomes ``never``: None for ``loose_config``, 0 for ``voyage_builder``).
    ValueError naming the option for a negative count, an inflation below 1 or not
    finite."""
    out = {}
    if args.reacquire_after is not None:
        if args.reacquire_after < 0:
            raise ValueError(f"--reacquire-after must be a number of failed fixes in a row, 1 "
                             f"or more (0: never); got {args.reacquire_after}")
        out["reacquire_after"] = args.reacquire_after or never
    if args.reacquire_inflation is not None:
        x = args.reacquire_inflation
        if not (math.isfinite(x) and x >= 1.0):
            raise ValueError(f"--reacquire-inflation must be a finite factor >= 1 (the "
                             f"filter's covariance is multiplied by it); got {x!r}")
        out["reacquire_inflation"] = float(x)
    return out


def run_loose(args, log, voyage, grid, track, steps, n_missing, n_off):
    """The loosely coupled loop over the log, its CSV (``args.out``) and summary line.

    ``log`` is the log's Track (its own rows), ``voyage`` the log on its regular step
    (raw readings), ``grid`` the map cropped to the log, ``steps`` the log's
    :class:`~jaxgrav.time_steps.TimeSteps`; ``n_missing``, ``n_off`` are counted for the
    summary.
    """
    chains = args.method == "chains"
    nav_map = chain_grid(grid) if chains else grid
    # chains: the largest distance between fixes sizes the search's displacement stencil
    step = (float(np.max(np.hypot(log.v_east, log.v_north))) * args.fix_every * steps.dt
            if chains else None)
    loop = {k: getattr(args, k) for k in ("segment_error", "fix_prior", "first_n_fixes",
                                          "shape_update")
            if getattr(args, k, None) is not None} | reacquire_options(args)
    cfg = loose_config(INS_GRADES[args.ins], args.map_error, args.map_error_length, args.noise,
                       matcher=args.method, grid=nav_map, step_m=step,
                       sigma_pos_m=args.sigma_pos, sigma_vel=args.sigma_vel,
                       fix_every=args.fix_every, n_fixes=args.n_fixes, stride=args.stride,
                       **loop)
    # not through executables: the loop's kept program crashes XLA:CPU when loaded
    # (jaxlib 0.10.2; its trial never passes), so keeping it would only cost a compile.
    # chains read the refined map's nodes: no spline to prepare
    res = navigate_loose(nav_map, voyage, cfg) if chains else _loose(grid, voyage, cfg)
    _write(args, log, res, cfg, track)
    n = len(voyage.ins.t)
    # the segment ends within the log (the last, padded one may fall beyond it)
    events = np.asarray(res.fix_event)[_end_rows(cfg, res.fix_event.shape[0]) < n]
    counts = ", ".join(f"{int(np.sum(events == k))} {FIX_EVENTS[k].split(':')[0]}"
                       for k in FIX_EVENTS if np.any(events == k))
    print(f"wrote {args.out}: {n} rows, {events.size} segment ends ({counts or 'none'}); "
          f"{n_missing} missing reading(s) skipped, {n_off} row(s) off the map (not aided)"
          f"; {steps.describe()}")
    warning = no_fix_warning(cfg, n, events)
    if warning is not None:
        print(f"warning: {warning}", file=sys.stderr)


def _end_rows(cfg, n_ends):
    """The rows at which the loop's segment ends fall (the fix applies from there)."""
    return (np.arange(n_ends) + 1) * cfg.stride * cfg.fix_every


def first_fix_rows(cfg):
    """Rows a log needs beyond the first row for its first fix: the first segment end whose
    segment (``first_n_fixes`` or ``n_fixes`` fixes of ``fix_every`` rows) is complete."""
    first = cfg.first_n_fixes or cfg.n_fixes
    return -(-first // cfg.stride) * cfg.stride * cfg.fix_every


def no_fix_warning(cfg, n_rows, events):
    """The warning for a log on which no fix was accepted (None if one was): too short for
    its first segment, or every segment end not matched or rejected (the counts).

    ``events`` are the fix events of the segment ends within the log."""
    if np.any(events == 0):
        return None
    need = first_fix_rows(cfg)
    if n_rows <= need:
        first = cfg.first_n_fixes or cfg.n_fixes
        return (f"no fix could be made: the log has {n_rows} rows and its first segment "
                f"({first} fixes of --fix-every {cfg.fix_every} rows, ending at a segment end "
                f"every --stride {cfg.stride} fixes) needs more than {need}; the output is the "
                "INS with the filter's growing 1-sigma, not aided"
                + ("" if cfg.first_n_fixes else "; --first-n-fixes N matches the last N fixes "
                   "at the segment ends before a whole segment"))
    counts = ", ".join(f"{int(np.sum(events == k))} {FIX_EVENTS[k]}" for k in FIX_EVENTS
                       if np.any(events == k))
    return (f"no fix was accepted ({counts}); the output is the INS with the filter's "
            "growing 1-sigma, not aided")


@jax.jit
def _loose(grid, voyage, cfg):
    """The loosely coupled loop as one program, the map's spline prepared inside it."""
    return navigate_loose(prepare_map(grid), voyage, cfg)


def check_fix_blocks(gravity, fix_every, path):
    """The loose loop averages ``--fix-every`` rows into a fix and does not match a
    segment with a missing one: refuse a log where most blocks miss a reading (a reading
    every few rows: no segment was ever matched, exit 0), warn where some do; refuse a
    block longer than the log (``--fix-every 1e9`` ended in NumPy's "Mean of empty slice"
    and an out-of-memory error for 217 TB)."""
    if fix_every > len(gravity):
        raise ValueError(f"--fix-every {fix_every} rows is longer than --track {path!r} "
                         f"({len(gravity)} rows): no fix could be averaged; expected at most "
                         f"{len(gravity)} rows a fix")
    m = len(gravity) // fix_every * fix_every
    holed = ~np.all(np.isfinite(gravity[:m].reshape(-1, fix_every)), axis=1)
    if holed.mean() > 0.5:
        raise ValueError(f"track file {path!r}: {100 * holed.mean():.0f} % of the blocks of "
                         f"--fix-every {fix_every} rows miss a reading, and a segment with one "
                         "is not matched by the loosely coupled methods; give a reading on "
                         "every row, or use a tightly coupled --method (ukf, pmf ...)")
    if holed.any():
        print(f"warning: {int(holed.sum())} of {holed.size} blocks of --fix-every {fix_every} "
              "rows miss a reading; the segments holding one are not matched", file=sys.stderr)


def _write(args, ins, res, cfg, track):
    """The navigation CSV: every row, fix columns on the rows that end a segment."""
    n = len(ins.t)
    sd = np.sqrt(np.diagonal(np.asarray(res.cov_north_east), axis1=1, axis2=2))
    rows = _end_rows(cfg, res.fix_event.shape[0])
    keep = rows < n
    fix = {k: np.full(n, np.nan) for k in ("fix_event", "fix_status", "fix_north", "fix_east")}
    fix["fix_event"][rows[keep]] = np.asarray(res.fix_event)[keep]
    fix["fix_status"][rows[keep]] = np.asarray(res.fix_status)[keep]
    fix["fix_north"][rows[keep]] = np.asarray(res.fix_offset_m)[keep, 0]
    fix["fix_east"][rows[keep]] = np.asarray(res.fix_offset_m)[keep, 1]
    write_track_csv(args.out, kept_columns(track, {
        "t": ins.t, "lat": res.nav.lat, "lon": res.nav.lon, "sigma_north": sd[:, 0],
        "sigma_east": sd[:, 1], "cov_north_east": np.asarray(res.cov_north_east)[:, 0, 1],
        "v_east": res.nav.v_east, "v_north": res.nav.v_north, **fix}), force=args.force)
