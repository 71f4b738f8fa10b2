"""Node geometry of regular latitude/longitude grids.

:class:`GeographicAxes` gives a grid-like dataclass with ``values (..., ny, nx)`` and
static ``lat0``, ``dlat``, ``lon0``, ``dlon`` its node coordinates, extent, spacing in
metres, the fractional node index of points, the inside mask, the count of missing
(NaN) nodes and the part of the map a track needs (:meth:`~GeographicAxes.finite_region`,
seamless across 0°/360° on global grids); it is the base of :class:`jaxgrav.grid.Grid`
and :class:`jaxgrav.dov.LayeredGrid`. :func:`regular_axis` validates a coordinate axis
(package-internal, shared by the map readers; longitudes without 360° jumps:
:func:`jaxgrav.grid_values.contiguous_longitudes`).
"""

import dataclasses
import math
import numbers

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import interp
from jaxgrav.constants import DEG, WGS84_A, WGS84_E2
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius

__all__ = ["GeographicAxes", "regular_axis"]

_EQUATOR_M_PER_DEG = 6335439.327 * DEG
"""Metres per degree of latitude at the equator (the smallest on WGS84): margins in
degrees computed with it are never too small."""


def regular_axis(coord, name, source=None, resolution=0.0):
    """Validate a 1-D regular coordinate (degrees).

    Parameters
    ----------
    coord : array_like, shape ``(n,)``
        Node coordinates, ascending or descending. Float32 coordinates are allowed
        the rounding of float32 in the spacing test.
    name : str
        The axis in messages (``"lat"``, ``"x"``).
    source : str, optional
        Where the axis comes from, leading the messages (e.g. ``"map 'gebco.nc'"``).
    resolution : float
        Precision of the stored nodes (a packed ``scale_factor``): steps may be off by it
        (also by the last decimal of nodes written with 3 to 8 decimals, :func:`_rounding`).

    Returns
    -------
    first, step : float
        First node and spacing of the ascending axis (degrees, ``step > 0``).
    flipped : bool
        True when ``coord`` was given descending.

    Raises
    ------
    ValueError
        Fewer than 2 nodes, a non-finite node, a repeated node, a turn (unsorted) or an
        irregular step, naming the offending node (index and value).
    """
    raw = np.asarray(coord)
    where = f"{source}: " if source else ""
    if raw.ndim != 1 or raw.size < 2:  # a map of one row was "got shape (1,)", a tuple
        at = f" (at {float(raw[0]):g})" if raw.shape == (1,) and np.isreal(raw[0]) else ""
        raise ValueError(f"{where}{name} has {raw.size} node{'s' * (raw.size != 1)}{at}" + (
            f" in {raw.ndim} dimensions" if raw.ndim != 1 else "") + "; a map needs at least 2 "
            "along each axis, in one dimension (a grid, not a single row or column)")
    try:
        coord = raw.astype(float)
    except (TypeError, ValueError):
        raise ValueError(f"{where}{name} must hold numbers (degrees); got {raw.dtype} "
                         "values") from None
    bad = np.flatnonzero(~np.isfinite(coord))
    if bad.size:
        raise ValueError(f"{where}{name} must be finite; {name}[{bad[0]}] is {coord[bad[0]]:g} "
                         f"({bad.size} non-finite node(s))")
    what = f"{where}{name} must be strictly monotonic and regularly spaced"
    step = np.diff(coord)
    same = np.flatnonzero(step == 0)
    if same.size:
        i = int(same[0])
        raise ValueError(f"{what}; {name}[{i + 1}] = {coord[i + 1]:.10g} repeats {name}[{i}] "
                         f"({same.size} repeated node(s))")
    sign = np.sign(step[0])
    turn = np.flatnonzero(np.sign(step) != sign)
    if turn.size:
        i = int(turn[0])
        order = "increase" if sign > 0 else "decrease"
        raise ValueError(f"{what}; values {order} up to {name}[{i}] = {coord[i]:.10g}, then "
                         f"{name}[{i + 1}] = {coord[i + 1]:.10g} goes back (unsorted)")
    mean = (coord[-1] - coord[0]) / (coord.size - 1)
    resolution = max(resolution, _rounding(coord, mean))
    typical = float(np.median(step))  # the step most nodes have: the odd one is named
    eps = np.finfo(raw.dtype).eps if raw.dtype.kind == "f" else np.finfo(float).eps
    tol = max(1e-6 * abs(mean) + 1e-9, 16 * eps * float(np.max(np.abs(coord))), 1.01 * resolution)
    irregular = np.flatnonzero(np.abs(step - typical) > tol)
    if irregular.size or abs(mean - typical) > tol:
        i = int(irregular[0]) if irregular.size else int(np.argmax(np.abs(step - typical)))
        raise ValueError(f"{what}; the step from {name}[{i}] = {coord[i]:.10g} to "
                         f"{name}[{i + 1}] = {coord[i + 1]:.10g} is {step[i]:.6g}, not the "
                         f"regular {typical:.6g} ({max(irregular.size, 1)} irregular step(s))")
    flipped = bool(sign < 0)
    first = coord[-1] if flipped else coord[0]
    if resolution > 0:  # rounded or packed nodes: the regular axis through their middle
        first = np.mean(coord) - abs(mean) * (coord.size - 1) / 2
    return float(first), float(abs(mean)), flipped


def _rounding(coord, mean):
    """``10**-d`` for nodes all written with ``d`` decimals (3 to 8) on an axis whose step
    has more (2.5' as 29.416667, 29.458333: the rounding was refused as irregular); else
    0. A step of ``d`` decimals (0.001) leaves no rounding to forgive."""
    for d in range(3, 9):
        if np.all(np.abs(coord - np.round(coord, d)) <= 4 * np.finfo(float).eps * np.abs(coord)):
            unit = 10.0 ** -d
            return unit if abs(mean - round(mean, d)) > unit / (coord.size - 1) else 0.0
    return 0.0


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
            default. For the default or a Python (or NumPy scalar) float, Python floats
            are returned, computed on the host (no device program; also under jit).

        Returns
        -------
        tuple
            North–south and east–west node spacing (m).
        """
        if lat is None or isinstance(lat, numbers.Real):  # static geometry: Python floats
            lat_c = self.lat0 + 0.5 * self.dlat * (self.ny - 1) if lat is None else float(lat)
            s2 = math.sin(lat_c * DEG) ** 2
            w = 1.0 - WGS84_E2 * s2  # M and N of geodesy.meridian/prime_vertical_radius
            return (WGS84_A * (1.0 - WGS84_E2) / w**1.5 * self.dlat * DEG,
                    WGS84_A / math.sqrt(w) * math.cos(lat_c * DEG) * self.dlon * DEG)
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
            NumPy arrays for NumPy (or Python) points, computed on the host in the dtype
            JAX would use (a check of a track compiles no device program); JAX arrays
            for JAX arrays and under ``jit``.
        """
        xp = jnp if any(isinstance(a, jax.Array) for a in (lat, lon)) else np
        lat, lon = xp.asarray(lat), xp.asarray(lon)
        dtype = jnp.result_type(lat.dtype, lon.dtype, float)
        lat0, lon0, dlat, dlon = (np.asarray(v, dtype) for v in (self.lat0, self.lon0,
                                                                 self.dlat, self.dlon))
        lon_w = lon0 + xp.mod(lon.astype(dtype) - lon0, np.asarray(360.0, dtype))
        return (lat.astype(dtype) - lat0) / dlat, (lon_w - lon0) / dlon

    def contains(self, lat, lon):
        """Boolean mask of points inside the grid (edges included), points' broadcast shape
        (NumPy for NumPy points, as :meth:`fractional_index`)."""
        iy, ix = self.fractional_index(lat, lon)
        eps = interp.edge_eps(iy.dtype, max(self.ny, self.nx))
        return (iy >= -eps) & (iy <= self.ny - 1 + eps) & (ix >= -eps) & (ix <= self.nx - 1 + eps)

    # ------------------------------------------------------------------ missing nodes, seams
    @property
    def n_missing(self):
        """Number of missing (NaN or infinite) node values, an ``int``."""
        return int(np.count_nonzero(~np.isfinite(np.asarray(self.values))))

    def values_near(self, lat, lon, reach_m):
        """Node values within ``reach_m`` (plus one node) of the points' bounding box.

        Parameters
        ----------
        lat, lon : array_like
            Points (degrees; longitudes in either convention, taken on the map's turn).
        reach_m : float
            Distance (m) beyond the box, e.g. a matcher's drift radius.

        Returns
        -------
        numpy.ndarray, shape ``(rows, cols)``
            The nodes' values (NaN kept), those of every cell a point within the reach
            can fall in.
        """
        lat = np.asarray(lat, float).reshape(-1)
        lon = _nearest_turn(np.asarray(lon, float).reshape(-1), self)
        d_lat = reach_m / _EQUATOR_M_PER_DEG
        d_lon = d_lat / max(np.cos(min(89.0, float(np.abs(lat).max())) * DEG), 1e-3)
        la, lo = self.lat, self.lon
        rows = (la >= lat.min() - d_lat - self.dlat) & (la <= lat.max() + d_lat + self.dlat)
        cols = (lo >= lon.min() - d_lon - self.dlon) & (lo <= lon.max() + d_lon + self.dlon)
        return np.asarray(self.values)[..., rows, :][..., cols]

    @property
    def is_global(self):
        """True when the columns go all the way round (``nx · dlon ≥ 360°``)."""
        return self.nx * self.dlon >= 360.0 - 1e-6 * self.dlon

    def recentred(self, lon_centre):
        """The same global map with its seam moved opposite ``lon_centre``.

        The columns are rolled (a repeated 360° column is dropped) so that the first
        column is the node nearest ``lon_centre − 180°``; the first longitude is then in
        [−180, 180). Node values are unchanged; only where the map "ends" moves, so a
        region around ``lon_centre`` is contiguous.

        Parameters
        ----------
        lon_centre : float
            Longitude (degrees, either convention) to put in the middle of the map.

        Returns
        -------
        same type as ``self``

        Raises
        ------
        ValueError
            If the map is not global or its spacing does not divide 360°.
        """
        if not self.is_global:
            w, e, _, _ = self.extent
            raise ValueError(f"only a global map (360 degrees of longitude) can be recentred; "
                             f"this one covers lon {w:g}..{e:g}")
        n = round(360.0 / self.dlon)
        if abs(n * self.dlon - 360.0) > 1e-6 * self.dlon:
            raise ValueError(f"the longitude spacing {self.dlon:g} does not divide 360 degrees; "
                             "a global map must repeat after a whole number of columns")
        k = round((float(lon_centre) - 180.0 - self.lon0) / self.dlon) % n
        lon0 = (self.lon0 + k * self.dlon + 180.0) % 360.0 - 180.0
        values = jnp.roll(jnp.asarray(self.values)[..., :n], -k, axis=-1)
        return dataclasses.replace(self, values=values, lon0=float(lon0))

    def finite_region(self, lat, lon, margin_m=0.0, *, pad_nodes=6, max_missing=0.0,
                      source="the map"):
        """The part of the map points need: contiguous (global maps recentred) and finite.

        The region is the points' bounding box (longitudes taken the short way round,
        so a track across 0° or 180° is one box) widened by ``margin_m`` and by
        ``pad_nodes`` nodes on each side, clipped to the map. Rules:

        - a global map (360° of columns) whose seam cuts the region is first recentred
          on the region (:meth:`recentred`), so a track across Greenwich on a 0–360
          grid (or across 180° on a ±180 grid) sees one contiguous map;
        - a regional map without missing nodes is returned whole, so its results are
          exactly those of the full map;
        - a global map, or a map with missing (NaN) nodes, is cut to the region (the
          bicubic values inside differ from the whole map's by less than 1e-4 of the
          field's local variation, see ``pad_nodes``): NaN cells elsewhere, such as land
          on a marine grid, do not matter, and a fine global grid costs only its region;
          missing nodes inside the region are refused when they are more than
          ``max_missing`` of its nodes.

        Parameters
        ----------
        lat, lon : array_like
            Points (degrees), e.g. a track; longitudes in either convention.
        margin_m : float
            Distance (m) the methods may reach from the points, e.g. the drift radius
            a matcher searches, ≥ 0.
        pad_nodes : int
            Extra nodes on each side (default 6): the bicubic stencil, and the
            not-a-knot spline's end effect of a cut map, which decays by about 0.27 per
            node (4e-4 of it left after 6).
        max_missing : float
            Largest fraction (0–1) of missing nodes accepted in the region; 0 (default)
            for methods that do not mask NaN cells.
        source : str
            How the map is named in messages (e.g. ``"--map 'gebco.nc'"``).

        Returns
        -------
        same type as ``self``
            The map or its region, values ``(..., ny', nx')``.

        Raises
        ------
        ValueError
            Points empty or not finite, the region off the map, a bad ``margin_m`` or
            ``max_missing``, or too many missing nodes in the region (their count and the
            first one's position are named).
        """
        lat = np.asarray(lat, dtype=float).reshape(-1)
        lon = np.asarray(lon, dtype=float).reshape(-1)
        if lat.size == 0 or lat.size != lon.size:
            raise ValueError(f"lat and lon must be non-empty and of equal length; got "
                             f"{lat.size} and {lon.size} points")
        if not (np.isfinite(lat).all() and np.isfinite(lon).all()):
            raise ValueError("lat and lon must be finite to find the map region they need")
        if not (np.isfinite(margin_m) and margin_m >= 0):
            raise ValueError(f"margin_m must be a distance >= 0 (m); got {float(margin_m):g}")
        if not (0.0 <= max_missing <= 1.0):
            raise ValueError(f"max_missing must be a fraction in [0, 1]; got {max_missing:g}")
        margin_lat = margin_m / _EQUATOR_M_PER_DEG
        south, north = lat.min() - margin_lat, lat.max() + margin_lat
        cos_lat = np.cos(min(89.0, max(abs(south), abs(north))) * DEG)
        margin_lon = min(360.0, margin_m / (_EQUATOR_M_PER_DEG * cos_lat))
        centre, half = _lon_span(lon)
        half += margin_lon + pad_nodes * self.dlon
        grid = self
        if grid.n_missing == 0 and not grid.is_global:
            return grid  # whole, as it is: the methods' own checks name points off the map
        centre_w = _nearest_turn(centre, grid)
        if grid.is_global and (centre_w - half < grid.lon0
                               or centre_w + half > grid.lon0 + (grid.nx - 1) * grid.dlon):
            grid = grid.recentred(centre)
            centre_w = _nearest_turn(centre, grid)
        iy0 = max(0, int(np.floor((south - grid.lat0) / grid.dlat)) - pad_nodes)
        iy1 = min(grid.ny - 1, int(np.ceil((north - grid.lat0) / grid.dlat)) + pad_nodes)
        ix0 = max(0, int(np.floor((centre_w - half - grid.lon0) / grid.dlon)))
        ix1 = min(grid.nx - 1, int(np.ceil((centre_w + half - grid.lon0) / grid.dlon)))
        if iy0 > iy1 or ix0 > ix1:
            w, e, s, n = grid.extent
            raise ValueError(
                f"the points (lat {lat.min():g}..{lat.max():g}, lon {centre - half:g}.."
                f"{centre + half:g} with the margin) lie outside {source} (lat {s:g}..{n:g}, "
                f"lon {w:g}..{e:g})")
        region = dataclasses.replace(
            grid, values=jnp.asarray(grid.values)[..., iy0:iy1 + 1, ix0:ix1 + 1],
            lat0=float(grid.lat0 + iy0 * grid.dlat), lon0=float(grid.lon0 + ix0 * grid.dlon))
        missing = ~np.isfinite(np.asarray(region.values))
        if missing.any() and missing.mean() > max_missing:
            idx = np.unravel_index(int(np.flatnonzero(missing)[0]), missing.shape)
            la, lo = region.lat[idx[-2]], region.lon[idx[-1]]
            raise ValueError(
                f"{source} has {int(missing.sum())} missing (NaN) node(s) among the "
                f"{missing.size} within {margin_m / 1000:.3g} km (+{pad_nodes} nodes) of the "
                f"track, the first at lat {la:.6g}, lon {lo:.6g}; "
                + ("the map must be complete there (missing nodes elsewhere are fine)"
                   if max_missing == 0 else
                   f"more than {max_missing:.0%} missing leaves too little map to use "
                   "(missing nodes elsewhere are fine)"))
        return region


def _nearest_turn(lon, grid):
    """``lon`` plus the multiple of 360° that brings it nearest the map's middle column."""
    mid = grid.lon0 + 0.5 * (grid.nx - 1) * grid.dlon
    return mid + (np.mod(lon - mid + 180.0, 360.0) - 180.0)


def _lon_span(lon):
    """Centre and half-width (degrees) of the shortest arc holding every longitude."""
    ref = float(lon[0])
    offsets = np.mod(lon - ref + 180.0, 360.0) - 180.0
    lo, hi = offsets.min(), offsets.max()
    return ref + 0.5 * (lo + hi), 0.5 * (hi - lo)
