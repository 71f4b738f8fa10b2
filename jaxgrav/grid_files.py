"""NetCDF files of :class:`~jaxgrav.grid.Grid` maps (xarray, GMT and CF conventions).

:func:`read_netcdf` is the one map reader: it refuses a file that is not NetCDF (a CSV
given as a map) in one line, finds the 1-D latitude and longitude coordinates (``lat``,
``latitude``, ``y`` / ``lon``, ``longitude``, ``x`` in any case, or by their CF
``standard_name``/``units``), picks the gridded variable, squeezes singleton extra
dimensions (``time`` of length 1) and refuses other ones by name, makes the longitudes
contiguous (a regional 0–360 map across 0°, 350 … 10, becomes −10 … 10) and checks both
axes (a repeated, unsorted or irregular node is named with the file and its value).
GMT 4's native grids (``x_range``, ``y_range``, ``dimension``, ``z``) are read too.
Nodes holding a fill value the file does not declare (−9999, 99999, … beyond the range
of every other node, or ``|v| >= 1e20``) are read as missing, with an
:class:`UndeclaredFillWarning`, and so are nodes outside a declared CF valid range. A
gravity or magnetic map declared in other units (CF ``units`` ``m s-2``, ``uGal``,
``uT`` …) is converted to mGal or nT (:func:`map_units`); see :mod:`jaxgrav.grid_values`.
It returns plain arrays; :meth:`Grid.from_netcdf` and :func:`jaxgrav.datasets.load_map`
build the grid. :func:`write_netcdf` writes a grid with CF ``lat``/``lon`` coordinates,
atomically. Both are package-internal: use the ``Grid`` methods or ``load_map``.
"""

import re
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np
import xarray as xr

from jaxgrav._io import atomic_output
from jaxgrav.grid_axes import regular_axis
from jaxgrav.grid_values import (
    FILL_VALUES,
    UndeclaredFillWarning,
    axis_degrees,
    contiguous_longitudes,
    eastward_longitudes,
    map_units,
    outside_valid_range,
    rolled_columns,
    undeclared_fills,
    units_attr,
    unpacked_axis,
)

__all__ = ["FILL_VALUES", "LAT_NAMES", "LON_NAMES", "GridArrays", "UndeclaredFillWarning",
           "check_netcdf_file", "map_units", "read_netcdf", "write_netcdf"]

LAT_NAMES = ("lat", "latitude", "y")
"""Accepted names of the latitude coordinate (any case), in order of preference."""
LON_NAMES = ("lon", "longitude", "x")
"""Accepted names of the longitude coordinate (any case), in order of preference."""

_CF = {
    "latitude": ("latitude", {"degrees_north", "degree_north", "degrees_n", "degree_n"}),
    "longitude": ("longitude", {"degrees_east", "degree_east", "degrees_e", "degree_e"}),
}
_MAGIC = (b"CDF\x01", b"CDF\x02", b"CDF\x05", b"\x89HDF\r\n\x1a\n")
"""First bytes of NetCDF-3 (classic, 64-bit offset, 64-bit data) and NetCDF-4 (HDF5)."""


class GridArrays(NamedTuple):
    """What :func:`read_netcdf` returns (unpacks as ``lat, lon, values, name, units``).

    Attributes
    ----------
    lat : ndarray, shape ``(ny,)``
        Latitudes (degrees), in the file's order.
    lon : ndarray, shape ``(nx,)``
        Longitudes (degrees), in the file's order, without 360° jumps.
    values : ndarray, shape ``(..., ny, nx)``
        The variable (float; fill values as NaN, undeclared ones too), latitude and
        longitude last.
    name, units : str
        The variable's name and its ``units`` attribute (``""`` if none; ``mGal`` or
        ``nT`` when the values were converted from other gravity or magnetic units).
    """

    lat: np.ndarray
    lon: np.ndarray
    values: np.ndarray
    name: str
    units: str


def check_netcdf_file(path, what="map"):
    """Refuse a path that is missing, a folder, or not a NetCDF file, in one line.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file is meant to be, for the message.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is a folder, or its first bytes are not those of NetCDF-3 or NetCDF-4 (the
        message says what it looks like instead: empty, text such as a CSV, other binary).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{what} {str(path)!r} does not exist")
    if path.is_dir():
        raise ValueError(f"{what} {str(path)!r} is a folder; expected a NetCDF file")
    with path.open("rb") as fh:
        head = fh.read(256)
    if any(head.startswith(m) for m in _MAGIC):
        return
    if not head:
        looks = "it is empty"
    elif head.startswith((b"\x1f\x8b", b"BZh", b"\xfd7zXZ", b"PK\x03\x04")):
        looks = "it is compressed (gzip, bzip2, xz or zip): decompress it first"
    elif head.startswith((b"II*\0", b"MM\0*", b"II+\0", b"MM\0+")):  # was "not NetCDF-3 or 4"
        looks = ("it is a (Geo)TIFF raster: convert it, e.g. gdal_translate -of netCDF IN "
                 "OUT.nc")
    elif head.startswith((b"DSAA", b"DSRB", b"DSBB")):  # Surfer grids, often named .grd too
        looks = "it is a Surfer grid: convert it, e.g. gdal_translate -of netCDF IN OUT.nc"
    elif head.startswith((b"\x89PNG", b"\xff\xd8\xff", b"%PDF")):
        looks = "it is an image or a PDF, not gridded values"
    elif head.lstrip().lower().startswith((b"ncols", b"nrows")):  # was "a CSV track?"
        looks = ("it is an ESRI ASCII grid: convert it, e.g. gdal_translate -of netCDF IN "
                 "OUT.nc")
    elif b"\0" not in head:
        first = head.decode("utf-8", "replace").lstrip("\ufeff").splitlines()[0][:40]
        looks = (f"it is a text file starting {first!r}, a CSV track or table? a table of "
                 "lon, lat, value converts with GMT's xyz2grd")
    else:
        looks = "its format is not NetCDF-3 or NetCDF-4"
    raise ValueError(f"{what} {str(path)!r} is not a NetCDF file ({looks}); expected a "
                     "NetCDF grid (CF, GMT .nc/.grd) with lat/lon coordinates")


def _listed(names, last=","):
    """Names in plain words: ``a, b, c`` (``last="or"``: ``a, b or c``); ``none`` if empty."""
    names = [str(n) for n in names]
    if len(names) < 2 or last == ",":
        return ", ".join(names) or "none"
    return f"{', '.join(names[:-1])} {last} {names[-1]}"


def _is_cf_by_name(v, kind):
    """Whether variable ``v`` declares CF ``standard_name`` ``kind`` (latitude, longitude)."""
    return v.attrs.get("standard_name") == _CF[kind][0]


def _is_cf_by_units(v, kind):
    """Whether variable ``v``'s ``units`` are CF degrees north (latitude) or east."""
    return units_attr(v.attrs).strip().lower() in _CF[kind][1]


def _find_axis(ds, names, kind, label):
    """Name of the latitude or longitude coordinate: by name (any case), then CF attributes."""
    found = {str(n).lower(): n for n in [*ds.coords, *ds.dims, *ds.data_vars]}
    for n in names:
        if n in found:
            return found[n]
    # a 1-D dimension coordinate first, standard_name before units: a 2-D node_lat(j, i)
    # data variable listed first was taken for the axis of j (standard_name latitude)
    ranked = sorted((v.dims != (n,), v.ndim != 1, not _is_cf_by_name(v, kind), i, n)
                    for i, (n, v) in enumerate(ds.variables.items())
                    if _is_cf_by_name(v, kind) or _is_cf_by_units(v, kind))
    if ranked:
        return ranked[0][-1]
    standard = _CF[kind][0]
    raise ValueError(f"{label} has no {kind} coordinate: expected one named "
                     f"{_listed(names, 'or')} (any case) or with CF standard_name {standard}; "
                     f"it has {_listed(ds.variables)}")


def _axis_dim(ds, name, label):
    """The dimension along which coordinate ``name`` varies (it must be 1-D)."""
    if name not in ds.variables:
        raise ValueError(f"{label}: dimension {name!r} has no coordinate values; the "
                         "file must store the node latitudes and longitudes")
    v = ds.variables[name]
    if v.ndim != 1:
        raise ValueError(f"{label}: coordinate {name!r} is {v.ndim}-D (along "
                         f"{_listed(v.dims)}); jaxgrav reads regular latitude/longitude grids "
                         "(1-D coordinates), not curvilinear or projected ones")
    return v.dims[0]


def _grid_dims(ds, lat_name, lon_name, label):
    """The latitude and longitude dimensions: two different 1-D axes (else ValueError)."""
    lat_dim, lon_dim = _axis_dim(ds, lat_name, label), _axis_dim(ds, lon_name, label)
    if lat_dim == lon_dim:  # a table of points, e.g. a montecarlo file's start_lat/start_lon
        raise ValueError(
            f"{label} is not a latitude/longitude grid: its latitudes {str(lat_name)!r} and "
            f"longitudes {str(lon_name)!r} are both listed along one dimension, "
            f"{str(lat_dim)!r} ({ds.sizes[lat_dim]} values), as in a table of points or runs "
            "(e.g. a montecarlo result); expected a NetCDF grid with a 1-D latitude axis and "
            "a separate 1-D longitude axis (e.g. lat, lon)")
    return lat_dim, lon_dim


def _choose_var(ds, var, dims, label, exclude):
    gridded = [str(v) for v in ds.data_vars if set(dims) <= set(ds[v].dims)
               and str(v) not in exclude]
    if var is None:  # node latitudes/longitudes (degrees_north, ...) are never the map
        gridded = [v for v in gridded if not any(
            test(ds[v], kind) for test in (_is_cf_by_name, _is_cf_by_units) for kind in _CF)]
    if var is None:
        if not gridded:  # was "holds 0 gridded variables (none); choose one with --var"
            raise ValueError(f"{label} holds no variable on its latitude/longitude grid (it "
                             f"has {_listed(ds.variables)}); expected a map variable along "
                             f"{_listed(dims, 'and')}, e.g. gravity({', '.join(dims)})")
        if len(gridded) != 1:
            raise ValueError(f"{label} holds {len(gridded)} gridded variables "
                             f"({_listed(gridded)}); choose one with --var NAME")
        return gridded[0]
    if var not in ds.variables:
        raise ValueError(f"{label} has no variable {var!r}; its gridded variables are "
                         f"{_listed(gridded)}")
    if not set(dims) <= set(ds[var].dims):
        raise ValueError(f"variable {var!r} of {label} is not on the latitude/longitude grid "
                         f"(dimensions {_listed(dims)}): its dimensions are "
                         f"{_listed(ds[var].dims)}; gridded variables: {_listed(gridded)}")
    return var


def _open(path, group=None):
    """``xr.open_dataset`` with times left as numbers, quiet about a variable that declares
    both ``_FillValue`` and ``missing_value`` (both are missing, as CF says and xarray reads
    them; it said so in two lines of ``{np.float64(-8888.0), ...}`` on stderr)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "variable .* has multiple fill values",
                                xr.SerializationWarning)
        return xr.open_dataset(path, decode_times=False, group=group)


def read_netcdf(path, var=None, *, ndim=None, exclude=()):
    """Read one gridded variable and its coordinates from a NetCDF file.

    Parameters
    ----------
    path : str or Path
        NetCDF file with 1-D latitude and longitude coordinates (see the module notes).
    var : str, optional
        Data variable to read; required when the file holds more than one.
    ndim : int, optional
        Refuse a variable with more than ``ndim`` dimensions after singleton ones are
        squeezed (2 for a map: a depth or time axis of several levels is named).
    exclude : sequence of str
        Variables never chosen when ``var`` is None (e.g. the map's uncertainty).

    Returns
    -------
    GridArrays
        ``lat, lon, values (..., ny, nx), name, units``; coordinates checked regular.

    Warns
    -----
    UndeclaredFillWarning
        When nodes hold an undeclared fill value (read as NaN).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        Not a NetCDF file, no latitude/longitude coordinates (or 2-D ones), ``var``
        missing, ambiguous or not gridded, an extra dimension beyond ``ndim``, latitudes
        outside ±90° or longitudes outside −360…720° (projected coordinates), coordinates
        declared in radians, or a repeated, unsorted, irregular or non-finite coordinate node.
    """
    check_netcdf_file(path)
    label = f"map {str(path)!r}"
    try:
        ds = _open(path)
        groups = [] if ds.variables else [  # NetCDF-4 with its grid in a group: "it has none"
            name for name, node in xr.open_groups(path, decode_times=False).items()
            if node.variables]
        if len(groups) == 1:
            ds.close()
            ds = _open(path, group=groups[0])
    except (OSError, ValueError, RuntimeError) as err:
        msg = str(err).splitlines()[0] if str(err) else type(err).__name__
        # "[Errno -101] NetCDF: HDF error: '/path'": the errno and the path again dropped
        msg = re.sub(r"^\[Errno -?\d+\]\s*", "", msg).replace(f": {str(path)!r}", "")
        msg = msg.replace(f": {str(Path(path).absolute())!r}", "")
        damaged = (" (the file may be truncated or damaged: copy it again)"
                   if "HDF error" in msg or "NetCDF: " in msg else "")
        raise ValueError(f"{label} cannot be read as NetCDF: {msg}{damaged}") from None
    if len(groups) > 1:
        raise ValueError(f"{label} holds no variables at its root and {len(groups)} groups "
                         f"with variables ({_listed(groups)}); expected one grid: extract it "
                         "first (e.g. ncks -G : -g GROUP IN OUT.nc)")
    with ds:
        if _GMT4 <= set(map(str, ds.variables)):  # GMT 4's native grid: "no latitude"
            lat, lon, values, units, attrs, encoding = _gmt4_grid(ds, var, label)
            var, lat_name, lon_name = "z", "y_range", "x_range"
        else:
            lat, lon, values, units, attrs, encoding, var, lat_name, lon_name = _cf_grid(
                ds, var, ndim, exclude, label)
    if values.dtype.kind not in "fciu":  # text was "could not convert string to float:
        # np.str_('a')"; a true/false mask read as a field of 0 and 1
        what = "true/false values (a mask?)" if values.dtype.kind == "b" else "text"
        raise ValueError(f"variable {var!r} of {label} holds {what}, not numbers "
                         f"(dtype {values.dtype}); expected the map's values (e.g. mGal)")
    if values.dtype.kind not in "fc":
        values = values.astype(float)
    values = undeclared_fills(outside_valid_range(values, attrs, encoding), label, var)
    values, units = map_units(values, units)
    lat, lon = _checked_axes(lat, lon, label, lat_name, lon_name)
    lon, order = rolled_columns(lon, label)  # -280..80: global from another meridian
    return GridArrays(lat, lon, values if order is None else values[..., order], str(var), units)


def _cf_grid(ds, var, ndim, exclude, label):
    """A CF or GMT 5+ grid's coordinates, values (``(..., ny, nx)``), units, the variable's
    attributes and encoding, its name and those of its coordinates."""
    lat_name = _find_axis(ds, LAT_NAMES, "latitude", label)
    lon_name = _find_axis(ds, LON_NAMES, "longitude", label)
    lat_dim, lon_dim = _grid_dims(ds, lat_name, lon_name, label)
    var = _choose_var(ds, var, (lat_dim, lon_dim), label, exclude)
    da = ds[var]
    extra = [d for d in da.dims if d not in (lat_dim, lon_dim)]
    extra = [d for d in extra if da.sizes[d] > 1]
    da = da.squeeze([d for d in da.dims if d not in (*extra, lat_dim, lon_dim)], drop=True)
    if ndim is not None and len(extra) + 2 > ndim:
        sizes = ", ".join(f"{d}: {da.sizes[d]}" for d in da.dims)
        raise ValueError(
            f"variable {var!r} of {label} has dimensions ({sizes}); a map must be 2-D "
            f"(latitude, longitude): extract one level of {extra[0]!r} first (e.g. "
            f"ncks -d {extra[0]},0 IN OUT)")
    values = np.asarray(da.transpose(*extra, lat_dim, lon_dim).values)
    lat, lon = (unpacked_axis(ds.variables[n], n, label) for n in (lat_name, lon_name))
    units = units_attr(da.attrs)  # "Units", "unit": m s-2 were sampled as mGal, exit 0
    lat, lon = (axis_degrees(c, units_attr(ds.variables[n].attrs), n, label)
                for n, c in ((lat_name, lat), (lon_name, lon)))
    return (lat, lon, values, units, da.attrs, da.encoding, var, lat_name, lon_name)


_GMT4 = {"x_range", "y_range", "dimension", "z"}
_GMT_PLACEHOLDERS = ("", "z", "user_z_unit")


def _gmt4_grid(ds, var, label):
    """Coordinates, values, units, attributes and encoding of a GMT 4 native netCDF grid
    (``x_range``, ``y_range``, ``dimension``, ``z(xysize)`` stored row by row from the
    north; ``node_offset`` 1 for pixel registration), which has no latitude coordinate."""
    if var not in (None, "z"):
        raise ValueError(f"{label} is a GMT 4 native grid, whose one variable is 'z'; got "
                         f"--var {var!r}")
    nx, ny = (int(v) for v in np.ravel(ds["dimension"].values)[:2])
    z = ds["z"]
    if nx < 2 or ny < 2 or z.size != nx * ny:
        raise ValueError(f"{label}: GMT 4 grid variable 'z' holds {z.size} values; its "
                         f"dimension says {nx} x {ny} (at least 2 x 2)")
    pixel = int(np.ravel(z.attrs.get("node_offset", 0))[0]) == 1
    (x0, x1), (y0, y1) = (np.ravel(ds[n].values).astype(float)[:2] for n in ("x_range",
                                                                          "y_range"))
    lon = x0 + (np.arange(nx) + 0.5 * pixel) * (x1 - x0) / (nx - 1 + pixel)
    lat = y1 - (np.arange(ny) + 0.5 * pixel) * (y1 - y0) / (ny - 1 + pixel)
    units = str(z.attrs.get("units", ds["z_range"].attrs.get("units", "") if "z_range" in ds
                            else ""))
    units = "" if units.strip().lower() in _GMT_PLACEHOLDERS else units
    return lat, lon, np.asarray(z.values).reshape(ny, nx), units, z.attrs, z.encoding


def _checked_axes(lat, lon, label, lat_name, lon_name):
    """Latitudes and contiguous longitudes, regular and in range (else ValueError)."""
    for name, c in ((lat_name, lat), (lon_name, lon)):
        if c.dtype.kind not in "iuf":
            raise ValueError(f"{label}: coordinate {name!r} holds {c.dtype} values; expected "
                             "degrees")
    far = np.abs(lat.astype(float)) > 90.0
    if far.any() or np.any(np.abs(lon.astype(float) - 180.0) > 540.0):
        name, c = (lat_name, lat) if far.any() else (lon_name, lon)
        value = c[far][0] if far.any() else c[np.abs(c - 180.0) > 540.0][0]
        # whole degrees x 1e7 were named "irregular" (step 416666, not 416667)
        e7 = (np.all(np.round(c) == c) and np.abs(c).max() / 1e7 <= (90 if far.any() else 360))
        raise ValueError(f"{label}: coordinate value {float(value):g} is not a latitude/"
                         "longitude in degrees (projected coordinates in metres?); jaxgrav "
                         "reads geographic grids: reproject it first (e.g. gmt grdproject -I)"
                         + (f"; whole degrees x 1e7? declare it: e.g. ncatted -a scale_factor,"
                            f"{name},c,d,1e-7" if e7 else ""))
    regular_axis(lat, str(lat_name), label)
    lon = eastward_longitudes(lon)  # -236..-224: the -360..0 convention
    joined = contiguous_longitudes(lon)
    if joined is not lon:
        try:  # a 360° jump only: use the joined axis; otherwise name the file's own values
            regular_axis(joined, str(lon_name), label)
            lon = joined
        except ValueError:
            pass
    regular_axis(lon, str(lon_name), label)
    return lat, lon


def write_netcdf(grid, path, *, attrs=None, force=False):
    """Write a grid to NetCDF (CF ``lat``/``lon`` coordinates), atomically.

    Parameters
    ----------
    grid : Grid
        Values ``(..., ny, nx)``; leading axes become ``dim_0``, ``dim_1``, ...
    path : str or Path
        Output file. An existing file is replaced only with ``force=True``.
    attrs : dict, optional
        Global attributes (provenance).
    force : bool
        Overwrite an existing file.
    """
    lead = [f"dim_{i}" for i in range(grid.values.ndim - 2)]
    da = xr.DataArray(
        np.asarray(grid.values),
        dims=[*lead, "lat", "lon"],
        coords={
            "lat": ("lat", grid.lat, {"units": "degrees_north", "standard_name": "latitude"}),
            "lon": ("lon", grid.lon, {"units": "degrees_east", "standard_name": "longitude"}),
        },
        attrs={"units": grid.units} if grid.units else {},
    )
    ds = da.to_dataset(name=grid.name or "z")
    ds.attrs.update(attrs or {})
    with atomic_output(path, force=force) as tmp:
        ds.to_netcdf(tmp)
