"""Kernels of layered DOV interpolation: horizontal in each layer, then vertical.

Used through :func:`jaxgrav.dov.interpolate`, :func:`jaxgrav.dov.make_interpolator`
and :func:`jaxgrav.dov.scan_track`; this module holds the traced arithmetic and knows
a :class:`jaxgrav.dov.LayeredGrid` only by its attributes.

Methods are named ``"<horizontal>-<vertical>"``:

horizontal
    ``bilinear`` (the paper) or ``bicubic`` (not-a-knot spline, SciPy's "cubic"),
    the kernels of :mod:`jaxgrav.interp`, applied to every layer.
vertical
    ``linear`` (the paper) between the two layers that bracket ``h``;
    ``lagrange``: quadratic through the three layers nearest ``h``;
    ``harmonic``: a cubic in ``h`` between the bracketing layers whose second
    derivative at each layer comes from Laplace's equation. Above the masses the
    disturbing potential, and to O(h/R) the deflections (its horizontal derivatives
    scaled by 1/(γr)), are harmonic, so ``∂²f/∂r² = −(2/r) ∂f/∂r − Δ_S f / r²``: the
    vertical curvature is known from the *horizontal* curvature of each layer. With
    ``f''`` at both ends the segment is the cubic-spline segment
    ``f = A f_k + B f_k+1 + Δ²/6 [(A³−A) f''_k + (B³−B) f''_k+1]`` (A = 1 − t, B = t).
    This is upward continuation to second order, built from the layers alone.
    ``Δ_S f`` is evaluated from not-a-knot spline derivatives of each layer along
    rows and columns (``f_φφ − tan φ f_φ + f_λλ / cos² φ``), and ``∂f/∂r`` from the
    secant between neighbouring layers.
"""

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import interp
from jaxgrav.constants import DEG

__all__ = ["DEFAULT_METHOD", "HARMONIC_GAP_LIMIT", "HORIZONTAL", "METHODS", "VERTICAL",
           "check_method", "harmonic_gap_ratio"]

HORIZONTAL = ("bilinear", "bicubic")
VERTICAL = ("linear", "lagrange", "harmonic")
METHODS = tuple(f"{a}-{b}" for a in HORIZONTAL for b in VERTICAL)
DEFAULT_METHOD = "bicubic-harmonic"  # the most accurate on paper C's trajectory
_RADIUS = 6378136.3  # reference sphere of the layers (m), as the shipped qinling data
HARMONIC_GAP_LIMIT = 2.0
"""Largest :func:`harmonic_gap_ratio` ``k·Δ`` at which ``harmonic`` is trusted: for a field
``exp(−k h)`` its segment error is 0.8 % of the amplitude at ``k·Δ = 1``, 8 % at 2, 29 %
at 3 (no better than ``linear``'s 32 %) and 180 % at 6 (it then extrapolates far outside
the layers' values)."""


def check_method(method, n_layers):
    """Split ``method`` into (horizontal, vertical) or raise ``ValueError``."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    horiz, vert = method.split("-")
    need = 3 if vert == "lagrange" else 2
    if n_layers < need:
        raise ValueError(
            f"method {method!r} needs at least {need} layers; the grid has {n_layers}"
        )
    return horiz, vert


def _curvature(layers):
    """Vertical curvature ``∂²f/∂r²`` of every layer from Laplace's equation, (L, C, ny, nx)."""
    v = layers.values
    dtype = jnp.result_type(v.dtype, layers.heights.dtype, float)
    v = v.astype(dtype)
    h = layers.heights.astype(dtype)
    r = _RADIUS + h[:, None, None, None]
    dphi, dlam = layers.dlat * DEG, layers.dlon * DEG
    f_y = interp.spline_slopes(v, -2) / dphi
    f_yy = interp.spline_slopes(f_y, -2) / dphi
    f_xx = interp.spline_slopes(interp.spline_slopes(v, -1), -1) / dlam**2
    lat = jnp.asarray(layers.lat0 + layers.dlat * np.arange(v.shape[-2]), dtype) * DEG
    tan, cos = jnp.tan(lat)[:, None], jnp.cos(lat)[:, None]
    lap_s = f_yy - tan * f_y + f_xx / cos**2
    # ∂f/∂r from the secant to the neighbouring layer (forward at the top: backward)
    dh = jnp.diff(h)[:, None, None, None]
    sec = jnp.diff(v, axis=0) / dh  # (L-1, ...)
    f_r = jnp.concatenate([sec[:1], 0.5 * (sec[1:] + sec[:-1]), sec[-1:]], axis=0)
    return -lap_s / r**2 - 2.0 * f_r / r


@jax.jit
def harmonic_gap_ratio(layers):
    """``k·Δ`` of every layer gap: how far ``harmonic``'s continuation is stretched.

    The ``harmonic`` segment continues each layer upward to second order; for a field
    component ``exp(−k h)`` that is good while ``k·Δ`` is small and diverges beyond about 3
    (see :data:`HARMONIC_GAP_LIMIT`). ``k`` is each layer's effective wavenumber
    ``sqrt(rms(∂²f/∂r²) / rms(f − mean f))`` (weighted to the short wavelengths that carry
    the curvature), the larger of the gap's two layers and of the channels.

    Parameters
    ----------
    layers : LayeredGrid
        Values ``(L, C, ny, nx)``, ``L ≥ 2``.

    Returns
    -------
    Array, shape ``(L − 1,)``
        ``k·Δ`` (dimensionless) of the gaps between consecutive layers; 0 for flat layers.
    """
    curv = _curvature(layers)
    v = layers.values.astype(curv.dtype)
    dev = v - jnp.nanmean(v, axis=(-2, -1), keepdims=True)
    rms_c = jnp.sqrt(jnp.nanmean(curv**2, axis=(-2, -1)))
    rms_f = jnp.sqrt(jnp.nanmean(dev**2, axis=(-2, -1)))
    k = jnp.sqrt(jnp.where(rms_f > 0, rms_c / jnp.where(rms_f > 0, rms_f, 1.0), 0.0))
    k = jnp.max(k, axis=1)  # (L,)
    return jnp.diff(layers.heights.astype(curv.dtype)) * jnp.maximum(k[:-1], k[1:])


def prepare(layers, horiz, vert):
    """Horizontal coefficients of every layer, computed once per map.

    Returns an array ``(L, C', ny, nx)`` (bilinear) or ``(L, C', ny, nx, 4)`` (bicubic)
    where ``C' = C`` or ``2C`` (values then vertical curvatures, for ``harmonic``).
    """
    v = layers.values
    if vert == "harmonic":
        dtype = jnp.result_type(v.dtype, layers.heights.dtype, float)
        v = jnp.concatenate([v.astype(dtype), _curvature(layers)], axis=1)
    if horiz == "bicubic":
        return interp.bicubic_coefficients(v)
    return v


def horizontal(layers, coef, horiz, lat, lon):
    """Every layer interpolated at the points: ``(L, C', *P)``, NaN off the map."""
    iy, ix = layers.fractional_index(lat, lon)
    if horiz == "bicubic":
        return interp.bicubic(coef, iy, ix)
    return interp.bilinear(coef, iy, ix)


def _onehot(k, n, dtype):
    return (k[None, ...] == jnp.arange(n).reshape((n,) + (1,) * k.ndim)).astype(dtype)


def vertical_weights(heights, h, vert):
    """Weights over the layers for values (and curvatures), and the in-range mask.

    Parameters
    ----------
    heights : Array, shape (L,)
        Ascending layer heights (m).
    h : Array, shape P
        Point heights (m).
    vert : {"linear", "lagrange", "harmonic"}

    Returns
    -------
    w : Array, shape (L, *P)
        Weights of the layer values.
    w2 : Array, shape (L, *P) or None
        Weights of the layer curvatures (``harmonic`` only).
    inside : Array of bool, shape P
        ``heights[0] ≤ h ≤ heights[-1]`` (with a rounding tolerance).
    """
    n = heights.shape[0]
    dtype = jnp.result_type(heights.dtype, h.dtype, float)
    heights, h = heights.astype(dtype), h.astype(dtype)
    span = heights[-1] - heights[0]
    tol = 64 * float(jnp.finfo(dtype).eps) * (jnp.abs(heights[-1]) + jnp.abs(heights[0]) + 1.0)
    inside = (h >= heights[0] - tol) & (h <= heights[-1] + tol)
    hs = jnp.where(inside, h, heights[0] + 0.5 * span)  # harmless value off range
    k = jnp.clip(jnp.searchsorted(heights, hs, side="right") - 1, 0, n - 2)
    h0, h1 = heights[k], heights[k + 1]
    if vert in ("linear", "harmonic"):
        d = h1 - h0
        t = (hs - h0) / d
        a, b = 1.0 - t, t
        e0, e1 = _onehot(k, n, dtype), _onehot(k + 1, n, dtype)
        w = e0 * a + e1 * b
        if vert == "linear":
            return w, None, inside
        c = d * d / 6.0
        w2 = e0 * (c * (a**3 - a)) + e1 * (c * (b**3 - b))
        return w, w2, inside
    # lagrange through the three nearest layers
    km1 = jnp.maximum(k - 1, 0)
    kp2 = jnp.minimum(k + 2, n - 1)
    use_lower = (k >= 1) & ((k + 2 > n - 1) | (hs - heights[km1] < heights[kp2] - hs))
    j0 = jnp.clip(jnp.where(use_lower, k - 1, k), 0, n - 3)
    nodes = [heights[j0 + i] for i in range(3)]
    w = 0.0
    for i in range(3):
        li = 1.0
        for j in range(3):
            if j != i:
                li = li * (hs - nodes[j]) / (nodes[i] - nodes[j])
        w = w + _onehot(j0 + i, n, dtype) * li
    return w, None, inside


def combine(vals, w, w2, inside_v, n_channels):
    """Vertical combination of horizontally interpolated layers: ``(C, *P)``."""
    f = vals[:, :n_channels]
    out = jnp.sum(w[:, None] * f, axis=0)
    if w2 is not None:
        out = out + jnp.sum(w2[:, None] * vals[:, n_channels:], axis=0)
    return jnp.where(inside_v, out, jnp.nan)


def evaluate(layers, coef, horiz, vert, lat, lon, h):
    """Interpolated channels ``(C, *P)`` (NaN off the grid) and the inside mask ``P``."""
    lat, lon, h = jnp.broadcast_arrays(jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(h))
    vals = horizontal(layers, coef, horiz, lat, lon)
    w, w2, inside_v = vertical_weights(layers.heights, h, vert)
    out = combine(vals, w, w2, inside_v, layers.values.shape[1])
    inside = inside_v & jnp.all(jnp.isfinite(vals), axis=(0, 1))
    return out, inside


def scan_points(layers, coef, horiz, vert, lat, lon, h):
    """:func:`evaluate` one fix at a time with ``lax.scan`` (on-board form).

    The carry is the previous fix's cell ``(layer, row, column)`` (the paper's
    "locate from the previous fix" step); the number of cell changes along the
    track is returned with the values.
    """
    def step(prev, x):
        la, lo, hh = x
        out, ok = evaluate(layers, coef, horiz, vert, la, lo, hh)
        iy, ix = layers.fractional_index(la, lo)
        k = jnp.searchsorted(layers.heights, hh, side="right") - 1
        cell = jnp.stack([k, jnp.floor(iy), jnp.floor(ix)]).astype(jnp.int32)
        cell = jnp.where(ok, cell, -1)
        changed = jnp.any(cell != prev)
        return cell, (out, ok, changed)

    xs = (lat.reshape(-1), lon.reshape(-1), h.reshape(-1))
    init = jnp.full((3,), -1, jnp.int32)
    _, (out, ok, changed) = jax.lax.scan(step, init, xs)
    c = out.shape[1]
    return (
        jnp.moveaxis(out, 0, 1).reshape((c, *lat.shape)),
        ok.reshape(lat.shape),
        jnp.sum(changed.astype(jnp.int32)),
    )
