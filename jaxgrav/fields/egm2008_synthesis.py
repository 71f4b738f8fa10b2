"""Regional EGM2008 products synthesised with pyshtools on Driscoll–Healy grids.

Step 4 of :mod:`jaxgrav.fields.egm2008`: :func:`anomaly_grid` and
:func:`deflection_grid` synthesise the model defined by the expanded coefficients on a
global Driscoll–Healy grid whose spacing is the product's (or a divisor of it,
:func:`dh_lmax`) and crop it to the region (:func:`_crop`). pyshtools' deflection
component signs are checked against finite differences of its potential on every call
(:func:`_check_signs`). :func:`dh_lmax` is package-internal.
"""

import numpy as np

from jaxgrav.constants import ARCSEC, MGAL
from jaxgrav.fields.egm2008_geoid import normal_gravity_si, require_extras

__all__ = ["anomaly_grid", "deflection_grid"]


def dh_lmax(lmax, spacing_arcmin):
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
    sh = require_extras()
    r = radius + height
    n = np.arange(lmax + 1, dtype=float)
    scale = (n - 1.0) * gm / r**2 * (radius / r) ** n / MGAL
    c = cilm[:, : lmax + 1, : lmax + 1] * scale[None, :, None]
    lmax_grid, stride = dh_lmax(lmax, spacing_arcmin)
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
    sh = require_extras()
    lmax_grid, stride = dh_lmax(lmax, spacing_arcmin)
    r = radius + height
    _, theta, phi, _, pot = sh.gravmag.MakeGravGridDH(
        np.ascontiguousarray(cilm[:, : lmax + 1, : lmax + 1]), gm, radius, a=r, f=0.0,
        lmax=lmax_grid, lmax_calc=lmax, sampling=2, normal_gravity=0,
    )
    lat, lon, parts = _crop(np.stack([theta, phi, pot]), lmax_grid, stride, region, spacing_arcmin)
    del theta, phi, pot
    g_theta, g_phi, v = parts
    _check_signs(g_theta, g_phi, v, lat, r, np.deg2rad(spacing_arcmin / 60.0))
    gamma = normal_gravity_si(lat, height)[:, None]
    return lat, lon, g_theta / gamma / ARCSEC, -g_phi / gamma / ARCSEC
