"""The matchers of the loosely coupled loop (navigate.loose_match): the error they are
told (the Eötvös error of the filter's velocity at its Schuler length, with the map's
error as one Gauss–Markov error of the same variance and slope variance) and the edge
test of the chains' fixes."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.constants import KNOT, MGAL, WGS84_MEAN_RADIUS
from jaxgrav.fields.map_error import map_error
from jaxgrav.geodesy import normal_gravity
from jaxgrav.match.correlation import ChainConfig, match_chains
from jaxgrav.match.gls import track_covariance
from jaxgrav.match.sizing import config_for
from jaxgrav.navigate import loose_match
from jaxgrav.navigate.loose_match import (
    LOOSE_MATCHERS,
    LOOSE_MAX_EDGE_MASS,
    match_segment,
    matcher_config,
    schuler_length_m,
    told_error,
)
from jaxgrav.scenarios import MatchingScenario, matching_scenario


def _one_minus_corr(sigma, length, h, order=2):
    """``1 − C(h)/C(0)`` of the told Gauss–Markov error (track_covariance, no noise)."""
    c = np.asarray(track_covariance(jnp.array([0.0, h]), jnp.zeros(2), 1e-9, sigma, length,
                                    order))
    return 1.0 - c[0, 1] / c[0, 0]


def test_the_schuler_length_gives_a_markov_error_the_schuler_curvature():
    """A velocity error cos(ω_s t) read at 10 kn and the Markov error of L = v/ω_s have the
    same curvature at zero lag; at 10 kn L is about 4.1 km (not the map error's 10 km)."""
    v, lat = 10 * KNOT, 26.0
    length = float(schuler_length_m(v, lat))
    rate = np.sqrt(float(normal_gravity(lat)) * MGAL / WGS84_MEAN_RADIUS)
    assert 2 * np.pi / rate / 60 == pytest.approx(84.4, abs=0.3)  # the Schuler period, min
    assert length == pytest.approx(4140.0, rel=0.01)
    h = 20.0  # m, small against L
    assert _one_minus_corr(1.0, length, h) == pytest.approx(1 - np.cos(rate * h / v), rel=0.02)
    assert float(schuler_length_m(0.0, lat)) == 0.0


def test_told_error_keeps_the_variance_and_the_slope_variance():
    sigma, length = (float(a) for a in told_error(3.0, 10000.0, 2.0, 4000.0))
    assert sigma**2 == pytest.approx(13.0)
    assert sigma**2 / length**2 == pytest.approx(9.0 / 1e8 + 4.0 / 1.6e7)
    # near zero lag the told error decorrelates as the sum of the two does
    h = 20.0
    both = (9 * _one_minus_corr(1, 1e4, h) + 4 * _one_minus_corr(1, 4e3, h)) / 13
    assert _one_minus_corr(sigma, length, h) == pytest.approx(both, rel=0.02)
    # order 1: the slope at zero lag, σ²/L = Σ σ_k²/L_k
    s1, l1 = (float(a) for a in told_error(3.0, 10000.0, 2.0, 4000.0, order=1))
    assert s1**2 / l1 == pytest.approx(9.0 / 1e4 + 4.0 / 4e3)
    # one error alone is told as it is; none: the map's L; a white one makes the sum white
    np.testing.assert_allclose(told_error(3.0, 10000.0, 0.0, 4000.0), (3.0, 10000.0))
    np.testing.assert_allclose(told_error(0.0, 10000.0, 2.0, 4000.0), (2.0, 4000.0))
    np.testing.assert_allclose(told_error(0.0, 10000.0, 0.0, 4000.0), (0.0, 10000.0))
    np.testing.assert_allclose(told_error(3.0, 10000.0, 2.0, 0.0), (np.sqrt(13.0), 0.0))


class _Told(Exception):
    """Carries the settings match_segment gave the chain matcher."""


def test_the_chains_are_told_the_eotvos_error_at_its_schuler_length(smooth_grid, monkeypatch):
    def fake(grid, lat, lon, g, config):
        raise _Told(config)

    monkeypatch.setattr(loose_match, "match_chains", fake)
    config = ChainConfig(noise_mgal=0.3, map_error_mgal=3.0, map_error_length_m=10000.0)
    lat, lon = jnp.linspace(29.9, 30.1, 10), jnp.full(10, 130.0)
    args = (config, smooth_grid, lat, lon, jnp.zeros(10), 1000.0, 2.0, (100.0, 1500.0))
    with pytest.raises(_Told) as told:
        match_segment(*args, eotvos_length_m=4000.0)
    sent = told.value.args[0]
    sigma, length = told_error(3.0, 10000.0, 2.0, 4000.0)
    assert float(sent.map_error_mgal) == pytest.approx(float(sigma))
    assert float(sent.map_error_length_m) == pytest.approx(float(length))
    assert float(sent.delta) == pytest.approx(2 * np.sqrt(0.3**2 + 13.0))
    with pytest.raises(_Told) as told:  # no length given: the map error's
        match_segment(*args)
    assert float(told.value.args[0].map_error_length_m) == pytest.approx(10000.0)


@pytest.mark.parametrize("matcher", ["dense", "entropy+iccp"])
def test_the_offset_grid_matchers_are_told_the_eotvos_error_at_its_schuler_length(
        matcher, smooth_grid, monkeypatch):
    """As the chains: the dense GLS score and ICCP's are told one Markov error standing for
    the map's (3 mGal, 10 km) and the Eötvös error (2 mGal, at 4 km), not the Eötvös error
    at the map's L; the perfect map is told the Eötvös error alone at its length."""
    def fake(grid, lat, lon, g, *configs):
        raise _Told(configs[-1])  # the dense config, or ICCP's

    monkeypatch.setattr(loose_match, "match_dense", fake)
    monkeypatch.setattr(loose_match, "match_entropy_iccp", fake)
    lat, lon = jnp.linspace(29.9, 30.1, 10), jnp.full(10, 130.0)
    for map_sigma in (3.0, 0.0):
        config = matcher_config(matcher, 0.3, map_sigma, 10000.0, grid=smooth_grid)
        args = (config, smooth_grid, lat, lon, jnp.zeros(10), 1000.0, 2.0, (100.0, 1500.0))
        with pytest.raises(_Told) as told:
            match_segment(*args, eotvos_length_m=4000.0)
        sent = told.value.args[0]
        sigma, length = told_error(map_sigma, 10000.0, 2.0, 4000.0)
        assert float(sent.map_error_mgal) == pytest.approx(float(sigma))
        assert float(sent.map_error_length_m) == pytest.approx(float(length))
        assert float(length) == pytest.approx(4000.0 if map_sigma == 0 else 6183.5, rel=1e-3)
        with pytest.raises(_Told) as told:  # no length given: the map error's
            match_segment(*args)
        assert float(told.value.args[0].map_error_length_m) == pytest.approx(10000.0)


def test_every_loop_matcher_is_given_the_edge_limit(smooth_grid):
    configs = {m: matcher_config(m, 0.3, 3.0, 10000.0, grid=smooth_grid, step_m=1000.0)
               for m in LOOSE_MATCHERS}
    assert configs["dense"].max_edge_mass == LOOSE_MAX_EDGE_MASS
    assert configs["chains"].max_edge_mass == LOOSE_MAX_EDGE_MASS
    assert configs["chains"].fix == "posterior" and configs["chains"].stencil_size > 0
    # the loop tells the chains a traced error (the Eötvös one even on a perfect map)
    assert matcher_config("chains", 0.3, 0.0, 10000.0, grid=smooth_grid,
                          step_m=1000.0).score_model == "auto"
    assert configs["entropy+iccp"][1].max_edge_mass == LOOSE_MAX_EDGE_MASS


def test_a_chain_fix_with_its_posterior_on_the_window_edge_is_rejected(smooth_grid):
    """The chain matcher's own edge test (status 4096, the INS track kept), on the first
    track whose window posterior has more than the loop's limit on the window's outer
    ring (the fourth of the first five, with 0.997)."""
    scen = MatchingScenario(region=(29.6, 30.4, 129.6, 130.4), drift_deg=0.01, n_fixes=12,
                            dt=120.0, eotvos=None)
    config = dataclasses.replace(
        config_for("chains", smooth_grid, 1500.0, step_m=scen.step_m,
                   map_error=map_error(3.0, 8000.0)), fix="posterior")
    for key in range(5):
        run = matching_scenario(jax.random.key(key), smooth_grid, scen)
        args = (smooth_grid, run.ins_lat, run.ins_lon, run.readings)
        free = match_chains(*args, config)
        edge = float(free.edge_mass)
        if edge > LOOSE_MAX_EDGE_MASS:
            break
    assert bool(free.accepted) and LOOSE_MAX_EDGE_MASS < edge <= 1.0
    assert abs(float(free.offset_north_m)) > 100.0
    kept = match_chains(*args, dataclasses.replace(config, max_edge_mass=edge + 0.01))
    rejected = match_chains(*args, dataclasses.replace(config, max_edge_mass=edge - 0.01))
    assert bool(kept.accepted) and not int(kept.status) & 4096
    np.testing.assert_array_equal(np.asarray(kept.lat), np.asarray(free.lat))
    assert not bool(rejected.accepted) and int(rejected.status) & 4096
    assert float(rejected.offset_north_m) == 0.0 and float(rejected.offset_east_m) == 0.0
    np.testing.assert_array_equal(np.asarray(rejected.lat), np.asarray(run.ins_lat))
    np.testing.assert_array_equal(np.asarray(rejected.lon), np.asarray(run.ins_lon))
    # the same fix and covariance either way: the test only decides acceptance
    np.testing.assert_array_equal(np.asarray(rejected.covariance_m2),
                                  np.asarray(free.covariance_m2))
