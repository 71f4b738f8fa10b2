"""``jaxgrav sample``: a map's values along a track, the track's columns passed through.

Wire into :mod:`jaxgrav.cli` with ``add_parser(sub)`` (called by
:func:`jaxgrav.cli.match.add_parsers`). Rows without a position (a GPS dropout: empty
``lat``/``lon`` cells) are kept with an empty sampled cell and a warning; they refused
the whole file ("column 'lat' ... must be complete"), as ``match`` and the filters,
which need every position, still do.
"""

import sys

import numpy as np

from jaxgrav._io import check_outputs
from jaxgrav.cli.filter_checks import check_on_map
from jaxgrav.cli.inputs import add_track_option, check_out_format, read_track, track_map
from jaxgrav.tracks import write_track_csv

__all__ = ["add_parser", "cmd_sample"]


def add_parser(sub):
    """Add the ``sample`` sub-command to an ``argparse`` set."""
    s = sub.add_parser("sample", help="sample a map along a track CSV")
    s.add_argument("--map", required=True, help="NetCDF grid with lat/lon coordinates")
    s.add_argument("--var", default=None, help="variable to read when the file has several")
    add_track_option(s, "CSV with lat, lon columns (degrees; a row without them is kept, "
                        "its sampled cell empty)")
    s.add_argument("--out", required=True, help="output CSV (track columns + sampled column)")
    s.add_argument("--method", choices=("bilinear", "bicubic"), default="bicubic")
    s.add_argument("--column", default="map",
                   help="name of the added column, not one the track already has (default map)")
    s.add_argument("--force", action="store_true", help="overwrite an existing output")
    s.set_defaults(func=cmd_sample)
    return s


def cmd_sample(args):
    """Run ``jaxgrav sample``."""
    if not args.column.strip():
        raise ValueError(f"--column must be a non-empty column name; got {args.column!r}")
    check_outputs([args.out], force=args.force, names=["--out"],
                  inputs={"--track": args.track, "--map": args.map})
    check_out_format(args.out, "CSV")
    track = read_track(args, required=("lat", "lon"), allow_nan=("lat", "lon"))
    cols = track.columns()
    taken = {c.lower(): c for c in (*cols, *track.renamed.values())}
    if args.column.strip().lower() in taken:
        raise ValueError(f"--column {args.column!r} is the name of a column of --track "
                         f"{str(args.track)!r} ({taken[args.column.strip().lower()]!r}); "
                         "expected a new name (the track's columns are kept)")
    placed = np.isfinite(track["lat"]) & np.isfinite(track["lon"])
    if not placed.any():
        raise ValueError(f"--track {str(args.track)!r} has no row with both a latitude and a "
                         f"longitude ({placed.size} row(s)); nothing to sample")
    at = {"lat": track["lat"][placed], "lon": track["lon"][placed]}
    grid, _ = track_map(args, at, 0.0, field=None,  # any map: nT was refused as not mGal
                        bicubic=args.method == "bicubic")
    rows = np.flatnonzero(placed)
    # off the map: was "point (lat=…) is outside the grid", naming neither file nor line
    check_on_map(grid, at["lat"], at["lon"], f"--track {str(args.track)!r}", args.map,
                 line=lambda i: track.line(int(rows[i])))
    values = np.full(placed.size, np.nan)
    values[placed] = np.asarray(grid.sample(at["lat"], at["lon"], args.method, strict=True))
    cols[args.column] = values
    write_track_csv(args.out, cols, force=args.force)
    n = int(placed.sum())
    units = f"in {grid.units}" if grid.units else "no units declared"  # mGal converted?
    print(f"wrote {args.out}: {n} sample{'s' * (n != 1)} of "
          f"{grid.name or 'map'} ({units}, {args.method})")
    if not placed.all():
        print(f"warning: {int((~placed).sum())} of {placed.size} rows have no position (first "
              f"on line {track.line(int(np.flatnonzero(~placed)[0]))}); their {args.column!r} "
              "cells are left empty", file=sys.stderr)
    masked = placed & ~np.isfinite(values)
    if masked.any():
        print(f"warning: {int(masked.sum())} of {values.size} points lie in map cells with a "
              f"missing (NaN) node (first on line {track.line(int(np.flatnonzero(masked)[0]))}); "
              f"their {args.column!r} cells are left empty", file=sys.stderr)
