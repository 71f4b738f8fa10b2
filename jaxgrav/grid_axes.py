"""Node geometry of regular latitude/longitude grids.

:class:`GeographicAxes` gives a grid-like dataclass with ``values (..., ny, nx)`` and
static ``lat0``, ``dlat``, ``lon0``, ``dlon`` its node coordinates, extent, spacing in
metres, the fractional node index of points and the inside mask; it is the base of
:class:`jaxgrav.grid.Grid` and :class:`jaxgrav.dov.LayeredGrid`. :func:`regular_axis`
validates a coordinate axis (package-internal).
"""

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import interp
from jaxgrav._validate import check_finite
from jaxgrav.constants import DEG
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius

__all__ = ["GeographicAxes"]


def regular_axis(coord, name):
    """Validate a 1-D regular coordinate (degrees).

    Returns
    -------
    first, step : float
        First node and spacing of the ascending axis (degrees, ``step > 0``).
    flipped : bool
        True when ``coord`` was given descending.

    Raises
    ------
    ValueError
        Fewer than 2 nodes, non-finite, non-monotonic or irregular spacing.
    """
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
        if lat is None:
            lat_c = self.lat0 + 0.5 * self.dlat * (self.ny - 1)
            with jax.ensure_compile_time_eval():  # static geometry: floats even under jit
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
        eps = interp.edge_eps(iy.dtype, max(self.ny, self.nx))
        return (iy >= -eps) & (iy <= self.ny - 1 + eps) & (ix >= -eps) & (ix <= self.nx - 1 + eps)
