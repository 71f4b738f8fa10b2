"""Track files: one reader for tracks and logs, one writer (CSV, atomic).

A track is a ``dict`` of equal-length 1-D float64 NumPy arrays keyed by column name,
e.g. ``t`` (s), ``lat``, ``lon`` (degrees), ``gravity`` (mGal); missing cells read as
NaN, so that missing readings survive a round trip. :func:`read_track_csv` returns a
:class:`TrackTable`, such a dict that also carries the file's text columns, the original
times and each row's line number, so outputs can pass every input column through.

What the reader accepts (parsing of the text: :mod:`jaxgrav.track_files`):

- comma, semicolon, tab or whitespace (``.xyz``) separated files, quoted fields, a
  UTF-8 byte-order mark, CRLF line ends, ``#`` comment lines, a decimal comma in
  semicolon/tab files;
- column names in any case, trimmed, with a ``(unit)`` suffix (read as a conversion
  when known: :func:`~jaxgrav.track_units.header_scale`), and the aliases
  of :data:`ALIASES` (``time`` for ``t``, ``latitude`` for ``lat``, ``longitude``,
  ``long``, ``lng`` for ``lon``, ``height`` for ``h``, ``faa`` for ``gravity``,
  ``ve``/``vn`` for ``v_east``/``v_north``); an exact name wins over an alias, and two
  names of one column (``lat`` beside ``latitude``) are refused;
  ``columns={"lat": "LAT", ...}`` (``--columns lat=LAT,...``, :func:`parse_columns`)
  names any other column, by name or by 1-based number;
- times in seconds or as ISO-8601 date-times (``2024-05-01T12:00:00Z``,
  :func:`~jaxgrav.track_times.parse_datetime`), which become seconds since the first row
  (the text is kept in the column ``time``); times of day are joined to a ``date``
  column; times must increase: a repeated or earlier time is refused with its line;
- longitudes in the 0–360, the ±180 or the −360…0 convention (as maps:
  :func:`~jaxgrav.grid_values.eastward_longitudes`); a track crossing 0° or 180° is made
  contiguous (359.5, 0.5 → −0.5, 0.5), as maps are (:func:`~jaxgrav.grid_values.
  contiguous_longitudes`); latitudes must lie within ±90°;
- extra numeric columns (in the dict) and text columns (in :attr:`TrackTable.text`).
"""

import csv
from pathlib import Path

import numpy as np

from jaxgrav._io import atomic_output
from jaxgrav.grid_values import contiguous_longitudes, eastward_longitudes
from jaxgrav.track_columns import ALIASES, listed, match_columns, parse_columns
from jaxgrav.track_degrees import e7_hint, join_position_parts, nmea_hint
from jaxgrav.track_files import column_key, comma_hint, parse_degrees, parse_numbers, read_table
from jaxgrav.track_times import DATE_COLUMNS, check_time_steps, iso_seconds
from jaxgrav.track_units import header_scale

__all__ = ["ALIASES", "KNOWN_COLUMNS", "TAB_SUFFIXES", "TrackTable", "csv_line", "parse_columns",
           "read_track_csv", "write_track_csv"]

TAB_SUFFIXES = (".tsv", ".tab")
"""Output suffixes :func:`write_track_csv` writes tab-separated."""

KNOWN_COLUMNS = ("t", "lat", "lon", "h", "gravity", "magnetic", "v_east", "v_north",
                 "drift_radius")
"""Columns the commands look for; found in any case and always numeric."""

_EXPECTED = {"t": "seconds or an ISO-8601 date-time", "lat": "degrees (35.5, -35.5, 35.5 S or "
             "35°30'S)", "lon": "degrees (127.5, -127.5, 127.5 W or 127°30'W)",
             "h": "metres", "gravity": "mGal", "magnetic": "nT", "v_east": "m/s",
             "v_north": "m/s", "drift_radius": "degrees"}


class TrackTable(dict):
    """A track read from a file: numeric columns as a dict, plus what outputs pass through.

    ``dict(track)`` (or ``track["lat"]``) gives the float64 columns as before.

    Attributes
    ----------
    path : str
        The file.
    text : dict of str to numpy.ndarray
        Text columns (str arrays), e.g. a ship name, or the original ISO times.
    lines : numpy.ndarray of int, shape ``(n,)``
        The file line number of each row (comment and blank lines skipped).
    order : list of str
        Every column name, numeric and text, in the file's order.
    time_origin : str or None
        The first row's ISO-8601 time when times were ISO (``t`` counts from it).
    time_text : str or None
        The text column holding those original times (``time`` unless named otherwise).
    renamed : dict of str to str
        Canonical name → the header it was read from, when they differ.
    cells : dict of str to numpy.ndarray
        The text of the numeric columns that no command reads, and the longitudes as
        read (before they are made contiguous), for :meth:`columns`.
    """

    path = ""
    text = None
    lines = None
    order = None
    time_origin = None
    time_text = None
    renamed = None
    cells = None

    def line(self, i):
        """The file line number of row ``i``."""
        return int(self.lines[i])

    def columns(self):
        """Every column in file order, for :func:`write_track_csv` to pass a track through.

        The columns the commands read (:data:`KNOWN_COLUMNS`, ``--columns``) as float
        arrays, normalised (``t`` in seconds), ``lon`` as read (not made contiguous: a
        user's convention is kept); text columns and other
        numeric columns as the file's own text (str arrays), so that identifiers such as
        ``0012`` or long integers come out as they went in.
        """
        return {k: self.cells.get(k, self[k]) if k in self else self.text[k]
                for k in self.order}


def read_track_csv(path, required=(), optional=(), *, allow_nan=(), columns=None):
    """Read a track or log file (see the module notes for what it accepts).

    Parameters
    ----------
    path : str or Path
        CSV (or semicolon, tab, whitespace separated) file, normally with a header row.
    required : sequence of str
        Columns that must be present (canonical names: ``t``, ``lat``, ``lon``, ...).
    optional : sequence of str
        Columns read under their canonical name when present (every other column is
        read too, numeric ones into the dict, text ones into ``.text``).
    allow_nan : sequence of str
        Required columns in which empty/NaN cells are allowed; NaN anywhere else in a
        required column is an error.
    columns : dict of str to str, optional
        Canonical name → header (any case) or 1-based column number, for names the
        aliases do not cover (:func:`parse_columns` reads ``--columns``).

    Returns
    -------
    TrackTable
        One float64 array per numeric column, all of the same length ``n``; ``t`` in
        seconds (from the first row for ISO times), ``lon`` without 360° jumps.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        Naming the file, the line, the column, the value and what was expected: an
        unreadable or binary file, missing columns, a cell that is not a number in a
        numeric column, NaN where not allowed, times that repeat or go back, latitudes
        beyond ±90° or longitudes outside [−180, 360], no rows.
    """
    label = f"track file {str(path)!r}"
    table = read_table(path, label)
    columns = dict(columns or {})
    wanted = [*required, *optional, *(c for c in KNOWN_COLUMNS if c not in required)]
    found = match_columns(table.header, wanted, columns, label, required)
    missing = [c for c in required if c not in found]
    if missing and not table.has_header:  # was "lacks columns lat and lon; it has 1, 2, 3"
        raise ValueError(f"{label} has no header row (line {table.lines[0]} holds only numbers); "
                         f"add one naming its {len(table.header)} columns (e.g. t,lat,lon,"
                         "gravity) or name them by number (e.g. --columns lat=2,lon=3)")
    if missing:
        raise ValueError(
            f"{label} lacks column{'s' * (len(missing) > 1)} {listed(missing, 'and')}; it "
            f"has {listed(table.header)}; required: {listed(required)} (names in any case; "
            f"aliases: time, latitude, longitude; others with --columns {missing[0]}=COLUMN)"
            + _depth_hint(table.header, missing))
    if not table.rows:
        raise ValueError(f"{label} has a header but no rows")
    track = TrackTable()
    track.path, track.text, track.order, track.cells = str(path), {}, [], {}
    track.lines = np.asarray(table.lines)
    track.renamed = {k: table.header[j] for k, j in found.items() if table.header[j] != k}
    canonical = {j: k for k, j in found.items()}
    keys = {}  # each column's header key, for the positions' parts
    lines = table.lines
    for j, header in enumerate(table.header):
        name = canonical.get(j, header)
        cells = [r[j] for r in table.rows]
        values, bad = parse_numbers(cells, decimal_comma=table.delimiter != ",")
        if j in canonical and bad is None:  # "t (min)", "gravity [m/s^2]", "lat (rad)"
            values = values * header_scale(name, header, label)
        if bad is not None and name == "t" and np.isfinite(values[:bad]).any():  # named line 2
            raise ValueError(f"{label}, line {lines[bad]}, column {header!r}: {cells[bad]!r} "
                             "is not a number, as the column's other times are (seconds); "
                             "give every time as a number, or every one as a date-time")
        if bad is not None and name == "t":
            day = [k for k, h in enumerate(table.header) if column_key(h) in DATE_COLUMNS]
            dates = [r[day[0]] for r in table.rows] if day and day[0] != j else None
            values, track.time_origin = iso_seconds(cells, lines, label, header, dates)
            text_name = header if header != "t" else "time"
            if text_name in table.header[:j] + table.header[j + 1:]:
                text_name += "_iso"
            track.time_text = text_name
            track.text[text_name] = np.asarray(cells, dtype=str)
            track.order += ["t", text_name]
            track[name] = values
            continue
        why = "not a number"
        if bad is not None and name in ("lat", "lon") and j in canonical:  # "35.5 N", 35°30'
            values, bad, why = parse_degrees(_numbers_as_read(cells, table.delimiter),
                                             name, table.delimiter != ",")
            values = values * header_scale(name, header, label)
        if bad is not None and j in canonical:
            raise ValueError(
                f"{label}, line {lines[bad]}, column {header!r}: {cells[bad]!r} " + (
                    f"is not a number (expected {_EXPECTED.get(name, 'a number')})"
                    if why == "not a number" else f"cannot be read as degrees: {why}")
                + comma_hint(cells[bad]))
        if j not in canonical and name in found:
            name = f"{header}_col{j + 1}"  # "lat" beside --columns lat=LAT2
        if bad is not None:
            track.text[name] = np.asarray(cells, dtype=str)
        else:
            track[name] = values
            if j not in canonical and name not in KNOWN_COLUMNS:
                track.cells[name] = np.asarray(cells, dtype=str)
        keys[name] = column_key(header)
        track.order.append(name)
    join_position_parts(track, keys, ALIASES, label)  # "lat_deg, lat_min", "lat, N/S"
    if "lon" in track:  # passed through as read (the reader makes it contiguous)
        track.cells["lon"] = np.asarray(
            [np.format_float_positional(v, trim="-") if np.isfinite(v) else ""
             for v in track["lon"]], dtype=str)
    _check_columns(track, required, allow_nan, label)
    return track


def _depth_hint(header, missing):
    """A message tail when ``h`` is missing and a column holds depths (``--columns
    h=depth``, which the message suggested, read 50 m down as 50 m up)."""
    depth = [h for h in header if column_key(h).startswith(("depth", "water_depth"))]
    if "h" not in missing or not depth:
        return ""
    return (f"; column {depth[0]!r} holds depths (metres down), and h is the height up, in "
            "metres above the ellipsoid: add a column of heights, the geoid height minus "
            "the depth")


def _numbers_as_read(cells, delimiter):
    """Angle cells with those :func:`parse_numbers` reads (a quoted ``"29,5"``) written
    as plain numbers, so that the degrees reader names the cell that is bad, not them."""
    out = list(cells)
    for i, cell in enumerate(cells):
        value, bad = parse_numbers([cell], decimal_comma=delimiter != ",")
        if bad is None and np.isfinite(value[0]):
            out[i] = repr(float(value[0]))
    return out


def _check_columns(track, required, allow_nan, label):
    """Complete required columns, increasing times, latitudes and longitudes in range."""
    lines = track.lines
    for name in required:
        bad = ~np.isfinite(track[name])
        if name not in allow_nan and bad.any():
            i = int(np.flatnonzero(bad)[0])
            what = ("missing, NaN or infinite" if np.isinf(track[name]).any()  # 1e400
                    else "missing or NaN")
            cut = ("; it is the last line, and only that one: was the file cut short while "
                   "being written?" if bad.sum() == 1 and i == bad.size - 1 > 0 else "")
            raise ValueError(
                f"{label}, column {name!r} has {int(bad.sum())} {what} value(s), "
                f"first on line {lines[i]}; this column must be complete{cut}")
        # "no reading" is an empty cell; inf was read as one
        inf = np.flatnonzero(np.isinf(track[name])) if name in allow_nan else ()
        if len(inf):
            i = int(inf[0])
            raise ValueError(
                f"{label}, line {lines[i]}, column {track.renamed.get(name, name)!r}: "
                f"{track[name][i]:g} is not a value; leave the cell empty where there is none")
    if "t" in track:
        t = track["t"]
        if np.isfinite(t).all():
            shown = (track.text[track.time_text] if track.time_text
                     else [f"{v:g}" for v in t])
            check_time_steps(t, shown, lines, label, track.renamed.get("t", "t"))
        elif "t" in required:
            i = int(np.flatnonzero(~np.isfinite(t))[0])
            raise ValueError(f"{label}, line {lines[i]}: the time is missing; times must be "
                             "complete")
    if "lat" in track:
        bad = np.flatnonzero(np.abs(track["lat"]) > 90.0)
        if bad.size:
            i = int(bad[0])
            swapped = ("; latitude and longitude look swapped (give --columns lat=NAME "
                       "lon=NAME)" if "lon" in track
                       and np.all(np.abs(track["lon"][np.isfinite(track["lon"])]) <= 90.0)
                       else "")
            raise ValueError(f"{label}, line {lines[i]}, column "
                             f"{track.renamed.get('lat', 'lat')!r}: latitude "
                             f"{track['lat'][i]:g} is outside [-90, 90] degrees"
                             f"{swapped or nmea_hint(track['lat'], i)}"
                             f"{e7_hint(track['lat'], i, 'lat')}")
    if "lon" in track:
        lon = track["lon"].copy()
        ok = np.isfinite(lon)
        lon[ok] = eastward_longitudes(lon[ok])  # -233.5: 126.5 E, as maps are read
        bad = np.flatnonzero(np.isinf(lon) | (lon < -180.0) | (lon > 360.0))
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"{label}, line {lines[i]}, column "
                             f"{track.renamed.get('lon', 'lon')!r}: longitude {lon[i]:g} is "
                             f"outside [-180, 360] degrees{nmea_hint(lon, i)}"
                             f"{e7_hint(track['lon'], i, 'lon')}")
        lon[ok] = contiguous_longitudes(lon[ok])
        track["lon"] = lon


def write_track_csv(path, columns, *, force=False, precision=12):
    """Write equal-length columns to a CSV file atomically.

    Parameters
    ----------
    path : str or Path
        Output file; an existing file is replaced only with ``force=True``. Comma-separated,
        or tab-separated when its suffix is one of :data:`TAB_SUFFIXES` (``.tsv``).
    columns : dict of str to array_like
        Column name → 1-D values: numbers (NaN written as an empty cell) or text (str
        arrays, e.g. :attr:`TrackTable.text`, written as they are, quoted when needed).
        ``{**track.columns(), "map": values}`` passes a read track through.
    force : bool
        Overwrite an existing file.
    precision : int
        Significant digits (at least 3 decimals for large values, e.g. epoch seconds);
        the default 12 keeps 1e-10° of a latitude (below a millimetre), so columns read
        from a user's log are passed through as precisely as any log gives them.
    """
    arrays, digits = {}, {}
    for k, v in columns.items():
        a = np.asarray(v).reshape(-1)
        arrays[k] = a.astype(str) if a.dtype.kind in "USO" else a.astype(float)
        if a.dtype.kind not in "USO":
            big = np.abs(arrays[k][np.isfinite(arrays[k])])
            whole = int(np.floor(np.log10(big.max()))) + 1 if big.size and big.max() > 0 else 0
            digits[k] = max(precision, whole + 3)  # epoch seconds keep their milliseconds
    lengths = {k: a.size for k, a in arrays.items()}
    if len(set(lengths.values())) > 1:
        raise ValueError(f"columns must have equal lengths; got {lengths}")
    tab = Path(path).suffix.lower() in TAB_SUFFIXES  # --out s.tsv held commas
    with atomic_output(path, force=force) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n", delimiter="\t" if tab else ",")  # not CRLF
        w.writerow(list(arrays))
        for row in zip(*arrays.values(), strict=True):
            w.writerow([v if isinstance(v, str) else "" if not np.isfinite(v)
                        else f"{v:.{digits[k]}g}" for k, v in zip(arrays, row, strict=True)])


def csv_line(i):
    """The file line number of data row ``i`` of a track CSV written by
    :func:`write_track_csv` (the header is line 1); for a file read with
    :func:`read_track_csv` use :meth:`TrackTable.line`, which counts skipped lines."""
    return int(i) + 2
