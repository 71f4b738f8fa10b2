"""The point-mass filter's prediction: the diffusion kernel and the prediction left pending.

Helpers of :mod:`jaxgrav.filters.pmf`: the zero-flux diffusion kernel that spreads the
cells (with a whole-cell re-centring shift folded in), and the prediction accumulated
between readings (:attr:`~jaxgrav.filters.pmf_cells.PMFState.pending`): spreads that
add, per-cell scalar models that compose.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["affine_cells", "compose_pending", "diffusion_kernel", "no_pending", "shifted_kernel",
           "staying_cells"]


@functools.cache
def _profile_table(n):
    """``(C, lam)``, NumPy constants: ``T = C @ exp(v/2 · lam)`` is the kernel's profile
    ``T(m)``, ``m = 0 … n`` (:func:`_kernel_profile`)."""
    k = np.arange(n)
    weight = np.where(k == 0, 1.0 / n, 2.0 / n)  # the squared norms of the cosine basis
    c = 0.5 * weight[None, :] * np.cos(np.pi * np.arange(n + 1)[:, None] * k[None, :] / n)
    lam = -4.0 * np.sin(np.pi * k / (2 * n)) ** 2
    return c, lam


def _kernel_profile(n, v):
    """``T(m) = ½ Σ_k w_k e^{v λ_k / 2} cos(π k m / n)`` for ``m = 0 … n``: the kernel is
    ``A[i, j] = T(|i − j|) + T(fold(i + j + 1))`` (Toeplitz plus Hankel, the Hankel part
    the reflection at the edges; ``T`` is even and of period ``2n``: ``fold(m) =
    min(m mod 2n, 2n − m mod 2n)``), from the cosine basis's product formula."""
    c, lam = _profile_table(n)
    dtype = jnp.result_type(v, float)
    e = jnp.exp(0.5 * jnp.maximum(v, 0.0) * jnp.asarray(lam, dtype))
    return jnp.asarray(c, dtype) @ e


def _toeplitz(x, n):
    """``M[i, j] = x[i − j + n − 1]``, ``(n, n)``, from ``x`` of length ``2n − 1``, by
    slicing and reshaping a tiled copy (no gather: XLA's CPU gathers are slow).

    The tiled period ``L`` is a power of two (``x`` zero-padded): XLA computes each
    element's place in the tile with a mask instead of an integer division (the kernels
    built 1.8 × faster, the whole point-mass filter 17 % less CPU time, 2026-12-07).
    """
    period = 1 << (2 * n - 2).bit_length()  # a power of two >= 2n - 1
    y = jnp.roll(jnp.pad(x[::-1], (0, period - (2 * n - 1))), -(n - 1))
    flat = jnp.tile(y, n)[: n * (period - 1)]  # y[(j − i) mod L] = x[i − j + n − 1]
    return flat.reshape(n, period - 1)[:, :n]  # row i starts at i (L − 1) ≡ −i (mod L)


def _kernel_columns(n, v, k):
    """``A S`` before normalisation: ``A[i, j − k]`` from the profile, zero in the columns
    of the cells pushed off (``k = 0``: the kernel itself)."""
    t = _kernel_profile(n, v)
    m = np.arange(-3 * n, 3 * n + 1) % (2 * n)  # the profile over m = -3n … 3n
    u = t[np.minimum(m, 2 * n - m)]  # constant indices
    # A[i, j - k] = T(i - j + k) + T(i + j - k + 1), the second Toeplitz in (i, n - 1 - j)
    start = 3 * n - (n - 1)
    toe = jax.lax.dynamic_slice_in_dim(u, start + k, 2 * n - 1)
    han = jax.lax.dynamic_slice_in_dim(u, start + n - k, 2 * n - 1)
    a = jnp.maximum(_toeplitz(toe, n) + _toeplitz(han, n)[:, ::-1], 0.0)
    j = jnp.arange(n) - k  # the old cell that column j takes
    return jnp.where(((j >= 0) & (j < n))[None, :], a, 0.0)


def diffusion_kernel(n, v):
    """Diffusion kernel ``exp(v/2 · L)`` on ``n`` cells with zero-flux edges.

    Built from its profile (:func:`_kernel_profile`: ``n + 1`` values, one ``(n + 1) × n``
    product, no ``n³`` one): the cosine basis diagonalises ``L``, and the product of two
    of its cosines is a sum of cosines of the difference and the sum of the indices.

    Parameters
    ----------
    n : int
        Cells (static).
    v : Array, shape ``()``
        Variance of the spread in cells² (any ``v ≥ 0``).

    Returns
    -------
    Array, shape ``(n, n)``
        ``A[i, j]``: share of cell ``j``'s mass that moves to cell ``i``. Entries
        are ``≥ 0`` (round-off negatives clipped) and each column sums to 1 (to
        rounding: the cosine basis's columns do; they are not renormalised).
    """
    return shifted_kernel(n, v, 0)


def shifted_kernel(n, v, k):
    """The diffusion kernel after a shift of ``k`` whole cells, ``A S``.

    ``S`` re-centres the grid (``(S w)[i] = w[i + k]``, zero for the cells shifted in),
    so that ``A S w`` shifts and spreads in one product.

    Parameters
    ----------
    n : int
        Cells (static).
    v : Array, shape ``()``
        Variance of the spread in cells².
    k : Array, shape ``()``, int
        Shift (cells).

    Returns
    -------
    Array, shape ``(n, n)``
        Columns of :func:`diffusion_kernel` moved by ``k``; the columns of the cells
        pushed off the grid are zero.
    """
    return _kernel_columns(n, v, k)


def staying_cells(n, k):
    """Which of ``n`` cells stay on the grid after a shift of ``k`` whole cells
    (:func:`shifted_kernel`), shape ``(n,)`` bool."""
    j = jnp.arange(n) - k
    return (j >= 0) & (j < n)


def no_pending(dtype):
    """The identity of :func:`compose_pending`: no spread, unit factors, no noise."""
    return jnp.array([0.0, 0.0, 1.0, 0.0, 1.0, 0.0], dtype)


def compose_pending(pending, spread, fb, qb, phi=1.0, qe=0.0):
    """A pending prediction followed by one more step.

    Spreading by ``v₁`` then ``v₂`` is spreading by ``v₁ + v₂`` (the kernels are
    ``exp(v/2 · L)``); the per-cell scalar models are affine and the same for every
    cell, so they commute with the mixing and compose: ``m ← f₂ f₁ m``,
    ``s ← f₂² (f₁² s + q₁) + q₂``. A prediction over several steps is therefore applied
    to the cells once, exactly (up to the clamps of
    :func:`~jaxgrav.filters.pmf_cells.mix_cells`).

    Parameters
    ----------
    pending : Array, shape ``(6,)``
        :attr:`PMFState.pending`.
    spread : Array, shape ``(2,)``
        The step's spread variance north and east (m²).
    fb, qb : Array, shape ``()``
        The step's bias factor and noise variance (mGal²).
    phi, qe : Array, shape ``()``
        The same for the map error (1 and 0 without one).

    Returns
    -------
    Array, shape ``(6,)``
    """
    v_n, v_e, f0, q0, p0, e0 = (pending[i] for i in range(6))
    return jnp.stack([v_n + spread[0], v_e + spread[1], fb * f0, fb**2 * q0 + qb,
                      phi * p0, phi**2 * e0 + qe])


def affine_cells(cell, pending):
    """Per-cell (or mixture) moments after the pending scalar models.

    ``m ← f m``, ``s ← f² s + q`` for the bias; with a map error likewise ``ε ← φ ε``
    and the cross covariance ``c ← f φ c``. The same on the mixture's moments
    (:func:`~jaxgrav.filters.pmf_cells.global_moments`), since every cell takes the same map.

    Parameters
    ----------
    cell : list of Array
        In :func:`~jaxgrav.filters.pmf_cells.cell_fields` order.
    pending : Array, shape ``(6,)``, or None
        None: unchanged.
    """
    if pending is None:
        return list(cell)
    fb, qb, phi, qe = (pending[i] for i in range(2, 6))
    out = [fb * cell[0], fb**2 * cell[1] + qb]
    if len(cell) > 2:
        out += [phi * cell[2], phi**2 * cell[3] + qe, fb * phi * cell[4]]
    return out
