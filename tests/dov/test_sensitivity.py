"""Tests of jaxgrav.dov.sensitivity (small models: the degree is not the point here)."""

import importlib
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import datasets
from jaxgrav.dov import sensitivity
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


@pytest.mark.long
def test_spacing_gradient_matches_fd(small):
    model, lat, lon, h, truth = small
    heights = np.array([0.0, 10000.0, 20000.0])

    def final(d):
        e = sensitivity.spacing_error(model, lat, lon, h, truth, heights, d, n_nodes=(24, 24),
                                      method="bilinear-linear")
        r = sensitivity.schuler_error(e[0], e[1], 300.0)
        return jnp.hypot(r.north[-1], r.east[-1])

    d0 = 0.05
    f = jax.jit(jax.value_and_grad(final))  # one program for the gradient and the FD values
    f0, g = f(d0)
    step = 1e-5
    fd = (f(d0 + step)[0] - f(d0 - step)[0]) / (2 * step)
    assert np.isfinite(float(g)) and float(f0) > 1e-4
    np.testing.assert_allclose(g, fd, rtol=1e-3)


@pytest.mark.long
def test_height_gradient_and_optimisation(small):
    model, lat, lon, h, truth = small
    build = sensitivity.harmonic_layers(model, np.linspace(34.0, 35.5, 16),
                                        np.linspace(108.0, 109.5, 16))
    x0 = jnp.array([0.0, 10000.0, 20000.0])
    free = [False, True, False]
    st = sensitivity.optimise_heights(build, x0, lat, lon, h, truth, free=free,
                                      steps=3, learning_rate=500.0)
    assert st.heights.shape == (4, 3) and st.rms.shape == (4,)
    np.testing.assert_allclose(st.heights[:, [0, 2]], [[0.0, 20000.0]] * 4)
    assert st.rms[-1] < st.rms[0]

    # st.grad is d rms / d heights at x0; against central differences of the RMS, each
    # evaluated by the same compiled program (steps=0: no new compilation)
    def rms_at(x):
        return sensitivity.optimise_heights(build, x, lat, lon, h, truth, free=free,
                                            steps=0).rms[0]

    size = sensitivity.height_loss_and_grad._cache_size()
    step = 1.0
    fd = (rms_at(x0.at[1].add(step)) - rms_at(x0.at[1].add(-step))) / (2 * step)
    np.testing.assert_allclose(st.grad[1], fd, rtol=1e-4)
    np.testing.assert_allclose(rms_at(x0), st.rms[0], rtol=1e-14)
    assert sensitivity.height_loss_and_grad._cache_size() == size


def test_old_import_path_warns_and_is_the_same_module():
    sys.modules.pop("jaxgrav.sensitivity", None)
    with pytest.warns(DeprecationWarning, match="jaxgrav.dov.sensitivity"):
        old = importlib.import_module("jaxgrav.sensitivity")
    assert old.optimise_heights is sensitivity.optimise_heights
    assert set(old.__all__) == set(sensitivity.__all__)
