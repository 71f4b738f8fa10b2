"""The point-mass filter's prediction: the diffusion kernel and the prediction left pending.

Helpers of :mod:`jaxgrav.filters.pmf`: the zero-flux diffusion kernel that spreads the
cells (with a whole-cell re-centring shift folded in), and the prediction accumulated
between readings (:attr:`~jaxgrav.filters.pmf_cells.PMFState.pending`): spreads that
add, per-cell scalar models that compose.
"""

import jax.numpy as jnp

__all__ = ["affine_cells", "compose_pending", "diffusion_kernel", "no_pending", "shifted_kernel",
           "staying_cells"]


def _neumann_basis(n):
    """Orthonormal cosine basis and eigenvalues of the zero-flux second difference on n cells."""
    i = jnp.arange(n)[:, None] + 0.5
    k = jnp.arange(n)[None, :]
    v = jnp.cos(jnp.pi * k * i / n) * jnp.where(k == 0, jnp.sqrt(1.0 / n), jnp.sqrt(2.0 / n))
    lam = -4.0 * jnp.sin(jnp.pi * jnp.arange(n) / (2 * n)) ** 2
    return v, lam


def diffusion_kernel(n, v):
    """Diffusion kernel ``exp(v/2 · L)`` on ``n`` cells with zero-flux edges.

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
        are ``≥ 0`` (round-off negatives clipped) and each column sums to 1.
    """
    basis, lam = _neumann_basis(n)
    a = (basis * jnp.exp(0.5 * jnp.maximum(v, 0.0) * lam)) @ basis.T
    a = jnp.maximum(a, 0.0)
    return a / a.sum(0, keepdims=True)


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
    j = jnp.arange(n) - k
    a = jnp.take(diffusion_kernel(n, v), jnp.clip(j, 0, n - 1), axis=1)
    return jnp.where(staying_cells(n, k)[None, :], a, 0.0)


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
