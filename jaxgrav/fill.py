"""Missing (NaN) nodes of a grid, filled for computing the spline slopes of their neighbours.

:func:`jaxgrav.interp.bicubic_coefficients` fills missing nodes (land on a marine grid,
a hole in a survey) with :func:`fill_missing` only so that the global, linear spline
solve does not spread a NaN over whole rows and columns, and then masks them again.
"""

import jax
import jax.numpy as jnp

__all__ = ["fill_missing"]


def fill_missing(values):
    """Missing (NaN) nodes filled by linear interpolation along rows, then columns.

    Only for computing spline slopes next to holes in a map (land on a marine grid):
    :func:`bicubic_coefficients` masks the filled nodes again. A node between two
    present ones in its row takes the linear interpolant of the nearest of them; a node
    with present ones on one side only takes the nearest value; a row with none is
    filled along its column the same way, and a node with no present value in its row
    or column is 0. Shapes are static (cumulative maxima of indices), so it runs under
    ``jit`` and is differentiable in the present values.

    Parameters
    ----------
    values : Array, shape ``(..., ny, nx)``

    Returns
    -------
    Array, shape ``(..., ny, nx)``
        ``values`` where finite, the fill elsewhere; no NaN or inf.
    """
    values = jnp.asarray(values)
    row = _fill_along(values, -1)
    col = _fill_along(values, -2)
    out = jnp.where(jnp.isfinite(row), row, col)
    return jnp.where(jnp.isfinite(out), out, jnp.zeros((), out.dtype))


def _fill_along(values, axis):
    """Linear fill of non-finite entries along ``axis`` from the nearest finite ones
    (constant beyond the last); NaN where the whole line is non-finite."""
    v = jnp.moveaxis(values, axis, -1)
    n = v.shape[-1]
    ok = jnp.isfinite(v)
    safe = jnp.where(ok, v, jnp.zeros((), v.dtype))
    idx = jnp.arange(n)
    left = jax.lax.cummax(jnp.where(ok, idx, -1), axis=v.ndim - 1)
    right = jax.lax.cummin(jnp.where(ok, idx, n), axis=v.ndim - 1, reverse=True)
    has_l, has_r = left >= 0, right < n
    lc, rc = jnp.clip(left, 0, n - 1), jnp.clip(right, 0, n - 1)
    vl = jnp.take_along_axis(safe, lc, axis=-1)
    vr = jnp.take_along_axis(safe, rc, axis=-1)
    w = jnp.where(has_l & has_r, (idx - lc) / jnp.maximum(rc - lc, 1), 0.0).astype(v.dtype)
    between = vl + w * (vr - vl)
    fill = jnp.where(has_l & has_r, between, jnp.where(has_l, vl, jnp.where(has_r, vr,
                                                                               jnp.nan)))
    return jnp.moveaxis(jnp.where(ok, v, fill), -1, axis)
