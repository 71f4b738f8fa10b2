"""Text tables of tracks and logs: decoding, delimiter sniffing, rows and numeric cells.

:func:`read_table` turns a track or log file into a header and rows of text cells with
their file line numbers, for :func:`jaxgrav.tracks.read_track_csv`:

- encodings: UTF-8 with or without a byte-order mark, UTF-16 with a BOM (spreadsheet
  "Unicode text"), else Windows-1252, else Latin-1; gzip, bzip2 or xz-compressed
  (``.csv.gz``), or the one file of a zip archive; a binary file (NetCDF, HDF5, a
  workbook ...) is refused;
- line ends: LF, CRLF or CR; blank lines and ``#`` comment lines (GMT headers) skipped,
  and title lines above the header (``Survey leg 3``: at most half its cells);
- the delimiter is sniffed from the header line: a tab, else ``|`` when it has more of
  them than of ``,`` and ``;``, else ``;`` when it has at least as many as ``,``, else
  ``,``, else runs of whitespace (``.xyz``, ``.txt``; GMT ``>`` segment lines skipped);
  quoted fields may hold the delimiter; NMEA sentences and XML (GPX) are refused;
- a units row under the header (``s,deg,deg,mGal``) is joined to it (``t (s)``, ...);
  a repeated header line (two files joined) is skipped;
- a first line that is all numbers is data, not a header: the header is then the comment
  line right above it when that has as many cells (``# t,lat,lon``, as ``numpy.savetxt``
  and GMT write), else the columns are named ``lon``, ``lat``, ``z`` for ``.xyz``/``.xy``
  files (GMT's order) and ``1``, ``2``, ... otherwise.

:func:`jaxgrav.track_units.header_scale` reads a unit in a header (``t (min)``,
``gravity [m/s^2]``, ``lat (rad)``, ``v_east (kn)``) as the factor to the library's units.
:func:`parse_numbers` reads one column of cells as float64 (empty, ``nan``, ``NA``,
``N/A``, ``#N/A``, ``null``, ``-`` as NaN; a decimal comma accepted when the delimiter
is not a comma; ``1,234.5``; Fortran's ``1.5D+01``); :func:`parse_degrees` reads
latitudes and longitudes with hemisphere letters or in DMS (``35°27.716'N``).
"""

import bz2
import csv
import gzip
import io
import itertools
import lzma
import re
import shlex
import zipfile
import zlib
from pathlib import Path
from typing import NamedTuple

import numpy as np

from jaxgrav.track_degrees import NA_TOKENS, parse_degrees
from jaxgrav.track_units import name_key, unit_of

__all__ = ["NA_TOKENS", "Table", "column_key", "comma_hint", "parse_degrees", "parse_numbers",
           "read_table"]

_DASHES = frozenset({"-", "--"})  # also a units row's "no unit"

_BINARY = {b"CDF": "a NetCDF-3 file", b"\x89HDF": "a NetCDF-4/HDF5 file",
           b"PK": "a zip/xlsx archive", b"\xd0\xcf\x11\xe0": "an old Excel/Office file"}
_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+([eE][+-]?\d+)?")
_THOUSANDS = re.compile(r"[+-]?\d{1,3},\d{3}")  # 1,234: a thousands separator, or 1.234?
_GROUPED = re.compile(r"[+-]?\d{1,3}(,\d{3})+\.\d*")  # "1,234.5": the comma groups thousands
_GROUPED_DOT = re.compile(r"[+-]?\d{1,3}(\.\d{3})+,\d*")  # "1.234,5", the decimal comma's
_FORTRAN = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)[dD][+-]?\d+")  # 1.5D+01: Fortran's exponent
_INVISIBLE = dict.fromkeys(map(ord, "\u200b\u200c\u200d\u2060\ufeff"))  # zero-width, BOMs
_MINUS = str.maketrans({"\u2212": "-", "\ufe63": "-", "\uff0d": "-"})  # −35.5 (typeset)
_DELIMITER_NAMES = {",": "comma", ";": "semicolon", "\t": "tab", " ": "whitespace", "|": "pipe"}
_NMEA = re.compile(r"[$!][A-Z]{5},")  # $GPGGA, $GNRMC, !AIVDM: a GPS receiver's raw log
_NOT_TABLES = {**dict.fromkeys("$!", ("NMEA 0183 sentences", "nmea")), "<": ("XML (GPX?)", "gpx")}
_SEP_LINE = re.compile(r'\s*"?sep=([,;\t])"?[,;\t]*\s*', re.IGNORECASE)  # Excel's first line


class Table(NamedTuple):
    """A text table read by :func:`read_table`.

    Attributes
    ----------
    header : list of str
        Column names as written (trimmed; generated names for a header-less file).
    rows : list of list of str
        Data cells, each row as long as the header (short rows padded with ``""``).
    lines : list of int
        The file line number (1-based) of each row.
    delimiter : str
        ``","``, ``";"``, ``"\\t"``, ``"|"`` or ``" "`` (runs of whitespace).
    has_header : bool
        False when the first line was data.
    """

    header: list
    rows: list
    lines: list
    delimiter: str
    has_header: bool

    @property
    def delimiter_name(self):
        """``"comma"``, ``"semicolon"``, ``"tab"``, ``"pipe"`` or ``"whitespace"``."""
        return _DELIMITER_NAMES[self.delimiter]


def column_key(name):
    """How a header matches a column name: its unit dropped (``"Gravity [mGal]"``,
    ``lat_deg``: :func:`~jaxgrav.track_units.unit_of`), then as ``name_key`` spells it."""
    return name_key(unit_of(name)[0])


_COMPRESSED = {b"\x1f\x8b": ("gzip", ".gz", gzip.decompress),
               b"BZh": ("bzip2", ".bz2", bz2.decompress),
               b"\xfd7zXZ\0": ("xz", ".xz", lzma.decompress)}


def _unzipped(data, label):
    """The one text member of a zip archive (``log.zip`` holding ``log.csv``); ValueError
    for a spreadsheet (``.xlsx``) or an archive of several files."""
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        names = [n for n in archive.namelist() if not n.endswith("/")]
        if "[Content_Types].xml" in names:
            raise ValueError(f"{label} is an Excel/OpenDocument workbook, not a text table; "
                             "save the sheet as CSV")
        if len(names) != 1:
            raise ValueError(f"{label} is a zip archive of {len(names)} files "
                             f"({', '.join(names[:4])}); expected one CSV file in it")
        return archive.read(names[0])


def _decode(data, label):
    for magic, (kind, suffix, decompress) in _COMPRESSED.items():  # log.csv.gz, .bz2, .xz: were
        if data.startswith(magic):  # "a binary file"
            try:
                data = decompress(data)
            except (OSError, EOFError, ValueError, zlib.error, lzma.LZMAError) as err:
                raise ValueError(f"{label} is a {kind} file that cannot be decompressed "
                                 f"({err}); expected a whole {suffix} of a CSV text file"
                                 ) from None
    if data.startswith(b"PK\x03\x04"):
        try:
            data = _unzipped(data, label)
        except zipfile.BadZipFile as err:
            raise ValueError(f"{label} is a zip file that cannot be read ({err})") from None
    head = data[:4096]
    for magic, what in _BINARY.items():
        if head.startswith(magic):
            raise ValueError(f"{label} is {what}, not a text table; a track is a CSV (or "
                             "whitespace-separated) text file with a header row")
    if head.startswith((b"\xff\xfe", b"\xfe\xff")):
        return data.decode("utf-16")
    if b"\0" in head:
        raise ValueError(f"{label} is a binary file, not a text table; a track is a CSV "
                         "(or whitespace-separated) text file with a header row")
    for encoding in ("utf-8-sig", "cp1252"):  # Windows' ’ (0x92) was read as a control
        try:  # character by Latin-1, which still reads what cp1252 leaves undefined
            return data.decode(encoding)
        except UnicodeDecodeError:
            pass
    return data.decode("latin-1")


def _sniff(line):
    if "\t" in line:
        return "\t"
    if line.count("|") > max(line.count(","), line.count(";")):  # t|lat|lon (psql, exports)
        return "|"
    if ";" in line and line.count(";") >= line.count(","):
        return ";"
    return "," if "," in line else " "


def _skip(cells):
    first = cells[0].lstrip() if cells else ""
    return not any(c.strip() for c in cells) or first.startswith("#")


def _whitespace_rows(text, label):
    for n, line in enumerate(io.StringIO(text, newline=None), start=1):
        s = line.strip()
        if not s or s.startswith(("#", ">")):
            continue
        try:
            yield n, (shlex.split(s) if ('"' in s or "'" in s) else s.split())
        except ValueError as err:
            raise ValueError(f"{label}, line {n}: {err} (unbalanced quotes?)") from None


def _delimited_rows(text, delimiter, label):
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter,
                        skipinitialspace=True)
    while True:
        try:
            cells = next(reader)
        except StopIteration:
            return
        except csv.Error as err:
            raise ValueError(f"{label}, line {reader.line_num}: {err}") from None
        yield reader.line_num, cells


def _count(line, delimiter):
    """Cells of one line with ``delimiter`` (``" "``: runs of whitespace)."""
    try:
        if delimiter == " ":  # as _whitespace_rows splits them
            return len(shlex.split(line) if ('"' in line or "'" in line) else line.split())
        return len(next(csv.reader([line], delimiter=delimiter)))
    except (ValueError, csv.Error, StopIteration):
        return 0


def _preamble(raw, k):
    """Indices of title lines above the header (``Survey leg 3``, ``Operator: X``), from
    line ``k``: the lines before the first one that has as many cells (at least 2) as the
    line after it, each with at most half its cells; none if there is no such line."""
    lines = [j for j, ln in enumerate(raw[k:k + 40], k)
             if ln.strip() and not ln.strip().startswith(("#", ">"))][:20]
    for a, b in itertools.pairwise(lines):
        delimiter = _sniff(raw[a].strip())
        n = _count(raw[a], delimiter)
        if n >= 2 and n == _count(raw[b], delimiter):
            title = [j for j in lines if j < a]
            return title if all(2 * _count(raw[j], delimiter) <= n for j in title) else []
    return []


def _is_number(cell):
    try:
        float(cell)
    except ValueError:
        return bool(_FORTRAN.fullmatch(cell))
    return True


def _numberish(cell):
    """A number, with a decimal point or a decimal comma."""
    return _is_number(cell) or bool(_DECIMAL_COMMA.fullmatch(cell))


def read_table(path, label=None):
    """Read a track or log file as a header and rows of text cells (see the module notes).

    Parameters
    ----------
    path : str or Path
        The file.
    label : str, optional
        How the file is named in messages (default ``"track file 'PATH'"``).

    Returns
    -------
    Table

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        A folder, a binary file, no header, a row with more cells than the header, an
        unclosed quote or a repeated column name (the line or the columns are named).
    """
    path = Path(path)
    label = label or f"track file {str(path)!r}"
    if not path.exists():
        raise FileNotFoundError(f"{label} does not exist")
    if path.is_dir():
        raise ValueError(f"{label} is a folder; expected a CSV file")
    text = _decode(path.read_bytes(), label).rstrip("\x1a")  # a DOS end-of-file mark (^Z)
    text = text.translate(_INVISIBLE)  # "lat\u200b" (pasted) was "lacks column lat"
    raw = text.splitlines()
    k = next((k for k, ln in enumerate(raw) if ln.strip() and not ln.strip().startswith(
        ("#", ">"))), None)
    if k is None:
        raise ValueError(f"{label} is empty; expected a header row (e.g. t,lat,lon,gravity)")
    first, declared = raw[k].strip(), _SEP_LINE.fullmatch(raw[k])
    if first.startswith(("{", "[")):
        raise ValueError(f"{label} looks like JSON (it starts with {first[:20]!r}), not a "
                         "track; a track is a CSV (or whitespace-separated) text file with a "
                         "header row, e.g. t,lat,lon,gravity")
    if _NMEA.match(first) or first.startswith("<"):  # were "column 'M' appears twice"
        what, fmt = _NOT_TABLES[first[0]]
        raise ValueError(f"{label} holds {what} ({first[:16]!r}...), not a table; convert it "
                         f"to a CSV first (e.g. gpsbabel -i {fmt} -f IN -o unicsv -F OUT.csv, "
                         "whose Date, Time, Latitude, Longitude jaxgrav reads)")
    if declared:  # "sep=;": the delimiter, declared; blanked so line numbers stay the file's
        text = "\n".join([*raw[:k], "", *raw[k + 1:]])
    title = [] if declared else _preamble(raw, k)
    above = raw[title[-1]] if title else ""  # the header, if its delimiter is not the rows'
    if title:  # "Survey leg 3" above the header was read as the header: blanked, as "sep="
        raw = ["" if j in title else ln for j, ln in enumerate(raw)]
        text, k = "\n".join(raw), next(j for j in range(title[-1] + 1, len(raw)) if raw[j].strip()
                                       and not raw[j].strip().startswith(("#", ">")))
        first = raw[k].strip()
    delimiter = declared.group(1) if declared else _sniff(first)
    rows = (_whitespace_rows(text, label) if delimiter == " "
            else _delimited_rows(text, delimiter, label))
    rows = [(n, [c.strip() for c in cells]) for n, cells in rows if not _skip(cells)]
    n_head, header = rows[0]
    has_header = not all(_is_number(c) for c in header if c)
    commented = None if has_header else _commented_header(raw[:n_head - 1], delimiter, header)
    if has_header:
        # "cat a.csv b.csv": b's header repeated mid-file ("'lat' is not a number")
        rows = [(n, cells) for n, cells in rows[1:] if cells != header]
        header, rows = _units_row(header, rows)
    elif commented:  # "# t,lat,lon" (numpy.savetxt, GMT): was "it has 1, 2, 3"
        header, has_header = commented, True
    elif _other_header(above, header):  # "t lat lon" over "0,29.5,126.5": "it has 1, 2, 3"
        header, has_header = _other_header(above, header), True
    elif path.suffix.lower() in (".xyz", ".xy"):
        # a two-column .xy(z) file gained an empty "z" column in the outputs
        header = ["lon", "lat", "z", *(str(j + 1) for j in range(3, len(header)))][:len(header)]
    else:
        header = [str(j + 1) for j in range(len(header))]
    while len(header) > 1 and not header[-1] and all(len(r) < len(header) or not r[-1]
                                                       for _, r in rows):
        header = header[:-1]  # a trailing delimiter on every line
    header = [h or f"column{j + 1}" for j, h in enumerate(header)]
    seen = {}
    for j, h in enumerate(header):
        if h in seen:
            raise ValueError(f"{label}: column {h!r} appears twice (columns {seen[h] + 1} and "
                             f"{j + 1} of line {n_head}); rename one")
        seen[h] = j
    out, lines = [], []
    for n, cells in rows:
        if len(cells) > len(header) and any(cells[len(header):]):
            raise ValueError(
                f"{label}, line {n} has {len(cells)} cells but the header has {len(header)} "
                f"column{'s' * (len(header) != 1)} ({_DELIMITER_NAMES[delimiter]}-"
                "separated); a quote missing around "
                "a cell that holds the delimiter?")
        out.append(cells[:len(header)] + [""] * (len(header) - len(cells)))
        lines.append(n)
    return Table(header, out, lines, delimiter, has_header)


def _commented_header(above, delimiter, first):
    """The header of a file whose header line is a comment (``# t,lat,lon``, as
    ``numpy.savetxt`` and GMT write it): the last non-blank line ``above`` the first data
    row ``first``, when it is a comment with as many cells, not all numbers; else None."""
    above = [ln.strip() for ln in above if ln.strip()]
    line = above[-1].lstrip("#").strip() if above and above[-1].startswith("#") else ""
    if not line:
        return None
    cells = [c.strip() for c in (line.split() if delimiter == " " else
                                 next(csv.reader([line], delimiter=delimiter)))]
    return cells if len(cells) == len(first) and not all(map(_is_number, cells)) else None


def _other_header(line, first):
    """The header of a file whose header line has another delimiter than its rows (``t lat
    lon`` or ``t;lat;lon`` over ``0,29.5,126.5``, typed by hand): ``line``, the last line
    above the first data row ``first`` (taken for a title), split on its own delimiter,
    when that gives as many cells, not all numbers; else None."""
    if not line.strip():
        return None
    delimiter = _sniff(line.strip())
    cells = [c.strip() for c in (line.split() if delimiter == " " else
                                 next(csv.reader([line], delimiter=delimiter)))]
    return cells if len(cells) == len(first) and not all(map(_is_number, cells)) else None


def _units_row(header, rows):
    """``header`` with a units row below it (``s,deg,deg,mGal``, as survey exports write)
    joined as ``t (s)``, ... and the rows without it; unchanged when the first row holds a
    number, or no column has a number in the next row below a text cell (was refused:
    "line 2, column 'lat': 'deg' is not a number")."""
    if len(rows) < 2 or any(_numberish(c) or c.lower() in NA_TOKENS - {""} - _DASHES
                            for c in rows[0][1]):
        return header, rows
    units = ["" if u in _DASHES else u.strip("()[] ") for u in rows[0][1]] + [""] * len(header)
    below = rows[1][1]
    if not any(u and j < len(below) and _numberish(below[j]) for j, u in enumerate(units)):
        return header, rows
    return ([f"{h} ({u})" if u else h for h, u in zip(header, units[:len(header)], strict=True)],
            rows[1:])


def comma_hint(cell):
    """A message tail for a cell such as ``1,234`` (1234 or 1.234?), else ``""``."""
    if not _THOUSANDS.fullmatch(cell.strip()):
        return ""
    cell = cell.strip()
    return (f"; it could be {cell.replace(',', '')} or {cell.replace(',', '.')} (a thousands "
            "separator or a decimal comma): write the number meant, with a decimal point")


def parse_numbers(cells, decimal_comma=False):
    """Cells of one column as float64; the index of the first cell that is not a number.

    Parameters
    ----------
    cells : sequence of str
        Trimmed cells.
    decimal_comma : bool
        Also accept ``1,5`` for 1.5, ``1.234,5`` for 1234.5 (``1,234.5`` always); without
        it a decimal comma is read only when it cannot be a thousands separator (``"29,5"``
        quoted in a comma-separated file, not ``"1,234"``).

    Returns
    -------
    values : numpy.ndarray, shape ``(n,)``
        NaN for missing cells (:data:`NA_TOKENS`); undefined from the first bad cell on.
    bad : int or None
        Index of the first cell that is neither a number nor missing, else None.
    """
    values = np.empty(len(cells))
    for i, cell in enumerate(cells):
        if cell.lower() in NA_TOKENS:
            values[i] = np.nan
            continue
        cell = cell.translate(_MINUS)  # a typeset minus sign was "not a number"
        try:
            values[i] = float(cell)
        except ValueError:
            # a comma-separated file's "29,5" was quoted: a decimal comma unless 1,234
            if _DECIMAL_COMMA.fullmatch(cell) and (decimal_comma
                                                    or not _THOUSANDS.fullmatch(cell)):
                values[i] = float(cell.replace(",", "."))
            elif _GROUPED.fullmatch(cell) or (decimal_comma and _GROUPED_DOT.fullmatch(cell)):
                sep = "," if _GROUPED.fullmatch(cell) else "."  # "1,234.5" was "not a number"
                values[i] = float(cell.replace(sep, "").replace(",", "."))
            elif _FORTRAN.fullmatch(cell):  # was "not a number"
                values[i] = float(cell.replace("D", "e").replace("d", "e"))
            else:
                return values, i
    return values, None
