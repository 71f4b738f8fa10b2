"""The GLS matchers and the Monte Carlo runs compile without LAPACK calls under ``vmap``.

jaxlib 0.10.x splits a batched LAPACK call (Cholesky, triangular solve) over XLA's CPU
thread pool from inside that pool; two independent ones in one program — a
``lax.map`` remainder batch beside the full ones, or two branches — deadlock a 2-core
machine (all threads parked on futexes; upstream jax-ml/jax#36927, fixed after 0.11.0).
It hung ``jax.lax.map(dense run told the map error, 80 keys, batch_size=50)``. So the
whitening is plain JAX (:func:`jaxgrav.match.gls.gls_whitener`), and these tests keep
LAPACK out of the lowered programs, which is deterministic where the hang is not.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.fields.map_error import map_error
from jaxgrav.match.gaps import gls_gap_score
from jaxgrav.match.gls import cholesky_scan, forward_substitution, gls_whitener, track_covariance
from jaxgrav.montecarlo import methods


def _lapack_calls(lowered):
    text = lowered.as_text()
    return sorted({w for w in text.replace('"', " ").replace("@", " ").split()
                   if "lapack" in w})


def test_whitener_matches_lapack_and_has_no_lapack_call():
    d = np.arange(12) * 900.0
    cov = track_covariance(jnp.asarray(d), jnp.asarray(0.5 * d), 1.0, 3.0, 10e3)
    w = gls_whitener(cov)
    np.testing.assert_allclose(w.chol, np.linalg.cholesky(np.asarray(cov)), rtol=1e-10)
    np.testing.assert_allclose(w.inv_chol @ w.chol, np.eye(12), atol=1e-10)
    batch = jnp.stack([cov, 2.0 * cov])
    assert _lapack_calls(jax.jit(jax.vmap(gls_whitener)).lower(batch)) == []


def test_gap_score_has_no_lapack_call():
    d = np.arange(10) * 900.0
    w = gls_whitener(track_covariance(jnp.asarray(d), jnp.asarray(d), 1.0, 3.0, 10e3))
    r = jnp.asarray(np.random.default_rng(0).normal(size=(7, 10))).at[2, 3].set(jnp.nan)
    score, _ = gls_gap_score(w, r, 3.0, 2)
    assert np.all(np.isfinite(np.asarray(score)))
    lowered = jax.jit(lambda r: gls_gap_score(w, r, 3.0, 2)).lower(r)
    assert _lapack_calls(lowered) == []


@pytest.mark.long
@pytest.mark.parametrize("method", ["dense", "voyage-dense", "voyage-entropy+iccp",
                                    "voyage-ukf", "ukf", "rbpf", "pmf"])
def test_monte_carlo_runs_have_no_lapack_call(method):
    """A vmapped run of each method (the matchers and voyages told a map error) lowers
    without LAPACK calls (the voyages' loop had three: F⁻¹, a 2 × 2 eigenvalue, the NEES
    inverse)."""
    told = None if method in ("ukf", "rbpf", "pmf") else map_error(3.0, 10e3)
    spec = methods.build(method, None, map_error=told)
    keys = jax.random.split(jax.random.key(0), 2)
    lowered = jax.jit(jax.vmap(lambda k: jax.tree.leaves(spec.fn(k, *spec.args))[0])).lower(
        keys)
    assert _lapack_calls(lowered) == []


def test_scan_factorisation_equals_numpy():
    rng = np.random.default_rng(1)
    m = rng.normal(size=(9, 9))
    a = m @ m.T + 9 * np.eye(9)
    chol = cholesky_scan(jnp.asarray(a))
    np.testing.assert_allclose(chol, np.linalg.cholesky(a), rtol=1e-10)
    b = rng.normal(size=(9, 2))
    np.testing.assert_allclose(forward_substitution(chol, jnp.asarray(b)),
                               np.linalg.solve(np.linalg.cholesky(a), b), rtol=1e-9)
    assert np.all(np.isnan(np.asarray(cholesky_scan(jnp.asarray(-a)))[0, 0]))
