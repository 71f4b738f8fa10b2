"""Small dense linear algebra in plain JAX operations (no LAPACK custom calls).

The filters factor a 13 × 13 covariance per run and per step. Under ``vmap`` the
``jnp.linalg`` routines become batched LAPACK custom calls, which on CPU (jaxlib
0.10.0 to 0.11.0; jax-ml/jax#36927, fixed upstream after 0.11.0) split the batch over
XLA's intra-op thread pool from inside that same pool (``jax::ParallelBatchMap``); on
a 2-core machine every worker can end up waiting for sub-tasks that no free worker will
run — a deadlock we hit repeatedly in Monte Carlo
runs (all threads parked on futexes, native stacks in ``lapack_dpotrf_ffi``). For
matrices this small, a loop over the columns in plain operations is also faster than a
library call, so jaxgrav uses these instead inside vmapped code (the GLS whitener of
:mod:`jaxgrav.match.gls` likewise; ``tests/match/test_no_lapack.py`` checks the Monte
Carlo runs).
"""

import jax
import jax.numpy as jnp

__all__ = ["cholesky", "expm", "inv_2x2", "modified_cholesky", "psd_sqrt", "solve_spd"]


def _column(a, low, j):
    """Pivot of column ``j`` and its sub-diagonal before division.

    Columns ``≥ j`` of ``low`` are still zero, so full-length products need no mask.
    """
    row = low[j]
    return a[j, j] - jnp.sum(row**2), a[:, j] - low @ row


def _set_column(low, j, d, col):
    """``low[:, j]`` ← ``d`` on the diagonal, ``col`` below it, zero above."""
    idx = jnp.arange(low.shape[-1])
    return low.at[:, j].set(jnp.where(idx == j, d, jnp.where(idx > j, col, 0.0)))


def _cholesky(a, rtol):
    """Column-by-column Cholesky; ``rtol=None``: NaN on a non-positive pivot, else zero column."""
    a = jnp.asarray(a)

    def body(j, low):
        pivot, col = _column(a, low, j)
        ok = True if rtol is None else pivot > rtol * jnp.abs(a[j, j])
        d = jnp.sqrt(jnp.where(ok, pivot, 1.0))
        return _set_column(low, j, jnp.where(ok, d, 0.0), jnp.where(ok, col / d, 0.0))

    return jax.lax.fori_loop(0, a.shape[-1], body, jnp.zeros_like(a))


def cholesky(a):
    """Lower Cholesky factor of a small symmetric matrix; NaN where it is not positive definite.

    Parameters
    ----------
    a : Array, shape ``(n, n)``
        ``n`` is small (a ``fori_loop`` over the columns: one compiled column step,
        not ``n`` unrolled copies, which cost compile time and ran no faster).

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
        Symmetric; ``n`` small (a ``fori_loop`` over the columns, as :func:`cholesky`).
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
    a = jnp.asarray(a)
    tiny = jnp.finfo(a.dtype).tiny

    def body(j, carry):
        low, repaired, failed = carry
        pivot, col = _column(a, low, j)
        eps = jitter * jnp.abs(a[j, j]) + tiny
        clamp = pivot <= 0.0
        failed = failed | ~jnp.isfinite(pivot) | (pivot < -eps)
        d = jnp.sqrt(jnp.where(clamp, eps, pivot))
        return _set_column(low, j, d, col / d), repaired | clamp, failed

    no = jnp.zeros((), bool)
    low, repaired, failed = jax.lax.fori_loop(0, a.shape[-1], body, (jnp.zeros_like(a), no, no))
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


def solve_spd(a, b):
    """Solve ``a x = b`` for a small symmetric positive definite ``a`` in one ``fori_loop``.

    ``a`` is equilibrated by its diagonal, then Gauss–Jordan elimination without pivoting
    runs on ``[a | b]``, one column per step (one compiled step: under ``vmap`` a few
    XLA kernels, where an unrolled scalar Cholesky solve is dozens). Step k's pivot is
    the Cholesky pivot ``L_kk²``; a negative one gives NaN, as the Cholesky square root
    would, so an ``a`` that is not positive definite gives a non-finite ``x``.

    Parameters
    ----------
    a : Array, shape ``(n, n)``
    b : Array, shape ``(n,)``

    Returns
    -------
    Array, shape ``(n,)``
    """
    n = b.shape[-1]
    d = 1.0 / jnp.sqrt(jnp.diagonal(a))
    m = jnp.concatenate([a * d[:, None] * d[None, :], (b * d)[:, None]], axis=1)
    idx = jnp.arange(n)

    def step(k, m):
        pivot = m[k, k]
        row = m[k] / jnp.where(pivot >= 0, pivot, jnp.nan)
        return jnp.where((idx == k)[:, None], row, m - m[:, k, None] * row)

    return jax.lax.fori_loop(0, n, step, m)[:, n] * d


def expm(m, squarings=16, order=10):
    """Matrix exponential of a small matrix by scaling and squaring (matmuls only).

    Taylor series of ``e^{X} − I`` after scaling by ``2^−squarings``, then
    ``D ← 2D + D²`` (squaring ``I + D`` without losing D's digits). Fixed loop
    counts (two ``fori_loop``s), so it is cheap to compile and differentiable in both
    modes; accurate for ``‖m‖ ≲ 10³``.

    Parameters
    ----------
    m : Array, shape ``(n, n)``
    squarings, order : int
        Static.

    Returns
    -------
    Array, shape ``(n, n)``
    """
    m = jnp.asarray(m)
    x = m / 2.0**squarings

    def taylor(k, carry):
        term, d = carry
        term = term @ x / k.astype(m.dtype)
        return term, d + term

    _, d = jax.lax.fori_loop(2, order + 1, taylor, (x, x))
    d = jax.lax.fori_loop(0, squarings, lambda _, d: 2.0 * d + d @ d, d)
    return jnp.eye(m.shape[0], dtype=m.dtype) + d


def inv_2x2(a):
    """Inverse of a 2 × 2 matrix by the closed form (NaN/inf if singular)."""
    det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    return jnp.array([[a[1, 1], -a[0, 1]], [-a[1, 0], a[0, 0]]]) / det
