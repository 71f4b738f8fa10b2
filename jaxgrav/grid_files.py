"""NetCDF files of :class:`~jaxgrav.grid.Grid` maps (xarray, GMT and CF conventions).

:func:`read_netcdf` finds the 1-D latitude and longitude coordinates and the gridded
variable of a file and returns plain arrays (:meth:`Grid.from_netcdf` validates them
through :meth:`Grid.from_arrays`); :func:`write_netcdf` writes a grid with CF
``lat``/``lon`` coordinates, atomically. Both are package-internal: use the
:class:`~jaxgrav.grid.Grid` methods.
"""

from pathlib import Path

import numpy as np
import xarray as xr

from jaxgrav._io import atomic_output

LAT_NAMES = ("lat", "latitude", "y")
"""Accepted names of the latitude coordinate, in order of preference."""
LON_NAMES = ("lon", "longitude", "x")
"""Accepted names of the longitude coordinate, in order of preference."""


def read_netcdf(path, var=None):
    """Read one gridded variable and its coordinates from a NetCDF file.

    Parameters
    ----------
    path : str or Path
        NetCDF file with 1-D latitude (one of :data:`LAT_NAMES`) and longitude (one
        of :data:`LON_NAMES`) coordinates.
    var : str, optional
        Data variable to read; required when the file holds more than one.

    Returns
    -------
    lat : ndarray, shape ``(ny,)``
        Latitudes (degrees), in the file's order.
    lon : ndarray, shape ``(nx,)``
        Longitudes (degrees), in the file's order.
    values : ndarray, shape ``(..., ny, nx)``
        The variable, latitude and longitude moved to the last two axes.
    name, units : str
        The variable's name and its ``units`` attribute (``""`` if none).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the coordinates are missing or ``var`` is ambiguous or not gridded.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"path {str(path)!r} does not exist")
    with xr.open_dataset(path) as ds:
        lat_name = next((n for n in LAT_NAMES if n in ds.coords or n in ds.dims), None)
        lon_name = next((n for n in LON_NAMES if n in ds.coords or n in ds.dims), None)
        if lat_name is None or lon_name is None:
            raise ValueError(
                f"{str(path)!r} needs latitude and longitude coordinates named one of "
                f"{LAT_NAMES} and {LON_NAMES}; found {sorted(ds.coords)}"
            )
        candidates = [v for v in ds.data_vars if {lat_name, lon_name} <= set(ds[v].dims)]
        if var is None:
            if len(candidates) != 1:
                raise ValueError(
                    f"{str(path)!r} holds {len(candidates)} gridded variables {candidates}; "
                    "pass var= to choose one"
                )
            var = candidates[0]
        elif var not in candidates:
            raise ValueError(
                f"var {var!r} is not a gridded variable of {str(path)!r}: {candidates}"
            )
        da = ds[var].transpose(..., lat_name, lon_name).load()
        return (
            da[lat_name].values,
            da[lon_name].values,
            da.values,
            str(var),
            str(da.attrs.get("units", "")),
        )


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
