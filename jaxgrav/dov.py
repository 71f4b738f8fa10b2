"""Layered deflection-of-the-vertical grids and their interpolation (paper C).

A :class:`LayeredGrid` holds DOV components (ξ, η, or any channels) on one regular
lat/lon grid at several heights. Heights and values are pytree leaves, so
interpolation is differentiable in the point, in the map values and in the layer
heights; the horizontal geometry is static.

Interpolation is horizontal in each layer, then vertical (see
:mod:`jaxgrav.dov_interp` for the formulas). Methods ``"<horizontal>-<vertical>"``:

=====================  ==========================================================
``bilinear-linear``    the paper's (trilinear; equals SciPy's 3-D "linear")
``bilinear-lagrange``  quadratic in h through the three nearest layers
``bilinear-harmonic``  cubic in h with vertical curvature from Laplace's equation
``bicubic-*``          the same with a not-a-knot bicubic spline in each layer
=====================  ==========================================================

``bicubic-harmonic`` is the most accurate on the paper's trajectory (see
``examples/paper_c_dov.py``) and the default. Points off the map or outside the
layers' height range give NaN and ``inside=False`` (``strict=True`` raises instead);
nothing is clamped.

Heights are above the reference sphere of the model (spherical approximation, as
in :mod:`jaxgrav.fields.harmonics`); ξ, η are in arcsec, Heiskanen–Moritz signs.
"""

import dataclasses
import functools
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import dov_interp as _k
from jaxgrav._io import atomic_output
from jaxgrav._validate import check_finite, check_latitude, check_same_shape, concrete
from jaxgrav.grid import GeographicAxes, Grid

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "Interpolated",
    "LayeredGrid",
    "interpolate",
    "make_interpolator",
    "paper_c_layers",
    "scan_track",
]

METHODS = _k.METHODS
DEFAULT_METHOD = "bicubic-harmonic"
PAPER_HEIGHTS = (0.0, 10_000.0, 20_000.0)


class Interpolated(NamedTuple):
    """Result of layered interpolation.

    Attributes
    ----------
    values : Array, shape ``(C, *P)``
        Interpolated channels (arcsec for DOV), NaN where ``inside`` is false.
    inside : Array of bool, shape ``P``
        Point on the map and within the layers' height range.
    """

    values: jax.Array
    inside: jax.Array


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class LayeredGrid(GeographicAxes):
    """Channels on a regular lat/lon grid at several heights.

    Parameters
    ----------
    values : Array, shape ``(L, C, ny, nx)``
        Layer ``l``, channel ``c``; row 0 south, column 0 west (arcsec for DOV).
    heights : Array, shape ``(L,)``
        Strictly ascending layer heights (m). Differentiable.
    lat0, dlat, lon0, dlon : float
        First node and spacing (degrees). Static.
    channels : tuple of str
        Channel names, default ``("xi", "eta")``. Static.
    units : str
        Units of the values. Static.

    Build with :meth:`from_arrays` (validated), :meth:`from_netcdf`,
    :meth:`from_harmonics`, :meth:`from_point_masses` or :func:`paper_c_layers`.
    """

    values: jax.Array
    heights: jax.Array
    lat0: float = dataclasses.field(metadata=dict(static=True))
    dlat: float = dataclasses.field(metadata=dict(static=True))
    lon0: float = dataclasses.field(metadata=dict(static=True))
    dlon: float = dataclasses.field(metadata=dict(static=True))
    channels: tuple = dataclasses.field(default=("xi", "eta"), metadata=dict(static=True))
    units: str = dataclasses.field(default="arcsec", metadata=dict(static=True))

    # ---------------------------------------------------------------- building
    @classmethod
    def from_arrays(cls, lat, lon, heights, values, *, channels=("xi", "eta"), units="arcsec"):
        """Build from coordinates and a value array, validating everything.

        Parameters
        ----------
        lat, lon : array_like, shapes ``(ny,)``, ``(nx,)``
            Regular coordinates (degrees), either order (see :meth:`Grid.from_arrays`).
        heights : array_like, shape ``(L,)``
            Strictly ascending, finite layer heights (m), ``L ≥ 2``.
        values : array_like, shape ``(L, C, ny, nx)``
            Finite values; ``C = len(channels)``.
        channels : sequence of str
        units : str

        Raises
        ------
        ValueError
            Bad coordinates or heights, shape mismatch, non-finite values.
        """
        channels = tuple(str(c) for c in channels)
        values = jnp.asarray(values)
        heights_np = np.asarray(heights, dtype=float)
        if heights_np.ndim != 1 or heights_np.size < 2:
            raise ValueError(
                f"heights must be a 1-D array of at least 2 layers (m); got shape "
                f"{heights_np.shape}"
            )
        check_finite(heights_np, "heights")
        if np.any(np.diff(heights_np) <= 0):
            raise ValueError(f"heights must be strictly ascending (m); got {heights_np.tolist()}")
        want = (heights_np.size, len(channels), np.size(lat), np.size(lon))
        if values.shape != want:
            raise ValueError(
                f"values must have shape (layers, channels, ny, nx) = {want} for "
                f"{heights_np.size} heights, channels {channels}, lat ({np.size(lat)},) and "
                f"lon ({np.size(lon)},); got {values.shape}"
            )
        g = Grid.from_arrays(lat, lon, values)  # validates coordinates and finiteness
        return cls(
            g.values, jnp.asarray(heights_np, jnp.result_type(float)),
            g.lat0, g.dlat, g.lon0, g.dlon, channels, str(units),
        )

    @classmethod
    def from_grids(cls, grids, heights):
        """Build from one :class:`Grid` per channel, each with values ``(L, ny, nx)``.

        Parameters
        ----------
        grids : dict of str to Grid
            Channel name → grid (same geometry), e.g. ``{"xi": ..., "eta": ...}``.
        heights : array_like, shape ``(L,)``
            Layer heights (m).
        """
        names = list(grids)
        g0 = grids[names[0]]
        for n in names[1:]:
            g = grids[n]
            if (g.lat0, g.dlat, g.lon0, g.dlon, g.values.shape) != (
                g0.lat0, g0.dlat, g0.lon0, g0.dlon, g0.values.shape
            ):
                raise ValueError(f"grid {n!r} differs in geometry or shape from {names[0]!r}")
        values = jnp.stack([grids[n].values for n in names], axis=1)
        return cls.from_arrays(g0.lat, g0.lon, heights, values, channels=names,
                               units=g0.units or "arcsec")

    @classmethod
    def from_harmonics(cls, model, lat, lon, heights):
        """DOV layers synthesised from a spherical-harmonic model (needs float64).

        Parameters
        ----------
        model : SphericalHarmonics
        lat, lon : array_like, shapes ``(ny,)``, ``(nx,)``
            Grid coordinates (degrees).
        heights : array_like, shape ``(L,)``
            Layer heights above the model's sphere (m).

        Returns
        -------
        LayeredGrid
            Channels ``("xi", "eta")`` in arcsec.
        """
        from jaxgrav.fields.harmonics import synthesize_grid

        lat, lon = np.asarray(lat, float), np.asarray(lon, float)
        out = []
        for hh in np.asarray(heights, float).reshape(-1):  # a few layers, at build time
            f = synthesize_grid(model, lat, lon, float(hh))
            out.append(jnp.stack([f.xi, f.eta]))
        return cls.from_arrays(lat, lon, heights, jnp.stack(out))

    @classmethod
    def from_point_masses(cls, masses, lat, lon, heights):
        """DOV layers of point masses (:func:`jaxgrav.fields.pointmass.deflection`).

        Parameters as :meth:`from_harmonics`, with ``masses`` a ``PointMasses``.
        """
        from jaxgrav.fields.pointmass import deflection

        lat, lon = np.asarray(lat, float), np.asarray(lon, float)
        la, lo = np.meshgrid(lat, lon, indexing="ij")
        out = []
        for hh in np.asarray(heights, float).reshape(-1):
            d = deflection(masses, la, lo, np.full_like(la, hh))
            out.append(jnp.stack([d.xi, d.eta]))
        return cls.from_arrays(lat, lon, heights, jnp.stack(out))

    @classmethod
    def from_netcdf(cls, path):
        """Read layers: variables on (``height``, ``lat``, ``lon``), ``height`` in m.

        Every data variable on those three dimensions becomes a channel (``xi`` and
        ``eta`` first when present), as :meth:`to_netcdf` and the shipped
        ``qinling`` file write them.
        """
        import xarray as xr

        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"grid file {str(path)!r} does not exist")
        with xr.open_dataset(path) as ds:
            for d in ("height", "lat", "lon"):
                if d not in ds.dims:
                    raise ValueError(
                        f"{str(path)!r} needs dimensions ('height', 'lat', 'lon'); it has "
                        f"{tuple(ds.dims)}"
                    )
            names = [v for v in ds.data_vars if set(ds[v].dims) == {"height", "lat", "lon"}]
            names = sorted(names, key=lambda v: (v not in ("xi", "eta"), v != "xi", v))
            if not names:
                raise ValueError(f"{str(path)!r} has no variable on ('height', 'lat', 'lon')")
            vals = np.stack(
                [ds[v].transpose("height", "lat", "lon").values for v in names], axis=1
            )
            units = str(ds[names[0]].attrs.get("units", "arcsec"))
            return cls.from_arrays(ds["lat"].values, ds["lon"].values, ds["height"].values,
                                   vals, channels=names, units=units)

    def to_netcdf(self, path, *, attrs=None, force=False):
        """Write the layers (one variable per channel on (height, lat, lon)), atomically.

        Parameters
        ----------
        path : str or Path
            Output; an existing file is replaced only with ``force=True``.
        attrs : dict, optional
            Global attributes (provenance).
        force : bool
        """
        import xarray as xr

        coords = {
            "height": ("height", np.asarray(self.heights, float), {"units": "m"}),
            "lat": ("lat", self.lat, {"units": "degrees_north", "standard_name": "latitude"}),
            "lon": ("lon", self.lon, {"units": "degrees_east", "standard_name": "longitude"}),
        }
        v = np.asarray(self.values)
        ds = xr.Dataset(
            {n: (("height", "lat", "lon"), v[:, i], {"units": self.units})
             for i, n in enumerate(self.channels)},
            coords=coords, attrs=dict(attrs or {}),
        )
        with atomic_output(path, force=force) as tmp:
            ds.to_netcdf(tmp)

    # ---------------------------------------------------------------- geometry

    def layer(self, index, channel=0):
        """One layer of one channel as a :class:`Grid` (``channel`` index or name)."""
        c = self.channels.index(channel) if isinstance(channel, str) else channel
        return Grid(self.values[index, c], self.lat0, self.dlat, self.lon0, self.dlon,
                    self.channels[c], self.units)

    def fractional_index(self, lat, lon):
        """Fractional (row, column) of points; see :meth:`Grid.fractional_index`."""
        return self.layer(0).fractional_index(lat, lon)

    def nbytes(self):
        """Storage of values and heights (bytes)."""
        return int(self.values.nbytes + self.heights.nbytes)

    def interpolate(self, lat, lon, h, method=DEFAULT_METHOD, *, strict=False):
        """Interpolate at points; see :func:`interpolate`."""
        return interpolate(self, lat, lon, h, method, strict=strict)

    def __repr__(self):
        w, e, s, n = self.extent
        return (f"LayeredGrid({self.channels} {tuple(self.values.shape)} {self.units!r}, "
                f"heights {np.asarray(self.heights).tolist()} m, lat {s:g}..{n:g} step "
                f"{self.dlat:g}, lon {w:g}..{e:g} step {self.dlon:g})")


def paper_c_layers(heights=PAPER_HEIGHTS, *, spacing_arcmin=3.0, nmax=None):
    """The paper's set-up on the shipped ``qinling`` data: 3′ grid, layers 0, 10, 20 km.

    With the default arguments this returns the shipped layers (built with
    pyshtools from the degree-360 model); other heights, spacings or a truncation
    ``nmax`` synthesise new layers from the shipped coefficients over the same region
    (32–41°N, 105–114°E) with :meth:`LayeredGrid.from_harmonics` (needs float64).

    Parameters
    ----------
    heights : sequence of float
        Layer heights (m).
    spacing_arcmin : float
        Grid spacing (arcminutes); must divide the 9° region into whole steps.
    nmax : int, optional
        Truncation degree of the model (≤ 360).

    Returns
    -------
    LayeredGrid
    """
    from jaxgrav import datasets

    d = datasets.load("qinling")
    heights = np.asarray(heights, float)
    shipped = d["height"]
    if (nmax is None and spacing_arcmin == 3.0 and heights.shape == shipped.shape
            and np.allclose(heights, shipped)):
        return LayeredGrid.from_grids({"xi": d["xi"], "eta": d["eta"]}, shipped)
    steps = 9.0 * 60.0 / spacing_arcmin
    if not (spacing_arcmin > 0 and abs(steps - round(steps)) < 1e-9):
        raise ValueError(
            f"spacing_arcmin must divide 540 arcmin (the 9° region) into whole steps; got "
            f"{spacing_arcmin!r}"
        )
    model = d["coefficients"]
    if nmax is not None:
        model = model.truncate(nmax)
    w, e, s, n = d["xi"].extent
    k = round(steps) + 1
    return LayeredGrid.from_harmonics(model, np.linspace(s, n, k), np.linspace(w, e, k), heights)


# -------------------------------------------------------------------- interpolation


def _check_layers(layers):
    if not isinstance(layers, LayeredGrid):
        raise TypeError(f"layers must be a LayeredGrid; got {type(layers).__name__}")


def _check_points(layers, lat, lon, h, strict):
    check_same_shape(lat=lat, lon=lon, h=h)
    check_latitude(lat, "lat")
    check_finite(lon, "lon")
    check_finite(h, "h")
    if not strict:
        return
    pts = [concrete(x) for x in (lat, lon, h)]
    if any(p is None for p in pts) or concrete(layers.heights) is None:
        raise ValueError("strict=True needs concrete points and heights (not traced)")
    la, lo, hh = np.broadcast_arrays(*pts)
    on_map = np.asarray(layers.layer(0).contains(la, lo))
    hs = np.asarray(layers.heights)
    in_h = (hh >= hs[0]) & (hh <= hs[-1])
    bad = ~(on_map & in_h)
    if bad.any():
        i = int(np.flatnonzero(bad.reshape(-1))[0])
        w, e, s, n = layers.extent
        raise ValueError(
            f"point (lat={float(la.reshape(-1)[i])!r}, lon={float(lo.reshape(-1)[i])!r}, "
            f"h={float(hh.reshape(-1)[i])!r} m) is outside the layered grid (lat {s}..{n}, lon "
            f"{w}..{e}, h {hs[0]}..{hs[-1]} m); {int(bad.sum())} point(s) out of range"
        )


def interpolate(layers, lat, lon, h, method=DEFAULT_METHOD, *, strict=False):
    """Interpolate layered DOV at points (horizontal, then vertical).

    Parameters
    ----------
    layers : LayeredGrid
        Values ``(L, C, ny, nx)``.
    lat, lon : array_like
        Points (degrees), broadcast with ``h`` to shape ``P``.
    h : array_like
        Heights (m) above the layers' reference surface.
    method : str
        One of :data:`METHODS` (static), default :data:`DEFAULT_METHOD`;
        ``"bilinear-linear"`` is the paper's.
    strict : bool
        Raise ``ValueError`` for (concrete) points off the map or outside
        ``[heights[0], heights[-1]]`` instead of returning NaN there.

    Returns
    -------
    Interpolated
        ``values (C, *P)`` and ``inside (P,)``. Differentiable in the points, in
        ``layers.values`` and in ``layers.heights``.
    """
    _check_layers(layers)
    _k.check_method(method, layers.values.shape[0])
    _check_points(layers, lat, lon, h, strict)
    dt = jnp.result_type(float)
    lat, lon, h = jnp.broadcast_arrays(*(jnp.asarray(x, dt) for x in (lat, lon, h)))
    return _interpolate(layers, lat, lon, h, method)


@functools.partial(jax.jit, static_argnames="method")
def _interpolate(layers, lat, lon, h, method):
    return Interpolated(*make_interpolator(layers, method)(lat, lon, h))


def make_interpolator(layers, method=DEFAULT_METHOD):
    """Interpolation function with the per-map work (spline slopes, curvatures) done once.

    For use inside ``jit`` (filters, sensitivity studies): no validation at call.

    Parameters
    ----------
    layers : LayeredGrid
    method : str
        One of :data:`METHODS`.

    Returns
    -------
    callable
        ``f(lat, lon, h) -> (values (C, *P), inside P)``, as :func:`interpolate`.
    """
    horiz, vert = _k.check_method(method, layers.values.shape[0])
    coef = _k.prepare(layers, horiz, vert)

    def f(lat, lon, h):
        return _k.evaluate(layers, coef, horiz, vert, lat, lon, h)

    return f


def scan_track(layers, lat, lon, h, method=DEFAULT_METHOD):
    """Interpolate along a trajectory one fix at a time with ``lax.scan`` (on-board form).

    Same values as :func:`interpolate`; the scan carries the previous fix's cell
    (layer, row, column), as the paper's locate step does.

    Parameters
    ----------
    layers : LayeredGrid
    lat, lon, h : array_like, shape ``(T,)``
        Fixes in time order (degrees, degrees, m).
    method : str

    Returns
    -------
    values : Array, shape ``(C, T)``
    inside : Array of bool, shape ``(T,)``
    cell_changes : Array of int32, scalar
        Fixes at which the enclosing cell differs from the previous fix's.
    """
    _check_layers(layers)
    _k.check_method(method, layers.values.shape[0])
    _check_points(layers, lat, lon, h, False)
    dt = jnp.result_type(float)
    lat, lon, h = jnp.broadcast_arrays(*(jnp.asarray(x, dt) for x in (lat, lon, h)))
    if lat.ndim != 1 or lat.shape[0] == 0:
        raise ValueError(f"lat, lon, h must be non-empty 1-D tracks; got shape {lat.shape}")
    return _scan(layers, lat, lon, h, method)


@functools.partial(jax.jit, static_argnames="method")
def _scan(layers, lat, lon, h, method):
    horiz, vert = _k.check_method(method, layers.values.shape[0])
    coef = _k.prepare(layers, horiz, vert)
    return _k.scan_points(layers, coef, horiz, vert, lat, lon, h)
