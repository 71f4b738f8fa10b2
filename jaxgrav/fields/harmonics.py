"""Spherical-harmonic synthesis of a disturbing-potential model, in JAX.

Model convention (fixed; other modules rely on it): 4π-normalised real coefficients
(geodesy normalisation, no Condon–Shortley phase, pyshtools ``normalization='4pi',
csphase=1``) of the disturbing potential

.. math:: T(r, φ, λ) = \\frac{GM}{r} \\sum_{n=0}^{N} \\left(\\frac{R}{r}\\right)^n
          \\sum_{m=0}^{n} (\\bar C_{nm} \\cos mλ + \\bar S_{nm} \\sin mλ) \\bar P_{nm}(\\sin φ).

**Spherical approximation.** A point (lat, lon, h) is mapped to the sphere point
φ = lat, λ = lon, r = R + h: the latitude is used as a spherical latitude and the
height as a radial offset. This is the standard spherical approximation of physical
geodesy (relative error O(flattening) ≈ 0.3 % in the anomalous quantities) and is how
the shipped EGM2008-derived data are built. Derived quantities, in the same
approximation:

* gravity disturbance ``δg = −∂T/∂r = GM/r² Σ (n+1) (R/r)^n Y_n`` (mGal);
* gravity anomaly ``Δg = −∂T/∂r − 2T/r = GM/r² Σ (n−1) (R/r)^n Y_n`` (mGal);
* deflection of the vertical, Heiskanen–Moritz signs, ``ξ = −∂T/(γ r ∂φ)``,
  ``η = −∂T/(γ r cos φ ∂λ)`` (arcsec), γ = :func:`jaxgrav.geodesy.normal_gravity`.

**Legendre functions** are those of :mod:`jaxgrav.fields.legendre`: the
forward-column recursion of Holmes & Featherstone (2002, J. Geodesy 76:279) on
scaled values, valid at every latitude up to degree ≈2700. Against pyshtools the
fields agree to ≈1e-12 relative at degree 2190 at 30°, 60° and 85° latitude.
float64 is required (the scaling needs it): enable ``jax_enable_x64``.
The coefficient model itself, :class:`SphericalHarmonics`, is defined in
:mod:`jaxgrav.fields.harmonic_model`; this module synthesises fields from it.

**Poles.** At lat = ±90° (where ``cos φ`` is ≈6e-17 in floating point) every output
is finite: ``η`` is evaluated through ``∂T/∂λ / cos φ`` written as a series in
``cos^(m−1) φ``, ``ξ`` and ``η`` are then the components along the meridian of the
given longitude. Gradients are finite there too, but the lat/lon frame is singular, so
derivatives of ``ξ, η`` with respect to ``lon`` at a pole are frame rotations, not
field changes.

**Cost.** The recursion costs ``O(N²)`` per point, or per latitude row for
:func:`synthesize_grid` (plus a matrix product over longitudes). Degrees run in up to
four blocks, each carrying only the orders ``m < n_block_end`` (≈⅜ less work at high
degree); points are processed in chunks of 8192/(N+1) clipped to [8, 256]
(``lax.map``), which keeps the working set in cache and bounds memory. Compilation
takes a few seconds (each block is one more compiled loop). Reverse-mode gradients
recompute each block (``jax.checkpoint``), so their memory grows with ``N²/blocks``
per point of a chunk.
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import constants as const
from jaxgrav._validate import check_finite, check_latitude, check_points, concrete
from jaxgrav.fields.harmonic_model import SphericalHarmonics
from jaxgrav.fields.legendre import order_sums, unscale_factors
from jaxgrav.geodesy import normal_gravity

__all__ = [
    "FieldValues",
    "SphericalHarmonics",
    "deflection",
    "disturbing_potential",
    "gravity_anomaly",
    "gravity_disturbance",
    "synthesize",
    "synthesize_grid",
]

_ELEMS_PER_CHUNK = 8192  # points × orders per recursion batch (measured on a 2-core Xeon)


class FieldValues(NamedTuple):
    """All synthesised quantities at the same points (each the points' shape).

    Attributes
    ----------
    potential : Array
        Disturbing potential T (m²/s²).
    anomaly : Array
        Gravity anomaly Δg, spherical approximation (mGal).
    disturbance : Array
        Gravity disturbance δg (mGal).
    xi, eta : Array
        Deflection of the vertical, north–south and east–west components (arcsec,
        Heiskanen–Moritz signs).
    """

    potential: jax.Array
    anomaly: jax.Array
    disturbance: jax.Array
    xi: jax.Array
    eta: jax.Array


def _prepare(model):
    if jnp.result_type(float) != jnp.float64:
        raise RuntimeError(
            "jaxgrav.fields.harmonics needs float64 (its Legendre scaling underflows in "
            "float32); call jax.config.update('jax_enable_x64', True) at program start"
        )
    c = jnp.asarray(model.c, jnp.float64)
    s = jnp.asarray(model.s, jnp.float64)
    if c.shape[1] < 2:
        c, s = jnp.pad(c, ((0, 0), (0, 1))), jnp.pad(s, ((0, 0), (0, 1)))
    return c, s


def _finish(model, lat, h, sums):
    """Turn the four sums (T, δg, ∂φ, ∂λ/cos φ) into the stacked fields (T, Δg, δg, ξ,
    η), shape (5, ...), in public units; NaN where |lat| > 90 (reachable under jit)."""
    bad = jnp.abs(lat) > 90.0
    v_t, v_b, v_d, v_l = (jnp.where(bad, jnp.nan, v) for v in sums)
    r = model.radius + h
    gm_r = model.gm / r
    pot = gm_r * v_t
    dist = gm_r / r * v_b
    defl = -gm_r / (normal_gravity(lat, h) * const.MGAL * r * const.ARCSEC)
    # one stacked output (fewer kernels to compile); slicing a row keeps the others dead
    return jnp.stack([pot, (dist - 2.0 * pot / r) / const.MGAL, dist / const.MGAL,
                      defl * v_d, defl * v_l])  # fmt: skip


def _trig_lat(lat, h, radius):
    phi = jnp.deg2rad(lat)
    return jnp.sin(phi), jnp.cos(phi), radius / (radius + h)


@functools.partial(jax.jit, static_argnames=("chunk",))
def _synthesize_points(model, lat, lon, h, chunk):
    """Core of :func:`synthesize` on flat float64 arrays of shape (P,)."""
    c, s = _prepare(model)
    width = c.shape[1]
    npts = lat.shape[0]
    nchunk = -(-npts // chunk)
    pad = nchunk * chunk - npts
    stacked = jnp.stack([lat, lon, h]).astype(jnp.float64)
    stacked = jnp.pad(stacked, ((0, 0), (0, pad))).reshape(3, nchunk, chunk)
    m = jnp.arange(width, dtype=jnp.float64)

    def one_chunk(x):
        la, lo, hh = x
        t, u, q = _trig_lat(la, hh, model.radius)
        ac, as_, bc, bs, dc, ds = order_sums(c, s, t, q)
        f0, f1 = unscale_factors(u, width)
        ml = jnp.deg2rad(lo)[:, None] * m
        cm, sm = jnp.cos(ml), jnp.sin(ml)
        terms = (f0 * (ac * cm + as_ * sm), f0 * (bc * cm + bs * sm),
                 f1 * (dc * cm + ds * sm), f1 * m * (as_ * cm - ac * sm))  # fmt: skip
        # separate outputs, so that XLA drops the unused sums (and their accumulators)
        return tuple(jnp.sum(v, axis=-1) for v in terms)

    if nchunk == 1:  # no loop over chunks (smaller program to compile and differentiate)
        sums = one_chunk(stacked[:, 0])
    else:
        sums = jax.lax.map(one_chunk, jnp.moveaxis(stacked, 1, 0))
    return _finish(model, lat, h, [v.reshape(-1)[:npts] for v in sums])


def _default_chunk(model, size):
    per_chunk = min(256, max(8, _ELEMS_PER_CHUNK // (model.nmax + 1)))
    return int(max(1, min(size, per_chunk)))


def _resolve_chunk(model, chunk, size):
    """Points (or latitude rows) per recursion batch: ``chunk`` checked, or the default."""
    if chunk is None:
        chunk = _default_chunk(model, size)
    if not (isinstance(chunk, (int, np.integer)) and chunk >= 1):
        raise ValueError(f"chunk must be a positive integer; got {chunk!r}")
    return int(chunk)


def _check_height(model, h):
    """Raise if a concrete height puts a point at or below the sphere's centre."""
    h_c = concrete(h)
    if h_c is not None and np.any(model.radius + h_c <= 0):
        raise ValueError(f"h must be > -radius = {-model.radius} m; got {float(np.min(h_c))!r}")


def _check_model(model):
    if not isinstance(model, SphericalHarmonics):
        raise TypeError(
            "model must be a SphericalHarmonics (see SphericalHarmonics.from_arrays); "
            f"got {type(model).__name__}"
        )


def synthesize(model, lat, lon, h=0.0, *, chunk=None):
    """Synthesise T, Δg, δg, ξ and η at points, sharing the Legendre work.

    Parameters
    ----------
    model : SphericalHarmonics
        Disturbing-potential model (degree N from its coefficient shape).
    lat : array_like
        Latitude (degrees, within [−90, 90]), used as spherical latitude.
    lon : array_like
        Longitude (degrees, 0–360 or ±180).
    h : array_like, default 0
        Height above the reference sphere (m): r = model.radius + h.
    chunk : int, optional
        Points per recursion batch (static); default 8192/(N+1) clipped to [8, 256].

    ``lat``, ``lon`` and ``h`` broadcast together (any shape S).

    Returns
    -------
    FieldValues
        potential (m²/s²), anomaly and disturbance (mGal), xi and eta (arcsec), each
        of shape S.

    Raises
    ------
    ValueError
        For concrete inputs: a latitude outside [−90, 90] (under ``jit`` such points
        give NaN instead), non-finite values, ``radius + h ≤ 0``, shapes that do not
        broadcast, or a bad ``chunk``.

    Notes
    -----
    The single-quantity functions (:func:`disturbing_potential`, ...) call this one.
    Under an enclosing ``jax.jit`` XLA drops the sums a caller does not use (T alone
    costs about half of all five fields); called eagerly, all five are computed.
    """
    _check_model(model)
    check_points(lat, lon, h)
    _check_height(model, h)
    dt = jnp.result_type(float)
    lat, lon, h = jnp.broadcast_arrays(*(jnp.asarray(x, dt) for x in (lat, lon, h)))
    chunk = _resolve_chunk(model, chunk, max(lat.size, 1))
    out = _synthesize_points(model, *(x.reshape(-1) for x in (lat, lon, h)), chunk)
    return FieldValues(*out.reshape((5, *lat.shape)))


def disturbing_potential(model, lat, lon, h=0.0, *, chunk=None):
    """Disturbing potential T (m²/s²) at points; arguments as in :func:`synthesize`."""
    return synthesize(model, lat, lon, h, chunk=chunk).potential


def gravity_anomaly(model, lat, lon, h=0.0, *, chunk=None):
    """Gravity anomaly Δg = −∂T/∂r − 2T/r (mGal); arguments as in :func:`synthesize`."""
    return synthesize(model, lat, lon, h, chunk=chunk).anomaly


def gravity_disturbance(model, lat, lon, h=0.0, *, chunk=None):
    """Gravity disturbance δg = −∂T/∂r (mGal); arguments as in :func:`synthesize`."""
    return synthesize(model, lat, lon, h, chunk=chunk).disturbance


def deflection(model, lat, lon, h=0.0, *, chunk=None):
    """Deflection of the vertical ``(xi, eta)`` (arcsec, Heiskanen–Moritz signs).

    ``ξ = −∂T/(γ r ∂φ)``, ``η = −∂T/(γ r cos φ ∂λ)`` with γ the WGS84 normal gravity
    at (lat, h); arguments as in :func:`synthesize`.
    """
    out = synthesize(model, lat, lon, h, chunk=chunk)
    return out.xi, out.eta


@functools.partial(jax.jit, static_argnames=("chunk",))
def _synthesize_grid(model, lat, lon, h, chunk):
    c, s = _prepare(model)
    width = c.shape[1]
    nlat = lat.shape[0]
    nchunk = -(-nlat // chunk)
    lat_p = jnp.pad(lat, (0, nchunk * chunk - nlat)).reshape(nchunk, chunk)

    def rows(la):
        t, u, q = _trig_lat(la, h, model.radius)
        q = jnp.broadcast_to(q, la.shape)
        ac, as_, bc, bs, dc, ds = order_sums(c, s, t, q)
        f0, f1 = unscale_factors(u, width)
        m = jnp.arange(width, dtype=jnp.float64)
        return (jnp.stack([f0 * ac, f0 * bc, f1 * dc, -f1 * m * ac]),
                jnp.stack([f0 * as_, f0 * bs, f1 * ds, f1 * m * as_]))  # fmt: skip

    lc, ls = jax.lax.map(rows, lat_p)  # (nchunk, 4, chunk, W)
    lc = jnp.moveaxis(lc, 1, 0).reshape(4, -1, width)[:, :nlat]
    ls = jnp.moveaxis(ls, 1, 0).reshape(4, -1, width)[:, :nlat]
    ml = jnp.arange(width, dtype=jnp.float64)[:, None] * jnp.deg2rad(lon)[None, :]
    cm, sm = jnp.cos(ml), jnp.sin(ml)  # (W, nlon)
    hi = jax.lax.Precision.HIGHEST
    # columns 0-2 pair (c, s) with (cos, sin); column 3 (∂/∂λ) with (sin, cos)
    v = jnp.matmul(lc[:3], cm, precision=hi) + jnp.matmul(ls[:3], sm, precision=hi)
    v_l = jnp.matmul(lc[3], sm, precision=hi) + jnp.matmul(ls[3], cm, precision=hi)
    lat2 = jnp.broadcast_to(lat[:, None], v_l.shape)
    return _finish(model, lat2, jnp.broadcast_to(h, v_l.shape), jnp.concatenate([v, v_l[None]]))


def synthesize_grid(model, lat_1d, lon_1d, h=0.0, *, chunk=None):
    """Synthesise all quantities on a regular lat/lon grid.

    The Legendre lattice is computed once per latitude row; the sum over orders is
    then a matrix product with ``cos mλ``/``sin mλ`` over the longitudes.

    Parameters
    ----------
    model : SphericalHarmonics
        Disturbing-potential model.
    lat_1d : array_like, shape (nlat,)
        Row latitudes (degrees, within [−90, 90]).
    lon_1d : array_like, shape (nlon,)
        Column longitudes (degrees).
    h : float, default 0
        Height above the reference sphere for the whole grid (m).
    chunk : int, optional
        Latitude rows per recursion batch (static); default 8192/(N+1) clipped to
        [8, 256].

    Returns
    -------
    FieldValues
        Each field of shape (nlat, nlon), units as in :func:`synthesize`.

    Raises
    ------
    ValueError
        If ``lat_1d``/``lon_1d`` are not 1-D, ``h`` is not a scalar, or values are out
        of range or non-finite (concrete inputs).
    """
    _check_model(model)
    for name, v in (("lat_1d", lat_1d), ("lon_1d", lon_1d)):
        if np.ndim(v) != 1 or np.shape(v)[0] == 0:
            raise ValueError(f"{name} must be a non-empty 1-D array; got shape {np.shape(v)}")
    if np.ndim(h) != 0:
        raise ValueError(f"h must be a scalar height (m) for a grid; got shape {np.shape(h)}")
    check_latitude(lat_1d, "lat_1d")
    check_finite(lon_1d, "lon_1d")
    check_finite(h, "h")
    _check_height(model, h)
    chunk = _resolve_chunk(model, chunk, np.shape(lat_1d)[0])
    dt = jnp.result_type(float)
    out = _synthesize_grid(
        model, jnp.asarray(lat_1d, dt), jnp.asarray(lon_1d, dt), jnp.asarray(h, dt), chunk
    )
    return FieldValues(*out)
