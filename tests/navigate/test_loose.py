"""Loosely coupled voyage navigation (navigate.loose, navigate.error_kf, navigate.metrics):
the filter's tables and update against brute-force NumPy, the Eötvös σ against finite
differences, the loop on an information-rich map, jit without retrace, vmap against a
loop, bad settings."""

import dataclasses
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.geodesy import eotvos
from jaxgrav.match.correlation import ChainConfig
from jaxgrav.match.dense import DenseConfig
from jaxgrav.match.entropy import EntropyConfig
from jaxgrav.match.sizing import chain_grid, iccp_config_for
from jaxgrav.navigate import (
    FIX_EVENTS,
    LooseConfig,
    eotvos_sigma,
    error_kf_tables,
    fix_update,
    hourly_rms,
    loose_config,
    navigate_loose,
    voyage_errors,
)
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import voyage_preset, voyage_scenario
from jaxgrav.sim.ins import INSErrorModel, transition

INS = INSErrorModel()


@pytest.mark.long
def test_tables_equal_matrix_powers_in_numpy():
    t = error_kf_tables(INS, 30.0, 10.0, 5, 4)
    f, q = (np.asarray(a) for a in transition(INS, 30.0, 10.0))
    acc = np.zeros_like(q)
    for i in range(5):
        np.testing.assert_allclose(t.forward[i], np.linalg.matrix_power(f, i), atol=1e-12)
        np.testing.assert_allclose(t.noise[i], acc, rtol=1e-9, atol=1e-18)
        acc = f @ acc @ f.T + q
    np.testing.assert_allclose(t.step_f, np.linalg.matrix_power(f, 5), atol=1e-12)
    np.testing.assert_allclose(t.step_q, acc, rtol=1e-9, atol=1e-18)
    back = [np.linalg.matrix_power(np.linalg.inv(f), k) for k in (4, 3, 2, 1)]
    np.testing.assert_allclose(t.backward, back, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(t.h_mean, np.mean([b[:2] for b in back], axis=0), atol=1e-12)


def test_fix_update_is_the_kalman_update_in_numpy():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(13, 13))
    p = a @ a.T + 13 * np.eye(13)
    h = rng.normal(size=(2, 13))
    r = np.array([[4.0, 1.0], [1.0, 3.0]])
    x = rng.normal(size=13)
    nu = np.array([0.5, -1.0])
    s = h @ p @ h.T + r
    k = p @ h.T @ np.linalg.inv(s)
    x_new, p_new, nis = fix_update(jnp.asarray(x), jnp.asarray(p), jnp.asarray(nu),
                                   jnp.asarray(r), jnp.asarray(h), jnp.asarray(True))
    np.testing.assert_allclose(x_new, x + k @ nu, rtol=1e-10)
    np.testing.assert_allclose(p_new, p - k @ s @ k.T, rtol=1e-8, atol=1e-10)
    assert float(nis) == pytest.approx(nu @ np.linalg.inv(s) @ nu, rel=1e-12)
    x_same, p_same, _ = fix_update(jnp.asarray(x), jnp.asarray(p), jnp.asarray(nu),
                                   jnp.asarray(r), jnp.asarray(h), jnp.asarray(False))
    np.testing.assert_array_equal(x_same, x)
    np.testing.assert_array_equal(p_same, p)


def test_eotvos_sigma_against_finite_differences():
    cov = np.array([[0.04, 0.01], [0.01, 0.09]])  # north, east (m²/s²)
    lat, ve, vn, h = 30.0, 4.0, 3.0, 1e-4
    d_n = (eotvos(lat, ve, vn + h) - eotvos(lat, ve, vn - h)) / (2 * h)
    d_e = (eotvos(lat, ve + h, vn) - eotvos(lat, ve - h, vn)) / (2 * h)
    jac = np.array([float(d_n), float(d_e)])
    assert float(eotvos_sigma(lat, ve, vn, jnp.asarray(cov))) == pytest.approx(
        np.sqrt(jac @ cov @ jac), rel=1e-6)


def test_hourly_rms_by_hand():
    e = jnp.concatenate([jnp.zeros(1), jnp.full(3, 3.0), jnp.full(3, 4.0), jnp.ones(2)])
    np.testing.assert_allclose(hourly_rms(e, 1.0, 3.0), [3.0, 4.0])


@pytest.fixture(scope="module")
def short_voyages(smooth_grid):
    """Two 2 h voyages on the information-rich synthetic map, strategic-grade INS."""
    sc = voyage_preset("patrol-12h", ins=INS, hours=2.0, region=(29.6, 30.4, 129.6, 130.4),
                       leg_m=20000.0, margin_deg=0.1, pos_error_m=1500.0)
    keys = jax.random.split(jax.random.key(4), 2)
    return jax.vmap(lambda g, k: voyage_scenario(k, g, sc), in_axes=(None, 0))(smooth_grid, keys)


CONFIG = LooseConfig(matcher=DenseConfig(noise_mgal=0.5, half_size=6, fix="posterior",
                                         score_model="white"),
                     ins=INS, sigma_pos_m=1100.0, fix_every=6, n_fixes=20, stride=10)


@pytest.mark.long
def test_the_loop_corrects_the_ins_on_an_informative_map(smooth_grid, short_voyages):
    pm = prepare_map(smooth_grid)
    v = jax.tree.map(lambda a: a[0], short_voyages)
    res = navigate_loose(pm, v, CONFIG)
    n = v.ins.t.shape[0]
    assert res.nav.lat.shape == (n,) and res.cov_north_east.shape == (n, 2, 2)
    assert res.fix_event.shape == (12,) and int(res.fix_event[0]) == 1  # first: incomplete
    assert int(np.sum(np.asarray(res.fix_event) == 0)) >= 5
    assert set(np.asarray(res.fix_event).tolist()) <= set(FIX_EVENTS)
    err = voyage_errors(v, res.nav, res.cov_north_east)
    # the free INS starts 1.5 km off; after the fixes the solution is within a few hundred m
    assert float(err.free_m[-1]) > 1000.0 and float(err.nav_m[-1]) < 0.3 * float(err.free_m[-1])
    assert 0.2 < float(jnp.mean(err.nees[n // 2:])) < 8.0


@pytest.mark.long
def test_the_entropy_iccp_loop_corrects_the_ins_too(smooth_grid, short_voyages):
    """Paper B's matcher in the loop: the gravimeter's bias marginalised, fixes accepted."""
    iccp = iccp_config_for(smooth_grid, 1000.0, stage="fine", noise=0.5, max_rotation_deg=3.0,
                           bias_sigma=float("inf"), max_sigma_m=3000.0)
    config = dataclasses.replace(CONFIG, matcher=(EntropyConfig(half_size=6), iccp))
    v = jax.tree.map(lambda a: a[0], short_voyages)
    res = navigate_loose(prepare_map(smooth_grid), v, config)
    assert int(np.sum(np.asarray(res.fix_event) == 0)) >= 5
    err = voyage_errors(v, res.nav, res.cov_north_east)
    assert float(err.nav_m[-1]) < 0.3 * float(err.free_m[-1])


@pytest.mark.long
def test_the_chain_loop_corrects_the_ins_too(smooth_grid, short_voyages):
    """Paper A's chains in the loop, on the map refined to 0.005° nodes (×2 here), their
    window fixed; the reading bias drops out of the difference score."""
    nodes = chain_grid(smooth_grid)
    assert nodes.dlat == pytest.approx(0.005)
    v = jax.tree.map(lambda a: a[0], short_voyages)
    step = 10 * 0.514444 * 10.0 * CONFIG.fix_every  # 10 kn, a reading every 10 s
    config = loose_config(INS, 0.0, 10000.0, 1.0, matcher="chains", grid=nodes, step_m=step,
                          chain_reach_m=6000.0, sigma_pos_m=1100.0, fix_every=6, n_fixes=20,
                          stride=10)
    assert isinstance(config.matcher, ChainConfig) and config.matcher.stencil_size > 0
    res = navigate_loose(nodes, v, config)
    assert int(np.sum(np.asarray(res.fix_event) == 0)) >= 5
    err = voyage_errors(v, res.nav, res.cov_north_east)
    assert float(err.nav_m[-1]) < 0.3 * float(err.free_m[-1])
    n = v.ins.t.shape[0]
    assert 0.2 < float(jnp.mean(err.nees[n // 2:])) < 8.0


@pytest.mark.long
def test_jit_without_retrace_and_vmap_equals_loop(smooth_grid, short_voyages):
    pm = prepare_map(smooth_grid)
    batch = jax.vmap(navigate_loose, in_axes=(None, 0, None))(pm, short_voyages, CONFIG)
    for i in range(2):
        v = jax.tree.map(lambda a, i=i: a[i], short_voyages)
        one = navigate_loose(pm, v, CONFIG)
        np.testing.assert_allclose(batch.nav.lat[i], one.nav.lat, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(batch.fix_event[i], one.fix_event)
    before = navigate_loose._cache_size()
    navigate_loose(pm, v, dataclasses.replace(CONFIG, gate=10.0, fix_cov_scale=2.0))
    assert navigate_loose._cache_size() == before


@pytest.mark.long
def test_missing_readings_are_not_matched(smooth_grid, short_voyages):
    pm = prepare_map(smooth_grid)
    v = jax.tree.map(lambda a: a[0], short_voyages)
    v = v._replace(gravity=v.gravity.at[300].set(jnp.nan))
    res = navigate_loose(pm, v, CONFIG)
    events = np.asarray(res.fix_event)
    assert 2 in events.tolist() and np.all(np.isfinite(np.asarray(res.nav.lat)))


@pytest.mark.parametrize(("change", "message"), [
    ({"n_fixes": 4}, "n_fixes must be an integer >= 5"),
    ({"stride": 40}, "stride must be at most n_fixes"),
    ({"fix_every": 0}, "fix_every must be an integer >= 1"),
])
def test_bad_settings_get_clear_errors(change, message):
    with pytest.raises(ValueError, match=message):
        LooseConfig(**change)


def test_loose_config_names_its_matchers(smooth_grid):
    with pytest.raises(ValueError, match=r"matcher must be one of .*; got 'iccp'"):
        loose_config(matcher="iccp")
    for matcher in ("chains", "entropy+iccp"):
        with pytest.raises(ValueError, match=re.escape(f"(matcher={matcher!r}) needs the grid")):
            loose_config(matcher=matcher)
    with pytest.raises(ValueError, match="chain_reach_m must be a positive distance"):
        loose_config(matcher="chains", grid=smooth_grid, chain_reach_m=0.0)
    with pytest.raises(TypeError, match="matcher must be a DenseConfig, a ChainConfig or a"):
        LooseConfig(matcher=(None, EntropyConfig()))
    entropy, iccp = loose_config(matcher="entropy+iccp", grid=smooth_grid).matcher
    assert iccp.bias_sigma == float("inf") and iccp.map_error_mgal == 3.0
    assert entropy.half_size == 20 and iccp.max_rotation_deg == 3.0
    chains = loose_config(matcher="chains", grid=smooth_grid, chain_reach_m=6000.0).matcher
    assert chains.map_error_mgal == 3.0 and chains.fix == "posterior"
    assert chains.half_size * 0.01 * 111e3 * np.cos(np.deg2rad(30.0)) >= 6000.0


@pytest.mark.long  # cheap, but short_voyages costs ~30 s to build: with its other users
def test_errors_need_the_truth(short_voyages):
    v = jax.tree.map(lambda a: a[0], short_voyages)._replace(truth=None)
    with pytest.raises(ValueError, match=r"voyage\.truth is None"):
        voyage_errors(v, v.ins, jnp.tile(jnp.eye(2), (v.ins.t.shape[0], 1, 1)))
