"""Small real-data regional maps shipped with jaxgrav, and their loader.

The files are derived from the EGM2008 geoid (tide-free) by
:mod:`jaxgrav.fields.egm2008` in a spherical approximation; see ``README.md`` in
this directory and each file's global attributes (:func:`provenance`) for the
method, the maximum degree and the command that rebuilds them.

======== ============================================================================
name     contents
======== ============================================================================
ryukyu   gravity anomaly (mGal, h = 0) over 24–36° N, 124–136° E: ``anomaly_0p5deg``
         (0.5°, degree 359, 25 × 25) and ``anomaly_2p5min`` (2.5′, degree 2159,
         289 × 289)
qinling  deflections of the vertical ξ, η (arcsec) over 32–41° N, 105–114° E at
         3′ (181 × 181) for heights 0, 10 000 and 20 000 m (degree 360), the
         degree-360 coefficients of the model, and ξ, η of the full degree-2159
         model at the 3333 fixes of paper C's trajectory (``paper_c_truth``)
======== ============================================================================

Examples
--------
>>> from jaxgrav import datasets
>>> datasets.available()
['qinling', 'ryukyu']
>>> maps = datasets.load("ryukyu")
>>> maps["anomaly_2p5min"].values.shape
(289, 289)
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import NamedTuple

import jax.numpy as jnp
import netCDF4
import numpy as np
import xarray as xr

from jaxgrav.fields.harmonics import SphericalHarmonics
from jaxgrav.grid import Grid
from jaxgrav.grid_files import read_netcdf

__all__ = ["TrackDeflections", "available", "load", "load_map", "map_for_track", "path",
           "provenance"]

_HERE = Path(__file__).resolve().parent

# name -> {key: file name}; keys are those of path() and provenance().
_FILES = {
    "qinling": {
        "dov": "qinling_dov_3min.nc",
        "coefficients": "qinling_egm2008_n360.nc",
        "paper_c_truth": "qinling_paperc_truth_n2159.nc",
    },
    "ryukyu": {
        "anomaly_0p5deg": "ryukyu_anomaly_0p5deg.nc",
        "anomaly_2p5min": "ryukyu_anomaly_2p5min.nc",
    },
}


class TrackDeflections(NamedTuple):
    """Deflections of the vertical at the fixes of a track (float64 NumPy arrays).

    Attributes
    ----------
    lat, lon : ndarray, shape (P,)
        Fix positions (degrees).
    h : ndarray, shape (P,)
        Heights above the sphere of radius R (m).
    xi, eta : ndarray, shape (P,)
        Deflection components (arcsec).
    """

    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    xi: np.ndarray
    eta: np.ndarray


def available():
    """Names of the shipped datasets.

    Returns
    -------
    list of str
        Sorted dataset names, e.g. ``["qinling", "ryukyu"]``.
    """
    return sorted(_FILES)


def _check(name):
    if name not in _FILES:
        raise ValueError(f"unknown dataset {name!r}; expected one of "
                         f"{', '.join(available())}")


def path(name):
    """Paths of a dataset's files.

    Parameters
    ----------
    name : str
        Dataset name (see :func:`available`).

    Returns
    -------
    dict of str to pathlib.Path
        For ``"ryukyu"``: keys ``anomaly_0p5deg``, ``anomaly_2p5min``; for
        ``"qinling"``: keys ``dov`` (ξ and η on (height, lat, lon)),
        ``coefficients`` and ``paper_c_truth``.

    Raises
    ------
    ValueError
        Unknown name.
    FileNotFoundError
        A file is missing from the installation.
    """
    _check(name)
    paths = {key: _HERE / fname for key, fname in _FILES[name].items()}
    missing = [str(p) for p in paths.values() if not p.is_file()]
    if missing:
        raise FileNotFoundError(
            f"dataset {name!r} is incomplete, missing {', '.join(missing)}; rebuild it with "
            f"`jaxgrav data egm2008 --region {name} --out {_HERE} --force` "
            "(needs pip install 'jaxgrav[egm2008]')"
        )
    return paths


def load(name):
    """Load a shipped dataset.

    Parameters
    ----------
    name : str
        ``"ryukyu"`` or ``"qinling"``.

    Returns
    -------
    dict
        ``"ryukyu"``: ``{"anomaly_0p5deg": Grid, "anomaly_2p5min": Grid}``, gravity
        anomaly in mGal, values ``(ny, nx)``.

        ``"qinling"``: ``{"xi": Grid, "eta": Grid, "height": ndarray,
        "coefficients": SphericalHarmonics}``: deflections in arcsec with values
        ``(3, ny, nx)`` (one layer per height), the heights ``[0, 1e4, 2e4]`` in m
        above the sphere of radius R, and the degree-360 model; ``"paper_c_truth"``,
        a :class:`TrackDeflections` of the full degree-2159 model at the 3333 fixes of
        :func:`jaxgrav.scenarios.paper_c.paper_c_trajectory` (each point evaluated
        exactly: paper C's finer truth).

    Raises
    ------
    ValueError
        Unknown name.
    """
    paths = path(name)
    if name == "ryukyu":
        return {key: Grid.from_netcdf(p, var="gravity_anomaly") for key, p in paths.items()}

    with xr.open_dataset(paths["dov"]) as ds:
        height = np.asarray(ds["height"].values, dtype=float)
    with xr.open_dataset(paths["paper_c_truth"]) as ds:
        truth = TrackDeflections(*(np.asarray(ds[v].values, dtype=np.float64)
                                   for v in TrackDeflections._fields))
    return {
        "xi": Grid.from_netcdf(paths["dov"], var="xi"),
        "eta": Grid.from_netcdf(paths["dov"], var="eta"),
        "height": height,
        "coefficients": SphericalHarmonics.from_netcdf(paths["coefficients"]),
        "paper_c_truth": truth,
    }


def _plain(value):
    """NumPy scalars and arrays from NetCDF attributes as plain Python values."""
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def provenance(name):
    """Global attributes (provenance) of a dataset's files.

    Parameters
    ----------
    name : str
        Dataset name.

    Returns
    -------
    dict of str to dict
        Keyed like :func:`path`; each value maps attribute names to plain Python
        values (``model``, ``max_degree``, ``approximation``, ``date_built``,
        ``command``, ...).

    Raises
    ------
    ValueError
        Unknown name.
    """

    out = {}
    for key, p in path(name).items():
        with netCDF4.Dataset(p) as ds:
            out[key] = {k: _plain(ds.getncattr(k)) for k in ds.ncattrs()}
    return out


def load_map(path, var=None, dataset_default="anomaly_2p5min", *, error_var=None,
             allow_nan=False):
    """A map by name or path: a shipped dataset (``ryukyu``, ``ryukyu:KEY``) or a NetCDF file.

    The loader behind every ``--map`` option of the ``jaxgrav`` command; files are read
    by :func:`jaxgrav.grid_files.read_netcdf` (lat/lon, latitude/longitude or GMT y/x
    coordinates, singleton extra dimensions squeezed, descending axes flipped, a
    regional 0–360 map across 0° made contiguous, a non-NetCDF file refused in one line).

    Parameters
    ----------
    path : str or pathlib.Path
        A NetCDF grid with lat/lon coordinates, or a shipped dataset name from
        :func:`available`, optionally ``NAME:KEY`` for one of its maps. An existing
        file of that name wins over the dataset.
    var : str, optional
        The variable to read from a NetCDF file with several.
    dataset_default : str
        The dataset's map when no ``KEY`` is given (default the 2.5′ anomaly).
    error_var : str, optional
        A second variable of the same file on the same grid: the map's 1-σ uncertainty
        (map units, ≥ 0), returned as a second Grid (never chosen as ``var``).
    allow_nan : bool
        Keep missing (NaN, fill-value) nodes in the Grid, as a mask: for commands that
        then take :meth:`Grid.finite_region` around the track (``grid.n_missing`` counts
        them). By default a map with missing nodes is refused, naming their count and
        the first one's position.

    Returns
    -------
    Grid, or (Grid, Grid)
        Values ``(ny, nx)``; with ``error_var`` the map and its uncertainty.

    Raises
    ------
    FileNotFoundError
        No such file (and no such dataset).
    ValueError
        The dataset has no map ``KEY`` (or no uncertainty); a file that is not a 2-D
        geographic NetCDF grid (see :func:`~jaxgrav.grid_files.read_netcdf`); missing
        nodes without ``allow_nan``; an uncertainty that is negative or on another grid.
    """
    name, _, key = str(path).partition(":")
    if name in available() and not Path(path).exists():
        if error_var is not None:
            raise ValueError(f"the shipped map {str(path)!r} has no uncertainty variable "
                             f"({error_var!r}); give a NetCDF map file that holds one")
        maps = {k: v for k, v in load(name).items() if isinstance(v, Grid)}
        key = key or dataset_default
        if key not in maps:
            raise ValueError(f"dataset {name!r} has no map {key!r}; expected one of "
                             f"{', '.join(sorted(maps))}")
        if var is not None and var not in (maps[key].name, key):  # was ignored, exit 0
            raise ValueError(f"the shipped map {str(path)!r} has one variable, "
                             f"{maps[key].name!r}; got the variable {var!r} to read (leave it "
                             "out, or give a NetCDF file that holds it)")
        return maps[key]
    label = f"map {str(path)!r}"
    exclude = () if error_var is None else (error_var,)
    arrays = read_netcdf(path, var, ndim=2, exclude=exclude)
    grid = _grid_with_mask(arrays, label, allow_nan)
    if error_var is None:
        return grid
    err = read_netcdf(path, error_var, ndim=2)
    if not (np.array_equal(err.lat, arrays.lat) and np.array_equal(err.lon, arrays.lon)):
        raise ValueError(f"the uncertainty {error_var!r} of {label} is not on the grid of "
                         f"{arrays.name!r}")
    negative = np.asarray(err.values) < 0
    if negative.any():
        i = np.unravel_index(int(np.flatnonzero(negative)[0]), negative.shape)
        raise ValueError(f"the uncertainty {error_var!r} of {label} must be >= 0 (1-sigma, "
                         f"{err.units or 'map units'}); found {float(err.values[i]):g} at lat "
                         f"{float(err.lat[i[0]]):g}, lon {float(err.lon[i[1]]):g} "
                         f"({int(negative.sum())} negative node(s))")
    return grid, _grid_with_mask(err, f"the uncertainty {error_var!r} of {label}", allow_nan)


def map_for_track(path, var, lat, lon, margin_m, *, max_missing=0.0, option="--map",
                  error_var=None):
    """The map a track needs: :func:`load_map` keeping NaN nodes, then its region.

    One call for the commands: the file (or shipped map) is read with missing nodes
    kept, and :meth:`Grid.finite_region` returns the map recentred when it is global and
    its seam cuts the track's region, cut to the region when it has missing nodes
    anywhere, and refused when the region itself has missing nodes (more than
    ``max_missing`` of them).

    Parameters
    ----------
    path, var
        As :func:`load_map`.
    lat, lon : array_like
        The track (degrees).
    margin_m : float
        How far (m) the method reaches from the track, e.g. a matcher's drift radius.
    max_missing : float
        Fraction of missing nodes accepted in the region (0 until the method masks them).
    option : str
        The command's option, for messages.
    error_var : str, optional
        The file's uncertainty variable, read in the same pass (:func:`load_map`).

    Returns
    -------
    Grid
        The map's region; with ``error_var``, ``(region, uncertainty)`` (the uncertainty
        Grid whole, as read).
    """
    loaded = load_map(path, var, allow_nan=True, error_var=error_var)
    grid, err = loaded if error_var is not None else (loaded, None)
    region = grid.finite_region(lat, lon, margin_m, max_missing=max_missing,
                                source=f"{option} {str(path)!r}")
    return region if error_var is None else (region, err)


def _grid_with_mask(arrays, label, allow_nan):
    """A Grid from read_netcdf's arrays, missing nodes kept as NaN (or refused)."""
    lat, lon, values, name, units = arrays
    missing = ~np.isfinite(values)
    n = int(missing.sum())
    if n and not allow_nan:
        i = np.unravel_index(int(np.flatnonzero(missing)[0]), missing.shape)
        raise ValueError(f"{label} has {n} missing (NaN or fill-value) node(s) of {missing.size}, "
                         f"the first at lat {float(lat[i[0]]):g}, lon {float(lon[i[1]]):g}; "
                         "this needs a complete map")
    grid = Grid.from_arrays(lat, lon, np.where(missing, 0.0, values).astype(values.dtype),
                            name=name, units=units)
    if not n:
        return grid
    if lat[1] < lat[0]:
        missing = missing[..., ::-1, :]
    if lon[1] < lon[0]:
        missing = missing[..., ::-1]
    nan = jnp.asarray(np.nan, dtype=grid.values.dtype)
    return dataclasses.replace(grid, values=jnp.where(jnp.asarray(missing), nan, grid.values))
