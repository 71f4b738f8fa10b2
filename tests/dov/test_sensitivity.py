"""Tests of jaxgrav.dov.sensitivity (small models: the degree is not the point here)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import datasets, sensitivity
from jaxgrav.fields.harmonics import deflection


@pytest.fixture(scope="module")
def small():
    model = datasets.load("qinling")["coefficients"].truncate(30)
    lat = np.linspace(34.3, 35.1, 12)
    lon = np.linspace(108.4, 109.2, 12)
    h = np.linspace(1000.0, 13000.0, 12)
    xi, eta = deflection(model, lat, lon, h)
    return model, lat, lon, h, jnp.stack([xi, eta])


def test_schuler_constant_error_is_bounded_oscillation():
    t = np.arange(1, 6001) * 1.0
    out = sensitivity.schuler_error(np.full(6000, 1.0), np.zeros(6000), 1.0)
    w = np.sqrt(9.80 / 6371000.0)
    expect = -6371000.0 * np.pi / 648000.0 * (1 - np.cos(w * t))
    np.testing.assert_allclose(out.north, expect, rtol=1e-9, atol=1e-9)
    assert float(jnp.max(jnp.abs(out.north))) < 2 * 6371000.0 * np.pi / 648000.0 + 1e-9
    np.testing.assert_allclose(out.east, 0.0)


def test_final_error_gradient_wrt_compensation_error_matches_fd():
    rng = np.random.default_rng(0)
    eps = jnp.asarray(rng.normal(0, 0.02, (2, 400)))

    def final(e):
        r = sensitivity.schuler_error(e[0], e[1], 5.0)
        return jnp.hypot(r.north[-1], r.east[-1])

    g = jax.jit(jax.grad(final))(eps)
    gf = jax.jit(jax.jacfwd(final))(eps)
    np.testing.assert_allclose(g, gf, rtol=1e-9, atol=1e-12)
    f = jax.jit(final)
    for idx in [(0, 0), (1, 200), (0, 399)]:
        d = jnp.zeros_like(eps).at[idx].set(1e-4)
        np.testing.assert_allclose(g[idx], (f(eps + d) - f(eps - d)) / 2e-4, rtol=1e-6)


def test_spacing_gradient_matches_fd(small):
    model, lat, lon, h, truth = small
    heights = np.array([0.0, 10000.0, 20000.0])

    def final(d):
        e = sensitivity.spacing_error(model, lat, lon, h, truth, heights, d, n_nodes=(24, 24),
                                      method="bilinear-linear")
        r = sensitivity.schuler_error(e[0], e[1], 300.0)
        return jnp.hypot(r.north[-1], r.east[-1])

    d0 = 0.05
    g = jax.jit(jax.grad(final))(d0)
    f = jax.jit(final)
    step = 1e-5
    fd = (f(d0 + step) - f(d0 - step)) / (2 * step)
    assert np.isfinite(float(g)) and float(f(d0)) > 1e-4
    np.testing.assert_allclose(g, fd, rtol=1e-3)


def test_height_gradient_and_optimisation(small):
    model, lat, lon, h, truth = small
    build = sensitivity.harmonic_layers(model, np.linspace(34.0, 35.5, 16),
                                        np.linspace(108.0, 109.5, 16))
    x0 = jnp.array([0.0, 10000.0, 20000.0])
    fun = jax.jit(lambda x: sensitivity.rms_error(build(x), lat, lon, h, truth))
    g = jax.jit(jax.grad(lambda x: sensitivity.rms_error(build(x), lat, lon, h, truth)))(x0)
    step = 1.0
    fd = (fun(x0.at[1].add(step)) - fun(x0.at[1].add(-step))) / (2 * step)
    np.testing.assert_allclose(g[1], fd, rtol=1e-4)
    st = sensitivity.optimise_heights(build, x0, lat, lon, h, truth, free=[False, True, False],
                                      steps=3, learning_rate=500.0)
    assert st.heights.shape == (4, 3) and st.rms.shape == (4,)
    np.testing.assert_allclose(st.heights[:, [0, 2]], [[0.0, 20000.0]] * 4)
    assert st.rms[-1] < st.rms[0]
