"""Map values on regular lattices of points by separable (tensor-product) evaluation.

The dense-offset matcher shifts every INS fix by every offset of a regular grid of
offsets (in metres, north and east). For one fix the shifted positions therefore
form a regular lattice in fractional map indices: rows ``iy + a·s_y`` and columns
``ix + b·s_x``. Both interpolants of :mod:`jaxgrav.interp` are tensor products of
1-D bases, so on such a lattice they factorise,

``V = B_y C B_xᵀ``,

with ``B_y`` (lattice rows × node weights) and ``B_x`` (lattice columns × node
weights) the 1-D basis weights and ``C`` one block of map coefficients around the
fix. Each fix costs a few short contiguous reads and one small matrix product instead
of four gathers per lattice point.

For the bicubic spline the coefficients are stored interleaved
(:func:`interleave`): node ``(r, c)`` holds ``[[f, f_x], [f_y, f_xy]]`` at rows
``2r, 2r+1`` and columns ``2c, 2c+1``, so that a block of nodes is one 2-D slice,
and the 16 coefficients of one bicubic patch are one ``4 × 4`` slice. The basis
weights are interleaved alike: Hermite value and slope weights of node ``k`` at
``2k`` and ``2k+1`` (bilinear: hat weights on the plain node values).

The block has a static size (``block`` nodes per axis), so a lattice must span at
most ``block − 2`` map cells per axis; callers check it (see
:func:`jaxgrav.match.dense.match_dense`) and fall back to point-by-point sampling
when it does not hold.
"""

import jax
import jax.numpy as jnp

from jaxgrav import interp
from jaxgrav._fusion import computed_once

__all__ = ["interleave", "lattice_values", "patch_values"]


def interleave(coefficients):
    """Bicubic coefficients ``(ny, nx, 4)`` as one interleaved ``(2·ny, 2·nx)`` array.

    :func:`jaxgrav.interp.interleave_coefficients`; with a
    :class:`~jaxgrav.prepared.PreparedMap` use its
    :meth:`~jaxgrav.prepared.PreparedMap.interleaved`.
    """
    return interp.interleave_coefficients(coefficients)


def _cells(i, n, block, cubic):
    """Block start, cell within the block and 1-D weights of lattice positions ``i``.

    Parameters
    ----------
    i : Array, shape ``(P, A)``
        Fractional indices, ascending along the last axis.
    n : int
        Nodes along this axis of the map.
    block : int
        Nodes in the block (≤ n).
    cubic : bool
        Hermite weights (node 0 value, slope, node 1 value, slope; the interleaved
        order) or hat weights (node 0, node 1).

    Returns
    -------
    start : Array of int32, shape ``(P, 1)``
        First node of each block.
    cell : Array, shape ``(P, A)``
        Cell of each position, counted from ``start`` (in ``[0, block − 2]``).
    weights : tuple of Array, shape ``(P, A)``
    inside : Array of bool, shape ``(P, A)``
    """
    eps = interp.edge_eps(i.dtype, n)
    inside = (i >= -eps) & (i <= (n - 1) + eps)
    i_safe = jnp.clip(i, 0.0, n - 1.0)
    start = jnp.clip(jnp.floor(i_safe[:, :1]), 0, n - block)
    (x,) = computed_once((i_safe - start,), i)  # position in the block
    cell = jnp.clip(jnp.floor(x), 0, block - 2)
    t = x - cell  # local coordinate in the cell, as interp.cell
    if cubic:
        h0, h1, g0, g1 = interp.hermite(t)
        weights = (h0, g0, h1, g1)
    else:
        weights = (1.0 - t, t)
    cell, weights = computed_once((cell, weights), i)
    return start.astype(jnp.int32), cell, weights, inside


def _basis(cell, weights, block):
    """Dense basis ``(P, K, A)`` from cells and weights (:func:`_cells`).

    Row ``f·k + j`` holds weight ``j`` of the positions in cell ``k`` (``f`` = 2 for
    Hermite, interleaved value and slope weights; 1 for hats), zero elsewhere.
    """
    f = len(weights) // 2
    k = jnp.arange(f * block, dtype=cell.dtype)[None, :, None] - f * cell[:, None, :]
    w = jnp.zeros((), cell.dtype)
    for j in reversed(range(len(weights))):
        w = jnp.where(k == j, weights[j][:, None, :], w)
    return w


def lattice_values(table, rows, cols, block, method="bicubic", *, nan_cells=False):
    """Interpolated map values on a batch of regular lattices.

    Parameters
    ----------
    table : Array
        :func:`interleave` d bicubic coefficients ``(2·ny, 2·nx)`` for ``bicubic``,
        or the node values ``(ny, nx)`` for ``bilinear``.
    rows : Array, shape ``(P, A)``
        Fractional row indices of each lattice, ascending, spanning at most
        ``block − 2`` cells.
    cols : Array, shape ``(P, B)``
        Fractional column indices, likewise.
    block : int
        Nodes per axis of the block read for each lattice (static).
    method : {"bicubic", "bilinear"}
    nan_cells : bool
        Missing (NaN) nodes as :func:`jaxgrav.interp.bicubic` treats them: NaN exactly at
        the points whose cell has a NaN corner (static). False (the matchers' hot
        path): a NaN node in the block also spreads to the other points of its lattice
        rows.

    Returns
    -------
    values : Array, shape ``(P, A, B)``
        ``values[p, a, b]`` at ``(rows[p, a], cols[p, b])``, equal to
        :func:`jaxgrav.interp.bicubic` (or ``bilinear``) there up to rounding when
        the point is on the map and the span condition holds. Points off the map
        carry finite, meaningless values (see ``in_rows``, ``in_cols``).
    in_rows : Array of bool, shape ``(P, A)``
        Rows inside the map.
    in_cols : Array of bool, shape ``(P, B)``
        Columns inside the map.

    Notes
    -----
    Along rows the basis is sparse: each lattice row reads the ``2f`` table rows of
    its cell (``f`` = 2 for the interleaved bicubic table, 1 for bilinear) across
    the block's columns and combines them with its weights, one fused gather.
    Along columns the basis is expanded to a dense ``(K, B)`` matrix and applied as
    a batched matrix product. On CPU this beats both a dense product along rows
    and gathers along columns.
    """
    interp.check_method(method)
    cubic = method == "bicubic"
    f = 2 if cubic else 1
    ny, nx = table.shape[0] // f, table.shape[1] // f
    by_, bx_ = min(block, ny), min(block, nx)
    dtype = jnp.result_type(table.dtype, rows.dtype, float)
    r0, cell_y, wy, in_y = _cells(rows.astype(dtype), ny, by_, cubic)
    c0, cell_x, wx, in_x = _cells(cols.astype(dtype), nx, bx_, cubic)
    table = table.astype(dtype)
    first = (f * (r0 + cell_y)).astype(jnp.int32)  # (P, A): first table row of each cell

    def slab(row, col):  # the 2f table rows of one cell across the block's columns
        return jax.lax.dynamic_slice(table, (row, col), (2 * f, f * bx_))

    g = jax.vmap(jax.vmap(slab, in_axes=(0, None)))(first, f * c0[:, 0])  # (P, A, 2f, Kx)
    t = sum(w[:, :, None] * g[:, :, j] for j, w in enumerate(wy))  # (P, A, Kx)
    if nan_cells:  # a NaN coefficient of a row's cell, per block node; kept out of the product
        bad = jnp.isnan(t)
        t = jnp.where(bad, 0.0, t)
        node = bad.reshape(*bad.shape[:2], bx_, f).any(-1)  # (P, A, bx)
        c = cell_x.astype(jnp.int32)[:, None, :]
        hit = (jnp.take_along_axis(node, c, axis=2, mode="clip")
               | jnp.take_along_axis(node, c + 1, axis=2, mode="clip"))
    v = jnp.einsum("paq,pqb->pab", t, _basis(cell_x, wx, bx_))
    if nan_cells:
        v = jnp.where(hit, jnp.nan, v)
    return v, in_y, in_x


def patch_values(table, iy, ix, method="bicubic", gradient=False):
    """Point values (and gradient) from an :func:`interleave` d table: one slice per point.

    Parameters
    ----------
    table : Array
        As in :func:`lattice_values`.
    iy, ix : Array, shape ``P``
        Fractional row and column indices.
    method : {"bicubic", "bilinear"}
    gradient : bool
        Also return the derivatives per index step.

    Returns
    -------
    Array, shape ``P`` (or a tuple ``value, d_iy, d_ix``)
        Values NaN off the map and in cells with a missing (NaN) node, derivatives 0
        there (never NaN); elsewhere the same as
        :func:`jaxgrav.interp.bicubic` and :func:`jaxgrav.interp.bicubic_value_and_gradient`.
    """
    interp.check_method(method)
    cubic = method == "bicubic"
    f = 2 if cubic else 1
    ny, nx = table.shape[0] // f, table.shape[1] // f
    iy, ix = jnp.broadcast_arrays(jnp.asarray(iy), jnp.asarray(ix))
    dtype = jnp.result_type(table.dtype, iy.dtype, float)
    eps = interp.edge_eps(dtype, max(ny, nx))
    r0, ty, in_y = interp.cell(iy.astype(dtype), ny, eps)
    c0, tx, in_x = interp.cell(ix.astype(dtype), nx, eps)
    shape = iy.shape
    r0, c0, ty, tx = (a.reshape(-1) for a in (r0, c0, ty, tx))
    p = jax.vmap(lambda r, c: jax.lax.dynamic_slice(table, (f * r, f * c), (2 * f, 2 * f)))(
        r0, c0
    ).astype(dtype)  # (P, 2f, 2f)
    if cubic:  # weights in the interleaved order: node 0 value, slope, node 1 value, slope
        h0, h1, g0, g1 = interp.hermite(ty)
        hy = (h0, g0, h1, g1)
        h0, h1, g0, g1 = interp.hermite(tx)
        hx = (h0, g0, h1, g1)
    else:
        hy, hx = (1.0 - ty, ty), (1.0 - tx, tx)
    rows = _rows(hy, p)  # the patch interpolated along y, one array per column
    val = _dot(rows, hx).reshape(shape)
    inside = (in_y & in_x).reshape(shape)
    val = jnp.where(inside, val, jnp.nan)
    if not gradient:
        return val
    if cubic:
        d0, d1, e0, e1 = interp.hermite_derivative(ty)
        dy = (d0, e0, d1, e1)
        d0, d1, e0, e1 = interp.hermite_derivative(tx)
        dx = (d0, e0, d1, e1)
    else:
        one = jnp.ones_like(ty)
        dy = dx = (-one, one)
    zero = jnp.zeros((), dtype)
    d_y = _dot(_rows(dy, p), hx).reshape(shape)
    d_x = _dot(rows, dx).reshape(shape)
    known = ~jnp.isnan(val)  # off the map or in a cell with a missing (NaN) node
    return val, jnp.where(known, d_y, zero), jnp.where(known, d_x, zero)


def _rows(weights, patch):
    """``[Σ_k weights[k] · patch[:, k, q] for q]``, unrolled (element-wise, fuses on CPU)."""
    n = patch.shape[1]
    return [sum(weights[k] * patch[:, k, q] for k in range(n)) for q in range(patch.shape[2])]


def _dot(a, b):
    """``Σ_k a[k] b[k]`` over two short lists of arrays."""
    return sum(x * y for x, y in zip(a, b, strict=True))
