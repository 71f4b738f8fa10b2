"""Interpolation kernels on regular 2-D arrays, in fractional index coordinates.

These are the building blocks of :class:`jaxgrav.Grid` sampling and of layered DOV
interpolation. They know nothing about latitude or longitude: a point is given by
its fractional row ``iy`` and column ``ix`` (``iy = 0`` is the first row). Points
outside ``[0, ny−1] × [0, nx−1]`` give NaN; the arithmetic is done on clipped,
harmless coordinates first so that gradients stay finite everywhere ("double where").

Methods
-------
``bilinear``
    Paper A's formula, ``g = [g_A (L−h_x)(L−h_y) + g_B (L−h_x) h_y + g_C h_x h_y
    + g_D h_x (L−h_y)] / L²``, exact for fields linear in each coordinate.
``bicubic``
    Tensor-product cubic spline with not-a-knot ends, the same interpolant as SciPy's
    ``RegularGridInterpolator(method="cubic")``: C² and exact for bicubic fields.
    It is evaluated as a bicubic Hermite patch from node values and spline slopes
    (:func:`spline_slopes`), which are linear in the values (a matrix product), so the
    interpolant stays differentiable in the map values too.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav.fill import fill_missing

__all__ = [
    "METHODS",
    "bicubic",
    "bicubic_coefficients",
    "bicubic_patches",
    "bicubic_value_and_gradient",
    "bilinear",
    "cell",
    "check_method",
    "edge_eps",
    "fill_missing",
    "hermite",
    "hermite_derivative",
    "interleave_coefficients",
    "spline_slopes",
]

METHODS = ("bilinear", "bicubic")


def check_method(method):
    """Raise ``ValueError`` unless ``method`` is one of :data:`METHODS`."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")


def cell(i, n, eps):
    """Cell index, local coordinate in [0, 1] and inside flag for fractional index ``i``.

    Parameters
    ----------
    i : Array
        Fractional indices along one axis.
    n : int
        Nodes along the axis.
    eps : float
        Tolerance (index steps) within which a point just outside counts as inside.

    Returns
    -------
    tuple of Array
        ``(i0, t, inside)``: cell (int32, in ``[0, n−2]``), local coordinate ``i − i0``
        and a bool mask, each shaped like ``i``.
    """
    inside = (i >= -eps) & (i <= (n - 1) + eps)
    i_safe = jnp.clip(jnp.where(inside, i, 0.0), 0.0, n - 1.0)
    i0 = jnp.clip(jnp.floor(i_safe), 0, max(n - 2, 0)).astype(jnp.int32)
    return i0, i_safe - i0, inside


def edge_eps(dtype, n):
    """Tolerance (index steps) for points on the edge of an ``n``-node axis: 8 ε·n."""
    return 8.0 * float(jnp.finfo(dtype).eps) * max(n, 1)


def bilinear(values, iy, ix):
    """Bilinear interpolation of ``values`` at fractional indices.

    Parameters
    ----------
    values : Array, shape ``(..., ny, nx)``
        Node values; leading axes are interpolated together (channels).
    iy, ix : Array
        Fractional row and column indices, broadcast together to shape ``P``.

    Returns
    -------
    Array, shape ``(..., *P)``
        Interpolated values; NaN where a point is outside the array.
    """
    ny, nx = values.shape[-2:]
    iy, ix = jnp.broadcast_arrays(jnp.asarray(iy), jnp.asarray(ix))
    dtype = jnp.result_type(values.dtype, iy.dtype, float)
    eps = edge_eps(dtype, max(ny, nx))
    r0, ty, in_y = cell(iy, ny, eps)
    c0, tx, in_x = cell(ix, nx, eps)
    r1 = jnp.minimum(r0 + 1, ny - 1)
    c1 = jnp.minimum(c0 + 1, nx - 1)
    g_a = values[..., r0, c0]
    g_b = values[..., r1, c0]  # one step north (h_y)
    g_c = values[..., r1, c1]
    g_d = values[..., r0, c1]  # one step east (h_x)
    out = g_a * (1 - tx) * (1 - ty) + g_b * (1 - tx) * ty + g_c * tx * ty + g_d * tx * (1 - ty)
    return jnp.where(in_x & in_y, out, jnp.nan).astype(dtype)


@functools.lru_cache(maxsize=64)
def _slope_matrix(n):
    """Matrix S (n×n) mapping node values to not-a-knot cubic-spline slopes (unit spacing)."""
    if n < 4:
        raise ValueError(f"bicubic interpolation needs at least 4 nodes per axis; got {n}")
    a = np.zeros((n, n))
    b = np.zeros((n, n))
    for i in range(1, n - 1):  # interior: m[i-1] + 4 m[i] + m[i+1] = 3 (y[i+1] - y[i-1])
        a[i, i - 1 : i + 2] = (1.0, 4.0, 1.0)
        b[i, i - 1], b[i, i + 1] = -3.0, 3.0
    # not-a-knot: third derivative continuous at nodes 1 and n-2
    a[0, 0], a[0, 2] = 1.0, -1.0
    b[0, 0:3] = (-2.0, 4.0, -2.0)
    a[-1, -1], a[-1, -3] = 1.0, -1.0
    b[-1, -3:] = (2.0, -4.0, 2.0)
    return np.linalg.solve(a, b)


def spline_slopes(values, axis):
    """Not-a-knot cubic-spline slopes of ``values`` along ``axis`` (per index step).

    Parameters
    ----------
    values : Array
        Node values; the spline runs along ``axis`` (at least 4 nodes).
    axis : int
        Axis along which the spline is fitted.

    Returns
    -------
    Array
        Slopes ``ds/di`` at every node, same shape as ``values``.
    """
    values = jnp.asarray(values)
    s = jnp.asarray(_slope_matrix(values.shape[axis]), dtype=jnp.result_type(values.dtype, float))
    moved = jnp.moveaxis(values, axis, -1)
    return jnp.moveaxis(moved @ s.T, -1, axis)


def bicubic_coefficients(values):
    """Stack node values and spline derivatives for :func:`bicubic`.

    Missing (NaN) nodes, such as land on a marine grid, do not spoil the rest of the
    map: the spline slopes are computed with them filled (:func:`fill_missing`), and
    then all four coefficients of a missing node are NaN again, so every cell with a
    missing corner interpolates to NaN (masked) and every other cell keeps finite
    values that equal the node values at the nodes.

    Parameters
    ----------
    values : Array, shape ``(..., ny, nx)``

    Returns
    -------
    Array, shape ``(..., ny, nx, 4)``
        ``[f, ∂f/∂ix, ∂f/∂iy, ∂²f/∂iy∂ix]`` at each node (NaN at missing nodes). Compute
        once per map and pass to :func:`bicubic` when sampling the same map many times.

    Notes
    -----
    The values pass an optimisation barrier first, so that a map which is a constant
    of the caller's program (closed over by a jitted function rather than passed in)
    is computed at run time, not folded by XLA's constant folder: folding the gap
    filling and the three spline products of a 289 × 289 map took ~15 s of compile time.
    """
    values = jax.lax.optimization_barrier(jnp.asarray(values))
    missing = ~jnp.isfinite(values)
    filled = fill_missing(values)
    fx = spline_slopes(filled, -1)
    fy = spline_slopes(filled, -2)
    fxy = spline_slopes(fx, -2)
    coefficients = jnp.stack([filled, fx, fy, fxy], axis=-1)
    return jnp.where(missing[..., None], jnp.nan, coefficients)


def _hermite_to_powers(v0, v1, s0, s1):
    """Coefficients of ``1, t, t², t³`` of ``v0 h0 + v1 h1 + s0 g0 + s1 g1`` (Hermite basis)."""
    return v0, s0, 3.0 * (v1 - v0) - 2.0 * s0 - s1, 2.0 * (v0 - v1) + s0 + s1


def bicubic_patches(coefficients):
    """Power-basis coefficients of the bicubic interpolant, 16 per cell.

    The same interpolant as :func:`bicubic`, in the form ``f(ty, tx) = Σ a_ij ty^i tx^j``
    for ``ty, tx ∈ [0, 1]`` within each cell: one contiguous read of 16 numbers per
    point, and the value and both derivatives by two short Horner sums.

    Parameters
    ----------
    coefficients : Array, shape ``(ny, nx, 4)``
        Output of :func:`bicubic_coefficients` (``ny, nx ≥ 4``).

    Returns
    -------
    Array, shape ``(ny−1, nx−1, 16)``
        Cell ``[r, c]`` holds ``a_ij`` at ``4i + j``, with ``ty = iy − r``, ``tx = ix − c``.
    """
    k = coefficients
    ny, nx = k.shape[0], k.shape[1]
    corner = lambda q, dr, dc: k[dr:ny - 1 + dr, dc:nx - 1 + dc, q]  # noqa: E731
    # along x first: for each row r0/r1 and each y-kind (value f / slope f_y), the
    # x-polynomial from the values (f or f_y) and x-slopes (f_x or f_xy) at c0, c1
    rows = [_hermite_to_powers(corner(q, dr, 0), corner(q, dr, 1), corner(q + 1, dr, 0),
                               corner(q + 1, dr, 1))
            for q, dr in ((0, 0), (0, 1), (2, 0), (2, 1))]  # value r0, value r1, slope r0, r1
    # then along y, per x-power j
    cols = [_hermite_to_powers(*(rows[a][j] for a in range(4))) for j in range(4)]
    return jnp.stack([cols[j][i] for i in range(4) for j in range(4)], axis=-1)


def interleave_coefficients(coefficients):
    """Bicubic coefficients ``(ny, nx, 4)`` as one interleaved ``(2·ny, 2·nx)`` array.

    Node ``(r, c)`` holds ``[[f, f_x], [f_y, f_xy]]`` at rows ``2r, 2r+1`` and columns
    ``2c, 2c+1``, so a block of nodes is one 2-D slice and the 16 coefficients of one
    bicubic patch are one ``4 × 4`` slice.

    Parameters
    ----------
    coefficients : Array, shape ``(ny, nx, 4)``
        Output of :func:`bicubic_coefficients`.

    Returns
    -------
    Array, shape ``(2·ny, 2·nx)``
        ``out[2r + u, 2c + v]`` is ``f, f_x, f_y, f_xy`` for ``(u, v)`` = (0, 0),
        (0, 1), (1, 0), (1, 1) at node ``(r, c)``.
    """
    ny, nx = coefficients.shape[:2]
    c = coefficients.reshape(ny, nx, 2, 2)
    return jnp.transpose(c, (0, 2, 1, 3)).reshape(2 * ny, 2 * nx)


def hermite(t):
    """Cubic Hermite basis at ``t ∈ [0, 1]``: ``(h0, h1, g0, g1)`` (values 0/1, slopes 0/1)."""
    t2, t3 = t * t, t * t * t
    return (2 * t3 - 3 * t2 + 1, -2 * t3 + 3 * t2, t3 - 2 * t2 + t, t3 - t2)


def bicubic(coefficients, iy, ix):
    """Bicubic (not-a-knot spline) interpolation at fractional indices.

    Parameters
    ----------
    coefficients : Array, shape ``(..., ny, nx, 4)``
        Output of :func:`bicubic_coefficients`.
    iy, ix : Array
        Fractional row and column indices, broadcast together to shape ``P``.

    Returns
    -------
    Array, shape ``(..., *P)``
        Interpolated values; NaN where a point is outside the array or its cell has a
        missing (NaN) corner (there the gradient with respect to the point is NaN too:
        one gather per corner on this hot path, no masking of the coefficients).
    """
    ny, nx = coefficients.shape[-3:-1]
    iy, ix = jnp.broadcast_arrays(jnp.asarray(iy), jnp.asarray(ix))
    dtype = jnp.result_type(coefficients.dtype, iy.dtype, float)
    eps = edge_eps(dtype, max(ny, nx))
    r0, ty, in_y = cell(iy, ny, eps)
    c0, tx, in_x = cell(ix, nx, eps)
    hy0, hy1, gy0, gy1 = hermite(ty)
    hx0, hx1, gx0, gx1 = hermite(tx)
    out = 0.0
    for r, hy, gy in ((r0, hy0, gy0), (r0 + 1, hy1, gy1)):
        for col, hx, gx in ((c0, hx0, gx0), (c0 + 1, hx1, gx1)):
            k = coefficients[..., r, col, :]  # NaN at a missing node: the cell is NaN
            out = out + (
                k[..., 0] * hy * hx
                + k[..., 1] * hy * gx
                + k[..., 2] * gy * hx
                + k[..., 3] * gy * gx
            )
    return jnp.where(in_x & in_y, out, jnp.nan).astype(dtype)


def hermite_derivative(t):
    """Derivatives ``d/dt`` of :func:`hermite`'s four basis functions."""
    t2 = t * t
    return (6 * t2 - 6 * t, -6 * t2 + 6 * t, 3 * t2 - 4 * t + 1, 3 * t2 - 2 * t)


def bicubic_value_and_gradient(coefficients, iy, ix):
    """Bicubic interpolant and its analytic gradient at fractional indices.

    One gather of the patch serves the value and both derivatives (cheaper than
    differentiating :func:`bicubic` with ``jax.jacfwd``).

    Parameters
    ----------
    coefficients : Array, shape ``(ny, nx, 4)``
        Output of :func:`bicubic_coefficients`.
    iy, ix : Array
        Fractional row and column indices, broadcast together to shape ``P``.

    Returns
    -------
    value, d_iy, d_ix : Array, shape ``P``
        Interpolated value (NaN off the array or in a cell with a missing corner) and
        its derivatives per index step along rows and columns (0 there).
    """
    ny, nx = coefficients.shape[-3:-1]
    iy, ix = jnp.broadcast_arrays(jnp.asarray(iy), jnp.asarray(ix))
    dtype = jnp.result_type(coefficients.dtype, iy.dtype, float)
    eps = edge_eps(dtype, max(ny, nx))
    r0, ty, in_y = cell(iy, ny, eps)
    c0, tx, in_x = cell(ix, nx, eps)
    hy, dhy = hermite(ty), hermite_derivative(ty)
    hx, dhx = hermite(tx), hermite_derivative(tx)
    val = d_y = d_x = 0.0
    for j, r in enumerate((r0, r0 + 1)):
        for i, col in enumerate((c0, c0 + 1)):
            k = coefficients[r, col, :]
            # value / slope weights: index j (or i) for the node, +2 for its slope
            a = k[..., 0] * hx[i] + k[..., 1] * hx[i + 2]  # rows' value part along x
            b = k[..., 2] * hx[i] + k[..., 3] * hx[i + 2]  # rows' slope part along x
            val = val + a * hy[j] + b * hy[j + 2]
            d_y = d_y + a * dhy[j] + b * dhy[j + 2]
            d_x = d_x + (k[..., 0] * dhx[i] + k[..., 1] * dhx[i + 2]) * hy[j] + (
                k[..., 2] * dhx[i] + k[..., 3] * dhx[i + 2]
            ) * hy[j + 2]
    inside = in_x & in_y & jnp.isfinite(val)  # a missing corner: NaN value, 0 gradient
    zero = jnp.zeros((), dtype)
    return (
        jnp.where(inside, val, jnp.nan).astype(dtype),
        jnp.where(inside, d_y, zero).astype(dtype),
        jnp.where(inside, d_x, zero).astype(dtype),
    )


def interpolation_matrix(n, positions, method):
    """Dense matrix W (len(positions) × n) with ``W @ y`` = 1-D interpolant of ``y`` at positions.

    Parameters
    ----------
    n : int
        Number of nodes (unit spacing, node i at index i).
    positions : array_like
        Fractional indices in [0, n−1] (NumPy).
    method : {"bilinear", "bicubic"}
        Linear, or not-a-knot cubic spline.

    Returns
    -------
    numpy.ndarray, shape ``(len(positions), n)``
    """
    check_method(method)
    p = np.asarray(positions, dtype=float)
    i0 = np.clip(np.floor(p), 0, n - 2).astype(int)
    t = p - i0
    rows = np.arange(p.size)
    w = np.zeros((p.size, n))
    if method == "bilinear":
        np.add.at(w, (rows, i0), 1 - t)
        np.add.at(w, (rows, i0 + 1), t)
        return w
    h0, h1, g0, g1 = (np.asarray(v) for v in hermite(t))
    s = _slope_matrix(n)
    np.add.at(w, (rows, i0), h0)
    np.add.at(w, (rows, i0 + 1), h1)
    return w + g0[:, None] * s[i0] + g1[:, None] * s[i0 + 1]

