"""Closest contour points on a map's bicubic interpolant, in local metres (paper B, ICCP).

ICCP evaluates the map and its gradient millions of times (points × Newton steps ×
iterations × tracks), so this module prepares the map once for that loop:

- :func:`patch_coefficients` (:meth:`jaxgrav.prepared.PreparedMap.patches`) turns the
  not-a-knot bicubic spline of :func:`jaxgrav.interp.bicubic_coefficients` (node values
  and slopes, Hermite form) into the 16 power-basis coefficients ``a_ij`` of every cell,
  ``f(ty, tx) = Σ a_ij ty^i tx^j`` for ``ty, tx ∈ [0, 1]``: the *same* interpolant,
  but one contiguous gather of 16 numbers per point instead of four of four, and the
  value and both derivatives by two short Horner sums with no basis functions to build.
- :class:`LocalField` maps local metres ``(north, east)`` about a track's centroid
  linearly to fractional grid indices (the frame of
  :func:`~jaxgrav.match.offsets.shifted_tracks`), so no latitude/longitude arithmetic
  is done inside the loop.
- :func:`value_grad` gives the value and the analytic gradient (per metre) at points
  (:func:`value_grad_ne` with north and east in separate arrays, the hot-loop form);
  :func:`project_to_contours` does the Newton projection onto each point's level set.

Points off the map give NaN values and zero gradients (computed on clipped, harmless
coordinates first, so gradients of callers stay finite).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav import interp
from jaxgrav.prepared import as_grid

__all__ = [
    "LocalField",
    "local_field",
    "patch_coefficients",
    "project_to_contours",
    "value_grad",
    "value_grad_ne",
]

def patch_coefficients(values):
    """Power-basis coefficients of the bicubic (not-a-knot spline) interpolant per cell.

    :func:`jaxgrav.interp.bicubic_patches` of the node coefficients; with a
    :class:`~jaxgrav.prepared.PreparedMap` use its :meth:`~jaxgrav.prepared.PreparedMap.patches`.

    Parameters
    ----------
    values : Array, shape ``(ny, nx)``
        Node values (map units), ``ny, nx ≥ 4``.

    Returns
    -------
    Array, shape ``(ny−1, nx−1, 16)``
        Cell ``[r, c]`` holds ``a_ij`` at ``4i + j``:
        ``f = Σ a_ij ty^i tx^j`` with ``ty = iy − r``, ``tx = ix − c`` in ``[0, 1]``.
    """
    return interp.bicubic_patches(interp.bicubic_coefficients(values))


class LocalField(NamedTuple):
    """A map prepared for sampling in local metres about an origin.

    Attributes
    ----------
    coef : Array, shape ``(ny−1, nx−1, 16)``
        :func:`patch_coefficients` of the map.
    iy0, ix0 : Array
        Fractional grid indices of the origin.
    sy, sx : Array
        Index steps per metre north and east.
    """

    coef: jax.Array
    iy0: jax.Array
    ix0: jax.Array
    sy: jax.Array
    sx: jax.Array


def local_field(coef, grid, lat_c, lon_c, m_per_deg_lat, m_per_deg_lon):
    """A :class:`LocalField` about ``(lat_c, lon_c)``.

    Parameters
    ----------
    coef : Array
        :func:`patch_coefficients` of ``grid.values``.
    grid : Grid or PreparedMap
    lat_c, lon_c : Array
        Origin (degrees).
    m_per_deg_lat, m_per_deg_lon : Array
        Metres per degree north and east at the origin (the local frame's scale).

    Returns
    -------
    LocalField
    """
    grid = as_grid(grid)
    iy0, ix0 = grid.fractional_index(lat_c, lon_c)
    dtype = jnp.result_type(coef.dtype, iy0.dtype)
    return LocalField(coef, iy0.astype(dtype), ix0.astype(dtype),
                      (1.0 / (m_per_deg_lat * grid.dlat)).astype(dtype),
                      (1.0 / (m_per_deg_lon * grid.dlon)).astype(dtype))


def value_grad_ne(field, north, east):
    """Map value and gradient at local points given as separate coordinate arrays.

    The hot-loop form of :func:`value_grad`: north and east components are kept in
    separate arrays (no stacking, no reductions over a length-2 axis).

    Parameters
    ----------
    field : LocalField
    north, east : Array
        Point coordinates (m), same shape.

    Returns
    -------
    tuple of Array
        ``(f, g_north, g_east)``: values (map units; NaN off the map) and gradient
        components (map units per metre; 0 off the map).
    """
    ny, nx = field.coef.shape[0] + 1, field.coef.shape[1] + 1
    eps = interp.edge_eps(field.coef.dtype, max(ny, nx))
    iy = field.iy0 + north * field.sy
    ix = field.ix0 + east * field.sx
    inside = (iy >= -eps) & (iy <= ny - 1 + eps) & (ix >= -eps) & (ix <= nx - 1 + eps)
    iy = jnp.clip(jnp.where(inside, iy, 0.0), 0.0, ny - 1.0)
    ix = jnp.clip(jnp.where(inside, ix, 0.0), 0.0, nx - 1.0)
    r0 = jnp.minimum(jnp.floor(iy), ny - 2.0)
    c0 = jnp.minimum(jnp.floor(ix), nx - 2.0)
    ty, tx = iy - r0, ix - c0
    flat = field.coef.reshape((ny - 1) * (nx - 1), 16)
    # (..., 16): one gather; r0, c0 are clipped above, so no bounds handling is needed
    a = flat.at[(r0 * (nx - 1) + c0).astype(jnp.int32)].get(mode="promise_in_bounds")
    # Horner in tx for the four rows i at once (the same arithmetic as row by row, in a
    # quarter of the operations: a smaller program for every evaluation)
    a = a.reshape((*a.shape[:-1], 4, 4))  # [..., i, j] = a_ij
    t = tx[..., None]
    u = a[..., 0] + t * (a[..., 1] + t * (a[..., 2] + t * a[..., 3]))  # Σ_j a_ij tx^j
    du = a[..., 1] + t * (2.0 * a[..., 2] + t * 3.0 * a[..., 3])  # its tx-derivative
    u0, u1, u2, u3 = (u[..., i] for i in range(4))
    f = u0 + ty * (u1 + ty * (u2 + ty * u3))
    f_y = u1 + ty * (2.0 * u2 + ty * 3.0 * u3)
    f_x = du[..., 0] + ty * (du[..., 1] + ty * (du[..., 2] + ty * du[..., 3]))
    return (jnp.where(inside, f, jnp.nan), jnp.where(inside, f_y * field.sy, 0.0),
            jnp.where(inside, f_x * field.sx, 0.0))


def value_grad(field, x):
    """Map value and gradient at local points.

    Parameters
    ----------
    field : LocalField
    x : Array, shape ``(..., 2)``
        Points ``(north, east)`` (m).

    Returns
    -------
    tuple of Array
        ``(f, g)``: values ``(...)`` (map units; NaN off the map) and gradients
        ``(..., 2)`` (map units per metre, north and east; 0 off the map).
    """
    f, g_n, g_e = value_grad_ne(field, x[..., 0], x[..., 1])
    return f, jnp.stack([g_n, g_e], axis=-1)


def project_to_contours(field, y_n, y_e, z, steps, max_step_m):
    """Newton projection of points onto the level sets of their measured values.

    From each point ``y``, ``steps`` steps ``x ← x − (f(x) − z) ∇f / |∇f|²``, each at
    most ``max_step_m`` long (for a locally linear field one step is the exact foot of
    the perpendicular on the contour ``f = z``).

    Parameters
    ----------
    field : LocalField
    y_n, y_e : Array, shape ``(N,)``
        Starting points, north and east (m).
    z : Array, shape ``(N,)``
        Measured values (map units).
    steps : int
        Newton steps (static, ≥ 1).
    max_step_m : float
        Longest single step (m).

    Returns
    -------
    tuple of Array
        ``(x_n, x_e, f, g_n, g_e)``: contour points and the value and gradient at
        them (one evaluation after the last step), each ``(N,)``.

    Notes
    -----
    Each evaluation's outputs pass an optimisation barrier: without it XLA fuses the
    Horner sums into every consumer and recomputes them there (each step's ``f`` and
    gradient were evaluated three to four times; for the ICCP loop's final step, once
    per Kabsch sum). The ``steps + 1`` evaluations are one loop (the last does not move
    the points), so the map's Horner sums are compiled once, not ``steps + 1`` times.
    Values are unchanged.
    """
    def step(i, s):
        x_n, x_e = s[:2]
        f, g_n, g_e = jax.lax.optimization_barrier(value_grad_ne(field, x_n, x_e))
        g2 = g_n * g_n + g_e * g_e
        ok = jnp.isfinite(f) & (g2 > 0)
        d = jnp.where(ok, z - f, 0.0) / jnp.where(ok, g2, 1.0)
        # step length |d|·|g|, limited to max_step_m: scale = min(1, max / (|d| |g|))
        length2 = d * d * g2
        d = d * jnp.where(length2 > max_step_m**2,
                          max_step_m * jax.lax.rsqrt(jnp.where(length2 > 0, length2, 1.0)), 1.0)
        move = i < steps
        x_n, x_e = jax.lax.optimization_barrier((jnp.where(move, x_n + d * g_n, x_n),
                                                 jnp.where(move, x_e + d * g_e, x_e)))
        return x_n, x_e, f, g_n, g_e

    zero = jnp.zeros_like(y_n)
    return jax.lax.fori_loop(0, steps + 1, step, (y_n, y_e, zero, zero, zero))
