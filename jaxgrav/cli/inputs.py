"""What every command reads: the track file (with ``--columns``) and the map a track needs.

One reader for tracks (:func:`jaxgrav.tracks.read_track_csv`) and one for maps
(:func:`jaxgrav.datasets.map_for_track`) behind the commands ``match``, ``sample``,
``filter``, ``navigate`` and ``dov``: the same column aliases, ``--columns NAME=COLUMN``
mapping, ISO times and text columns everywhere; global 0–360 maps are recentred when
their seam cuts the track. Missing (NaN) map nodes, such as land on a marine grid, are a
mask: every cell with a missing corner interpolates to NaN
(:func:`jaxgrav.interp.bicubic_coefficients`), so candidate tracks, sigma points,
particles and point-mass cells that touch one are masked and flagged by the methods
(match status bit 8192, filter status ``off_map``), never a NaN result. The map is
refused only when the track's own region is unusable: more than :data:`MAX_MISSING` of
its nodes missing.
"""

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from jaxgrav.datasets import map_for_track
from jaxgrav.filters.pmf_cells import MISSING
from jaxgrav.track_times import MAX_EPOCH_SECONDS, epoch_unit, epoch_year, time_units
from jaxgrav.track_units import declared_unit, unit_of
from jaxgrav.tracks import KNOWN_COLUMNS, parse_columns, read_track_csv

__all__ = [
    "FIELD_UNITS",
    "MAX_COUNT",
    "MAX_MISSING",
    "STDIN_HELP",
    "add_columns_option",
    "add_map_error_var_option",
    "add_missing_option",
    "add_track_option",
    "check_bicubic_nodes",
    "check_map_field",
    "check_missing_option",
    "check_out_format",
    "fill_map_error_length",
    "kept_columns",
    "map_error_args",
    "read_track",
    "track_map",
    "track_time_units",
    "whole_number",
]

OUT_FORMATS = {".json": "JSON", ".csv": "CSV", ".nc": "NetCDF", ".nc4": "NetCDF",
               ".grd": "NetCDF", ".png": "PNG", ".pdf": "PDF", ".xlsx": "Excel", ".md": "Markdown",
               ".tsv": "TSV", ".tab": "TSV", ".xls": "Excel", ".h5": "HDF5", ".hdf5": "HDF5",
               ".parquet": "Parquet", ".geojson": "GeoJSON", ".kml": "KML"}
"""What a user expects in a file by its suffix (:func:`check_out_format`)."""

_SUFFIX = {"JSON": ".json", "CSV": ".csv", "NetCDF": ".nc", "Markdown": ".md"}

MAX_MISSING = 0.9
"""Largest fraction of missing (NaN) nodes accepted in the map region a track needs."""


MAX_COUNT = 10**15
"""Largest count option :func:`whole_number` reads (more than any run could use)."""

STDIN_HELP = "; '-' reads it from standard input (e.g. a pipe)"
"""The end of every ``--track`` help (:func:`add_track_option`): ``main`` reads ``-`` so."""


def add_track_option(parser, help):
    """Add ``--track`` (its ``help`` plus :data:`STDIN_HELP`) and ``--columns`` to a
    command's parser."""
    parser.add_argument("--track", required=True, help=help + STDIN_HELP)
    add_columns_option(parser)


def add_columns_option(parser):
    """Add ``--columns NAME=COLUMN,...`` to a command's parser."""
    parser.add_argument(
        "--columns", default=None, metavar="NAME=COLUMN,...",
        help="which file columns hold the names the command reads, by header (any case) "
             "or 1-based number, e.g. --columns lat=LAT,lon=LON,gravity=FAA (headers t/time, "
             "lat/latitude, lon/longitude, h/height, v_east/ve, v_north/vn are found "
             "without it)")


def read_track(args, required, optional=(), allow_nan=()):
    """The ``--track`` file of a command, read with its ``--columns`` mapping.

    Parameters
    ----------
    args : argparse.Namespace
        With ``track`` and ``columns``.
    required, optional, allow_nan : sequence of str
        As :func:`jaxgrav.tracks.read_track_csv`.

    Returns
    -------
    TrackTable
    """
    columns = parse_columns(args.columns)
    unknown = [k for k in columns if k not in KNOWN_COLUMNS]
    if unknown:  # "foo=gravity" renamed the column; "LAT=lat" ended in a riddle
        name = unknown[0]
        raise ValueError(f"--columns {name}={columns[name]}: {name!r} is not a name the "
                         f"commands read; the names are {', '.join(KNOWN_COLUMNS)} (lower "
                         "case); COLUMN is the file's header or 1-based column number")
    track = read_track_csv(args.track, required, optional, allow_nan=allow_nan,
                           columns=columns)
    _epoch_times(track)
    if "h" in track and "h" not in required:
        _height_warning(track, args.track)
    return track


FLIGHT_HEIGHT_M = 300.0
"""Height (m) beyond which a track's ``h`` is named (a ship's deck, the geoid: < 100 m)."""


def _height_warning(track, path):
    """A warning for a track whose ``h`` column puts it far above or below the map's
    surface: the commands other than ``dov`` read the map there (an airborne survey at 5
    km was matched against the sea-level map, exit 0, in silence)."""
    h = np.asarray(track["h"], float)
    h = h[np.isfinite(h)]
    if not h.size or np.max(np.abs(h)) <= FLIGHT_HEIGHT_M:
        return
    far = float(h[np.argmax(np.abs(h))])
    print(f"warning: column {track.renamed.get('h', 'h')!r} of --track {str(path)!r} puts the "
          f"track at heights up to {far:g} m; the map is read at its own surface, not at "
          "that height (the anomaly there is smoother above, sharper below): continue the "
          "map to the track's height first (e.g. GMT grdfft -C), or drop the column if it is "
          "no height", file=sys.stderr)


def _epoch_times(track):
    """Unix times in milliseconds, microseconds or nanoseconds (a phone's or a GNSS
    logger's) read as seconds, with a warning naming the unit; ValueError for times that
    are no plausible seconds in a unit the header declares, or that mix units.

    Such times were read as seconds: ``1714564800000`` (2024 in ms) labelled the year
    56 302, its steps 1000 times too long, exit 0. The magnitude tells the unit for every
    date from 1973 to 5138, so they are converted as a header ``t (ms)`` converts them
    (a log need not be edited); a declared unit is the user's word, and not overridden.
    """
    if "t" not in track or track.time_origin is not None:  # ISO times count from the first
        return
    t = track["t"]
    unit = epoch_unit(t)
    if unit is None:
        return
    header = track.renamed.get("t", "t")
    label = f"track file {track.path!r}, column {header!r}"
    k = int(np.flatnonzero(np.isfinite(t))[0])  # the first time given
    first = np.format_float_positional(t[k], trim="-")
    declared = declared_unit("t", header)
    if declared is not None:
        raise ValueError(f"{label}: the first time, read in the header's unit "
                         f"({declared}), is {first} s, the year {epoch_year(t[k])} as a Unix "
                         "time (today's is about 1.8e9 s); check the unit in the header (e.g. "
                         f"'{unit_of(header)[0]} (ms)' for milliseconds)")
    factor, name, symbol = unit
    seconds = t * factor
    if np.nanmax(seconds) > MAX_EPOCH_SECONDS:
        i = int(np.argmax(seconds > MAX_EPOCH_SECONDS))
        raise ValueError(f"{label}: the times mix units: {first} on line {track.line(k)} is a "
                         f"Unix time in {name}, "
                         f"{np.format_float_positional(t[i], trim='-')} on line {track.line(i)} "
                         "is not; expected one unit, seconds or one declared in the header")
    print(f"warning: {label}: times such as {first} are Unix times in {name} (as seconds they "
          f"would be in the year {epoch_year(t[k])}); read as {name} since 1970-01-01 "
          f"(declare the unit in the header, e.g. '{header} ({symbol})', to silence this)",
          file=sys.stderr)
    track["t"] = seconds
    track.unix_times = True


def track_time_units(track):
    """The unit and reference of ``track["t"]`` (s) for an output's units block, and the
    first time in ISO-8601 UTC when they are Unix times (else None):
    :func:`jaxgrav.track_times.time_units`. A ``t`` of Unix seconds was labelled ``"s"``."""
    header = (track.renamed or {}).get("t", "t")
    return time_units(track["t"], origin=track.time_origin, unit=unit_of(header)[1],
                      unix=getattr(track, "unix_times", False))


FIELD_UNITS = {"gravity": "mGal", "magnetic": "nT"}
"""The units of each field's readings and maps (a map declared in other gravity or
magnetic units is converted on reading, :func:`jaxgrav.grid_files.map_units`)."""
_UNIT_NAMES = {"gravity": "a gravity unit (mGal, Gal, uGal, m s-2, gu)",
               "magnetic": "a magnetic unit (nT, uT, T)"}


def kept_columns(track, columns):
    """``columns`` (an output's, ``t`` first) with the track's text columns after ``t``
    and its other numeric columns last.

    The ISO-8601 times as given (``time``) and text columns such as a ship's name pass
    through to a command's per-row output, and so do numeric columns no command reads (a
    depth, a heading: dropped before), as the file wrote them; one whose name the output
    uses already gets ``_track`` appended.

    Parameters
    ----------
    track : TrackTable
        As read by :func:`read_track` (rows in the output's order).
    columns : dict of str to array_like
        The output's columns, ``t`` first.

    Returns
    -------
    dict of str to array_like
    """
    kept = {(k if k not in columns else f"{k}_track"): v for k, v in (track.text or {}).items()}
    cells = track.cells or {}
    extra = {(k if k not in columns else f"{k}_track"): cells[k]
             for k in (track.order or ()) if k in cells and k not in KNOWN_COLUMNS}
    first, *rest = columns
    return {first: columns[first], **kept, **{k: columns[k] for k in rest}, **extra}


def check_bicubic_nodes(grid, source, where=""):
    """ValueError naming ``source`` (e.g. ``--map 'x.nc'``) for a map with fewer than 4
    nodes along an axis (``where``: the part read, e.g. " where the track needs it"):
    bicubic interpolation needs 4 (``simulate-voyage`` ended in the interpolator's "needs
    at least 4 nodes per axis; got 2", naming no file)."""
    shape = (np.size(grid.lat), np.size(grid.lon))
    if min(shape) < 4:
        raise ValueError(f"{source} has {shape[0]} x {shape[1]} nodes (lat x lon){where}; "
                         "bicubic interpolation needs at least 4 along each axis: give a "
                         "larger map")


def track_map(args, track, margin_m, *, error_reach_m=None, sigma_given=False,
              field="gravity", bicubic=True):
    """The ``--map`` of a command, cut to what ``track`` needs, and ``--map-error-var``'s σ.

    Parameters
    ----------
    args : argparse.Namespace
        With ``map``, ``var`` and (optionally) ``map_error_var``.
    track : mapping
        With ``lat`` and ``lon`` (degrees).
    margin_m : float
        How far (m) the command's method reaches from the track.
    error_reach_m : float, optional
        With ``--map-error-var``: the nodes of the uncertainty averaged over are those
        within this distance (m) of the track's box (default ``margin_m``).
    sigma_given : bool
        ``--map-error`` was given too (refused with ``--map-error-var``: one source of σ).
    field : {"gravity", "magnetic"} or None
        What the readings measure: a map declared in the other field's units is refused
        (:func:`check_map_field`); None: not checked here.
    bicubic : bool
        The command interpolates bicubically: fewer than 4 nodes along an axis is refused.

    Returns
    -------
    grid : Grid
        The map or its region; missing (NaN) nodes kept as a mask, refused only when
        they are more than :data:`MAX_MISSING` of the region's nodes.
    sigma_var : float or None
        The RMS (map units) of the uncertainty variable over its finite nodes near the
        track (one read of the file with the map); None without ``--map-error-var``.

    Raises
    ------
    ValueError
        Both ``--map-error`` and ``--map-error-var``; a shipped map (no uncertainty); no
        such variable, another grid or negative values (:func:`jaxgrav.datasets.load_map`);
        no finite uncertainty near the track.
    """
    error_var = getattr(args, "map_error_var", None)
    if error_var is not None and sigma_given:
        raise ValueError("give either --map-error SIGMA or --map-error-var NAME (the map's "
                         "own uncertainty), not both")
    loaded = map_for_track(args.map, args.var, track["lat"], track["lon"], margin_m,
                           max_missing=MAX_MISSING, option="--map", error_var=error_var)
    grid, err = (loaded, None) if error_var is None else loaded
    if bicubic:
        check_bicubic_nodes(grid, f"--map {str(args.map)!r}", " where the track needs it")
    if field is not None:
        check_map_field(grid, field, args.map)
    if error_var is None:
        return grid, None
    reach_m = margin_m if error_reach_m is None else error_reach_m
    near = err.values_near(track["lat"], track["lon"], reach_m)
    finite = near[np.isfinite(near)]
    if finite.size == 0:
        raise ValueError(f"--map-error-var {error_var!r} of --map {str(args.map)!r} has no "
                         f"value within {reach_m / 1000:.3g} km of the track")
    return grid, float(np.sqrt(np.mean(finite**2)))


def check_map_field(grid, field, map_name):
    """ValueError when ``grid`` is declared in the other field's units (``nT`` for
    gravity readings, ``mGal`` for magnetic ones); a map without units passes, one in
    units of neither field (a geoid in ``m``, DOV in ``arcsec``) is warned of on stderr."""
    other = {u: f for f, u in FIELD_UNITS.items() if f != field}
    if grid.units in other:
        raise ValueError(f"--map {str(map_name)!r} is a {other[grid.units]} map (units "
                         f"{grid.units!r}) and the readings are {field} "
                         f"({FIELD_UNITS[field]}); give a {field} map")
    if grid.units and grid.units != FIELD_UNITS[field]:  # was read as mGal with no word
        print(f"warning: --map {str(map_name)!r} declares units {grid.units!r}, not "
              f"{_UNIT_NAMES[field]}: its values are read as {FIELD_UNITS[field]}",
              file=sys.stderr)


_COMPRESSED = (".gz", ".bz2", ".xz", ".zst", ".zip", ".7z")


def check_out_format(path, writes, option="--out"):
    """ValueError naming ``option`` when ``path``'s suffix promises another format than the
    ``writes`` one (``"JSON"``, ``"CSV"``, ``"NetCDF"`` or ``"Markdown"``): ``match --out
    result.csv`` wrote JSON into it, exit 0. Suffixes of no known format pass, and a CSV
    named ``.tsv`` is written tab-separated."""
    path = Path(path)
    if path.suffix.lower() in _COMPRESSED:  # s.csv.gz held plain text (gunzip: not gzip)
        raise ValueError(f"{option} {str(path)!r} names a compressed file, but this command "
                         f"writes plain {writes} there; give a name ending "
                         f"{_SUFFIX[writes]} (e.g. {str(path.with_suffix(''))!r}) and compress "
                         "it afterwards")
    fmt = OUT_FORMATS.get(path.suffix.lower())
    if fmt == "TSV" and writes == "CSV":  # written tab-separated (tracks.write_track_csv)
        return
    if fmt is not None and fmt != writes:
        raise ValueError(f"{option} {str(path)!r} names a{'n' if fmt[0] in 'AEIOUH' else ''} "
                         f"{fmt} file, but this command writes {writes} there; give a name "
                         f"ending {_SUFFIX[writes]}, e.g. "
                         f"{str(path.with_suffix(_SUFFIX[writes]))!r}")


def fill_map_error_length(args, used, default=10_000.0):
    """Fill ``args.map_error_length`` (None when not given) with ``default`` (m); a
    ValueError naming it when it was given while no map error uses it (``used`` false):
    ``--map-error-length 5000`` without ``--map-error`` ran on a perfect map, silently."""
    if args.map_error_length is None:
        args.map_error_length = default
    elif not used:
        raise ValueError(f"--map-error-length {args.map_error_length:g} is the correlation "
                         "length of the map's error, and no map error is given: add "
                         "--map-error SIGMA (or --map-error-var NAME where the command takes "
                         "it), or leave it out")


def map_error_args(args):
    """Validated ``--map-error`` / ``--map-error-length`` (a ValueError naming the option;
    the length filled in, refused without a map error: :func:`fill_map_error_length`)."""
    fill_map_error_length(args, args.map_error != 0
                          or getattr(args, "map_error_var", None) is not None)
    if not (np.isfinite(args.map_error) and args.map_error >= 0):
        raise ValueError(f"--map-error must be a finite map-error sigma >= 0 (mGal); got "
                         f"{args.map_error!r}")
    if not (np.isfinite(args.map_error_length) and args.map_error_length > 0):
        raise ValueError(f"--map-error-length must be a finite correlation length > 0 (m); "
                         f"got {args.map_error_length!r}")
    order = getattr(args, "map_error_order", None)  # None: not given, or no such option
    if order is not None and order not in (1, 2):
        raise ValueError(f"--map-error-order must be 1 or 2; got {order!r}")
    if order == 2 and getattr(args, "method", None) == "pmf":
        raise ValueError("--map-error-order 2 is not available with --method pmf (its per-cell "
                         "map-error state is first order); use --map-error-order 1 with 2 L")
    if order is not None and args.map_error == 0 and getattr(args, "map_error_var", None) is None:
        raise ValueError(f"--map-error-order {order} is the order of the map-error state, and "
                         "no map error is given (the filter carries none): add --map-error "
                         "SIGMA or --map-error-var NAME, or leave it out")  # was ignored
    if hasattr(args, "map_error_order"):
        args.map_error_order = 1 if order is None else order
    return args.map_error, args.map_error_length


def add_map_error_var_option(parser):
    """Add ``--map-error-var NAME`` to a command that takes ``--map-error``."""
    parser.add_argument(
        "--map-error-var", default=None, metavar="NAME",
        help="a variable of the --map file holding the map's 1-sigma uncertainty on its "
             "grid (map units, e.g. an error grid from the map's compilation): the "
             "map-error sigma told to the method is its RMS over the track's region, "
             "instead of --map-error (with --map-error-length as the correlation length)")


def add_missing_option(parser):
    """Add ``--missing gaps|land`` (the point-mass filter's reading of missing map nodes,
    :data:`~jaxgrav.filters.pmf_cells.MISSING`) to ``filter`` or ``navigate``."""
    parser.add_argument(
        "--missing", choices=MISSING, default=None,
        help="pmf: a map's missing (NaN) nodes are survey gaps (default: unknown values) or "
             "land (the vehicle cannot be where the nearest node is missing: only for a land "
             "mask the track never crosses)")


def check_missing_option(args):
    """ValueError naming ``--missing`` given to a method other than ``pmf``; the value
    (``"gaps"`` when not given)."""
    if args.missing is not None and args.method != "pmf":
        raise ValueError(f"--missing {args.missing} is for --method pmf; got --method "
                         f"{args.method}")
    return args.missing or "gaps"


def whole_number(text):
    """A count option (``--runs``, ``--fixes``, ``--particles`` ...) as an int: digits, or a
    whole number in exponent form (``1e6``; was argparse's "invalid int value: '1e6'");
    argparse.ArgumentTypeError for anything else (``2.5``, ``nan``, ``ten``) and for counts
    above :data:`MAX_COUNT` (``--n 1e300`` was refused by a message holding its 301 digits)."""
    try:
        number = int(text)
    except ValueError:
        try:
            number = float(text)
        except ValueError:
            number = math.nan
        if not (math.isfinite(number) and number == int(number)):
            raise argparse.ArgumentTypeError(
                f"expected a whole number (e.g. 1000 or 1e6); got {text!r}") from None
    if abs(number) > MAX_COUNT:
        raise argparse.ArgumentTypeError(f"expected a whole number of at most {MAX_COUNT:.0e} "
                                         f"(a count); got {text.strip()!r}")
    return int(number)
