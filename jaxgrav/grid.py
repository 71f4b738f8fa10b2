"""Regular latitude/longitude grids as JAX pytrees.

:class:`Grid` holds map values ``(..., ny, nx)`` (leading axes are channels, such
as layers or field components) as its only pytree leaf; the geometry (first node
and spacing in each direction) is static metadata, so a Grid passes through
``jit``, ``vmap`` and ``grad`` like an array and sampling is differentiable in the
points and in the values.

Latitudes are stored ascending (south to north) and longitudes ascending; input in
either order is accepted and flipped once. Longitudes may be given in the 0–360
or the ±180 convention, for the grid and for the sample points independently:
points are wrapped into the grid's own range. Grids are not periodic in longitude.
"""

import dataclasses
import functools
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import interp
from jaxgrav._io import atomic_output
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import check_finite, check_latitude, check_same_shape, concrete
from jaxgrav.constants import DEG

__all__ = ["Grid", "Window", "make_sampler", "sample"]

_LAT_NAMES = ("lat", "latitude", "y")
_LON_NAMES = ("lon", "longitude", "x")


def _regular_axis(coord, name):
    """Return (first, step, flipped) of a 1-D regular coordinate, or raise."""
    coord = np.asarray(coord, dtype=float)
    if coord.ndim != 1 or coord.size < 2:
        raise ValueError(f"{name} must be a 1-D array of at least 2 nodes; got shape {coord.shape}")
    check_finite(coord, name)
    flipped = coord[1] < coord[0]
    if flipped:
        coord = coord[::-1]
    step = np.diff(coord)
    mean = (coord[-1] - coord[0]) / (coord.size - 1)
    if mean <= 0 or np.max(np.abs(step - mean)) > 1e-6 * abs(mean) + 1e-9:
        raise ValueError(
            f"{name} must be strictly monotonic and regularly spaced; steps range from "
            f"{step.min()!r} to {step.max()!r}"
        )
    return float(coord[0]), float(mean), bool(flipped)


class Window(NamedTuple):
    """Fixed-size windows of grid nodes around points (see :meth:`Grid.window`).

    Attributes
    ----------
    values : Array, shape ``(..., *P, 2k+1, 2k+1)``
        Node values of each window (rows south to north, columns west to east).
    row0, col0 : Array of int32, shape ``P``
        Grid indices of each window's south-west node.
    complete : Array of bool, shape ``P``
        False where the window did not fit inside the grid and was shifted to fit.
    """

    values: jax.Array
    row0: jax.Array
    col0: jax.Array
    complete: jax.Array


class GeographicAxes:
    """Node geometry shared by :class:`Grid` and :class:`jaxgrav.dov.LayeredGrid`.

    Needs ``values`` (last two axes rows × columns) and static ``lat0``, ``dlat``,
    ``lon0``, ``dlon``.
    """

    @property
    def ny(self):
        """Number of latitude rows."""
        return self.values.shape[-2]

    @property
    def nx(self):
        """Number of longitude columns."""
        return self.values.shape[-1]

    @property
    def lat(self):
        """Node latitudes (degrees, ascending), NumPy ``(ny,)``."""
        return self.lat0 + self.dlat * np.arange(self.ny)

    @property
    def lon(self):
        """Node longitudes (degrees, ascending), NumPy ``(nx,)``."""
        return self.lon0 + self.dlon * np.arange(self.nx)

    @property
    def extent(self):
        """``(lon_min, lon_max, lat_min, lat_max)`` in degrees (matplotlib order)."""
        return (
            self.lon0,
            self.lon0 + self.dlon * (self.nx - 1),
            self.lat0,
            self.lat0 + self.dlat * (self.ny - 1),
        )


@pytree_dataclass
class Grid(GeographicAxes):
    """Values on a regular geographic grid.

    Parameters
    ----------
    values : Array, shape ``(..., ny, nx)``
        Node values; row 0 is the southernmost latitude, column 0 the westernmost.
    lat0, dlat : float
        Latitude of row 0 and row spacing (degrees, ``dlat > 0``). Static.
    lon0, dlon : float
        Longitude of column 0 and column spacing (degrees, ``dlon > 0``). Static.
    name, units : str
        Variable name and units (for files and plots). Static.

    Build grids with :meth:`from_arrays` or :meth:`from_netcdf`, which validate.
    """

    values: jax.Array
    lat0: float = static_field()
    dlat: float = static_field()
    lon0: float = static_field()
    dlon: float = static_field()
    name: str = static_field("")
    units: str = static_field("")

    # ------------------------------------------------------------------ building
    @classmethod
    def from_arrays(cls, lat, lon, values, *, name="", units=""):
        """Build a grid from 1-D coordinates and a value array.

        Parameters
        ----------
        lat : array_like, shape ``(ny,)``
            Regularly spaced latitudes (degrees), ascending or descending, in ±90.
        lon : array_like, shape ``(nx,)``
            Regularly spaced longitudes (degrees), ascending or descending, in the
            0–360 or the ±180 convention, spanning at most 360°.
        values : array_like, shape ``(..., ny, nx)``
            Finite node values.
        name, units : str
            Metadata.

        Raises
        ------
        ValueError
            Irregular or non-monotonic coordinates, latitudes beyond ±90, shape
            mismatch, or NaN/inf in ``values``.
        """
        check_latitude(lat, "lat")
        lat0, dlat, flip_y = _regular_axis(lat, "lat")
        lon0, dlon, flip_x = _regular_axis(lon, "lon")
        values = jnp.asarray(values)
        ny, nx = np.size(lat), np.size(lon)
        if values.ndim < 2 or values.shape[-2:] != (ny, nx):
            raise ValueError(
                f"values must have shape (..., {ny}, {nx}) to match lat ({ny},) and lon ({nx},);"
                f" got {values.shape}"
            )
        if (
            (nx - 1) * dlon > 360.0 + 1e-9
            or lon0 < -180.0 - 1e-9
            or lon0 + (nx - 1) * dlon > 360 + 1e-9
        ):
            raise ValueError(
                f"lon must lie within [-180, 360] and span at most 360 degrees; got "
                f"{lon0!r} .. {lon0 + (nx - 1) * dlon!r}"
            )
        check_finite(values, "values")
        if flip_y:
            values = jnp.flip(values, axis=-2)
        if flip_x:
            values = jnp.flip(values, axis=-1)
        return cls(values, lat0, dlat, lon0, dlon, name, units)

    @classmethod
    def from_netcdf(cls, path, var=None):
        """Read a grid from a NetCDF file (xarray, GMT, CF conventions).

        Parameters
        ----------
        path : str or Path
            NetCDF file with 1-D latitude (``lat``, ``latitude`` or ``y``) and longitude
            (``lon``, ``longitude`` or ``x``) coordinates.
        var : str, optional
            Data variable to read; required when the file holds more than one.

        Returns
        -------
        Grid
        """
        import xarray as xr

        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"path {str(path)!r} does not exist")
        with xr.open_dataset(path) as ds:
            lat_name = next((n for n in _LAT_NAMES if n in ds.coords or n in ds.dims), None)
            lon_name = next((n for n in _LON_NAMES if n in ds.coords or n in ds.dims), None)
            if lat_name is None or lon_name is None:
                raise ValueError(
                    f"{str(path)!r} needs latitude and longitude coordinates named one of "
                    f"{_LAT_NAMES} and {_LON_NAMES}; found {sorted(ds.coords)}"
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
            return cls.from_arrays(
                da[lat_name].values,
                da[lon_name].values,
                da.values,
                name=str(var),
                units=str(da.attrs.get("units", "")),
            )

    def to_netcdf(self, path, *, attrs=None, force=False):
        """Write the grid to NetCDF (CF ``lat``/``lon`` coordinates), atomically.

        Parameters
        ----------
        path : str or Path
            Output file. An existing file is replaced only with ``force=True``.
        attrs : dict, optional
            Global attributes (provenance).
        force : bool
            Overwrite an existing file.
        """
        import xarray as xr

        lead = [f"dim_{i}" for i in range(self.values.ndim - 2)]
        da = xr.DataArray(
            np.asarray(self.values),
            dims=[*lead, "lat", "lon"],
            coords={
                "lat": ("lat", self.lat, {"units": "degrees_north", "standard_name": "latitude"}),
                "lon": ("lon", self.lon, {"units": "degrees_east", "standard_name": "longitude"}),
            },
            attrs={"units": self.units} if self.units else {},
        )
        ds = da.to_dataset(name=self.name or "z")
        ds.attrs.update(attrs or {})
        with atomic_output(path, force=force) as tmp:
            ds.to_netcdf(tmp)

    # ------------------------------------------------------------------ geometry
    def spacing_m(self, lat=None):
        """Node spacing ``(dy, dx)`` in metres on the WGS84 ellipsoid.

        Parameters
        ----------
        lat : float or Array, optional
            Latitude (degrees) at which to measure; the grid's central latitude by
            default, in which case Python floats are returned.

        Returns
        -------
        tuple
            North–south and east–west node spacing (m).
        """
        from jaxgrav.geodesy import meridian_radius, prime_vertical_radius

        if lat is None:
            lat_c = self.lat0 + 0.5 * self.dlat * (self.ny - 1)
            return tuple(float(v) for v in self.spacing_m(lat_c))
        dy = meridian_radius(lat) * self.dlat * DEG
        dx = prime_vertical_radius(lat) * jnp.cos(jnp.asarray(lat) * DEG) * self.dlon * DEG
        return dy, dx

    def fractional_index(self, lat, lon):
        """Fractional (row, column) indices of points; longitudes wrapped into the grid's range.

        Parameters
        ----------
        lat, lon : array_like
            Points (degrees), broadcast together.

        Returns
        -------
        tuple of Array
            ``(iy, ix)``; inside the grid when ``0 ≤ iy ≤ ny−1`` and ``0 ≤ ix ≤ nx−1``.
        """
        lat = jnp.asarray(lat)
        lon = jnp.asarray(lon)
        dtype = jnp.result_type(lat.dtype, lon.dtype, float)
        lon_w = self.lon0 + jnp.mod(lon.astype(dtype) - self.lon0, 360.0)
        return (lat.astype(dtype) - self.lat0) / self.dlat, (lon_w - self.lon0) / self.dlon

    def contains(self, lat, lon):
        """Boolean mask of points inside the grid (edges included), points' broadcast shape."""
        iy, ix = self.fractional_index(lat, lon)
        eps = interp._edge_eps(iy.dtype, max(self.ny, self.nx))
        return (iy >= -eps) & (iy <= self.ny - 1 + eps) & (ix >= -eps) & (ix <= self.nx - 1 + eps)

    # ------------------------------------------------------------------ sampling
    def sample(self, lat, lon, method="bilinear", *, strict=False):
        """Interpolate the grid at points; see :func:`sample`."""
        return sample(self, lat, lon, method, strict=strict)

    def refine(self, factor, method="bilinear"):
        """Subdivide every cell ``factor`` times (paper A: 0.5° → 0.005° at factor 100).

        Parameters
        ----------
        factor : int
            Integer subdivision factor ≥ 1 (static).
        method : {"bilinear", "bicubic"}
            Interpolant used for the new nodes; the old nodes keep their values.

        Returns
        -------
        Grid
            ``((ny−1)·factor + 1, (nx−1)·factor + 1)`` nodes over the same extent.
        """
        if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
            raise ValueError(f"factor must be an integer >= 1; got {factor!r}")
        interp._check_method(method)
        factor = int(factor)
        wy = interp.interpolation_matrix(
            self.ny, np.arange((self.ny - 1) * factor + 1) / factor, method
        )
        wx = interp.interpolation_matrix(
            self.nx, np.arange((self.nx - 1) * factor + 1) / factor, method
        )
        dtype = jnp.result_type(self.values.dtype, float)
        v = jnp.asarray(wy, dtype) @ self.values.astype(dtype) @ jnp.asarray(wx.T, dtype)
        return dataclasses.replace(self, values=v, dlat=self.dlat / factor, dlon=self.dlon / factor)

    def window(self, lat, lon, half_size):
        """Fixed-size square windows of nodes centred on the node nearest each point.

        Parameters
        ----------
        lat, lon : array_like
            Window centres (degrees), broadcast to shape ``P``.
        half_size : int
            Half-width k in nodes (static); windows are ``(2k+1) × (2k+1)``.

        Returns
        -------
        Window
            Values, south-west indices and a ``complete`` flag. A window that would
            cross the grid's edge is shifted inside and flagged ``complete=False``.

        Raises
        ------
        ValueError
            If the window is larger than the grid.
        """
        k = int(half_size)
        if k < 0 or 2 * k + 1 > min(self.ny, self.nx):
            raise ValueError(
                f"half_size must be in [0, {(min(self.ny, self.nx) - 1) // 2}] for a "
                f"{self.ny}x{self.nx} grid; got {half_size!r}"
            )
        iy, ix = self.fractional_index(lat, lon)
        r = jnp.round(iy).astype(jnp.int32) - k
        col = jnp.round(ix).astype(jnp.int32) - k
        size = 2 * k + 1
        r_in = jnp.clip(r, 0, self.ny - size)
        c_in = jnp.clip(col, 0, self.nx - size)
        complete = (r == r_in) & (col == c_in) & jnp.isfinite(iy) & jnp.isfinite(ix)
        lead = self.values.shape[:-2]

        def one(r0, c0):
            start = (0,) * len(lead) + (r0, c0)
            return jax.lax.dynamic_slice(self.values, start, (*lead, size, size))

        flat = jax.vmap(one)(r_in.reshape(-1), c_in.reshape(-1))  # (M, *lead, s, s)
        vals = jnp.moveaxis(flat, 0, len(lead)).reshape(*lead, *r.shape, size, size)
        return Window(vals, r_in, c_in, complete)

    # ------------------------------------------------------------------ derived maps
    def gradient(self):
        """Horizontal gradient of the field in units per metre.

        Second-order central differences inside, second-order one-sided at the
        edges, scaled by the WGS84 radii of curvature of each row.

        Returns
        -------
        tuple of Grid
            ``(d_north, d_east)``, same geometry, units ``units + "/m"``.
        """
        from jaxgrav.geodesy import meridian_radius, prime_vertical_radius

        v = jnp.asarray(self.values, dtype=jnp.result_type(self.values.dtype, float))
        lat = jnp.asarray(self.lat)
        dy = meridian_radius(lat) * self.dlat * DEG
        dx = prime_vertical_radius(lat) * jnp.cos(lat * DEG) * self.dlon * DEG
        d_north = _diff(v, -2) / dy[:, None]
        d_east = _diff(v, -1) / dx[:, None]
        units = f"{self.units}/m" if self.units else "1/m"
        return (
            dataclasses.replace(self, values=d_north, units=units),
            dataclasses.replace(self, values=d_east, units=units),
        )

    def upward_continue(self, height):
        """Upward-continue the field by ``height`` metres with the FFT (flat-Earth, padded).

        Uses :func:`jaxgrav.fields.spectral.upward_continuation` with the node
        spacing in metres at the grid's central latitude (:meth:`spacing_m`).

        Parameters
        ----------
        height : float or Array
            Continuation height Δz ≥ 0 (m); an array, so sweeping it does not recompile.

        Returns
        -------
        Grid
        """
        from jaxgrav.fields.spectral import upward_continuation

        v = upward_continuation(self.values, self.spacing_m(), height)
        return dataclasses.replace(self, values=v)

    def __repr__(self):
        w, e, s, n = self.extent
        return (
            f"Grid({self.name or 'values'} {tuple(self.values.shape)} {self.units!r}, "
            f"lat {s:g}..{n:g} step {self.dlat:g}, lon {w:g}..{e:g} step {self.dlon:g})"
        )


def _diff(v, axis):
    """Second-order finite difference per index step along ``axis`` (same shape)."""
    v = jnp.moveaxis(v, axis, -1)
    inner = 0.5 * (v[..., 2:] - v[..., :-2])
    first = 0.5 * (-3 * v[..., :1] + 4 * v[..., 1:2] - v[..., 2:3])
    last = 0.5 * (3 * v[..., -1:] - 4 * v[..., -2:-1] + v[..., -3:-2])
    return jnp.moveaxis(jnp.concatenate([first, inner, last], axis=-1), -1, axis)


def sample(grid, lat, lon, method="bilinear", *, strict=False):
    """Interpolate a grid at points.

    Parameters
    ----------
    grid : Grid
        Map, values ``(..., ny, nx)``.
    lat, lon : array_like
        Points (degrees), broadcast together to shape ``P``; longitudes in either
        convention.
    method : {"bilinear", "bicubic"}
        Paper A's bilinear formula, or the not-a-knot bicubic spline (equal to
        SciPy's ``RegularGridInterpolator(method="cubic")``); see :mod:`jaxgrav.interp`.
    strict : bool
        Raise ``ValueError`` if a (concrete) point lies outside the grid instead of
        returning NaN there.

    Returns
    -------
    Array, shape ``(..., *P)``
        Interpolated values, NaN off the grid (use :meth:`Grid.contains` for the mask).
        Differentiable in the points and in ``grid.values``.
    """
    interp._check_method(method)
    check_same_shape(lat=lat, lon=lon)
    check_latitude(lat, "lat")
    if strict:
        lat_c, lon_c = concrete(lat), concrete(lon)
        if lat_c is None or lon_c is None:
            raise ValueError(
                "strict=True needs concrete points (not traced); use grid.contains() under jit"
            )
        inside = np.asarray(grid.contains(lat_c, lon_c))
        if not inside.all():
            i = np.flatnonzero(~inside.reshape(-1))[0]
            la, lo = np.broadcast_arrays(lat_c, lon_c)
            w, e, s, n = grid.extent
            raise ValueError(
                f"point (lat={float(la.reshape(-1)[i])}, lon={float(lo.reshape(-1)[i])}) "
                "is outside the grid "
                f"(lat {s}..{n}, lon {w}..{e}); {int((~inside).sum())} point(s) off the map"
            )
    return _sample(grid, lat, lon, method)


@functools.partial(jax.jit, static_argnames="method")
def _sample(grid, lat, lon, method):
    return make_sampler(grid, method)(lat, lon)


def make_sampler(grid, method="bilinear"):
    """Sampling function with the interpolation coefficients computed once.

    For hot loops that sample the same map many times (matchers, filters): the
    bicubic spline slopes are computed here, not at every call. No validation is
    done by the returned function (it is meant for use inside ``jit``).

    Parameters
    ----------
    grid : Grid
    method : {"bilinear", "bicubic"}

    Returns
    -------
    callable
        ``f(lat, lon) -> values``, as :func:`sample` (NaN off the grid).
    """
    interp._check_method(method)
    if method == "bilinear":
        values = grid.values

        def f(lat, lon):
            return interp.bilinear(values, *grid.fractional_index(lat, lon))

        return f
    coef = interp.bicubic_coefficients(grid.values)

    def f(lat, lon):
        return interp.bicubic(coef, *grid.fractional_index(lat, lon))

    return f
