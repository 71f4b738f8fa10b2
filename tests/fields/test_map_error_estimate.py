"""estimate_map_error: a map's omission error from its own spectrum (synthetic known spectrum)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import Grid
from jaxgrav.constants import WGS84_MEAN_RADIUS as R
from jaxgrav.fields.map_error_estimate import (
    TR_A_MGAL2,
    TR_B,
    TR_S,
    estimate_map_error,
    tail_covariance,
    tscherning_rapp,
)
from jaxgrav.fields.random import gaussian_random_field

MAX_N = 6000
"""Highest degree summed in the tests (fast; the default sums to ≈ 36 000)."""


def _tr_field(scale, n=96, step_deg=0.1, seed=0):
    """A field with Tscherning–Rapp degree variances of scale ``scale`` (mGal²)."""
    lat = 20.0 + step_deg * np.arange(n)
    lon = 130.0 + step_deg * np.arange(n)
    dy = np.deg2rad(step_deg) * R
    dx = dy * np.cos(np.deg2rad(lat.mean()))

    def spectrum(k):  # S(k) = 2π R² c_n / n, n = k R (the estimator's convention)
        kr = jnp.maximum(k * R, 3.0)
        c = scale * (kr - 1.0) / ((kr - 2.0) * (kr + TR_B)) * TR_S ** (kr + 2.0)
        return jnp.where(k > 0, 2 * np.pi * R**2 * c / kr, 0.0)

    f = gaussian_random_field(jax.random.key(seed), (n, n), (dy, dx), spectrum)
    return Grid.from_arrays(lat, lon, np.asarray(f), units="mGal")


def test_recovers_the_scale_of_a_known_spectrum():
    scales = [estimate_map_error(_tr_field(900.0, seed=s), max_degree=MAX_N).scale_mgal2
              for s in (0, 1)]
    np.testing.assert_allclose(np.mean(scales), 900.0, rtol=0.25)
    est = estimate_map_error(_tr_field(900.0), max_degree=MAX_N)
    # σ is the model's tail above the map's Nyquist degree
    tail = np.arange(est.nyquist_degree + 1, est.max_degree + 1)
    np.testing.assert_allclose(float(est.model.sigma) ** 2,
                               tscherning_rapp(tail, est.scale_mgal2).sum(), rtol=1e-5)
    # the tail's covariance is ½ σ² at the half-correlation distance, L matches markov2
    c = tail_covariance(est.half_correlation_m, est.nyquist_degree + 1, est.max_degree,
                        est.scale_mgal2)
    np.testing.assert_allclose(c / float(est.model.sigma) ** 2, 0.5, atol=0.02)
    np.testing.assert_allclose(float(est.model.length_m) * 1.678347, est.half_correlation_m,
                               rtol=1e-4)
    # a coarser map misses more: larger σ, longer L
    coarse = estimate_map_error(_tr_field(900.0, n=48, step_deg=0.2), max_degree=MAX_N)
    assert float(coarse.model.sigma) > float(est.model.sigma)
    assert float(coarse.model.length_m) > float(est.model.length_m)


def test_tail_covariance_at_zero_is_the_sum():
    np.testing.assert_allclose(tail_covariance(0.0, 10, 200),
                               tscherning_rapp(np.arange(10, 201), TR_A_MGAL2).sum(), rtol=1e-10)


def test_bad_input():
    g = _tr_field(400.0, n=16)
    with pytest.raises(ValueError, match="fit_band must be"):
        estimate_map_error(g, fit_band=(0.8, 0.2))
    with pytest.raises(ValueError, match="max_degree must exceed"):
        estimate_map_error(g, max_degree=10)
    with pytest.raises(ValueError, match="family must be"):
        estimate_map_error(g, family="gauss")
    small = Grid.from_arrays(np.arange(5.0), np.arange(5.0), np.zeros((5, 5)))
    with pytest.raises(ValueError, match="at least 8 x 8"):
        estimate_map_error(small)
