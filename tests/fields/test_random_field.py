"""Gaussian random fields: statistics against the requested spectrum, keys, transformations.

Statistical bounds are derived, not guessed: for a field drawn with per-mode amplitude
A(k), the sample mean square ``mean(f²)`` of one realisation has expectation
``Σ A²/N`` and variance ``2 Σ A⁴ / N²``; periodogram values are independent
exponential variables (up to the k ↔ −k pairing). Every test allows 5 standard errors.
"""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgrav.fields import random as rf
from jaxgrav.fields.spectral import wavenumbers

SHAPE = (64, 64)
SPACING = (1000.0, 1000.0)
N_SAMPLES = 256
MARKOV = rf.markov_spectrum(rms=10.0, correlation_length=3000.0, order=2)


def _draw_many(keys, spectrum, rms=None):
    # vmap without an outer jit: the library's jitted noise-colouring part is then
    # compiled once for all spectra (it does not depend on the spectrum).
    return jax.vmap(lambda k: rf.gaussian_random_field(k, SHAPE, SPACING, spectrum, rms))(keys)


def _amp2(spectrum):
    """Per-mode variance A(k)² on the full FFT grid, k = 0 dropped (zero_mean)."""
    k = wavenumbers(SHAPE, SPACING).k
    a2 = np.asarray(spectrum(k)) / (SPACING[0] * SPACING[1])
    a2[0, 0] = 0.0
    return a2


def _check_mean_square(fields, a2_scaled):
    n = fields.shape[-1] * fields.shape[-2]
    expected = a2_scaled.sum() / n
    sd_one = np.sqrt(2.0 * np.sum(a2_scaled**2)) / n
    ms = np.mean(np.asarray(fields) ** 2, axis=(-2, -1))
    assert abs(ms.mean() - expected) < 5.0 * sd_one / np.sqrt(ms.size), (ms.mean(), expected)
    # the empirical spread of the per-realisation variance matches the theory too
    assert 0.7 < ms.std() / sd_one < 1.3


def test_variance_matches_requested_rms_exactly_in_expectation():
    keys = jax.random.split(jax.random.key(0), N_SAMPLES)
    fields = _draw_many(keys, MARKOV, 10.0)
    assert fields.shape == (N_SAMPLES, *SHAPE)
    np.testing.assert_allclose(jnp.mean(fields, axis=(-2, -1)), 0.0, atol=1e-12)  # zero_mean
    a2 = _amp2(MARKOV)
    _check_mean_square(fields, a2 * (100.0 * a2.size / a2.sum()))


def test_absolute_level_is_the_riemann_sum_of_the_spectrum():
    keys = jax.random.split(jax.random.key(1), N_SAMPLES)
    fields = _draw_many(keys, MARKOV)
    a2 = _amp2(MARKOV)
    _check_mean_square(fields, a2)
    # and that sum is close to the continuous variance rms² once L ≫ spacing, L ≪ domain
    assert 0.85 < a2.sum() / a2.size / 100.0 < 1.0


def test_radial_spectrum_matches_the_requested_one():
    keys = jax.random.split(jax.random.key(2), N_SAMPLES)
    fields = np.asarray(_draw_many(keys, MARKOV))
    n = SHAPE[0] * SHAPE[1]
    periodogram = np.mean(np.abs(np.fft.fft2(fields)) ** 2, axis=0) * SPACING[0] * SPACING[1] / n
    k = np.asarray(wavenumbers(SHAPE, SPACING).k)
    target = np.asarray(MARKOV(k))
    edges = np.linspace(0.0, np.pi / SPACING[0], 9)[1:]  # skip k = 0 (dropped)
    for lo, hi in itertools.pairwise(edges):
        sel = (k >= lo) & (k < hi)
        ratio = periodogram[sel] / target[sel]  # each ≈ Exp(1) averaged over samples
        n_eff = sel.sum() * N_SAMPLES / 2  # k and −k carry the same value
        assert abs(ratio.mean() - 1.0) < 5.0 / np.sqrt(n_eff), (lo, ratio.mean())


def test_covariance_at_lags_matches_the_markov_model():
    keys = jax.random.split(jax.random.key(3), N_SAMPLES)
    f = np.asarray(_draw_many(keys, MARKOV, 10.0))
    for lag in (0, 2, 5):
        emp = np.mean(f * np.roll(f, lag, axis=-1))
        model = float(MARKOV.covariance(lag * SPACING[1]))
        # the periodic domain (64 km vs L = 3 km) and dropped mean bias it by < 3 % of rms²
        assert abs(emp - model) < 0.06 * 100.0, (lag, emp, model)


def test_power_law_with_rms():
    spectrum = rf.power_law_spectrum(exponent=3.0)
    keys = jax.random.split(jax.random.key(4), N_SAMPLES)
    fields = _draw_many(keys, spectrum, 2.5)
    a2 = _amp2(spectrum)
    _check_mean_square(fields, a2 * (2.5**2 * a2.size / a2.sum()))


def test_plain_callable_and_zero_mean_false():
    def flat(k):
        return jnp.full_like(k, 1.0e6)  # white noise of unit variance per 1 km² cell

    f = rf.gaussian_random_field(jax.random.key(5), SHAPE, SPACING, flat, zero_mean=False)
    assert f.shape == SHAPE and f.dtype == jnp.float64
    # white spectrum + k = 0 kept: the field is exactly the N(0, 1) draw
    np.testing.assert_allclose(f, jax.random.normal(jax.random.key(5), SHAPE), atol=1e-12)


def test_keys_decide_the_field():
    a = rf.gaussian_random_field(jax.random.key(7), SHAPE, SPACING, MARKOV)
    b = rf.gaussian_random_field(jax.random.key(7), SHAPE, SPACING, MARKOV)
    c = rf.gaussian_random_field(jax.random.key(8), SHAPE, SPACING, MARKOV)
    np.testing.assert_array_equal(a, b)
    assert np.corrcoef(np.ravel(a), np.ravel(c))[0, 1] < 0.2
    legacy = rf.gaussian_random_field(jax.random.PRNGKey(7), SHAPE, SPACING, MARKOV)
    assert legacy.shape == SHAPE


def test_jit_no_retrace_vmap_equals_loop_and_grad():
    traces = []

    @jax.jit
    def draw(key, spectrum, rms):
        traces.append(1)
        return rf.gaussian_random_field(key, SHAPE, SPACING, spectrum, rms)

    key = jax.random.key(9)
    a = draw(key, MARKOV, jnp.asarray(3.0))
    b = draw(key, rf.markov_spectrum(5.0, 8000.0), jnp.asarray(4.0))
    assert len(traces) == 1
    assert not np.allclose(a, b)
    eager = rf.gaussian_random_field(key, SHAPE, SPACING, MARKOV, 3.0)
    np.testing.assert_allclose(a, eager, atol=1e-12)

    keys = jax.random.split(key, N_SAMPLES)
    batched = _draw_many(keys, MARKOV, 10.0)
    for i in range(3):
        np.testing.assert_allclose(batched[i], draw(keys[i], MARKOV, jnp.asarray(10.0)), atol=1e-12)

    # d/dL of a smooth functional is finite and matches finite differences
    def score(length):
        f = rf.gaussian_random_field(key, SHAPE, SPACING, rf.markov_spectrum(10.0, length), 10.0)
        return jnp.sum(f[0, :8] ** 2)

    score_jit = jax.jit(score)
    g = jax.jit(jax.grad(score))(3000.0)
    fd = (score_jit(3010.0) - score_jit(2990.0)) / 20.0
    assert np.isfinite(g)
    np.testing.assert_allclose(g, fd, rtol=1e-4)


# --- validation --------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(st.floats(max_value=0.0) | st.just(np.nan) | st.just(np.inf))
def test_bad_markov_parameters_are_rejected(bad):
    with pytest.raises(ValueError, match="correlation_length"):
        rf.markov_spectrum(1.0, bad)
    with pytest.raises(ValueError, match="rms"):
        rf.markov_spectrum(bad, 1000.0)
    with pytest.raises(ValueError, match="rms"):
        rf.gaussian_random_field(jax.random.key(0), (8, 8), SPACING, MARKOV, rms=bad)


def test_other_bad_inputs():
    key = jax.random.key(0)
    with pytest.raises(ValueError, match="order"):
        rf.markov_spectrum(1.0, 1000.0, order=3)
    with pytest.raises(ValueError, match="exponent"):
        rf.power_law_spectrum(-1.0)
    with pytest.raises(ValueError, match="two positive integers"):
        rf.gaussian_random_field(key, (8, 0), SPACING, MARKOV)
    with pytest.raises(ValueError, match="two positive integers"):
        rf.gaussian_random_field(key, (8, 8.5), SPACING, MARKOV)
    with pytest.raises(ValueError, match="spacing"):
        rf.gaussian_random_field(key, (8, 8), (1000.0, -1.0), MARKOV)
    with pytest.raises(TypeError, match="callable"):
        rf.gaussian_random_field(key, (8, 8), SPACING, "markov")
    with pytest.raises(ValueError, match=">= 0"):
        rf.gaussian_random_field(key, (8, 8), SPACING, lambda k: -jnp.ones_like(k))
    with pytest.raises(ValueError, match=">= 0"):
        rf.gaussian_random_field(key, (8, 8), SPACING, lambda k: jnp.full_like(k, jnp.nan))
    with pytest.raises(ValueError, match="zero at every"):
        rf.gaussian_random_field(key, (8, 8), SPACING, lambda k: jnp.where(k == 0, 1.0, 0.0))
