"""The posterior Cramér–Rao bound: the exact Kalman covariance on a linear map, a NumPy
brute-force recursion on paper D's point masses, off-map steps, vmap and grad."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.fields.pointmass import paper_d
from jaxgrav.filters import Dynamics, Step, ekf, map_anomaly, pcrlb, run_filter
from jaxgrav.filters.model import map_at_error
from jaxgrav.scenarios import FilterScenario, filter_scenario, initial_state, run_steps
from jaxgrav.sim.ins import GRAV, transition

LAT0, LON0 = 24.0, 123.0


def _plane(lat, lon):
    return 400.0 * (lat - LAT0) - 250.0 * (lon - LON0)


def _steps(t=40):
    lat = LAT0 + 0.0005 * np.arange(t)
    lon = LON0 + 0.0003 * np.arange(t)
    z = np.full(t, 1.0)
    z[7] = np.nan
    return Step(jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(z), jnp.full(t, 1.0))


def _model():
    scen = FilterScenario()
    _, p0 = initial_state(scen)
    f, q = transition(scen.ins, LAT0, 10.0)
    return Dynamics(f, q, jnp.asarray(10.0)), p0


@pytest.mark.long
def test_bound_is_the_kalman_covariance_on_a_linear_map():
    """H does not depend on the state: the bound is the (exact) KF covariance."""
    dyn, p0 = _model()
    steps = _steps()
    truth = jnp.asarray(np.random.default_rng(0).normal(0, 800, (40, 2)))
    res = pcrlb(_plane, dyn, p0, steps, truth)
    _, kf = run_filter(ekf(), _plane, dyn, jnp.zeros(13), p0, steps)
    np.testing.assert_allclose(res.cov[:, :2, :2], kf.p_pos, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(np.sqrt(np.diagonal(res.cov, axis1=1, axis2=2)), kf.sigma,
                               rtol=1e-9, atol=1e-12)
    assert not np.any(np.asarray(res.off_map))


@pytest.mark.long
def test_bound_equals_a_numpy_recursion_on_the_point_masses():
    """Brute force: H by central differences of the map at the true position, the
    Riccati recursion in NumPy."""
    field = paper_d()
    scen = FilterScenario(dt=10.0, reading_every=1, n_steps=121)
    run = filter_scenario(jax.random.key(3), field, scen)
    dyn, steps = run_steps(run, scen)
    _, p0 = initial_state(scen)
    truth = run.errors[1:, :2]
    res = pcrlb(field, dyn, p0, steps, truth)
    f, q = np.asarray(dyn.f), np.asarray(dyn.q)
    b = np.asarray(p0)
    eps = 1.0  # m
    for k in range(steps.z.shape[0]):
        b = f @ b @ f.T + q
        d = np.asarray(truth[k])
        h = np.zeros(13)
        for i in range(2):
            e = np.zeros(2)
            e[i] = eps
            hp = float(map_at_error(field, jnp.asarray(d + e), steps.lat[k], steps.lon[k]))
            hm = float(map_at_error(field, jnp.asarray(d - e), steps.lat[k], steps.lon[k]))
            h[i] = (hp - hm) / (2 * eps)
        h[GRAV] = 1.0
        bh = b @ h
        b = b - np.outer(bh, bh) / (h @ bh + float(steps.r[k]))
        if k in (0, 30, 119):
            np.testing.assert_allclose(np.asarray(res.cov[k]), b, rtol=1e-5, atol=1e-12)
    # the bound is below the filter's own covariance on the same run, on average
    _, ukf_infos = run_filter(ekf(), field, dyn, jnp.zeros(13), p0, steps)
    assert float(jnp.mean(res.position_rms[60:])) <= float(
        jnp.mean(jnp.sqrt(ukf_infos.p_pos[60:, 0, 0] + ukf_infos.p_pos[60:, 1, 1]))) * 1.05


def test_off_map_and_missing_readings_add_no_information():
    dyn, p0 = _model()
    steps = _steps(12)

    def cliff(lat, lon):  # the map ends 0.003 deg north of the start
        return jnp.where(lat < LAT0 + 0.003, _plane(lat, lon), jnp.nan)

    res = pcrlb(cliff, dyn, p0, steps, jnp.zeros((12, 2)))
    off = np.asarray(res.off_map)
    assert off[-1] and not off[0]
    assert not off[7]  # a missing reading is not "off the map"
    # off the map, and without a reading, the bound is the prediction alone
    b = np.asarray(res.cov)
    f, q = np.asarray(dyn.f), np.asarray(dyn.q)
    np.testing.assert_allclose(b[-1], f @ b[-2] @ f.T + q, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(b[7], f @ b[6] @ f.T + q, rtol=1e-10, atol=1e-14)


@pytest.mark.long
def test_vmap_equals_loop_and_grad_matches_finite_differences():
    dyn, p0 = _model()
    steps = _steps(20)
    truths = jnp.asarray(np.random.default_rng(1).normal(0, 500, (3, 20, 2)))

    def rms_end(truth, r):
        return pcrlb(map_anomaly_field, dyn, p0, steps._replace(r=jnp.full(20, r)),
                     truth).position_rms[-1]

    batched = jax.vmap(rms_end, (0, None))(truths, 1.0)
    loop = jnp.stack([rms_end(t, 1.0) for t in truths])
    np.testing.assert_allclose(batched, loop, rtol=1e-12)
    g = float(jax.grad(rms_end, argnums=1)(truths[0], 1.0))
    fd = float((rms_end(truths[0], 1.0 + 1e-4) - rms_end(truths[0], 1.0 - 1e-4)) / 2e-4)
    assert g == pytest.approx(fd, rel=1e-4)
    assert g > 0  # noisier readings, a weaker bound


def map_anomaly_field(lat, lon):
    """A smooth non-linear field (mGal) for the transformation tests."""
    return 30.0 * jnp.sin(40.0 * (lat - LAT0)) * jnp.cos(30.0 * (lon - LON0)) + map_anomaly(
        _plane, lat, lon)


def test_a_perfect_reading_counts_and_a_negative_variance_is_refused():
    """r = 0 is the most informative reading, not none (the bound equalled the prior's
    there, above what a filter reaches; review of 2026-12-06, helper-30)."""
    dyn, p0 = _model()
    truth = jnp.zeros((40, 2))
    base = _steps()
    prior = pcrlb(_plane, dyn, p0, base._replace(z=jnp.full(40, jnp.nan)), truth)
    tiny = pcrlb(_plane, dyn, p0, base._replace(r=jnp.full(40, 1e-6)), truth)
    perfect = pcrlb(_plane, dyn, p0, base._replace(r=jnp.zeros(40)), truth)
    assert np.all(np.isfinite(np.asarray(perfect.position_rms)))
    assert float(perfect.position_rms[-1]) <= float(tiny.position_rms[-1]) * (1 + 1e-6)
    # a plane observes one direction: that one goes to ~0, the other stays
    assert float(perfect.position_rms[-1]) < 0.75 * float(prior.position_rms[-1])
    np.testing.assert_allclose(np.asarray(perfect.position_rms), np.asarray(
        tiny.position_rms), rtol=1e-3)
    flat = pcrlb(lambda lat, lon: 0.0 * lat, dyn, p0, base._replace(r=jnp.zeros(40)), truth)
    np.testing.assert_allclose(np.asarray(flat.position_rms), np.asarray(prior.position_rms),
                               rtol=1e-12)  # nothing to learn from a flat map, no NaN
    with pytest.raises(ValueError, match=r"steps\.r must be >= 0"):
        pcrlb(_plane, dyn, p0, base._replace(r=jnp.full(40, -1.0)), truth)

