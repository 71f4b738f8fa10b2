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
         3′ (181 × 181) for heights 0, 10 000 and 20 000 m (degree 360), plus the
         degree-360 coefficients of the model
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

from pathlib import Path

import netCDF4
import numpy as np
import xarray as xr

from jaxgrav.fields.harmonics import SphericalHarmonics
from jaxgrav.grid import Grid

__all__ = ["available", "load", "load_map", "path", "provenance"]

_HERE = Path(__file__).resolve().parent

# name -> {key: file name}; keys are those of path() and provenance().
_FILES = {
    "qinling": {
        "dov": "qinling_dov_3min.nc",
        "coefficients": "qinling_egm2008_n360.nc",
    },
    "ryukyu": {
        "anomaly_0p5deg": "ryukyu_anomaly_0p5deg.nc",
        "anomaly_2p5min": "ryukyu_anomaly_2p5min.nc",
    },
}


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
        raise ValueError(f"unknown dataset {name!r}; available: {available()}")


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
        ``"qinling"``: keys ``dov`` (ξ and η on (height, lat, lon)) and
        ``coefficients``.

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
            f"dataset {name!r} is incomplete, missing {missing}; rebuild it with "
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
        above the sphere of radius R, and the degree-360 model.

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
    return {
        "xi": Grid.from_netcdf(paths["dov"], var="xi"),
        "eta": Grid.from_netcdf(paths["dov"], var="eta"),
        "height": height,
        "coefficients": SphericalHarmonics.from_netcdf(paths["coefficients"]),
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


def load_map(path, var=None, dataset_default="anomaly_2p5min"):
    """A map by name or path: a shipped dataset (``ryukyu``, ``ryukyu:KEY``) or a NetCDF file.

    The loader behind every ``--map`` option of the ``jaxgrav`` command.

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

    Returns
    -------
    Grid

    Raises
    ------
    ValueError
        The dataset has no map ``KEY``; and the errors of :meth:`Grid.from_netcdf`.
    """
    name, _, key = str(path).partition(":")
    if name in available() and not Path(path).exists():
        maps = load(name)
        key = key or dataset_default
        if key not in maps:
            raise ValueError(f"dataset {name!r} has no map {key!r}; it has {sorted(maps)}")
        return maps[key]
    return Grid.from_netcdf(path, var=var)
