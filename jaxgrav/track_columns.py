"""Track file columns: the header names each column goes by, and ``--columns``.

:data:`ALIASES` (defined in :mod:`jaxgrav.track_units`, whose ``name_unit`` headers
follow it) lists the names (any case) accepted for each canonical column;
:func:`match_columns` finds each wanted column in a header, refusing a header in which
two columns could both be one (``lat`` beside ``latitude``: which one is the position?);
:func:`parse_columns` reads ``--columns lat=LAT,lon=LON``. For
:func:`jaxgrav.tracks.read_track_csv`.
"""

import re

from jaxgrav.track_files import column_key
from jaxgrav.track_units import ALIASES

__all__ = ["ALIASES", "listed", "match_columns", "parse_columns"]

def parse_columns(text):
    """Parse ``--columns lat=LAT,lon=LON`` into ``{"lat": "LAT", "lon": "LON"}``.

    Parameters
    ----------
    text : str or None
        ``NAME=COLUMN`` pairs separated by commas (or semicolons); COLUMN is a header (any
        case) or a 1-based column number.

    Returns
    -------
    dict of str to str
        Empty for None or ``""``.

    Raises
    ------
    ValueError
        A pair without ``=``, an empty side, a name given twice or two names for one
        column.
    """
    out = {}
    example = "(e.g. --columns lat=LAT,lon=LON,gravity=FAA)"
    for part in re.split(r"[,;]", text or ""):  # "lat=LAT;lon=LON" was one column's name
        if not part.strip():
            continue
        name, eq, col = (s.strip() for s in part.partition("="))
        if not eq or not name or not col:
            raise ValueError(f"--columns must be NAME=COLUMN pairs separated by commas "
                             f"{example}; got {part.strip()!r} in {text!r}")
        if name in out:
            raise ValueError(f"--columns names {name!r} twice in {text!r}")
        if col.lower() in (c.lower() for c in out.values()):
            raise ValueError(f"--columns gives column {col!r} two names in {text!r}")
        out[name] = col
    return out


def listed(names, last=","):
    """Names in plain words: ``a, b, c`` (``last="and"``: ``a, b and c``)."""
    names = [str(n) for n in names]
    if len(names) < 2 or last == ",":
        return ", ".join(names)
    return f"{', '.join(names[:-1])} {last} {names[-1]}"


def _other_alias(header, keys, name, found):
    """The index of a second column whose header is another alias of ``name`` than the
    one found (``latitude`` beside ``lat``), or None. ``t`` is exempt: the commands'
    own outputs write ``t`` (seconds from the first row) beside the log's ISO ``time``."""
    if name == "t" or name not in found:
        return None
    taken = set(found.values())
    first = keys[found[name]]
    others = [j for j, k in enumerate(keys) if j not in taken and k != first
              and k in ALIASES.get(name, ())]
    return others[0] if others else None


def match_columns(header, wanted, columns, label, required=()):
    """Header index of each canonical name found: ``--columns``, exact name, aliases."""
    keys = [column_key(h) for h in header]
    found = {}
    for name, col in columns.items():
        hits = [j for j, h in enumerate(header) if h == col] or [
            j for j, k in enumerate(keys) if k == column_key(col)]
        if not hits and col.isdigit() and 1 <= int(col) <= len(header):
            hits = [int(col) - 1]
        if not hits:
            counted = (f"; columns are counted from 1 to {len(header)}" if col.isdigit()
                       else "")
            raise ValueError(f"{label} has no column {col!r} (asked for by --columns "
                             f"{name}={col}); it has {listed(header)}{counted}")
        found[name] = hits[0]
    for name in wanted:
        if name in found:
            continue
        for alias in ALIASES.get(name, (name,)):
            hits = [j for j, k in enumerate(keys) if k == alias and j not in found.values()]
            exact = [j for j in hits if header[j] == alias]
            hits = exact if len(exact) == 1 else hits
            if len(hits) > 1:
                both = listed([header[j] for j in hits], "and")
                raise ValueError(f"{label}: columns {both} could all be {name!r}; choose one "
                                 f"with --columns {name}=COLUMN")
            if hits:
                found[name] = hits[0]
                break
        other = _other_alias(header, keys, name, found)
        if other is not None:  # "lat" was read and "latitude" passed through, in silence
            pair = sorted((found[name], other))
            raise ValueError(f"{label}: columns {header[pair[0]]!r} and {header[pair[1]]!r} "
                             f"could both be {name!r}; choose one with --columns "
                             f"{name}=COLUMN")
        # was "lacks column(s) ['lat']; it has ['lat', ...]"
        taken = [] if name in found or name not in required else [
            n for n, j in found.items() if n in columns and keys[j] in ALIASES.get(name, (name,))]
        if taken:
            raise ValueError(f"{label}: column {header[found[taken[0]]]!r} would be read as "
                             f"{name!r}, but --columns {taken[0]}={columns[taken[0]]} reads "
                             f"it as {taken[0]!r}; give {name!r} its own column with "
                             f"--columns {name}=COLUMN")
    used = {}
    for name, j in found.items():
        if j in used:
            raise ValueError(f"{label}: column {header[j]!r} cannot be both {used[j]!r} and "
                             f"{name!r}")
        used[j] = name
    return found
