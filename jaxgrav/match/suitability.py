"""Matching-area suitability: the predicted precision of a fix from every start cell of a map.

For a straight segment of ``N`` fixes ``spacing_m`` apart on a heading, starting at a
map node, the readings are ``z_i = map(p_i + δ) + b + e_i`` with the error ``e`` white
reading noise plus the map's own error correlated along the track,
``Σ = σ_n² I + C_map(‖p_i − p_j‖)`` (:func:`~jaxgrav.match.gls.track_covariance`). The
Fisher information of the mean-track offset ``δ`` (north, east) with the bias ``b``
marginalised (prior σ_b; ∞: free) is ``Gᵀ (Σ + σ_b² 11ᵀ)⁻¹ G`` with ``G`` the map
gradient along the track (:func:`~jaxgrav.match.fix_covariance.gauss_newton_information`),
and its inverse the Cramér–Rao bound of the offset (2 × 2, m²). Every start cell shares
the track's shape, so ``Σ`` is factored once and each cell costs one whitening product
of its ``N × 2`` gradient: all cells in one ``vmap``.

:func:`suitability` also returns the standard descriptors over a window centred on each
node, all by box sums (vectorised over the map): the standard deviation, the standard
deviation of the slope (gradient magnitude), the roughness (mean absolute difference
between neighbouring nodes), the Shannon entropy of the values (16 bins over the map's
range) and the correlation length (from the lag-one autocorrelation along rows and
columns, ``L = −Δ / ln ρ₁``).

The bound is local (it assumes the matcher finds the right peak): it ranks cells, it
does not promise the error of a matcher that may lock onto a wrong peak where the map
repeats itself; ``examples/suitability_validation.py`` measures how well it ranks.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav.constants import DEG
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.grid import Grid
from jaxgrav.match.fix_covariance import (
    gauss_newton_information,
    offset_covariance,
)
from jaxgrav.match.gls import gls_whitener, track_covariance
from jaxgrav.prepared import prepare_map

__all__ = ["DESCRIPTORS", "Suitability", "suitability"]

DESCRIPTORS = ("std", "slope_std", "roughness", "entropy", "correlation_length_m")
"""The window descriptors :func:`suitability` returns, in map units (``std``,
``roughness``), map units per km (``slope_std``), nats (``entropy``) and metres."""

_BINS = 16
_CHUNK = 4096  # start cells per vmapped block


class Suitability(NamedTuple):
    """Predicted matching precision and descriptors on the map's nodes.

    Attributes
    ----------
    precision_m : numpy.ndarray, shape ``(ny, nx)``
        ``√(tr CRLB)``: the RMS radial bound of the offset of a segment starting at the
        node (m); NaN where the segment leaves the map or the map has NaN on it.
    sigma_north_m, sigma_east_m, corr : numpy.ndarray, shape ``(ny, nx)``
        The bound's 1-σ per axis (m) and their correlation.
    descriptors : dict of str to numpy.ndarray
        :data:`DESCRIPTORS`, each ``(ny, nx)``, NaN where the window is not complete.
    """

    precision_m: np.ndarray
    sigma_north_m: np.ndarray
    sigma_east_m: np.ndarray
    corr: np.ndarray
    descriptors: dict


def _check_positive(name, value, zero_ok=False, unit=""):
    v = float(value)
    if not (np.isfinite(v) and (v >= 0 if zero_ok else v > 0)):
        bound = ">= 0" if zero_ok else "> 0"
        raise ValueError(f"{name} must be a finite number {bound}{unit}; got {value!r}")
    return v


def _track_offsets(n_fixes, spacing_m, heading_deg):
    k = np.arange(n_fixes) * spacing_m
    h = np.radians(heading_deg)
    return k * np.cos(h), k * np.sin(h)


@jax.jit
def _precision(grid, lat0, lon0, north, east, noise, map_sigma, length, bias_prior_sigma):
    """Offset CRLB (2 × 2, m²) of the segments starting at ``lat0, lon0`` (P,).

    One compiled program with the map's preparation and the track's covariance and
    whitener (eagerly, these were ~80 programs compiled one by one: 4.5 s of a
    ``jaxgrav suitability`` call).
    """
    prepared = prepare_map(grid)
    whitener = gls_whitener(track_covariance(north, east, noise, map_sigma, length))

    def one(la, lo):
        m = meridian_radius(la)
        e = prime_vertical_radius(la) * jnp.cos(la * DEG)
        lat = la + north / m / DEG
        lon = lo + east / e / DEG
        v, d_lat, d_lon = prepared.value_and_gradient(lat, lon)
        jac = jnp.stack([d_lat / (meridian_radius(lat) * DEG),
                         d_lon / (prime_vertical_radius(lat) * jnp.cos(lat * DEG) * DEG)], -1)
        ok = jnp.all(jnp.isfinite(v)) & jnp.all(jnp.isfinite(jac))
        info = gauss_newton_information(whitener, jnp.where(ok, jac, 0.0), bias_prior_sigma)
        cov = offset_covariance(info)
        return jnp.where(ok, cov, jnp.nan)

    return jax.lax.map(lambda a: one(*a), (lat0, lon0), batch_size=_CHUNK)


def _box(a, half):
    """Mean of ``a`` over a ``(2 half + 1)²`` window centred on each node (NaN if any
    node of the window is missing or it leaves the grid)."""
    w = 2 * half + 1
    bad = ~np.isfinite(a)
    c = np.pad(np.where(bad, 0.0, a), ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    nb = np.pad(bad.astype(float), ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    s = c[w:, w:] - c[:-w, w:] - c[w:, :-w] + c[:-w, :-w]
    n_bad = nb[w:, w:] - nb[:-w, w:] - nb[w:, :-w] + nb[:-w, :-w]
    out = np.full(a.shape, np.nan)
    out[half:a.shape[0] - half, half:a.shape[1] - half] = np.where(n_bad > 0, np.nan, s / w**2)
    return out


def _descriptors(grid, half):
    """The window descriptors of :data:`DESCRIPTORS` on every node."""
    z = np.asarray(grid.values, float)
    lat = np.asarray(grid.lat)
    dy = grid.dlat * DEG * np.asarray(meridian_radius(lat))[:, None]  # m per row
    dx = (grid.dlon * DEG * np.asarray(prime_vertical_radius(lat))
          * np.cos(lat * DEG))[:, None]  # m per column
    mean = _box(z, half)
    std = np.sqrt(np.maximum(_box(z * z, half) - mean**2, 0.0))
    gy, gx = np.gradient(z, axis=0) / dy, np.gradient(z, axis=1) / dx
    slope = np.hypot(gy, gx) * 1e3  # per km
    ms = _box(slope, half)
    slope_std = np.sqrt(np.maximum(_box(slope**2, half) - ms**2, 0.0))
    diff_y = np.full(z.shape, np.nan)
    diff_y[1:] = np.abs(np.diff(z, axis=0))
    diff_x = np.full(z.shape, np.nan)
    diff_x[:, 1:] = np.abs(np.diff(z, axis=1))
    rough = 0.5 * (_box(np.where(np.isnan(diff_y), 0.0, diff_y), half)
                   + _box(np.where(np.isnan(diff_x), 0.0, diff_x), half))
    lo, hi = np.nanmin(z), np.nanmax(z)
    idx = np.clip(((z - lo) / max(hi - lo, 1e-12) * _BINS).astype(int), 0, _BINS - 1)
    entropy = np.zeros(z.shape)
    for b in range(_BINS):  # 16 box sums, each over the whole map
        p = _box(np.where(np.isfinite(z), (idx == b).astype(float), np.nan), half)
        entropy -= np.where(p > 0, p * np.log(np.where(p > 0, p, 1.0)), 0.0)
    entropy = np.where(np.isnan(std), np.nan, entropy)  # an incomplete window
    var = std**2
    cov_y = np.full(z.shape, np.nan)
    cov_y[1:] = z[1:] * z[:-1]
    cov_x = np.full(z.shape, np.nan)
    cov_x[:, 1:] = z[:, 1:] * z[:, :-1]
    rho = 0.5 * (_box(cov_y, half) + _box(cov_x, half)) - mean**2
    rho = rho / np.where(var > 0, var, np.nan)
    step = 0.5 * (dy + dx) * np.ones_like(z)
    length = np.where((rho > 0) & (rho < 1), -step / np.log(np.clip(rho, 1e-12, 1 - 1e-12)),
                      np.nan)
    return dict(std=std, slope_std=slope_std, roughness=rough, entropy=entropy,
                correlation_length_m=length)


def suitability(grid, *, heading_deg=45.0, n_fixes=30, spacing_m=1200.0, noise_mgal=1.0,
                map_error_mgal=0.0, map_error_length_m=10e3, bias_prior_sigma=float("inf"),
                window_cells=None):
    """Predicted matching precision (CRLB of the mean-track offset) from every node of a map.

    Parameters
    ----------
    grid : Grid
        Anomaly map (mGal).
    heading_deg : float
        Track heading (degrees clockwise from north).
    n_fixes : int
        Fixes per segment (≥ 2).
    spacing_m : float
        Distance between fixes (m).
    noise_mgal : float
        Reading noise 1-σ (mGal, > 0).
    map_error_mgal, map_error_length_m : float
        The map's error: 1-σ (mGal, ≥ 0) and correlation length (m, > 0) of a
        second-order Markov field along the track (0: the map is the truth).
    bias_prior_sigma : float
        Prior σ of the common reading bias (mGal); ∞ (default) marginalises a free bias.
    window_cells : int, optional
        Side of the descriptors' window (nodes, odd); default the segment's length in
        nodes (at least 3).

    Returns
    -------
    Suitability

    Raises
    ------
    ValueError
        A non-finite or non-positive setting, ``n_fixes`` < 2, an even or too small
        ``window_cells``, a map smaller than the window.
    TypeError
        ``grid`` not a Grid.
    """
    if not isinstance(grid, Grid):
        raise TypeError(f"grid must be a Grid; got {type(grid).__name__}")
    if isinstance(n_fixes, bool) or int(n_fixes) != n_fixes or n_fixes < 2:
        raise ValueError(f"n_fixes must be an integer >= 2; got {n_fixes!r}")
    n_fixes = int(n_fixes)
    spacing_m = _check_positive("spacing_m", spacing_m, unit=" (m)")
    noise = _check_positive("noise_mgal", noise_mgal, unit=" (mGal)")
    map_sigma = _check_positive("map_error_mgal", map_error_mgal, zero_ok=True, unit=" (mGal)")
    length = _check_positive("map_error_length_m", map_error_length_m, unit=" (m)")
    heading = float(heading_deg)
    if not np.isfinite(heading):
        raise ValueError(f"heading_deg must be finite (degrees); got {heading_deg!r}")
    if not float(bias_prior_sigma) >= 0:
        raise ValueError(f"bias_prior_sigma must be >= 0 (mGal; inf: free); got "
                         f"{bias_prior_sigma!r}")
    lat = np.asarray(grid.lat)
    cell_m = grid.dlat * DEG * float(meridian_radius(np.mean(lat)))
    if window_cells is None:
        window_cells = max(3, 2 * round((n_fixes - 1) * spacing_m / cell_m / 2) + 1)
    if int(window_cells) != window_cells or window_cells < 3 or window_cells % 2 == 0:
        raise ValueError(f"window_cells must be an odd integer >= 3 (nodes); got "
                         f"{window_cells!r}")
    ny, nx = np.asarray(grid.values).shape[-2:]
    if window_cells > min(ny, nx):
        raise ValueError(f"window_cells={window_cells} is larger than the map ({ny} x {nx} "
                         "nodes)")
    north, east = _track_offsets(n_fixes, spacing_m, heading)
    lat0, lon0 = np.meshgrid(lat, np.asarray(grid.lon), indexing="ij")
    crlb = np.asarray(_precision(grid, jnp.asarray(lat0.ravel()), jnp.asarray(lon0.ravel()),
                                 jnp.asarray(north), jnp.asarray(east), noise, map_sigma, length,
                                 float(bias_prior_sigma)))
    crlb = crlb.reshape(ny, nx, 2, 2)
    # a flat or confounded window's Fisher matrix is singular: its inverse's diagonal can
    # come out negative, whose NaN the command reports as no_information
    with np.errstate(invalid="ignore", divide="ignore"):
        sn, se = np.sqrt(crlb[..., 0, 0]), np.sqrt(crlb[..., 1, 1])
        corr = crlb[..., 0, 1] / (sn * se)
        precision = np.sqrt(crlb[..., 0, 0] + crlb[..., 1, 1])
    return Suitability(precision, sn, se, corr, _descriptors(grid, int(window_cells) // 2))
