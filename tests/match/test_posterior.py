"""The offset posterior (:mod:`jaxgrav.match.posterior`) against a NumPy reference."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav.match.gls import offset_posterior as from_gls
from jaxgrav.match.posterior import offset_posterior
from jaxgrav.match.scoring import k_smallest


def _reference(j, on, oe, cell):
    """Mean, covariance, curvature covariance, n_effective, edge mass, log evidence."""
    ok = np.isfinite(j)
    jj = np.where(ok, j, np.inf)
    best = int(np.argmin(jj))
    d0 = np.stack([on, oe], -1)
    d = d0 - d0[best]
    p = np.where(ok, np.exp(-0.5 * (np.where(ok, jj, 0.0) - jj[best])), 0.0)
    z = p.sum()
    p = p / z
    mean = p @ d
    e = d - mean
    cov = (p[:, None] * e).T @ e + np.eye(2) * cell**2 / 12
    dist2 = np.where(ok, np.sum(d * d, -1), np.inf).astype(np.float32)
    near = np.argsort(dist2, kind="stable")[:9]  # ties to the lower index
    used = ok[near]
    s = np.sqrt(np.max(np.where(used, np.sum(d[near] ** 2, -1), 0.0)))
    x, y = d[near, 0] / s, d[near, 1] / s
    a = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], -1)[used]
    q = np.linalg.lstsq(a, (jj[near] - jj[best])[used], rcond=None)[0]
    h = np.array([[2 * q[3], q[4]], [q[4], 2 * q[5]]]) / s**2
    outer = np.any((d0 == d0.min(0)) | (d0 == d0.max(0)), -1)
    return (mean + d0[best], cov, 2 * np.linalg.inv(h), 1 / np.sum(p**2),
            np.sum(p[outer]), np.log(z) - 0.5 * jj[best])


def test_posterior_equals_a_numpy_reference_on_an_irregular_score():
    rng = np.random.default_rng(3)
    g = (np.arange(15) - 7) * 250.0
    on, oe = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    j = ((on - 140.0) ** 2 / 4e5 + (oe + 320.0) ** 2 / 9e5 + (on - 140.0) * oe / 2e6
         + rng.uniform(0, 0.3, on.size) + 20.0)
    j[[3, 50, 111]] = [np.inf, np.nan, np.inf]  # invalid offsets
    post = jax.jit(offset_posterior)(j, on, oe, 250.0, dof=20)
    mean, cov, curv, n_eff, edge, log_ev = _reference(j, on, oe, 250.0)
    np.testing.assert_allclose([post.mean_north_m, post.mean_east_m], mean, rtol=1e-12)
    np.testing.assert_allclose(post.covariance_m2, cov, rtol=1e-12)
    np.testing.assert_allclose(post.curvature_covariance_m2, curv, rtol=1e-9)
    np.testing.assert_allclose(post.n_effective, n_eff, rtol=1e-12)
    np.testing.assert_allclose(post.edge_mass, edge, rtol=1e-12)
    np.testing.assert_allclose(post.log_evidence, log_ev, rtol=1e-12)
    assert bool(post.curvature_ok) and int(post.n_invalid) == 3 and int(post.n_valid) == 222
    assert from_gls is offset_posterior  # still importable where the matchers import it


def test_the_nine_nearest_are_k_smallest_ranking_with_ties():
    """On a lattice most distances tie: the fit uses k_smallest's choice (lower index)."""
    g = np.arange(-3, 4) * 100.0
    on, oe = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    j = (on**2 + oe**2) / 1e4 + np.where(oe > 0, 0.5 * oe / 100.0, 0.0)  # asymmetric fit
    j[25] = np.inf  # a neighbour of the best (24) missing: the ninth is one of four at 200 m
    best = 24
    d = np.stack([on, oe], -1) - [on[best], oe[best]]
    dist2 = np.where(np.isfinite(j), np.sum(d * d, -1), np.inf)
    near = np.asarray(k_smallest(jnp.asarray(dist2), 9))
    assert np.isclose(dist2[near[-1]], 200.0**2)
    a = np.stack([np.ones(9), *(d[near] / 100.0).T, *(
        np.stack([d[near, 0] ** 2, d[near, 0] * d[near, 1], d[near, 1] ** 2]) / 1e4)], -1)
    q = np.linalg.lstsq(a, j[near] - j[best], rcond=None)[0]
    h = np.array([[2 * q[3], q[4]], [q[4], 2 * q[5]]]) / 100.0**2
    post = offset_posterior(jnp.asarray(j), on, oe)
    np.testing.assert_allclose(post.curvature_covariance_m2, 2 * np.linalg.inv(h), rtol=1e-9,
                               atol=1e-6)


def test_a_fit_on_a_line_of_offsets_fails():
    """Collinear offsets leave the quadratic fit undetermined: no curvature covariance."""
    on = np.arange(-6, 7) * 100.0
    post = offset_posterior(jnp.asarray(on**2 / 1e4), on, np.zeros_like(on))
    assert not bool(post.curvature_ok)
    assert np.all(np.isinf(np.diagonal(post.curvature_covariance_m2)))
