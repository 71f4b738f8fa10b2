"""Work on a grid's node lattice: fixed-size windows of nodes, and cell subdivision.

:func:`node_windows` (:meth:`Grid.window <jaxgrav.grid.Grid.window>`) cuts square
windows of nodes around points, shifted inside the grid at its edges and flagged;
:func:`refined` (:meth:`Grid.refine <jaxgrav.grid.Grid.refine>`) subdivides every cell
with the bilinear or bicubic interpolant. Both take any grid-like object with
``values (..., ny, nx)``, ``ny``, ``nx``, ``fractional_index`` and the static geometry
fields; the :class:`~jaxgrav.grid.Grid` methods are the public interface.
"""

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import interp

__all__ = ["Window", "node_windows", "refined"]


class Window(NamedTuple):
    """Fixed-size windows of grid nodes around points (see :meth:`Grid.window`).

    Attributes
    ----------
    values : Array, shape ``(..., *P, 2k+1, 2k+1)``
        Node values of each window (rows south to north, columns west to east).
    row0, col0 : Array of int32, shape ``P``
        Grid indices of each window's south-west node.
    complete : Array of bool, shape ``P``
        False where the window did not fit inside the grid and was shifted to fit.
    """

    values: jax.Array
    row0: jax.Array
    col0: jax.Array
    complete: jax.Array


def node_windows(grid, lat, lon, half_size):
    """Fixed-size square windows of nodes centred on the node nearest each point.

    Parameters
    ----------
    grid : Grid
        Values ``(..., ny, nx)``.
    lat, lon : array_like
        Window centres (degrees), broadcast to shape ``P``.
    half_size : int
        Half-width k in nodes (static); windows are ``(2k+1) × (2k+1)``.

    Returns
    -------
    Window
        Values, south-west indices and a ``complete`` flag. A window that would
        cross the grid's edge is shifted inside and flagged ``complete=False``.

    Raises
    ------
    ValueError
        If the window is larger than the grid.
    """
    k = int(half_size)
    if k < 0 or 2 * k + 1 > min(grid.ny, grid.nx):
        raise ValueError(
            f"half_size must be in [0, {(min(grid.ny, grid.nx) - 1) // 2}] for a "
            f"{grid.ny}x{grid.nx} grid; got {half_size!r}"
        )
    iy, ix = grid.fractional_index(lat, lon)
    r = jnp.round(iy).astype(jnp.int32) - k
    col = jnp.round(ix).astype(jnp.int32) - k
    size = 2 * k + 1
    r_in = jnp.clip(r, 0, grid.ny - size)
    c_in = jnp.clip(col, 0, grid.nx - size)
    complete = (r == r_in) & (col == c_in) & jnp.isfinite(iy) & jnp.isfinite(ix)
    lead = grid.values.shape[:-2]

    def one(r0, c0):
        start = (0,) * len(lead) + (r0, c0)
        return jax.lax.dynamic_slice(grid.values, start, (*lead, size, size))

    flat = jax.vmap(one)(r_in.reshape(-1), c_in.reshape(-1))  # (M, *lead, s, s)
    vals = jnp.moveaxis(flat, 0, len(lead)).reshape(*lead, *r.shape, size, size)
    return Window(vals, r_in, c_in, complete)


def refined(grid, factor, method="bilinear"):
    """Subdivide every cell ``factor`` times (paper A: 0.5° → 0.005° at factor 100).

    Parameters
    ----------
    grid : Grid
        Values ``(..., ny, nx)``.
    factor : int
        Integer subdivision factor ≥ 1 (static).
    method : {"bilinear", "bicubic"}
        Interpolant used for the new nodes; the old nodes keep their values.

    Returns
    -------
    Grid
        ``((ny−1)·factor + 1, (nx−1)·factor + 1)`` nodes over the same extent; a new
        node that any missing (NaN) node weighs in is missing too (the mask is kept,
        not spread).
    """
    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
        raise ValueError(f"factor must be an integer >= 1; got {factor!r}")
    interp.check_method(method)
    factor = int(factor)
    wy = interp.interpolation_matrix(
        grid.ny, np.arange((grid.ny - 1) * factor + 1) / factor, method
    )
    wx = interp.interpolation_matrix(
        grid.nx, np.arange((grid.nx - 1) * factor + 1) / factor, method
    )
    dtype = jnp.result_type(grid.values.dtype, float)
    values = jnp.asarray(grid.values).astype(dtype)
    missing = ~jnp.isfinite(values)
    v = jnp.asarray(wy, dtype) @ jnp.where(missing, 0.0, values) @ jnp.asarray(wx.T, dtype)
    # a new node is missing when a missing node has weight in it (|w| > 0: exact)
    touched = (jnp.asarray(np.abs(wy) > 0, dtype) @ missing.astype(dtype)
               @ jnp.asarray(np.abs(wx.T) > 0, dtype))
    v = jnp.where(touched > 0, jnp.nan, v)
    return dataclasses.replace(grid, values=v, dlat=grid.dlat / factor, dlon=grid.dlon / factor)
