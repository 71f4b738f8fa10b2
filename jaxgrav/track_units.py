"""Units declared in the headers of track and log files (``t (min)``, ``gravity [m/s^2]``).

:func:`header_scale` reads the unit a header declares, ``name (unit)``, ``name [unit]``
or ``name_unit`` (``lat_deg``, ``time_s``; ``latitudeE7``, ``lon_e7``: degrees × 1e7, as
Google's location history and MAVLink write them: :func:`unit_of`), as the factor to the
library's unit of that column: seconds, degrees, metres, m/s, degrees of arc for
``drift_radius``, mGal and nT (the map units of :func:`jaxgrav.grid_files.map_units`).
CF-style ``UNIT since DATE`` reads as ``UNIT`` (``t (hours since 2024-05-01)``: 3600). A
unit it does not know is read as a note (``lat (WGS84)``, ``time (UTC)``): factor 1.
"""

import math
import re

import numpy as np

from jaxgrav.constants import WGS84_MEAN_RADIUS
from jaxgrav.grid_files import map_units

__all__ = ["ALIASES", "UNIT_SUFFIX", "declared_unit", "header_scale", "name_key", "unit_of"]

UNIT_SUFFIX = re.compile(r"\s*[(\[][^()\[\]]*[)\]]\s*$")
"""A ``(unit)`` or ``[unit]`` at the end of a header."""

ALIASES = {  # German and Spanish exports' names last ("Breite;Länge" needed --columns)
    "t": ("t", "time", "timestamp", "datetime", "date_time", "utc", "utc_time", "zeit",
          "zeitstempel"),
    "lat": ("lat", "latitude", "breite", "breitengrad", "latitud"),
    "lon": ("lon", "longitude", "long", "lng", "länge", "laenge", "längengrad",
            "laengengrad", "longitud"),
    "h": ("h", "height", "altitude", "alt", "höhe", "hoehe"),
    # a survey's anomaly column under its own name was "needs a 'gravity' column"
    "gravity": ("gravity", "gravity_anomaly", "free_air_anomaly", "free_air", "faa", "grav",
                "schwere", "schwereanomalie", "freiluftanomalie"),
    "magnetic": ("magnetic", "magnetic_anomaly", "mag_anomaly", "total_field_anomaly"),
    # "ve, vn" logs ran as if without velocities: raw readings taken as Eötvös-corrected
    "v_east": ("v_east", "ve", "v_e", "vel_east", "velocity_east", "east_velocity", "veast"),
    "v_north": ("v_north", "vn", "v_n", "vel_north", "velocity_north", "north_velocity",
                "vnorth"),
}
"""Header names (any case) accepted for each column, in order of preference."""

_SNAKE_BY_COLUMN = {  # a column -> the units an "_unit" ending of any of its names may give it
    "lat": ("deg", "degs", "degrees", "rad"), "lon": ("deg", "degs", "degrees", "rad"),
    "t": ("s", "sec", "secs", "ms", "us", "ns", "min", "h", "hr", "hrs",
          "utc", "gmt"),  # "Time_UTC": a note, as "time (UTC)"
    "h": ("m", "km", "ft", "cm", "mm"),
    "gravity": ("mgal", "ugal", "µgal", "gal", "gu"), "magnetic": ("nt", "ut", "µt"),
    "v_east": ("kn", "kt", "kts", "kmh", "kph", "mph", "fps"),
    "drift_radius": ("deg", "m", "km", "nmi"),
}
_SNAKE_UNITS = {  # by header name (lower case): every alias ("faa_mgal" was no column)
    name: _SNAKE_BY_COLUMN.get(column.replace("north", "east"), ())
    for column, names in (*ALIASES.items(), ("h", ("alt", "altitude", "elev", "elevation")),
                          ("drift_radius", ("drift_radius",)))
    for name in names}
_SPACES = re.compile(r"[\s\-]+")
_E7 = re.compile(r"(.+?)_?e7", re.IGNORECASE)  # "latitudeE7", "lat_e7": degrees x 1e7
_SINCE = re.compile(r"(.+?)\s+since\s+.*", re.IGNORECASE)  # CF "hours since 2024-05-01"
_DEG = dict.fromkeys(("deg", "degs", "degree", "degrees", "°", "decimal degrees", "dd"), 1.0)
_ARC_M = 180.0 / (math.pi * WGS84_MEAN_RADIUS)  # degrees of arc per metre
_HEADER_UNITS = {  # column -> unit (lower case, spaces kept) -> factor to the library's
    "t": {**dict.fromkeys(("s", "sec", "secs", "second", "seconds"), 1.0),
          **dict.fromkeys(("ms", "millisecond", "milliseconds"), 1e-3),
          **dict.fromkeys(("us", "µs", "μs", "microsecond", "microseconds"), 1e-6),
          **dict.fromkeys(("ns", "nanosecond", "nanoseconds"), 1e-9),
          **dict.fromkeys(("min", "mins", "minute", "minutes"), 60.0),
          **dict.fromkeys(("h", "hr", "hrs", "hour", "hours"), 3600.0),
          **dict.fromkeys(("d", "day", "days"), 86400.0),
          **dict.fromkeys(("week", "weeks", "wk"), 604800.0)},
    "lat": {**_DEG, **dict.fromkeys(("rad", "radian", "radians"), 180.0 / np.pi),
            "arcmin": 1.0 / 60.0, "arcsec": 1.0 / 3600.0,
            **dict.fromkeys(("dege7", "deg e7", "deg*1e7", "deg x 1e7"), 1e-7)},
    "h": {**dict.fromkeys(("m", "metre", "metres", "meter", "meters"), 1.0),
          "km": 1e3, "cm": 1e-2, "mm": 1e-3, **dict.fromkeys(("ft", "feet"), 0.3048),
          **dict.fromkeys(("in", "inch", "inches"), 0.0254),
          **dict.fromkeys(("fathom", "fathoms", "fm"), 1.8288)},
    "v_east": {**dict.fromkeys(("m/s", "m s-1", "ms-1", "m/sec", "m s^-1"), 1.0),
               **dict.fromkeys(("kn", "kt", "kts", "knot", "knots"), 1852.0 / 3600.0),
               **dict.fromkeys(("km/h", "kmh", "kph", "km h-1"), 1.0 / 3.6),
               **dict.fromkeys(("ft/s", "fps", "ft s-1", "ft/sec"), 0.3048),
               **dict.fromkeys(("cm/s", "cm s-1"), 1e-2),
               **dict.fromkeys(("mm/s", "mm s-1"), 1e-3),
               **dict.fromkeys(("mph", "mi/h"), 0.44704),
               **dict.fromkeys(("m/min", "m min-1"), 1.0 / 60.0)},
    "drift_radius": {**_DEG, **dict.fromkeys(("rad", "radian", "radians"), 180.0 / np.pi),
                     **dict.fromkeys(("m", "metre", "metres", "meter", "meters"), _ARC_M),
                     "km": 1e3 * _ARC_M, **dict.fromkeys(("nmi", "nm", "nautical miles"),
                                                         1852.0 * _ARC_M),
                     **dict.fromkeys(("arcmin", "'"), 1.0 / 60.0),
                     **dict.fromkeys(("mi", "mile", "miles"), 1609.344 * _ARC_M)},
}
_HEADER_UNITS.update(lon=dict(_HEADER_UNITS["lat"]), v_north=_HEADER_UNITS["v_east"])
for _name, _sign, _words in (("lat", 1.0, ("n", "north")), ("lat", -1.0, ("s", "south")),
                             ("lon", 1.0, ("e", "east")), ("lon", -1.0, ("w", "west"))):
    # "lon (W)", "longitude (degrees_west)": positive west was read as east
    _HEADER_UNITS[_name].update(dict.fromkeys(
        [f"{p}{w}" for w in _words for p in ("", "°", "° ", "deg ", "deg", "degrees ",
                                             "degrees_", "degree_")], _sign))
_FIELD_UNITS = {"gravity": "mGal", "magnetic": "nT"}


def unit_of(header):
    """A header's name and the unit it declares: ``lat (deg)`` or ``lat [deg]`` → ``("lat",
    "deg")``; ``lat_deg``, ``time_s``, ``height_m``, ``gravity_mgal`` → the same, for the
    names and units of :data:`_SNAKE_UNITS` (``lat_s`` stays a name: ``s`` is no unit of
    latitudes), also after a space (``Gravity mGal``); ``latitudeE7``, ``lat_e7`` →
    ``("latitude", "1e-7 deg")``; ``(header, None)`` when it declares none.
    """
    text = str(header).strip()
    found = UNIT_SUFFIX.search(text)
    if found:
        return text[:found.start()].strip(), found.group(0).strip()[1:-1].strip()
    for sep in ("_", " "):  # "lat_deg", "Gravity mGal": were no latitude, no gravity
        base, found, unit = text.rpartition(sep)
        if found and unit.lower() in _SNAKE_UNITS.get(name_key(base), ()):
            return base.strip(), unit
    e7 = _E7.fullmatch(text)  # Google's "latitudeE7", MAVLink's degE7: was no column
    if e7 and name_key(e7.group(1)) in (*ALIASES["lat"], *ALIASES["lon"]):
        return e7.group(1), "1e-7 deg"
    return text, None


def name_key(name):
    """A header name as the aliases spell it: trimmed, lower case, runs of spaces and
    hyphens as one ``_`` (``"Free-air Anomaly"`` → ``"free_air_anomaly"``)."""
    return _SPACES.sub("_", str(name).strip().lower())


def header_scale(name, header, label):
    """Factor from the unit a header declares to the library's unit of column ``name``.

    Parameters
    ----------
    name : str
        The canonical column (``t``, ``lat``, ``gravity``, ...).
    header : str
        The header as written, e.g. ``"t (min)"``, ``"gravity [m/s^2]"``.
    label : str
        The file, for messages.

    Returns
    -------
    float
        1 when the header declares no unit, or one this function does not know (a note
        such as ``lat (WGS84)`` or ``time (UTC)``); else the factor (``t (min)``: 60,
        ``gravity [m/s^2]``: 1e5, ``lat (rad)``: 180/π, ``v_east (kn)``: 0.5144,
        ``v_east (ft/s)``: 0.3048, ``drift_radius (km)``: 1/111.2, ``lon (W)`` or ``lon
        (degrees_west)``: -1, positive west).

    Raises
    ------
    ValueError
        A gravity column declared in a magnetic unit, or a magnetic column in a gravity
        unit (the file and the header named).
    """
    base, unit = unit_of(header)
    if name == "h" and base.lower().replace(" ", "_").startswith(("depth", "water_depth")):
        # --columns h=depth (as dov's message suggests) read 50 m down as 50 m up
        raise ValueError(f"{label}: column {header!r} holds depths (metres down, below the "
                         "sea surface) and h is the height up, in metres above the "
                         "ellipsoid: give a column of heights, the geoid height minus the "
                         "depth (a submarine 50 m down where the geoid is at 30 m: h = -20)")
    if unit is None:
        return 1.0
    since = _SINCE.fullmatch(unit)  # "t (hours since 2024-05-01)" was read as seconds
    unit = since.group(1).strip() if since else unit
    if name in _FIELD_UNITS:
        factor_units = map_units(np.ones(1), unit)
        if factor_units[1] not in _FIELD_UNITS.values():  # "mGal FAA", "mGal, free-air"
            factor_units = map_units(np.ones(1), _first_word(unit))
        if factor_units[1] in _FIELD_UNITS.values() and factor_units[1] != _FIELD_UNITS[name]:
            raise ValueError(f"{label}: column {header!r} declares {unit!r}, a unit of "
                             f"{'gravity' if factor_units[1] == 'mGal' else 'magnetic'} "
                             f"fields; column {name!r} holds {_FIELD_UNITS[name]}: rename it "
                             "or name the right column with --columns")
        if factor_units[1] == _FIELD_UNITS[name]:
            return float(factor_units[0][0])
        _refuse_unknown(name, header, unit, label)
        return 1.0
    other = {"lat": "lon", "lon": "lat"}.get(name)
    if other and abs(_HEADER_UNITS[other].get(unit.lower(), 0.0)) == 1.0 and (
            unit.lower() not in _HEADER_UNITS[name]):  # "lat (W)": the columns swapped?
        raise ValueError(f"{label}: column {header!r} declares {unit!r}, a "
                         f"{'longitude' if other == 'lon' else 'latitude'} hemisphere, for "
                         f"{'latitudes' if name == 'lat' else 'longitudes'}: name the right "
                         f"column with --columns {name}=COLUMN")
    table = _HEADER_UNITS.get(name, {})
    key = unit.lower()
    scaled = _SCALED.fullmatch(key)  # "lat (1e-7 deg)": a receiver's integer degrees
    if scaled and scaled.group(2).strip() in table:
        return 10.0 ** int(scaled.group(1)) * table[scaled.group(2).strip()]
    hemisphere = _hemisphere(name, key, header, label) if name in _HEMISPHERES else None
    if key not in table and hemisphere is not None:  # "deg. S", "dd S": S was read as N
        return hemisphere
    if key not in table and _first_word(key) in table:  # "h (m MSL)", "lat (deg WGS84)"
        key = _first_word(key)
    if key not in table:
        _refuse_unknown(name, header, unit, label)
    return table.get(key, 1.0)


_HEMISPHERES = {"lat": {"n": 1.0, "north": 1.0, "s": -1.0, "south": -1.0},
                "lon": {"e": 1.0, "east": 1.0, "w": -1.0, "west": -1.0}}
_DEGREE_WORDS = ("deg", "degs", "degree", "degrees", "dd", "decimal")


def _hemisphere(name, key, header, label):
    """The sign a position unit's hemisphere word gives (``deg. S``, ``dd S``, ``decimal
    degrees W``: -1; both, ``N/S``: 1), when its other words are degrees; None otherwise
    (also for a sign, ``-W``). The other axis's hemisphere (``lat (deg. W)``) is
    refused."""
    words = re.findall(r"[a-z]+", key)
    other = _HEMISPHERES["lon" if name == "lat" else "lat"]
    signs = [_HEMISPHERES[name][w] for w in words if w in _HEMISPHERES[name]]
    if any(w in other for w in words) and not signs:
        raise ValueError(f"{label}: column {header!r} declares {key!r}, a "
                         f"{'longitude' if name == 'lat' else 'latitude'} hemisphere, for "
                         f"{'latitudes' if name == 'lat' else 'longitudes'}: name the right "
                         f"column with --columns {name}=COLUMN")
    rest = [w for w in words if w not in _HEMISPHERES[name]]
    if not signs or "+" in key or "-" in key or not all(w in _DEGREE_WORDS for w in rest):
        return None  # "(-W)": west negative, or west? not guessed
    return signs[0] if len(set(signs)) == 1 else 1.0  # "N/S": the cells' letters or signs


def _first_word(unit):
    words = re.split(r"[\s,;]+", unit.strip())
    return words[0].lower() if words else ""


_UNIT_WORDS = frozenset({
    "s", "sec", "ms", "us", "ns", "ks", "min", "h", "hr", "d", "day", "days", "week", "weeks",
    "wk", "yr", "year", "years", "m", "km", "cm", "mm", "um", "ft", "feet", "in", "inch",
    "inches", "yd", "yard", "yards", "fathom", "fathoms", "fm", "mi", "mile", "miles", "nmi",
    "kn", "kt", "mph", "deg", "degree", "degrees", "rad", "mrad", "urad", "arcsec", "arcmin",
    "mas", "grad", "gon", "gal", "mgal", "ugal", "gu", "nt", "ut", "t", "gamma", "tesla"})
"""Unit words (lower case) a header may declare; one that a column's table does not
hold is refused instead of read as a note (``h (in)`` was read as metres)."""
_SCALED = re.compile(r"(?:1e|10\^?)([-+]?\d+)\s*(.+)")  # "1e-7 deg", "10^-7 deg"


def _refuse_unknown(name, header, unit, label):
    """ValueError for a declared ``unit`` that is a unit (a known word, a ratio such as
    ``m/min``, a scale such as ``0.1 mGal``) but not one of column ``name``'s; a note
    (``time (UTC)``, ``lat (WGS84)``) passes."""
    first = _first_word(unit).replace("µ", "u").replace("μ", "u")
    if not (first in _UNIT_WORDS or re.search(r"[/^*]", first)
            or re.match(r"[-+]?(\d|\.\d)", first)):
        return
    target = {"t": "seconds", "lat": "degrees", "lon": "degrees", "h": "metres",
              "v_east": "m/s", "v_north": "m/s", "drift_radius": "degrees of arc",
              **_FIELD_UNITS}[name]
    known = [u for u in _HEADER_UNITS.get(name, {}) if u.isascii() and len(u) > 1][:5]
    examples = ", ".join(known) if known else "mGal, uGal, Gal, m/s^2" if (
        name == "gravity") else "nT, uT"
    raise ValueError(f"{label}: column {header!r} declares the unit {unit!r}, which jaxgrav "
                     f"cannot convert to {target}; convert the column to {target}, or declare "
                     f"a unit it knows (e.g. {examples})")


def declared_unit(name, header):
    """The unit ``header`` declares for column ``name`` when :func:`header_scale` knows it
    (``"ms"`` for ``t (ms)``, ``"hours"`` for ``t (hours since 2024-05-01)``), else None
    (no unit, or a note such as ``time (UTC)``)."""
    unit = unit_of(header)[1]
    if unit is None:
        return None
    since = _SINCE.fullmatch(unit)
    unit = (since.group(1).strip() if since else unit).lower()
    return unit if unit in _HEADER_UNITS.get(name, {}) else None
