"""Particle filters: resampling against filterpy, the SIR and Rao–Blackwellised filters
against the exact Kalman filter on a linear map, transformations, flags and bad settings."""

import filterpy.monte_carlo.resampling as fp_resampling
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.stats

from jaxgrav.filters import (
    STATUS_FILTER,
    Step,
    augment,
    effective_sample_size,
    ekf,
    gravity_measurement,
    map_error_state,
    pf,
    rbpf,
    residual_resample,
    run_filter,
    systematic_resample,
    ukf,
)
from jaxgrav.filters.model import Dynamics
from jaxgrav.filters.particles import (
    kernel_bandwidth,
    particle_summary,
    resample_regularised,
    roughen,
    standard_normal,
    weighted_moments,
)
from jaxgrav.scenarios import FilterScenario, initial_state
from jaxgrav.sim.ins import transition

LAT0, LON0 = 24.0, 123.0


def _log_w(seed, n=50):
    w = np.random.default_rng(seed).gamma(0.3, size=n)
    return jnp.log(w / w.sum())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_systematic_resample_equals_filterpy(seed, monkeypatch):
    key = jax.random.PRNGKey(seed)
    log_w = _log_w(seed)
    u = float(jax.random.uniform(key, (), jnp.float64))
    monkeypatch.setattr(fp_resampling, "random", lambda: u)
    expected = fp_resampling.systematic_resample(np.exp(np.asarray(log_w)))
    np.testing.assert_array_equal(np.asarray(systematic_resample(key, log_w)), expected)


def test_standard_normal_is_a_standard_normal():
    """The particles' Box–Muller sampler: Kolmogorov–Smirnov against SciPy's normal, the
    first four moments, an odd count, the dtype, and reproducible for a key."""
    key = jax.random.PRNGKey(7)
    z = np.asarray(jax.jit(standard_normal, static_argnums=(1, 2))(key, (401, 251),
                                                                   jnp.float64))
    assert z.shape == (401, 251) and z.dtype == np.float64
    flat = z.ravel()
    assert scipy.stats.kstest(flat, "norm").pvalue > 0.01
    assert abs(flat.mean()) < 5 / np.sqrt(flat.size)
    assert flat.std() == pytest.approx(1.0, abs=0.01)
    assert scipy.stats.kurtosis(flat, fisher=False) == pytest.approx(3.0, abs=0.05)
    assert np.abs(flat).max() <= np.sqrt(2 * 23 * np.log(2)) + 1e-6
    np.testing.assert_array_equal(np.asarray(standard_normal(key, (401, 251), jnp.float64)), z)
    assert standard_normal(key, (3,), jnp.float32).dtype == jnp.float32


@pytest.mark.long
def test_residual_resample_copies_and_is_unbiased():
    log_w = _log_w(4, 40)
    n = log_w.shape[0]
    nw = n * np.exp(np.asarray(log_w))
    idx = np.asarray(jax.vmap(residual_resample, (0, None))(
        jax.random.split(jax.random.PRNGKey(0), 4000), log_w))
    counts = np.stack([np.bincount(i, minlength=n) for i in idx])
    assert np.all(counts >= np.floor(nw)[None])  # the deterministic copies, every draw
    assert np.all(idx >= 0) and np.all(idx < n)
    se = counts.std(0) / np.sqrt(len(counts)) + 1e-3
    assert np.all(np.abs(counts.mean(0) - nw) < 5 * se)  # E[copies] = N w


def test_systematic_counts_are_floor_or_ceil():
    log_w = _log_w(5, 64)
    nw = 64 * np.exp(np.asarray(log_w))
    for k in jax.random.split(jax.random.PRNGKey(1), 20):
        c = np.bincount(np.asarray(systematic_resample(k, log_w)), minlength=64)
        assert np.all((c >= np.floor(nw) - 1e-9) & (c <= np.ceil(nw) + 1e-9))


def test_effective_sample_size_and_moments():
    n = 10
    flat = jnp.full(n, -jnp.log(n))
    assert float(effective_sample_size(flat)) == pytest.approx(n)
    one = jnp.full(n, -jnp.inf).at[3].set(0.0)
    assert float(effective_sample_size(one)) == pytest.approx(1.0)
    x = np.random.default_rng(0).normal(size=(n, 3))
    w = np.exp(np.asarray(_log_w(7, n)))
    mean, cov = weighted_moments(jnp.log(w), jnp.asarray(x))
    np.testing.assert_allclose(mean, w @ x, rtol=1e-12)
    np.testing.assert_allclose(cov, np.cov(x.T, aweights=w, bias=True), rtol=1e-10)


def test_roughen_keeps_mean_and_covariance_and_spreads_copies():
    cov = jnp.array([[4.0, 1.0], [1.0, 1.0]])
    mean = jnp.array([10.0, -3.0])
    k1, k2 = jax.random.split(jax.random.PRNGKey(0))
    x = mean + jax.random.normal(k1, (40000, 2)) @ jnp.linalg.cholesky(cov).T
    copies = jnp.repeat(x[:20000], 2, axis=0)  # what resampling makes
    out = np.asarray(roughen(k2, copies, mean, cov, 0.5))
    np.testing.assert_allclose(out.mean(0), mean, atol=0.05)
    np.testing.assert_allclose(np.cov(out.T), cov, rtol=0.05, atol=0.03)
    assert np.unique(out[:, 0]).size == out.shape[0]
    assert roughen(k2, copies, mean, cov, 0.0) is copies
    assert kernel_bandwidth(1000, 13) == pytest.approx((4 / 15000) ** (1 / 17))


# --------------------------------------------------------- linear map: the exact answer
def _linear_field(lat, lon):
    """A plane (mGal): 40 mGal per 0.1° north, −25 per 0.1° east — the measurement is linear."""
    return 400.0 * (lat - LAT0) - 250.0 * (lon - LON0)


def _linear_problem(t=60, seed=0):
    scen = FilterScenario()
    x0, p0 = initial_state(scen)
    f, q = transition(scen.ins, LAT0, 10.0)
    dyn = Dynamics(f, q, jnp.asarray(10.0))
    rng = np.random.default_rng(seed)
    lat = LAT0 + 0.0005 * np.arange(t)
    lon = LON0 + 0.0003 * np.arange(t)
    z = _linear_field(lat, lon) + rng.normal(0.0, 1.0, t) + 12.0
    if t > 5:
        z[5] = np.nan  # a missing reading
    steps = Step(jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(z), jnp.full(t, 1.0))
    return dyn, x0, p0, steps


@pytest.mark.parametrize("kind", ["rbpf", "pf"])
@pytest.mark.long
def test_particle_filters_match_the_kalman_filter_on_a_linear_map(kind):
    """With a plane map the EKF is the exact posterior; both particle filters approach it."""
    dyn, x0, p0, steps = _linear_problem()
    _, kf = run_filter(ekf(), _linear_field, dyn, x0, p0, steps)
    filt = rbpf(4000) if kind == "rbpf" else pf(20000, roughening=0.0)
    _, got = jax.jit(lambda k: run_filter(filt, _linear_field, dyn, x0, p0, steps, key=k))(
        jax.random.PRNGKey(1))
    sig = np.asarray(kf.sigma)
    # position and bias means within a fifth of the exact posterior's σ at every step
    for i in (0, 1, 12):
        err = np.abs(np.asarray(got.x[:, i]) - np.asarray(kf.x[:, i])) / sig[:, i]
        assert err.max() < (0.2 if kind == "rbpf" else 0.35), (i, err.max())
        np.testing.assert_allclose(np.asarray(got.sigma[-10:, i]), sig[-10:, i],
                                   rtol=0.15 if kind == "rbpf" else 0.3)
    assert np.asarray(got.status)[5] == STATUS_FILTER["no_reading"]
    assert np.isnan(np.asarray(got.innovation)[5])
    fin = np.isfinite(np.asarray(kf.innovation))
    np.testing.assert_allclose(np.asarray(got.innovation_var)[fin],
                               np.asarray(kf.innovation_var)[fin], rtol=0.25)


@pytest.mark.long
def test_rbpf_shared_covariance_equals_the_kalman_one_on_a_linear_map():
    """The RBPF's Riccati part: with one particle-free direction it is the KF's exactly."""
    dyn, x0, p0, steps = _linear_problem(20)
    kf_final, _ = run_filter(ekf(), _linear_field, dyn, x0, p0, steps)
    st, _ = run_filter(rbpf(4000, ess_threshold=0.0), _linear_field, dyn, x0, p0, steps,
                       key=jax.random.PRNGKey(0))
    # mixture covariance of the linear states = shared P + spread of the means
    x = jnp.concatenate([st.position, st.mean], 1)
    _, cov = weighted_moments(st.log_w, x)
    cov = np.asarray(cov.at[2:, 2:].add(st.p))
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), np.sqrt(np.diag(kf_final.p)), rtol=0.1)


# ------------------------------------------------------------ transformations, settings
def _small(kind, n=64):
    return rbpf(n) if kind == "rbpf" else pf(n)


@pytest.mark.parametrize("kind", ["rbpf", "pf"])
@pytest.mark.long
def test_vmap_equals_loop_and_no_retrace(kind):
    dyn, x0, p0, steps = _linear_problem(15)
    traces = []

    def run(key):
        traces.append(1)
        return run_filter(_small(kind), _linear_field, dyn, x0, p0, steps, key=key)[1].x

    fn = jax.jit(run)
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    loop = np.stack([np.asarray(fn(k)) for k in keys])
    assert len(traces) == 1
    batched = np.asarray(jax.vmap(run)(keys))
    np.testing.assert_allclose(batched, loop, rtol=1e-9, atol=1e-6)
    assert not np.allclose(loop[0], loop[1])  # the key matters
    np.testing.assert_array_equal(np.asarray(fn(keys[0])), loop[0])  # and reproduces


@pytest.mark.long
def test_every_stride_and_map_error_state():
    dyn, x0, p0, steps = _linear_problem(30)
    cfg = map_error_state(2.0, 10e3, 1)
    dyn2, x1, p1, meas = augment(cfg, dyn, x0, p0, 5.0)
    for filt in (rbpf(64, meas), pf(64, meas)):
        _, infos = run_filter(filt, _linear_field, dyn2, x1, p1, steps, every=3,
                              key=jax.random.PRNGKey(2))
        assert infos.x.shape == (30, 14)
        st = np.asarray(infos.status)
        assert np.all(st[0::3] & STATUS_FILTER["no_reading"])  # predicted only
        assert np.all(np.isfinite(np.asarray(infos.x)))


@pytest.mark.long
def test_off_map_particles_skip_the_reading():
    dyn, x0, p0, steps = _linear_problem(5)

    def edge(lat, lon):  # "map" that ends 1 km north of the track start
        return jnp.where(lat < LAT0 + 0.009, _linear_field(lat, lon), jnp.nan)

    for filt in (rbpf(256), pf(256)):
        _, infos = run_filter(filt, edge, dyn, x0, p0, steps, key=jax.random.PRNGKey(0))
        st = np.asarray(infos.status)
        assert np.all((st & STATUS_FILTER["off_map"]) | (st & STATUS_FILTER["no_reading"]))
        assert np.all(np.isfinite(np.asarray(infos.x)))


def _map_edge(lat, lon):
    """A "map" that ends 200 m north of the linear problem's track start (NaN beyond)."""
    return jnp.where(lat < LAT0 + 0.0018, _linear_field(lat, lon), jnp.nan)


def _at_a_map_edge(filt):
    """A particle filter's prior, the first step and the dynamics of the linear problem."""
    dyn, x0, p0, steps = _linear_problem(5)
    return filt.init(x0, p0, jax.random.PRNGKey(3)), jax.tree.map(lambda a: a[0], steps), dyn


@pytest.mark.long
def test_pf_particles_without_a_map_value_take_the_others_mean_likelihood():
    """A map edge through the cloud: the particles beyond it neither gain nor lose weight
    against the rest (Bayes by hand), and the reading is used, flagged off_map (it was
    skipped whenever one particle of the cloud met a missing value)."""
    filt = pf(256, ess_threshold=0.0)  # no resampling: the weights stay comparable
    state, step, dyn = _at_a_map_edge(filt)
    new, info = jax.jit(filt.update, static_argnums=2)(state, step, _map_edge, dyn)
    zs = np.asarray(jax.vmap(lambda x: gravity_measurement(_map_edge, x, step.lat, step.lon))(
        new.particles))
    known = np.isfinite(zs)
    assert 0.2 < known.mean() < 0.8
    w = np.exp(np.asarray(state.log_w))
    lik = np.where(known, np.exp(-0.5 * (float(step.z) - np.where(known, zs, 0.0)) ** 2), 0.0)
    post = w * np.where(known, lik, np.sum(w * lik) / np.sum(w[known]))
    post /= post.sum()
    np.testing.assert_allclose(np.exp(np.asarray(new.log_w)), post, rtol=1e-9, atol=1e-300)
    assert post[~known].sum() == pytest.approx(w[~known].sum(), rel=1e-9)
    assert int(info.status) & STATUS_FILTER["off_map"] and np.isfinite(float(info.innovation))


@pytest.mark.long
def test_rbpf_particles_without_a_map_value_keep_their_mean():
    """The RBPF at a map edge through the cloud: the reading is used (it was skipped
    whenever one particle met a missing value); particles beyond the edge take the others'
    mean likelihood and keep their Kalman mean, the others take the Kalman update, and
    the shared covariance shrinks by the posterior share of those with a map value."""
    filt = rbpf(256, ess_threshold=0.0)  # no resampling: the particles stay comparable
    state, step, dyn = _at_a_map_edge(filt)
    moved, _ = filt.predict(state, step, _map_edge, dyn)  # the same draw as update's
    new, info = jax.jit(filt.update, static_argnums=2)(state, step, _map_edge, dyn)
    np.testing.assert_array_equal(np.asarray(new.position), np.asarray(moved.position))
    x = np.concatenate([np.asarray(moved.position), np.asarray(moved.mean)], 1)
    zs = np.asarray(jax.vmap(
        lambda xi: gravity_measurement(_map_edge, xi, step.lat, step.lon))(x))
    known = np.isfinite(zs)
    assert 0.2 < known.mean() < 0.8
    p = np.asarray(moved.p)
    c = np.zeros(p.shape[0])
    c[12 - 2] = 1.0  # the gravimeter bias, the linear states' only reading row
    s = c @ p @ c + float(step.r)
    resid = float(step.z) - np.where(known, zs, 0.0)
    w = np.exp(np.asarray(moved.log_w))
    lik = np.where(known, np.exp(-0.5 * resid**2 / s), 0.0)
    post = w * np.where(known, lik, np.sum(w * lik) / np.sum(w[known]))
    post /= post.sum()
    np.testing.assert_allclose(np.exp(np.asarray(new.log_w)), post, rtol=1e-9, atol=1e-300)
    gain = p @ c / s
    want = np.asarray(moved.mean) + np.where(known, resid, 0.0)[:, None] * gain
    np.testing.assert_allclose(np.asarray(new.mean), want, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(np.asarray(new.mean)[~known], np.asarray(moved.mean)[~known])
    share = post[known].sum()
    np.testing.assert_allclose(np.asarray(new.p), p - share * s * np.outer(gain, gain),
                               rtol=1e-9, atol=1e-12)
    assert int(info.status) & STATUS_FILTER["off_map"] and np.isfinite(float(info.innovation))


@pytest.mark.long
def test_rbpf_q_pos_adds_a_position_random_walk():
    """rbpf(q_pos=q): with no readings, the particles' position variance grows by q·dt per
    step and axis beyond the error model's (the same draws with and without); q = 0 is
    the old filter; a bad q_pos or a missing step length is a clear error."""
    dyn, x0, p0, steps = _linear_problem(20)
    steps = steps._replace(z=jnp.full_like(steps.z, jnp.nan))
    q = 1e4  # m²/s: 2e6 m² over 20 steps of 10 s, against ~4e6 m² of the prior

    @jax.jit
    def var(q_pos):
        _, info = run_filter(rbpf(4000, q_pos=q_pos), _linear_field, dyn, x0, p0, steps,
                             key=jax.random.PRNGKey(5))
        return info.sigma[:, :2] ** 2

    grown = np.asarray(var(q) - var(0.0))
    want = q * 10.0 * np.arange(1, 21)
    want = np.stack([want, want], 1)
    np.testing.assert_allclose(grown, want, rtol=0.3)  # 4000 particles: sampling noise
    np.testing.assert_allclose(grown[-5:], want[-5:], rtol=0.15)
    for bad in (-1.0, np.inf, np.nan):
        with pytest.raises(ValueError, match=r"q_pos must be a finite number >= 0"):
            rbpf(64, q_pos=bad)
    filt = rbpf(64, q_pos=1.0)
    with pytest.raises(ValueError, match="q_pos needs the step length"):
        filt.predict(filt.init(x0, p0), jax.tree.map(lambda a: a[0], steps), _linear_field,
                     Dynamics(dyn.f, dyn.q))


@pytest.mark.long
def test_bad_settings_are_clear_errors():
    with pytest.raises(ValueError, match="n_particles"):
        pf(1)
    with pytest.raises(ValueError, match="resample"):
        rbpf(10, resample="stratified-ish")
    with pytest.raises(ValueError, match="ess_threshold"):
        pf(10, ess_threshold=1.5)
    with pytest.raises(ValueError, match="roughening"):
        rbpf(10, roughening=1.5)
    with pytest.raises(ValueError, match="MapPlusBias"):
        rbpf(10, lambda field, x, lat, lon: x[0])
    dyn, x0, p0, steps = _linear_problem(3)
    with pytest.raises(ValueError, match="key is for the particle filters"):
        run_filter(ukf(), _linear_field, dyn, x0, p0, steps, key=jax.random.PRNGKey(0))
    _, infos = run_filter(pf(16), _linear_field, dyn, x0, p0,
                          steps._replace(r=jnp.zeros(3)), key=jax.random.PRNGKey(0))
    assert np.all(np.asarray(infos.status)[[0, 2]] & STATUS_FILTER["covariance_failed"])


@pytest.mark.parametrize("degenerate", [False, True])
def test_particles_in_parts_are_the_joined_particles(degenerate):
    # a Rao-Blackwellised filter passes positions and means apart (no joined copy at
    # every step); the summary and the resampling are those of the joined array
    k1, k2, k3 = jax.random.split(jax.random.PRNGKey(7), 3)
    x = jax.random.normal(k1, (64, 5)) * jnp.arange(1.0, 6.0)
    log_w = jax.nn.log_softmax((8.0 if degenerate else 0.1) * jax.random.normal(k2, (64,)))
    extra = jnp.linspace(0.0, 1.0, 5)
    for got, want in zip(particle_summary(log_w, (x[:, :2], x[:, 2:]), extra),
                         particle_summary(log_w, x, extra), strict=True):
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-12, atol=1e-12)
    keys = tuple(jax.random.split(k3))
    (pos, rest), lw = resample_regularised(keys, log_w, (x[:, :2], x[:, 2:]),
                                           systematic_resample, 1.0, 0.5)
    joined, lw_joined = resample_regularised(keys, log_w, x, systematic_resample, 1.0, 0.5)
    assert pos.shape == (64, 2) and rest.shape == (64, 3)
    np.testing.assert_allclose(np.asarray(jnp.concatenate([pos, rest], 1)),
                               np.asarray(joined), rtol=1e-12, atol=1e-12)  # to rounding
    np.testing.assert_array_equal(np.asarray(lw), np.asarray(lw_joined))
    assert bool(jnp.all(lw == -jnp.log(64.0))) == degenerate
