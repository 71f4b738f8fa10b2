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

The node geometry lives in :mod:`jaxgrav.grid_axes`, NetCDF reading and writing in
:mod:`jaxgrav.grid_files`, node windows and cell subdivision in
:mod:`jaxgrav.grid_windows`; :class:`Grid`'s methods are the interface to them.
"""

import dataclasses
import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import interp
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import check_finite, check_latitude, check_same_shape, concrete
from jaxgrav.constants import DEG
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.grid_axes import GeographicAxes, regular_axis
from jaxgrav.grid_files import read_netcdf, write_netcdf
from jaxgrav.grid_windows import Window, node_windows, refined
from jaxgrav.prepared import prepare_map

__all__ = ["Grid", "Window", "make_sampler", "sample"]


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
        lat0, dlat, flip_y = regular_axis(lat, "lat")
        lon0, dlon, flip_x = regular_axis(lon, "lon")
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
        lat, lon, values, name, units = read_netcdf(path, var)
        return cls.from_arrays(lat, lon, values, name=name, units=units)

    def to_netcdf(self, path, *, attrs=None, force=False):
        """Write the grid to NetCDF (CF ``lat``/``lon`` coordinates), atomically.

        See :func:`jaxgrav.grid_files.write_netcdf` for the parameters (``path``,
        ``attrs``, ``force``: an existing file is replaced only with ``force=True``).
        """
        write_netcdf(self, path, attrs=attrs, force=force)

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
        return refined(self, factor, method)

    def window(self, lat, lon, half_size):
        """Fixed-size ``(2k+1) × (2k+1)`` node windows centred on the node nearest each point.

        See :func:`jaxgrav.grid_windows.node_windows` (centres in degrees, ``half_size``
        k static; a window crossing the edge is shifted inside and flagged
        ``complete=False``; ValueError if larger than the grid).
        """
        return node_windows(self, lat, lon, half_size)

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
        """Deprecated: use :func:`jaxgrav.fields.spectral.upward_continue_grid`.

        Upward-continues the field by ``height`` metres with the FFT (flat-Earth,
        padded); kept for one release with a :class:`DeprecationWarning` (the FFT
        continuation belongs to :mod:`jaxgrav.fields`, a layer above the grid).

        Parameters
        ----------
        height : float or Array
            Continuation height Δz ≥ 0 (m); an array, so sweeping it does not recompile.

        Returns
        -------
        Grid
        """
        warnings.warn("Grid.upward_continue is deprecated: use "
                      "jaxgrav.fields.spectral.upward_continue_grid(grid, height)",
                      DeprecationWarning, stacklevel=2)
        # deprecation shim: the one import from a higher layer, at call time only
        from jaxgrav.fields.spectral import upward_continue_grid

        return upward_continue_grid(self, height)

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
        Interpolated values, NaN off the grid (use :meth:`Grid.contains` for the mask)
        and in cells with a missing (NaN) corner node, such as land on a marine grid
        (missing nodes do not spread: :func:`jaxgrav.interp.bicubic_coefficients`).
        Differentiable in the points and in ``grid.values``.
    """
    interp.check_method(method)
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
    interp.check_method(method)
    if method == "bilinear":
        values = grid.values

        def f(lat, lon):
            return interp.bilinear(values, *grid.fractional_index(lat, lon))

        return f
    return prepare_map(grid).sampler("bicubic")
