"""Latitudes and longitudes as ship logs and GPS exports write them.

:func:`parse_degrees` reads a column of angle cells with hemisphere letters (``35.4619
N``, ``N35.4619``, ``127.71W``) or in degrees, minutes and seconds (``35°27.716'N``,
``35 27 43.2 S``) as signed decimal degrees, for :func:`jaxgrav.tracks.read_track_csv`
(through :mod:`jaxgrav.track_files`, which exports it); :func:`nmea_hint` names a
column written as NMEA's ``ddmm.mmmm`` (degrees × 100 + minutes), :func:`e7_hint` one
of whole degrees × 1e7.
"""

import re

import numpy as np

__all__ = ["NA_TOKENS", "e7_hint", "join_position_parts", "nmea_hint", "parse_degrees"]

NA_TOKENS = frozenset({"", "nan", "na", "n/a", "null", "none", "#n/a", "-", "--"})
"""Cells (lower case) read as a missing value (NaN): also a spreadsheet's ``#N/A`` and a
logger's ``-`` or ``--`` (were "not a number"). Exported by :mod:`jaxgrav.track_files`."""


def _is_number(cell):
    try:
        float(cell)
    except ValueError:
        return False
    return True


_HEMISPHERE = re.compile(r"([NSEW])?\s*([^NSEW]*?)\s*([NSEW])?", re.IGNORECASE)
_ANGLE_PARTS = re.compile(r"[°º˚:'′’\"″”\s]+")  # ’ ”: a word processor's quotes as marks
_SIGNS = {"lat": {"N": 1.0, "S": -1.0}, "lon": {"E": 1.0, "W": -1.0}}


def _degrees(cell, name):
    """One angle cell (``35.5 N``, ``S35.5``, ``35°27.7'N``, ``35 27 43.2 S``) in signed
    degrees; ValueError with the reason for anything else."""
    m = _HEMISPHERE.fullmatch(cell.strip())
    if not m or (m[1] and m[3]):
        raise ValueError("not a number")
    letter = (m[1] or m[3] or "").upper()
    if letter and letter not in _SIGNS[name]:
        raise ValueError(f"hemisphere {letter} in a {'latitude' if name == 'lat' else 'longitude'}"
                         f" column (expected {' or '.join(_SIGNS[name])})")
    parts = [p for p in _ANGLE_PARTS.split(m[2]) if p]
    if not 1 <= len(parts) <= 3 or not all(_is_number(p) for p in parts):
        raise ValueError("not a number")
    numbers = [float(p) for p in parts]
    if any(p[0] in "+-" for p in parts[1:]) or any(not 0 <= v < 60 for v in numbers[1:]) or any(
            not v.is_integer() for v in numbers[:-1]):
        raise ValueError("not degrees, minutes and seconds (whole degrees and minutes, "
                         "minutes and seconds below 60)")
    if letter and parts[0].startswith("-"):
        raise ValueError(f"both a sign and hemisphere {letter}")
    magnitude = abs(numbers[0]) + sum(v / 60.0 ** k for k, v in enumerate(numbers[1:], 1))
    sign = _SIGNS[name].get(letter, -1.0 if parts[0].startswith("-") else 1.0)
    return sign * magnitude


def parse_degrees(cells, name, decimal_comma=False):
    """A latitude (``name="lat"``) or longitude column written with hemisphere letters or
    in degrees, minutes and seconds, as ship logs and GPS exports do: ``35.4619 N``,
    ``N35.4619``, ``127.71W``, ``35°27.716'N``, ``35 27 43.2 S``; plain numbers as well.

    Returns
    -------
    values : numpy.ndarray
        Signed decimal degrees (S and W negative; NaN for missing cells).
    bad : int or None
        Index of the first cell that cannot be read.
    why : str
        Why that cell cannot be read (``""`` when ``bad`` is None).
    """
    values = np.empty(len(cells))
    for i, cell in enumerate(cells):
        if cell.lower() in NA_TOKENS:
            values[i] = np.nan
            continue
        if decimal_comma:  # "35,5 N", "35°27,7'N" in a semicolon file
            cell = cell.replace(",", ".")
        cell = cell.replace("\u2212", "-")  # a typeset minus: −35°30'
        try:
            values[i] = float(cell)
        except ValueError:
            try:
                values[i] = _degrees(cell, name)
            except ValueError as err:
                return values, i, str(err)
    return values, None, ""


def nmea_hint(values, i):
    """A message tail when the angles ``values`` (a lat or lon column read as degrees, its
    value ``i`` out of range) look like NMEA ``ddmm.mmmm``, degrees × 100 plus minutes
    (GPS receivers' GGA/RMC sentences, exported as numbers), else ``""``.

    Such a column has every value's last two whole digits below 60 (the minutes).
    """
    v = np.abs(np.asarray(values, dtype=float))
    v = v[np.isfinite(v)]
    if not v.size or v.max() >= 18000.0 or np.any(v % 100.0 >= 60.0):
        return ""
    x = abs(float(values[i]))
    deg, minutes = divmod(x, 100.0)
    shown = (np.format_float_positional(a, trim="-") for a in (x, round(minutes, 6)))
    return (f"; it looks like NMEA ddmm.mmmm (degrees x 100 + minutes): {next(shown)} is "
            f"{deg:.0f} deg {next(shown)}' = {deg + minutes / 60.0:.6g} degrees; convert the "
            "column to decimal degrees")


def e7_hint(values, i, name):
    """A message tail when the angles ``values`` (a ``lat`` or ``lon`` column, value ``i``
    out of range) are whole numbers that, divided by 1e7, are degrees: ``degE7``, as
    MAVLink, PX4 and Google's location history write positions; else ``""``."""
    v = np.abs(np.asarray(values, dtype=float))
    v = v[np.isfinite(v)]
    limit = 90.0 if name == "lat" else 360.0
    if not v.size or np.any(v != np.round(v)) or v.max() / 1e7 > limit:
        return ""
    return (f"; whole numbers of degrees x 1e7 (degE7, as MAVLink and Google's location "
            f"history write them)? {float(values[i]):.0f} would be {float(values[i]) / 1e7:.7g} "
            f"degrees: declare it in the header, e.g. '{name} (1e-7 deg)' or '{name}_e7'")


_PART_WORDS = {"min": ("min", "mins", "minute", "minutes"),
               "sec": ("sec", "secs", "second", "seconds")}
_PART_SCALE = {"min": 1.0 / 60.0, "sec": 1.0 / 3600.0}
_LETTERS = {"lat": {"N": 1.0, "S": -1.0}, "lon": {"E": 1.0, "W": -1.0}}


def _part_names(aliases, part):
    """Header keys (lower case) of a position's minutes or seconds column: ``lat_min``,
    ``latmin``, ``latitude minutes`` …"""
    return {f"{a}{sep}{w}" for a in aliases for sep in ("_", "", " ", "-")
            for w in _PART_WORDS[part]}


def join_position_parts(track, keys, aliases, label):
    """Positions written in parts, joined into signed decimal degrees (in place).

    Survey exports write a latitude as whole degrees beside a minutes column (``lat_deg,
    lat_min``; also seconds) and GPS exports beside a hemisphere column (``lat, N/S``):
    the degrees alone were read and the rest passed through (a track in 29° 30' was
    sampled at 29°, one at 35° S at 35° N, exit 0). A minutes or seconds column named
    after the position (``lat_min``, ``latitude_minutes``, ``lat_sec``), all in [0, 60),
    is added to degrees that are all whole, with their sign (else it is some other
    column, e.g. a minimum, and passed through); a text column right after the position
    holding only its hemisphere letters (``N``/``S``; ``E``/``W``) gives the sign.

    Parameters
    ----------
    track : jaxgrav.tracks.TrackTable
        As read, ``lat``/``lon`` in degrees; its ``order`` the columns in file order.
    keys : dict of str to str
        Each column name in ``track`` → its header key (lower case, unit dropped).
    aliases : dict of str to tuple of str
        The position columns' header names (``ALIASES``).
    label : str
        The file, for messages.

    Raises
    ------
    ValueError
        A hemisphere letter beside a negative position.
    """
    for name in ("lat", "lon"):
        if name not in track:
            continue
        values = degrees = track[name]
        for part in ("min", "sec"):
            wanted = _part_names(aliases[name], part)
            cols = [c for c in track.order if c in track and keys.get(c) in wanted]
            if not cols:
                continue
            extra, ok = track[cols[0]], np.isfinite(degrees)
            if (np.any(degrees[ok] != np.round(degrees[ok]))  # lat_min: a minimum latitude?
                    or np.any((extra[ok] < 0) | (extra[ok] >= 60))):
                continue
            values = values + np.copysign(extra * _PART_SCALE[part], degrees)  # -0 deg 30'
        j = track.order.index(name)
        after = track.order[j + 1] if j + 1 < len(track.order) else None
        cells = track.text.get(after)
        if cells is not None:
            letters = np.char.upper(np.char.strip(cells.astype(str)))
            if letters.size and set(letters.tolist()) <= set(_LETTERS[name]):
                if np.any(values < 0):
                    raise ValueError(f"{label}: column {after!r} gives {name!r} a hemisphere, "
                                     "and the column has negative values too; give one of "
                                     "the two")
                values = values * np.vectorize(_LETTERS[name].get)(letters)
        track[name] = values
