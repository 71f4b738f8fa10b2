"""The loosely coupled loop told its own error exactly: the segment's Eötvös and stretch
errors linear in the INS error state (navigate.loose_match.segment_error_covariance), the
dense matcher weighing its offsets by the filter's prior (DenseConfig.offset_prior_m2), and
the filter moved to that posterior (navigate.error_kf.posterior_update)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrav as jg
from jaxgrav.match.dense import DenseConfig, match_dense
from jaxgrav.match.integrity import fix_quality
from jaxgrav.match.offsets import shifted_tracks
from jaxgrav.navigate import (
    LooseConfig,
    error_kf_tables,
    fix_update,
    navigate_loose,
    voyage_errors,
)
from jaxgrav.navigate.error_kf import posterior_update
from jaxgrav.navigate.loose import corrected_segment
from jaxgrav.navigate.loose_match import segment_error_covariance
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import NAVIGATION_GRADE
from jaxgrav.sim.ins import initial_covariance
from jaxgrav.sim.trajectory import Track

INS = NAVIGATION_GRADE


def _spd(rng, n):
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


def test_posterior_update_is_the_kalman_update_of_the_equivalent_measurement():
    """A posterior of H x found with the filter's own prior, given back by conditioning,
    is the Kalman update by the measurement that would have made it."""
    rng = np.random.default_rng(1)
    p, h = _spd(rng, 13), rng.normal(size=(2, 13))
    x, r, nu = rng.normal(size=13), np.array([[4.0, 1.0], [1.0, 3.0]]), np.array([0.5, -1.0])
    s = h @ p @ h.T
    cov = np.linalg.inv(np.linalg.inv(s) + np.linalg.inv(r))  # posterior of H x
    shift = cov @ np.linalg.solve(r, nu)
    args = (jnp.asarray(a) for a in (x, p, h, shift, cov))
    x_post, p_post, nis = posterior_update(*args, jnp.asarray(True))
    x_kf, p_kf, _ = fix_update(jnp.asarray(x), jnp.asarray(p), jnp.asarray(nu), jnp.asarray(r),
                               jnp.asarray(h), jnp.asarray(True))
    np.testing.assert_allclose(x_post, x_kf, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(p_post, p_kf, rtol=1e-7, atol=1e-9)
    assert float(nis) == pytest.approx(shift @ np.linalg.solve(s, shift), rel=1e-10)
    same = posterior_update(*(jnp.asarray(a) for a in (x, p, h, shift, cov)), jnp.asarray(False))
    np.testing.assert_array_equal(same[0], x)
    np.testing.assert_array_equal(same[1], p)


def test_the_prior_multiplies_the_offset_likelihood():
    """A Gaussian likelihood on a wide lattice times the prior: the product's mean and
    covariance; an unresolved (Laplace) fix is combined with the prior the same way."""
    h, spacing = 30, 100.0
    d = np.arange(-h, h + 1) * spacing
    on, oe = (a.reshape(-1) for a in np.meshgrid(d, d, indexing="ij"))
    lik_cov, mu = np.array([[4e5, 1e5], [1e5, 2e5]]), np.array([300.0, -200.0])
    dev = np.stack([on, oe], -1) - mu
    chi2 = np.einsum("ki,ij,kj->k", dev, np.linalg.inv(lik_cov), dev)
    prior = np.array([[3e5, 0.0], [0.0, 5e5]])
    cfg = DenseConfig(spacing_m=spacing, half_size=h, offset_prior_m2=jnp.asarray(prior))
    quality = jax.jit(fix_quality, static_argnums=1)

    def args(lap):
        return (jnp.asarray(on), jnp.asarray(oe), jnp.asarray(mu), jnp.asarray(lap), 58.0, 58.0,
                jnp.asarray(True), cfg)

    q = quality(jnp.asarray(chi2), 1, *args(lik_cov))
    post = np.linalg.inv(np.linalg.inv(lik_cov) + np.linalg.inv(prior))
    np.testing.assert_allclose(q.covariance_m2, post + spacing**2 / 12 * np.eye(2), rtol=0.02)
    np.testing.assert_allclose([q.mean_north_m, q.mean_east_m],
                               post @ np.linalg.solve(lik_cov, mu), atol=5.0)
    lap = lik_cov / 1e4
    sharp = quality(jnp.asarray(chi2 * 1e4), 1, *args(lap))  # unresolved: Laplace × prior
    assert not bool(sharp.resolved)
    both = np.linalg.inv(np.linalg.inv(lap) + np.linalg.inv(prior))
    np.testing.assert_allclose(sharp.covariance_m2, both, rtol=1e-9)
    flat = quality(jnp.zeros_like(jnp.asarray(chi2)), 1, *args(lik_cov))  # no information
    np.testing.assert_allclose(flat.covariance_m2, prior + spacing**2 / 12 * np.eye(2),
                               rtol=0.02, atol=1e3)


@pytest.mark.long  # three compilations of the dense matcher
def test_the_extra_reading_covariance_is_added_to_the_gls_one(smooth_grid):
    """Zeros change nothing; the fields are traced (no recompilation)."""
    lat, lon = np.full(20, 30.0), np.linspace(129.8, 130.2, 20)
    g = prepare_map(smooth_grid).sample(lat, lon)
    cfg = DenseConfig(map_error_mgal=2.0, score_model="gls", fix="posterior", half_size=5)
    base = match_dense(smooth_grid, lat, lon, g, cfg)
    zero = match_dense(smooth_grid, lat, lon, g, dataclasses.replace(
        cfg, reading_covariance=jnp.zeros((20, 20))))
    np.testing.assert_allclose(zero.covariance_m2, base.covariance_m2, rtol=1e-12)
    before = match_dense._cache_size()
    trend = np.linspace(-1, 1, 20)
    wide = match_dense(smooth_grid, lat, lon, g, dataclasses.replace(
        cfg, reading_covariance=jnp.asarray(25.0 * np.outer(trend, trend)),
        offset_prior_m2=jnp.eye(2) * 1e6))
    match_dense(smooth_grid, lat, lon, g, dataclasses.replace(
        cfg, reading_covariance=jnp.eye(20), offset_prior_m2=jnp.eye(2) * 4e6))
    assert match_dense._cache_size() == before + 1
    assert np.all(np.isfinite(np.asarray(wide.covariance_m2)))
    # a coupling: the candidate offset's expected residual is taken off its residuals
    zero_k = match_dense(smooth_grid, lat, lon, g, dataclasses.replace(
        cfg, reading_coupling=jnp.zeros((20, 2))))
    np.testing.assert_allclose(zero_k.covariance_m2, base.covariance_m2, rtol=1e-12)
    # readings of the track 500 m north, with the trend the coupling says that offset brings
    k = np.stack([np.linspace(-1.0, 1.0, 20), np.zeros(20)], -1) * 4e-3  # mGal per m
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), 500.0, 0.0, 0.0)
    g_k = prepare_map(smooth_grid).sample(t_lat, t_lon) + k[:, 0] * 500.0
    told = match_dense(smooth_grid, lat, lon, g_k, dataclasses.replace(
        cfg, reading_coupling=jnp.asarray(k)))
    assert abs(float(told.offset_north_m) - 500.0) < 50.0
    assert abs(float(told.offset_east_m)) < 50.0


@pytest.mark.long  # the tables and the autodiff compile for ~10 s
def test_the_segment_error_covariance_is_the_eotvos_error_of_the_state_on_a_flat_map():
    """On a flat map only the Eötvös error is left: G P Gᵀ with G the readings' Jacobian
    in the filter's state, by autodiff of the segment the loop builds."""
    n_fix, every, dt = 8, 3, 10.0
    w = n_fix * every
    t = jnp.arange(w + 1) * dt
    lat = 30.0 + jnp.arange(w + 1) * 2e-4
    ins = Track(t, lat, jnp.full(w + 1, 130.0), jnp.full(w + 1, 4.0), jnp.full(w + 1, 3.0))
    flat = jg.Grid.from_arrays(np.linspace(29, 31, 11), np.linspace(129, 131, 11),
                               np.full((11, 11), 7.0), units="mGal")
    cfg = LooseConfig(ins=INS, fix_every=every, n_fixes=n_fix, stride=n_fix)
    tables = error_kf_tables(INS, 30.0, dt, w, w)
    p = jnp.asarray(initial_covariance(INS, 500.0, 0.3))
    x0 = jnp.zeros(13)

    def readings(x):
        return corrected_segment(cfg, tables, ins, jnp.zeros(w + 1), x, w)[2]

    jac = jax.jacfwd(readings)(x0)
    lat_f, lon_f, _, v_e, v_n, _ = corrected_segment(cfg, tables, ins, jnp.zeros(w + 1), x0, w)
    b = tables.backward[:, :4].reshape(n_fix, every, 4, -1).mean(1)
    c, none = segment_error_covariance(prepare_map(flat), lat_f, lon_f, v_e, v_n, b,
                                       tables.h_mean, p)
    want = jac @ p @ jac.T
    np.testing.assert_allclose(c, want, rtol=1e-3, atol=1e-6 * float(jnp.max(want)))
    assert none is None and float(jnp.max(want)) > 1.0  # mGal²: 0.3 m/s is visible
    # given the mean position error H̄ e = −o: the Gaussian conditional of G e
    c_o, k = segment_error_covariance(prepare_map(flat), lat_f, lon_f, v_e, v_n, b,
                                      tables.h_mean, p, conditional=True)
    h = np.asarray(tables.h_mean)
    j, pp = np.asarray(jac), np.asarray(p)
    s = h @ pp @ h.T
    want_k = j @ pp @ h.T @ np.linalg.inv(s)  # jac is −G: the readings move with the estimate
    np.testing.assert_allclose(k, want_k, rtol=1e-3, atol=2e-2 * np.max(np.abs(want_k)))
    np.testing.assert_allclose(c_o, j @ (pp - pp @ h.T @ np.linalg.solve(s, h @ pp)) @ j.T,
                               rtol=1e-3, atol=1e-6 * float(jnp.max(want)))


@pytest.mark.long
@pytest.mark.parametrize(("error", "prior"), [("linear", False), ("linear", True),
                                              ("conditional", True)])
def test_the_loop_told_its_error_exactly_corrects_the_ins(smooth_grid, error, prior):
    """The first voyage of test_loose's short_voyages, the dense matcher's GLS score told
    1 mGal, the segment's error told exactly, with or without the filter's prior."""
    from tests.navigate.test_loose import CONFIG, voyage_preset, voyage_scenario
    from tests.navigate.test_loose import INS as STRATEGIC
    sc = voyage_preset("patrol-12h", ins=STRATEGIC, hours=2.0, region=(29.6, 30.4, 129.6, 130.4),
                       leg_m=20000.0, margin_deg=0.1, pos_error_m=1500.0)
    v = voyage_scenario(jax.random.split(jax.random.key(4), 2)[0], smooth_grid, sc)
    cfg = dataclasses.replace(CONFIG, matcher=dataclasses.replace(
        CONFIG.matcher, score_model="gls", map_error_mgal=1.0), segment_error=error,
        fix_prior=prior, fix_cov_scale=1.0 if prior else 3.0)
    pm = prepare_map(smooth_grid)
    res = navigate_loose(pm, v, cfg)
    err = voyage_errors(v, res.nav, res.cov_north_east)
    assert int(np.sum(np.asarray(res.fix_event) == 0)) >= 5
    assert float(err.nav_m[-1]) < 0.3 * float(err.free_m[-1])
    n = v.ins.t.shape[0]
    assert 0.2 < float(jnp.mean(err.nees[n // 2:])) < 8.0
    before = navigate_loose._cache_size()
    navigate_loose(pm, v, dataclasses.replace(cfg, gate=10.0, fix_cov_scale=2.0))
    assert navigate_loose._cache_size() == before


@pytest.mark.parametrize("change", [{"segment_error": "exact"},
                                    {"fix_prior": True, "matcher": (None, None)}])
def test_the_exact_error_and_the_prior_are_dense_only(change):
    with pytest.raises((ValueError, TypeError)):
        LooseConfig(**change)
