"""The small linear algebra of ``jaxgrav._linalg`` against NumPy and SciPy."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from jaxgrav._linalg import cholesky, expm, modified_cholesky, psd_sqrt, solve_spd


def _spd(n, seed):
    a = np.random.default_rng(seed).normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


@pytest.mark.parametrize("n", [1, 2, 13])
def test_cholesky_equals_lapack(n):
    a = _spd(n, n)
    np.testing.assert_allclose(jax.jit(cholesky)(a), np.linalg.cholesky(a), rtol=1e-12,
                               atol=1e-12)


def test_cholesky_is_nan_where_not_positive_definite():
    a = np.diag([1.0, -1.0, 2.0])
    low = np.asarray(jax.jit(cholesky)(a))
    assert np.isfinite(low[0, 0]) and np.isnan(low[1, 1])


def test_psd_sqrt_factors_a_semidefinite_matrix_with_zero_columns():
    b = np.random.default_rng(0).normal(size=(6, 3))
    a = b @ b.T  # rank 3
    a[:, 4] = a[4, :] = 0.0  # a noise-free state
    low = np.asarray(jax.jit(psd_sqrt)(a))
    np.testing.assert_allclose(low @ low.T, a, atol=1e-10)
    assert np.all(low[:, 4] == 0.0) and np.all(np.isfinite(low))


def test_factors_vmap_equals_loop():
    mats = np.stack([_spd(13, s) for s in range(4)])
    batched = jax.jit(jax.vmap(modified_cholesky))(mats)[0]
    for i, a in enumerate(mats):
        np.testing.assert_allclose(batched[i], modified_cholesky(a)[0], rtol=1e-13)


def test_column_loop_is_one_compiled_step():
    """The factor is a loop over columns, not ``n`` unrolled copies (compile time)."""
    text = jax.jit(cholesky).lower(jnp.asarray(_spd(13, 1))).as_text()
    assert "while" in text and text.count("sqrt") == 1


def test_expm_equals_scipy_and_its_gradient_finite_differences():
    m = np.random.default_rng(2).normal(size=(5, 5)) * 0.3
    np.testing.assert_allclose(jax.jit(expm)(m), scipy.linalg.expm(m), rtol=1e-12, atol=1e-13)
    _check_gradient(expm, m, (1, 3), seed=3)


def _check_gradient(fn, x, at, seed):
    """``grad`` of a random weighting of ``fn(x)`` against a central difference at ``at``."""
    w = np.random.default_rng(seed).normal(size=x.shape)

    def f(y):
        return jnp.sum(w * fn(y))

    e = np.zeros_like(x)
    e[at] = 1e-6
    fd = (f(x + e) - f(x - e)) / 2e-6
    np.testing.assert_allclose(jax.grad(f)(x)[at], fd, rtol=1e-6)


def test_cholesky_gradient_finite_differences():
    _check_gradient(lambda x: cholesky(0.5 * (x + x.T)), _spd(4, 7), (2, 1), seed=8)


def test_psd_sqrt_tolerance_is_relative_to_each_state():
    """A state with a tiny variance keeps it; a pivot that is rounding of a dependent
    column (below rtol of its own diagonal entry) gives a zero column."""
    low = np.asarray(psd_sqrt(np.diag([1.0, 1e-14, 4.0])))
    np.testing.assert_allclose(np.diag(low), [1.0, 1e-7, 2.0])
    dependent = np.array([[1.0, 1.0], [1.0, 1.0 + 1e-15]])
    low = np.asarray(psd_sqrt(dependent))
    assert low[1, 1] == 0.0 and low[1, 0] == 1.0


def test_solve_spd_equals_numpy_and_is_not_finite_where_indefinite():
    a, b = _spd(6, 4), np.arange(6.0) - 2.5
    np.testing.assert_allclose(jax.jit(solve_spd)(a, b), np.linalg.solve(a, b), rtol=1e-12)
    batch = jax.jit(jax.vmap(solve_spd))(np.stack([a, 2 * a]), np.stack([b, b]))
    np.testing.assert_allclose(batch[1], np.linalg.solve(2 * a, b), rtol=1e-12)
    indefinite = np.diag([1.0, 2.0, -1.0, 3.0, 1.0, 1.0]) + 0.1
    assert not np.all(np.isfinite(solve_spd(jnp.asarray(indefinite), jnp.ones(6))))
