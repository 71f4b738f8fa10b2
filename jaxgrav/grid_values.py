"""What a map's numbers mean: fill values, the CF valid range and the units.

:func:`undeclared_fills` reads nodes holding a fill value the file does not declare
(:data:`FILL_VALUES` beyond every other node's value, ``|v| >= 1e20``, infinite) as
missing, with an :class:`UndeclaredFillWarning`; :func:`outside_valid_range` reads nodes
outside a declared CF ``valid_range`` / ``valid_min`` / ``valid_max`` as missing, as CF
says they are; :func:`map_units` converts a gravity or magnetic map declared in other
units (``m s-2``, ``uGal``, ``uT`` …) to mGal or nT; :func:`axis_degrees` reads a
coordinate's units (CF ``degrees_west``/``degrees_south`` count the other way),
:func:`eastward_longitudes` the −360…0 convention, :func:`contiguous_longitudes`
removes 360° jumps (maps and tracks), :func:`rolled_columns` a global grid
stored from another meridian and :func:`unpacked_axis` coordinates packed as integers.
Used by
:func:`jaxgrav.grid_files.read_netcdf` (and the last by the track reader too).
"""

import re
import warnings

import numpy as np

from jaxgrav.grid_axes import regular_axis

__all__ = [
    "FILL_VALUES",
    "UndeclaredFillWarning",
    "axis_degrees",
    "contiguous_longitudes",
    "eastward_longitudes",
    "map_units",
    "outside_valid_range",
    "rolled_columns",
    "undeclared_fills",
    "units_attr",
    "unpacked_axis",
]

_UNIT_SCALES = {  # a map's declared units, normalised (see _unit_key) -> (factor, units)
    **dict.fromkeys(("mgal", "mgals", "milligal", "milligals"), (1.0, "mGal")),
    **dict.fromkeys(("gal", "gals"), (1e3, "mGal")),
    **dict.fromkeys(("ugal", "microgal", "microgals"), (1e-3, "mGal")),
    **dict.fromkeys(("ms-2", "m/s2", "m/s/s", "ms-1s-1"), (1e5, "mGal")),
    **dict.fromkeys(("gu", "um/s2", "ums-2", "gravityunit", "gravityunits"),  # µm/s²
                    (0.1, "mGal")),  # "gravity units" was read as mGal: 10 x too large
    **dict.fromkeys(("nt", "nanotesla", "gamma", "gammas"), (1.0, "nT")),
    **dict.fromkeys(("ut", "microtesla"), (1e3, "nT")),
    **dict.fromkeys(("t", "tesla"), (1e9, "nT")),
}
_SCALED_UNIT = re.compile(r"(?:1e|10(?=[-+]))([-+]?\d+)(.+)")
"""A normalised unit with a power of ten in front (``10^-5 m/s^2``, ``1e-6 m s-2``)."""
_NUMBER_UNIT = re.compile(r"\s*(\d*\.?\d+(?:[eE][-+]?\d+)?)\s*[*x×]?\s*([^\d\s^*].*)")
"""A unit with a plain number in front (``0.1 mGal``, ``10 uGal``)."""
FILL_VALUES = (-9999.0, 9999.0, -99999.0, 99999.0, -999999.0, 999999.0, -32767.0, 32767.0,
               -32768.0, 65535.0)
"""Fill values a grid may hold without declaring them (no ``_FillValue`` or
``missing_value`` attribute, e.g. a grid converted from ASCII); with ``|v| >= 1e20``."""


_COUNTED_BACK = ("degreew", "degrees", "degreewest", "degreesouth")
"""CF's west and south units, lower case, ``degrees`` → ``degree``, ``_`` dropped."""


def units_attr(attrs):
    """A variable's units: its CF ``units`` attribute, else one spelled ``Units``,
    ``UNITS`` or ``unit`` (files written by hand or by other tools; ``""`` if none)."""
    if "units" in attrs:
        return str(attrs["units"])
    spelled = [k for k in attrs if str(k).lower() in ("units", "unit")]
    return str(attrs[spelled[0]]) if spelled else ""


def eastward_longitudes(lon):
    """Longitudes in the −360…0 convention (every value at most 0°, some below −180°)
    shifted by +360° into 0…360; others returned unchanged (degrees).

    The one rule of the map and track readers: −233.5 is 126.5° E (a value below −180°
    has no other reading; maps were shifted, tracks refused).

    Parameters
    ----------
    lon : numpy.ndarray, shape ``(n,)``
        Longitudes (degrees), finite.

    Returns
    -------
    numpy.ndarray, shape ``(n,)``
        ``lon + 360`` in the −360…0 convention, else ``lon`` itself.
    """
    lon = np.asarray(lon)
    if lon.size and lon.min() < -180.0 and lon.max() <= 0.0 and lon.min() >= -360.0:
        return lon + 360.0
    return lon


def rolled_columns(lon, label):
    """Contiguous regular longitudes brought within [−180, 360], and the column order.

    A regional grid is shifted by 360° where that brings it within (350 … 370: −10 …
    10); a global grid stored from another meridian (GFDL MOM's −280 … 80, a rolled 20 …
    379.5) is rolled to start within ±180° (it ended in the grid's "lon must lie within
    [-180, 360]", naming no file); a repeated seam column is dropped. A regional grid
    beyond that range has no such reading and is refused.

    Parameters
    ----------
    lon : numpy.ndarray, shape ``(nx,)``
        Longitudes (degrees), regular, without 360° jumps, either order.
    label : str
        The file, for the message.

    Returns
    -------
    lon : numpy.ndarray, shape ``(m,)``
        Within [−180, 360] (ascending when rolled).
    order : numpy.ndarray of int, shape ``(m,)``, or None
        The columns to take, in order (``m`` is ``nx`` or ``nx − 1``); None: as stored.
    """
    lon = np.asarray(lon)  # its own type: float32 axes are checked with float32's rounding
    if lon.min() >= -180.0 - 1e-9 and lon.max() <= 360.0 + 1e-9:
        return lon, None
    for shift in (-360.0, 360.0):  # 350 .. 370: -10 .. 10
        if lon.min() + shift >= -180.0 - 1e-9 and lon.max() + shift <= 360.0 + 1e-9:
            return lon + shift, None
    step = abs(float(lon[1] - lon[0]))
    if lon.size * step < 360.0 - 1e-6 * step:
        raise ValueError(f"{label}: longitudes {lon.min():g} .. {lon.max():g} reach beyond "
                         "-180 .. 360 degrees on a map that is not global, and no shift by 360 "
                         "degrees brings them within; expected a map within -180 .. 360 (cut "
                         "it to the region needed)")
    if lon.size * step > 360.0 + 0.5 * step:  # the seam stored twice
        lon = lon[:-1]
    wrapped = np.mod(lon + 180.0, 360.0) - 180.0
    order = np.argsort(wrapped, kind="stable")
    return wrapped[order], order


_ARC_UNITS = {**dict.fromkeys(("arcmin", "arc_minutes", "arc-minutes", "arcminutes",
                                "minutes of arc"), 1.0 / 60.0),
              **dict.fromkeys(("arcsec", "arc_seconds", "arc-seconds", "arcseconds",
                               "seconds of arc"), 1.0 / 3600.0)}
"""Degrees per unit of a coordinate declared in minutes or seconds of arc."""


def axis_degrees(coord, units, name, label):
    """A latitude or longitude coordinate in degrees north or east.

    Parameters
    ----------
    coord : numpy.ndarray
        The coordinate's values as stored.
    units : str
        Its ``units`` attribute: CF's ``degrees_west`` or ``degrees_south`` (also
        ``degree_W``, ``degreesS`` …) are negated (they were read as east and north: a
        map of the Americas in degrees west was "off the map" of every track);
        ``arcmin``/``arcsec`` are converted to degrees.
    name, label : str
        The coordinate and the file, for the message.

    Raises
    ------
    ValueError
        Units of radians (they were read as degrees: "off the map" at 0.5..2.3).
    """
    declared = str(units).strip()
    if declared.lower() in ("rad", "radian", "radians"):
        raise ValueError(f"{label}: coordinate {name!r} is in {declared!r}; jaxgrav "
                         "reads latitudes and longitudes in degrees: convert them "
                         "(x 180/pi) and set units 'degrees_north'/'degrees_east'")
    scale = _ARC_UNITS.get(declared.lower())  # arc-minutes were "projected coordinates?"
    if scale is not None:
        return coord * scale
    key = declared.lower().replace("degrees", "degree").replace("_", "")
    return -coord if key in _COUNTED_BACK else coord


class UndeclaredFillWarning(UserWarning):
    """A map's nodes hold a fill value its file does not declare; they were read as
    missing (NaN) nodes (:func:`read_netcdf`)."""


def undeclared_fills(values, label, var):
    """``values`` with undeclared fill values (:data:`FILL_VALUES` beyond the range of every
    other node, ``|v| >= 1e20`` or infinite) as NaN, and an :class:`UndeclaredFillWarning`
    naming them."""
    finite = np.isfinite(values)
    fill = np.isinf(values) | (finite & (np.abs(values) >= 1e20))  # inf: was silently missing
    candidates = finite & np.isin(values, FILL_VALUES) & ~fill
    if candidates.any():  # the range of every other node, without copying a large map
        others = finite & ~fill & ~candidates
        low = values.min(where=others, initial=np.inf)
        high = values.max(where=others, initial=-np.inf)
        fill |= candidates & ((values < low) | (values > high)) & others.any()
    if not fill.any():
        return values
    found = ", ".join(f"{v:g}" for v in np.unique(values[fill])[:3])
    warnings.warn(f"{label}: {int(fill.sum())} node(s) of variable {var!r} hold {found}, a fill "
                  "value the file does not declare (no _FillValue or missing_value attribute); "
                  "read as missing nodes", UndeclaredFillWarning, stacklevel=3)
    return np.where(fill, np.nan, values)


def _unit_key(units):
    key = re.sub(r"\s*\([^()]*\)$", "", units.strip().lower())  # "mGal (free-air)"
    key = key.replace("µ", "u").replace("μ", "u")
    key = key.replace("²", "2").replace("⁻", "-")
    for c in " *^.·":
        key = key.replace(c, "")
    return key


def map_units(values, units):
    """A map's values in the library's units: gravity in mGal, magnetic fields in nT.

    The file's CF ``units`` attribute says what the numbers are (``m s-2``, ``Gal``,
    ``uGal``, ``gu``, ``T``, ``uT``, ``0.1 mGal`` …); matching, filtering and the readings' checks
    work in mGal and nT, so a map in other units is converted, not misread as mGal.

    Parameters
    ----------
    values : ndarray
    units : str
        The ``units`` attribute (``""``: none, the values are taken as they are).

    Returns
    -------
    values : ndarray
    units : str
        ``"mGal"`` or ``"nT"`` for a recognised gravity or magnetic unit, else ``units``
        unchanged (geoid heights in ``m``, DOV in ``arcsec`` …).
    """
    scaled = _SCALED_UNIT.fullmatch(_unit_key(units))  # "10^-5 m/s^2": mGal
    factor, canonical = (
        (_UNIT_SCALES[scaled.group(2)][0] * 10.0 ** int(scaled.group(1)),
         _UNIT_SCALES[scaled.group(2)][1]) if scaled and scaled.group(2) in _UNIT_SCALES
        else _UNIT_SCALES.get(_unit_key(units), (None, units)))
    number = _NUMBER_UNIT.fullmatch(str(units))  # "0.1 mGal" (tenths) was read as mGal
    if factor is None and number and _unit_key(number.group(2)) in _UNIT_SCALES:
        factor, canonical = _UNIT_SCALES[_unit_key(number.group(2))]
        factor *= float(number.group(1))
    if factor is None:
        return values, units
    return (values if factor == 1.0 else values * factor), canonical


def outside_valid_range(values, attrs, encoding):
    """``values`` with the nodes outside the variable's declared CF valid range as NaN.

    Parameters
    ----------
    values : ndarray
        The decoded values (scale and offset applied).
    attrs, encoding : dict
        The variable's attributes (``valid_range``, ``valid_min``, ``valid_max``: in packed
        units when of the stored, packed type, else in the unpacked ones, as CF says) and
        its encoding (``dtype``, ``scale_factor``, ``add_offset``).

    Returns
    -------
    ndarray
        ``values``, or a copy with the nodes beyond the range as NaN (xarray does not
        apply the range: a node of -500 in a map declaring ``valid_range = -400, 400`` was
        read as -500 mGal).
    """
    low, high, declared = -np.inf, np.inf, []
    if "valid_range" in attrs and np.size(attrs["valid_range"]) == 2:
        low, high = (float(v) for v in np.ravel(attrs["valid_range"]))
        declared.append(attrs["valid_range"])
    for name in ("valid_min", "valid_max"):
        if name in attrs:
            declared.append(attrs[name])
    low = float(np.ravel(attrs["valid_min"])[0]) if "valid_min" in attrs else low
    high = float(np.ravel(attrs["valid_max"])[0]) if "valid_max" in attrs else high
    if not (np.isfinite(low) or np.isfinite(high)):
        return values
    stored = np.dtype(encoding.get("dtype", values.dtype))
    if ("scale_factor" in encoding or "add_offset" in encoding) and all(
            np.asarray(v).dtype == stored for v in declared):  # else in unpacked units (CF)
        scale = float(encoding.get("scale_factor", 1.0))
        offset = float(encoding.get("add_offset", 0.0))
        low, high = sorted((low * scale + offset, high * scale + offset))
    outside = (values < low) | (values > high)
    return np.where(outside, np.nan, values) if outside.any() else values


def unpacked_axis(v, name, label):
    """A coordinate's nodes, regular again when they were packed as integers.

    Parameters
    ----------
    v : xarray.Variable
        The coordinate variable (decoded; its ``encoding`` says how it was stored).
    name, label : str
        The coordinate and the file, for messages.

    Returns
    -------
    numpy.ndarray, shape ``(n,)``
        ``v``'s values; for integers packed with a ``scale_factor`` (``int32`` × 1e-6
        degrees), checked regular to within that quantum and returned as the regular axis
        they round (the rounding was refused as an "irregular step").
    """
    values = np.asarray(v.values)
    stored = np.dtype(v.encoding.get("dtype", values.dtype))
    if stored.kind not in "iu" or "scale_factor" not in v.encoding or values.size < 2:
        return values
    quantum = abs(float(np.ravel(v.encoding["scale_factor"])[0]))
    regular_axis(values, str(name), label, resolution=quantum)
    return np.linspace(float(values[0]), float(values[-1]), values.size)


def contiguous_longitudes(lon):
    """Longitudes without 360° jumps: each step taken the short way round (degrees).

    The result equals ``lon`` plus a multiple of 360° at each point, shifted as a whole
    by ∓360° when it would leave [−180, 360]. A regional map across 0° stored in the
    0–360 convention (350 … 358, 0 … 10) becomes −10 … 10; a rolled global grid (180 …
    359.5, 0 … 179.5) becomes −180 … 179.5; a track crossing 0° given in 0–360 (359.5,
    0.5) becomes −0.5, 0.5; one crossing 180° given in ±180 (179.5, −179.5) becomes
    179.5, 180.5. Points with no jump are returned unchanged.

    Parameters
    ----------
    lon : array_like, shape ``(n,)``
        Longitudes (degrees), finite, in either convention.

    Returns
    -------
    numpy.ndarray, shape ``(n,)``
        Longitudes in the input's float type (float64 for integers); ``lon`` itself when
        it has no jump.
    """
    lon = np.asarray(lon).reshape(-1)
    if lon.dtype.kind != "f":
        lon = lon.astype(float)
    if lon.size < 2:
        return lon
    step = np.diff(lon)
    turns = np.concatenate([[0], np.cumsum((step < -180.0).astype(int) - (step > 180.0))])
    if not turns.any():
        return lon
    out = lon + (360.0 * turns).astype(lon.dtype)
    if out.max() > 360.0 + 1e-9:
        out = out - 360.0
    elif out.min() < -180.0 - 1e-9:
        out = out + 360.0
    return out
