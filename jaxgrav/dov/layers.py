"""Layered grids: DOV channels on one regular lat/lon grid at several heights (paper C).

:class:`LayeredGrid` holds the values ``(L, C, ny, nx)`` and the layer heights as
pytree leaves (differentiable) and the horizontal geometry as static fields; it is
built from arrays, per-channel grids, a spherical-harmonic model, point masses or a
NetCDF file, and written back to NetCDF. :func:`paper_c_layers` gives the paper's
layers on the shipped ``qinling`` data. Interpolation is :func:`jaxgrav.dov.interpolate`.
"""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from jaxgrav import datasets
from jaxgrav._io import atomic_output
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import check_finite
from jaxgrav.dov.units import declared_units, in_arcsec_and_metres
from jaxgrav.fields.harmonics import synthesize_grid
from jaxgrav.fields.pointmass import deflection
from jaxgrav.grid import Grid
from jaxgrav.grid_axes import GeographicAxes
from jaxgrav.grid_files import LAT_NAMES, LON_NAMES
from jaxgrav.grid_values import axis_degrees, eastward_longitudes, units_attr

__all__ = ["PAPER_HEIGHTS", "LayeredGrid", "paper_c_layers"]

PAPER_HEIGHTS = (0.0, 10_000.0, 20_000.0)


@pytree_dataclass
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
    lat0: float = static_field()
    dlat: float = static_field()
    lon0: float = static_field()
    dlon: float = static_field()
    channels: tuple = static_field(("xi", "eta"))
    units: str = static_field("arcsec")

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

        The dimensions may also be called ``altitude``, ``latitude``/``y`` and
        ``longitude``/``x`` (any case), and the layers stored from the top down;
        coordinates in CF ``degrees_west``/``degrees_south`` or the −360…0 convention
        are read as the map reader reads them.
        Every data variable on those three dimensions becomes a channel (``xi`` and
        ``eta`` first when present), as :meth:`to_netcdf` and the shipped
        ``qinling`` file write them. Channels declared in an angle unit (CF ``units`` or
        ``Units``, ``UNITS``, ``unit``; none: arcsec) are converted to arcsec, heights
        in km or ft to metres (:mod:`jaxgrav.dov.units`); other channel units are kept.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            Other dimensions, no channel, heights in units of no length.
        """
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"grid file {str(path)!r} does not exist")
        with xr.open_dataset(path) as ds:
            ds = _canonical_dims(ds, repr(str(path)))
            names = [v for v in ds.data_vars if set(ds[v].dims) == {"height", "lat", "lon"}]
            names = sorted(names, key=lambda v: (v not in ("xi", "eta"), v != "xi", v))
            if not names:
                raise ValueError(f"{str(path)!r} has no variable on ('height', 'lat', 'lon')")
            vals = np.stack(
                [ds[v].transpose("height", "lat", "lon").values for v in names], axis=1
            )
            # "Units", "unit" and heights in km were ignored (read as arcsec and m)
            vals, heights, units = in_arcsec_and_metres(
                vals, np.asarray(ds["height"].values, float), *declared_units(ds, names[0]),
                repr(str(path)))
            order = np.argsort(heights, kind="stable")  # layers stored from the top down
            vals, heights = vals[order], heights[order]
            # the map reader's rules: degrees_west/south (were read as east), -360..0
            lat, lon = (axis_degrees(ds[c].values, units_attr(ds[c].attrs), c, repr(str(path)))
                        for c in ("lat", "lon"))
            return cls.from_arrays(lat, eastward_longitudes(lon), heights,
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

    def nbytes(self):
        """Storage of values and heights (bytes)."""
        return int(self.values.nbytes + self.heights.nbytes)

    def __repr__(self):
        w, e, s, n = self.extent
        return (f"LayeredGrid({self.channels} {tuple(self.values.shape)} {self.units!r}, "
                f"heights {np.asarray(self.heights).tolist()} m, lat {s:g}..{n:g} step "
                f"{self.dlat:g}, lon {w:g}..{e:g} step {self.dlon:g})")


HEIGHT_NAMES = ("height", "altitude", "alt", "elevation")
"""Accepted names of a layers file's height dimension (any case), in order of preference."""


def _canonical_dims(ds, label):
    """``ds`` with its height, latitude and longitude dimensions named ``height``, ``lat``
    and ``lon`` (``latitude``, ``altitude``, ``y`` … were refused: "needs dimensions"); a
    ValueError naming ``label`` and what is missing otherwise."""
    lower = {str(d).lower(): d for d in ds.dims}
    found = {}
    for key, names in (("height", HEIGHT_NAMES), ("lat", LAT_NAMES), ("lon", LON_NAMES)):
        hit = next((lower[n] for n in names if n in lower), None)
        if hit is not None:
            found[hit] = key
    missing = [k for k in ("height", "lat", "lon") if k not in found.values()]
    if missing:
        raise ValueError(f"{label} has dimensions {', '.join(map(str, ds.dims)) or 'none'}; "
                         "expected height, lat, lon (xi and eta in arcsec on layers at heights "
                         "in m, as the shipped qinling file), missing " + ", ".join(missing))
    return ds.rename({d: k for d, k in found.items() if d != k})


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
