"""Magnetic maps: IGRF main field plus the paper's polynomial anomaly (paper B).

Paper B's map is the main field (EMM in the paper; here IGRF, the public model
shipped by the ``ppigrf`` package, extra ``jaxgrav[mag]``) plus an anomaly built by
a polynomial method and scaled to −1296.8 … +1620.0 nT, on 39–41°N, 115–117°E at
0.01° (200 × 200 nodes), plus measurement noise.

Polynomial anomaly (the paper gives no formula; this is the construction used
here, fully determined by ``seed``):

1. Normalise the node coordinates to ``x, y ∈ [−1, 1]`` (east, north).
2. ``A(x, y) = Σ_{i+j ≤ degree} c_ij P_i(x) P_j(y)`` with Legendre polynomials
   ``P_i`` and coefficients ``c_ij ~ N(0, 1) / (1 + i + j)^decay`` drawn from
   ``numpy.random.default_rng(seed)``; ``c_00 = 0``. Legendre polynomials keep the
   terms well conditioned on [−1, 1]; the ``decay`` gives a red spectrum (large
   features dominate, as in real anomaly maps); ``degree`` sets the finest feature,
   about ``2 / degree`` of the region.
3. Scale linearly so that the minimum and maximum over the nodes are exactly the
   requested range.

The map is built in NumPy (once, outside any jit) and returned as a
:class:`~jaxgrav.grid.Grid` in nT, ready for the matchers.
"""

import datetime
from typing import NamedTuple

import numpy as np
from numpy.polynomial import legendre

from jaxgrav.grid import Grid

__all__ = [
    "PAPER_B_RANGE_NT",
    "PAPER_B_REGION",
    "MagneticMap",
    "igrf_total_intensity",
    "magnetic_map",
    "polynomial_anomaly",
    "read_anomaly",
]

PAPER_B_REGION = (39.0, 41.0, 115.0, 117.0)
"""``(lat_min, lat_max, lon_min, lon_max)`` of paper B's map (degrees)."""

PAPER_B_RANGE_NT = (-1296.8, 1620.0)
"""Range of paper B's polynomial anomaly (nT)."""


class MagneticMap(NamedTuple):
    """A magnetic map and its parts, all in nT on the same nodes.

    Attributes
    ----------
    total : Grid
        Total intensity: main field + anomaly (+ map noise).
    main : Grid
        IGRF total intensity.
    anomaly : Grid
        Polynomial anomaly (+ map noise).
    """

    total: Grid
    main: Grid
    anomaly: Grid


def _ppigrf():
    try:
        import ppigrf
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError(
            "the IGRF main field needs the optional package 'ppigrf'; install the 'mag' extra: "
            "pip install 'jaxgrav[mag]'"
        ) from err
    return ppigrf


def _axes(region, step):
    s, n, w, e = (float(v) for v in region)
    if not (-90.0 <= s < n <= 90.0) or not (w < e):
        raise ValueError(
            f"region must be (lat_min, lat_max, lon_min, lon_max) with lat_min < lat_max in "
            f"[-90, 90] and lon_min < lon_max; got {region!r}"
        )
    if not step > 0:
        raise ValueError(f"step must be a positive node spacing (degrees); got {step!r}")
    ny = round((n - s) / step)
    nx = round((e - w) / step)
    if ny < 4 or nx < 4:
        raise ValueError(
            f"step={step!r} gives a {ny}x{nx} grid over region {region!r}; need at least 4x4 nodes"
        )
    return s + step * np.arange(ny), w + step * np.arange(nx)


def igrf_total_intensity(lat, lon, *, height_m=0.0, date=datetime.datetime(2020, 1, 1)):
    """IGRF total intensity ``F = |B|`` (nT) on a grid of nodes.

    Parameters
    ----------
    lat : array_like, shape ``(ny,)``
        Geodetic latitudes (degrees), regular.
    lon : array_like, shape ``(nx,)``
        Longitudes (degrees), regular.
    height_m : float
        Height above the WGS84 ellipsoid (m).
    date : datetime.datetime
        Epoch of the model (IGRF is defined from 1900 to its last epoch + 5 years).

    Returns
    -------
    Grid
        ``(ny, nx)`` values in nT, name ``"F"``.

    Raises
    ------
    ImportError
        If ``ppigrf`` (extra ``mag``) is not installed.
    """
    ppigrf = _ppigrf()
    lat = np.asarray(lat, float)
    lon = np.asarray(lon, float)
    if lat.ndim != 1 or lon.ndim != 1:
        raise ValueError(f"lat and lon must be 1-D node coordinates; got shapes {lat.shape}, "
                         f"{lon.shape}")
    if not isinstance(date, datetime.datetime):
        raise ValueError(f"date must be a datetime.datetime; got {date!r}")
    lon2, lat2 = np.meshgrid(lon, lat)
    be, bn, bu = ppigrf.igrf(lon2, lat2, float(height_m) / 1000.0, date)
    f = np.sqrt(be**2 + bn**2 + bu**2).reshape(lat.size, lon.size)
    return Grid.from_arrays(lat, lon, f, name="F", units="nT")


def polynomial_anomaly(lat, lon, *, seed=0, degree=12, decay=1.0, value_range=PAPER_B_RANGE_NT):
    """Paper B's polynomial anomaly, scaled to a range (see the module docstring).

    Parameters
    ----------
    lat : array_like, shape ``(ny,)``
        Node latitudes (degrees), regular.
    lon : array_like, shape ``(nx,)``
        Node longitudes (degrees), regular.
    seed : int
        Seed of the coefficients.
    degree : int
        Largest total degree ``i + j`` (≥ 1).
    decay : float
        Coefficient decay exponent (≥ 0).
    value_range : tuple of float
        ``(min, max)`` of the scaled anomaly (nT), ``min < max``.

    Returns
    -------
    Grid
        ``(ny, nx)`` anomaly in nT whose node minimum and maximum equal ``value_range``.
    """
    if int(degree) != degree or degree < 1:
        raise ValueError(f"degree must be an integer >= 1; got {degree!r}")
    if not decay >= 0:
        raise ValueError(f"decay must be >= 0; got {decay!r}")
    lo, hi = (float(v) for v in value_range)
    if not lo < hi:
        raise ValueError(f"value_range must be (min, max) with min < max; got {value_range!r}")
    lat = np.asarray(lat, float)
    lon = np.asarray(lon, float)
    y = 2.0 * (lat - lat.min()) / (lat.max() - lat.min()) - 1.0
    x = 2.0 * (lon - lon.min()) / (lon.max() - lon.min()) - 1.0
    rng = np.random.default_rng(seed)
    d = int(degree)
    i, j = np.meshgrid(np.arange(d + 1), np.arange(d + 1), indexing="ij")
    c = rng.standard_normal((d + 1, d + 1)) / (1.0 + i + j) ** decay
    c[(i + j) > d] = 0.0
    c[0, 0] = 0.0
    # legval2d-style evaluation on the grid: a[y, x] = Σ c[i, j] P_i(x) P_j(y)
    px = legendre.legvander(x, d)  # (nx, d+1)
    py = legendre.legvander(y, d)  # (ny, d+1)
    a = py @ c.T @ px.T
    a = lo + (a - a.min()) * (hi - lo) / (a.max() - a.min())
    return Grid.from_arrays(lat, lon, a, name="anomaly", units="nT")


def magnetic_map(region=PAPER_B_REGION, step=0.01, *, height_m=0.0,
                 date=datetime.datetime(2020, 1, 1), seed=0, degree=12, decay=1.0,
                 value_range=PAPER_B_RANGE_NT, map_noise_nt=0.0, main_field=True):
    """Paper B's magnetic map: IGRF total intensity + scaled polynomial anomaly (+ noise).

    Parameters
    ----------
    region : tuple of float
        ``(lat_min, lat_max, lon_min, lon_max)`` (degrees); nodes start at the south-west
        corner, ``round(span/step)`` per axis (paper: 200 × 200).
    step : float
        Node spacing (degrees).
    height_m : float
        Height of the main field (m above the ellipsoid).
    date : datetime.datetime
        IGRF epoch.
    seed, degree, decay, value_range
        Polynomial anomaly, see :func:`polynomial_anomaly`.
    map_noise_nt : float
        σ of white noise added to the anomaly nodes (nT; seeded with ``seed + 1``).
    main_field : bool
        Add the IGRF main field (needs ``ppigrf``); False gives ``total = anomaly`` and
        a zero ``main``.

    Returns
    -------
    MagneticMap
    """
    lat, lon = _axes(region, step)
    if not map_noise_nt >= 0:
        raise ValueError(f"map_noise_nt must be >= 0 (nT); got {map_noise_nt!r}")
    anomaly = polynomial_anomaly(lat, lon, seed=seed, degree=degree, decay=decay,
                                 value_range=value_range)
    a = np.asarray(anomaly.values)
    if map_noise_nt > 0:
        a = a + map_noise_nt * np.random.default_rng(seed + 1).standard_normal(a.shape)
        anomaly = Grid.from_arrays(lat, lon, a, name="anomaly", units="nT")
    if main_field:
        main = igrf_total_intensity(lat, lon, height_m=height_m, date=date)
    else:
        main = Grid.from_arrays(lat, lon, np.zeros_like(a), name="F", units="nT")
    total = Grid.from_arrays(lat, lon, np.asarray(main.values) + a, name="total_intensity",
                             units="nT")
    return MagneticMap(total, main, anomaly)


def read_anomaly(path, var=None, *, add_main_field=False, height_m=0.0,
                 date=datetime.datetime(2020, 1, 1)):
    """A user's magnetic map from NetCDF (nT), optionally with the IGRF main field added.

    Parameters
    ----------
    path : str or Path
        NetCDF file with ``lat``/``lon`` coordinates (see :meth:`Grid.from_netcdf`).
    var : str, optional
        Variable to read when the file holds several.
    add_main_field : bool
        Add IGRF total intensity at the nodes (an anomaly map becomes a total-intensity
        map, comparable with scalar magnetometer readings).
    height_m, date
        Main-field height (m) and epoch.

    Returns
    -------
    Grid
        Values in nT.
    """
    grid = Grid.from_netcdf(path, var)
    if grid.units and grid.units.strip().lower() not in ("nt", "nanotesla", "nanotesla (nt)"):
        raise ValueError(f"the map in {str(path)!r} has units {grid.units!r}; expected nT")
    if not add_main_field:
        return grid
    main = igrf_total_intensity(grid.lat, grid.lon, height_m=height_m, date=date)
    return Grid.from_arrays(grid.lat, grid.lon, np.asarray(grid.values) + np.asarray(main.values),
                            name="total_intensity", units="nT")
