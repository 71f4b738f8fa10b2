"""Small dense linear algebra in plain JAX operations (no LAPACK custom calls).

The filters factor a 13 × 13 covariance per run and per step. Under ``vmap`` the
``jnp.linalg`` routines become batched LAPACK custom calls, which on CPU (jaxlib
0.10.0 to 0.11.0; jax-ml/jax#36927, fixed upstream after 0.11.0) split the batch over
XLA's intra-op thread pool from inside that same pool (``jax::ParallelBatchMap``); on
a 2-core machine every worker can end up waiting for sub-tasks that no free worker will
run — a deadlock we hit repeatedly in Monte Carlo
runs (all threads parked on futexes, native stacks in ``lapack_dpotrf_ffi``). For
matrices this small, unrolled elementwise code is also faster than a library call,
so jaxgrav uses these instead inside vmapped code (the GLS whitener of
:mod:`jaxgrav.match.gls` likewise; ``tests/match/test_no_lapack.py`` checks the Monte
Carlo runs).
"""

import jax.numpy as jnp

__all__ = ["cholesky", "expm", "inv_2x2", "modified_cholesky", "psd_sqrt"]


def _cholesky(a, rtol):
    """Column-by-column Cholesky; ``rtol=None``: NaN on a non-positive pivot, else zero column."""
    n = a.shape[-1]
    low = jnp.zeros_like(a)
    for j in range(n):  # unrolls over the (static, small) matrix size
        pivot = a[j, j] - jnp.sum(low[j, :j] ** 2)
        ok = True if rtol is None else pivot > rtol * jnp.abs(a[j, j])
        d = jnp.sqrt(jnp.where(ok, pivot, 1.0))
        low = low.at[j, j].set(jnp.where(ok, d, 0.0))
        if j + 1 < n:
            col = (a[j + 1 :, j] - low[j + 1 :, :j] @ low[j, :j]) / d
            low = low.at[j + 1 :, j].set(jnp.where(ok, col, 0.0))
    return low


def cholesky(a):
    """Lower Cholesky factor of a small symmetric matrix; NaN where it is not positive definite.

    Parameters
    ----------
    a : Array, shape ``(n, n)``
        ``n`` is static and small (the loop over columns unrolls at trace time).

    Returns
    -------
    Array, shape ``(n, n)``
    """
    return _cholesky(a, None)


def modified_cholesky(a, jitter=1e-9):
    """Cholesky factor of a nearly positive definite matrix in one pass, with a repair flag.

    Column by column as :func:`cholesky`; a pivot ``d_j`` (the Schur complement's
    diagonal entry) that is not positive but within ``ε_j = jitter · |a_jj|`` of zero
    is clamped to ``ε_j`` (the factor is then that of ``a`` plus at most ``2 ε_j`` on
    that diagonal entry) and ``repaired`` is set; a pivot below ``−ε_j``, or a
    non-finite one, means ``a`` is indefinite beyond repair: ``failed`` is set and
    the factor is zero. On a positive definite ``a`` the factor equals
    :func:`cholesky`'s. The tolerance is relative to each state's own variance, so
    states in very different units are treated alike.

    Parameters
    ----------
    a : Array, shape ``(n, n)``
        Symmetric; ``n`` static and small (the loop over columns unrolls).
    jitter : float
        Relative pivot clamp ``ε_j / |a_jj|``.

    Returns
    -------
    low : Array, shape ``(n, n)``
        Lower factor, ``low @ low.T ≈ a``; zeros if ``failed``.
    repaired : Array, shape ``()``, bool
        ``a`` was not numerically positive definite (a pivot was clamped, or failed).
    failed : Array, shape ``()``, bool
    """
    n = a.shape[-1]
    low = jnp.zeros_like(a)
    repaired = failed = jnp.zeros((), bool)
    tiny = jnp.finfo(a.dtype).tiny
    for j in range(n):  # unrolls over the (static, small) matrix size
        pivot = a[j, j] - jnp.sum(low[j, :j] ** 2)
        eps = jitter * jnp.abs(a[j, j]) + tiny
        clamp = pivot <= 0.0
        repaired = repaired | clamp
        failed = failed | ~jnp.isfinite(pivot) | (pivot < -eps)
        d = jnp.sqrt(jnp.where(clamp, eps, pivot))
        low = low.at[j, j].set(d)
        if j + 1 < n:
            low = low.at[j + 1 :, j].set((a[j + 1 :, j] - low[j + 1 :, :j] @ low[j, :j]) / d)
    return jnp.where(failed, 0.0, low), repaired | failed, failed


def psd_sqrt(a, rtol=1e-12):
    """A factor ``L`` with ``L Lᵀ = a`` for a positive *semi*-definite ``a``.

    Cholesky with a pivot below ``rtol`` times its own diagonal entry treated as zero
    (its column of ``L`` is zero), as for a process-noise matrix with noise-free
    states. The test is relative per state, so states in very different units
    (m/s next to rad/s) keep their noise.

    Parameters
    ----------
    a : Array, shape ``(n, n)``
    rtol : float

    Returns
    -------
    Array, shape ``(n, n)``
    """
    return _cholesky(a, rtol)


def expm(m, squarings=16, order=10):
    """Matrix exponential of a small matrix by scaling and squaring (matmuls only).

    Taylor series of ``e^{X} − I`` after scaling by ``2^−squarings``, then
    ``D ← 2D + D²`` (squaring ``I + D`` without losing D's digits). Fixed loop
    counts, so it is cheap to compile and differentiable in both modes; accurate
    for ``‖m‖ ≲ 10³``.

    Parameters
    ----------
    m : Array, shape ``(n, n)``
    squarings, order : int
        Static.

    Returns
    -------
    Array, shape ``(n, n)``
    """
    x = m / 2.0**squarings
    term, d = x, x
    for k in range(2, order + 1):
        term = term @ x / k
        d = d + term
    for _ in range(squarings):
        d = 2.0 * d + d @ d
    return jnp.eye(m.shape[0], dtype=m.dtype) + d


def inv_2x2(a):
    """Inverse of a 2 × 2 matrix by the closed form (NaN/inf if singular)."""
    det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    return jnp.array([[a[1, 1], -a[0, 1]], [-a[1, 0], a[0, 0]]]) / det
