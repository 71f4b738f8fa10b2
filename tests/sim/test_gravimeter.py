"""Gravimeter chain of paper D: FIR design and filtering, speed bound, tilt KF, Eötvös."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxgrav as jg
from jaxgrav.constants import KNOT
from jaxgrav.sim import fir as fir_mod
from jaxgrav.sim import gravimeter as gm
from jaxgrav.sim import straight_track


@pytest.fixture(scope="module")
def lp():
    return fir_mod.design_lowpass(0.025, 0.025, 1e-3, 1e-4)


def _freqz_ripples(taps, f_pass, f_stop):
    f, h = scipy.signal.freqz(np.asarray(taps), worN=1 << 15, fs=1.0)
    mag = np.abs(h)
    return np.max(np.abs(mag[f <= f_pass] - 1)), np.max(mag[f >= f_stop])


# ------------------------------------------------------------------ FIR design
@pytest.mark.parametrize(
    ("cutoff", "transition", "d1", "d2"),
    [(0.025, 0.025, 1e-3, 1e-4), (0.05, 0.02, 1e-2, 1e-3), (0.03, 0.015, 1e-2, 1e-5)],
)
def test_design_meets_ripples(cutoff, transition, d1, d2):
    f = fir_mod.design_lowpass(cutoff, transition, d1, d2)
    taps = np.asarray(f.taps)
    assert f.numtaps % 2 == 1 and f.delay == (f.numtaps - 1) // 2
    np.testing.assert_allclose(taps, taps[::-1], atol=1e-15)  # linear phase
    dp, ds = _freqz_ripples(taps, cutoff, cutoff + transition)
    assert dp <= d1 * (1 + 1e-6) and ds <= d2 * (1 + 1e-6)
    # the Herrmann estimate is close (the search only adds a few taps)
    m0 = fir_mod.estimate_numtaps(transition, d1, d2)
    assert m0 % 2 == 1 and m0 <= f.numtaps <= 1.15 * m0


def test_design_in_hz_equals_cycles_per_sample(lp):
    f = fir_mod.design_lowpass(0.25, 0.25, 1e-3, 1e-4, fs=10.0)
    np.testing.assert_allclose(f.taps, lp.taps)


# ------------------------------------------------------------------ FIR filtering
def test_group_delay_compensated_slow_sinusoid_unshifted(lp):
    n = np.arange(1000)
    x = 50.0 * np.sin(2 * np.pi * 0.004 * n + 0.3)
    y = fir_mod.apply_fir(x, lp)
    v = np.asarray(y.valid)
    assert v.sum() == 1000 - 2 * lp.delay
    assert not v[: lp.delay].any() and not v[-lp.delay:].any() and v[lp.delay:-lp.delay].all()
    assert np.all(np.isnan(np.asarray(y.values)[~v]))
    np.testing.assert_allclose(np.asarray(y.values)[v], x[v], atol=50.0 * 1e-3)


def test_filter_equals_scipy_lfilter_and_numpy_convolve(lp):
    x = np.random.default_rng(0).normal(size=700) * 100
    y = fir_mod.apply_fir(x, lp)
    v = np.asarray(y.valid)
    d = lp.delay
    causal = scipy.signal.lfilter(np.asarray(lp.taps), 1.0, x)
    # y[n] = causal[n + d] for the valid n = d … N−1−d
    np.testing.assert_allclose(np.asarray(y.values)[v], causal[2 * d:], rtol=1e-12, atol=1e-10)
    same = np.convolve(x, np.asarray(lp.taps), mode="same")
    np.testing.assert_allclose(np.asarray(y.values)[v], same[v], rtol=1e-12, atol=1e-10)
    # raw taps give the same
    np.testing.assert_array_equal(fir_mod.apply_fir(x, np.asarray(lp.taps)).values, y.values)


def test_vmap_equals_loop_and_jit_no_retrace(lp):
    xs = np.random.default_rng(1).normal(size=(4, 400))
    batched = jax.vmap(fir_mod.apply_fir, in_axes=(0, None))(xs, lp)
    for i in range(4):
        one = fir_mod.apply_fir(xs[i], lp)
        np.testing.assert_array_equal(batched.values[i], one.values)
        np.testing.assert_array_equal(batched.valid[i], one.valid)
    size = fir_mod.apply_fir_compiled._cache_size()
    fir_mod.apply_fir(xs[0] * 3.0, lp)
    assert fir_mod.apply_fir_compiled._cache_size() == size
    f = jax.jit(fir_mod.apply_fir)
    np.testing.assert_array_equal(f(xs[0], lp).values, fir_mod.apply_fir(xs[0], lp).values)


# ------------------------------------------------------------------ speed bound
def test_speed_bound_numbers():
    # 100 m map, swell from 0.05 Hz, factor 2.5: 2 m/s (3.89 kn); and back
    assert float(fir_mod.max_speed(100.0)) == pytest.approx(2.0)
    assert float(fir_mod.max_speed(100.0)) / KNOT == pytest.approx(3.888, abs=1e-3)
    assert float(fir_mod.min_map_spacing(2.0)) == pytest.approx(100.0)
    assert float(fir_mod.signal_frequency(2.0, 100.0)) == pytest.approx(0.05 / 2.5)
    # the 2.5' map (≈4 km) allows 80 m/s; Shannon factor 2 allows more
    assert float(fir_mod.max_speed(4000.0, 0.05)) == pytest.approx(80.0)
    assert float(fir_mod.max_speed(4000.0, 0.05, factor=2.0)) == pytest.approx(100.0)
    v = np.array([1.0, 5.0, 10.0])
    np.testing.assert_allclose(fir_mod.max_speed(fir_mod.min_map_spacing(v, 0.1), 0.1), v)


# ------------------------------------------------------------------ tilt Kalman filter
def _numpy_matrices(p, dt):
    w0 = 2 * np.pi * p.natural_freq_hz
    a = np.array([[0.0, 1.0], [-(w0**2), -2 * p.damping * w0]])
    b = np.array([0.0, w0**2 / p.g])
    m = np.zeros((4, 4))
    m[:2, :2], m[:2, 2], m[2, 3] = a, b, 1.0
    e = scipy.linalg.expm(m * dt)
    return e[:2, :2], e[:2, 2] - e[:2, 3] / dt, e[:2, 3] / dt


def _numpy_kf(p, dt, gyro, acc, sa, sg, th0, r0):
    f, g0, g1 = _numpy_matrices(p, dt)
    q = sa**2 * (np.outer(g0, g0) + np.outer(g1, g1))
    c = np.array([0.0, 1.0])
    x, pp = np.zeros(2), np.diag([th0**2, r0**2])
    xs, ps = [], []
    for k in range(len(gyro)):
        if k > 0:
            x = f @ x + g0 * acc[k - 1] + g1 * acc[k]
            pp = f @ pp @ f.T + q
        s = c @ pp @ c + sg**2
        kk = pp @ c / s
        x = x + kk * (gyro[k] - c @ x)
        pp = (np.eye(2) - np.outer(kk, c)) @ pp
        xs.append(x.copy())
        ps.append(pp.copy())
    return np.array(xs), np.array(ps)


@pytest.fixture(scope="module")
def record():
    tr = straight_track(26.5, 125.0, 5.0, 1.0, 900, 1.0)
    anomaly = 30 * np.sin(np.arange(900) / 150.0)
    cfg = gm.GravimeterConfig()
    return tr, anomaly, cfg, gm.simulate_gravimeter(jax.random.key(3), tr, anomaly, cfg)


def test_platform_discretisation_and_response():
    p = gm.PlatformModel(0.03, 0.6)
    f, g0, g1 = gm.platform_discrete(p, 0.5)
    for got, want in zip((f, g0, g1), _numpy_matrices(p, 0.5), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-15)
    h = gm.platform_response(p, np.array([0.0, 0.03]))
    np.testing.assert_allclose(h, [1.0, 1 / (2j * 0.6)], rtol=1e-12)


@pytest.mark.long
def test_tilt_kf_equals_numpy_loop(record):
    _, _, cfg, rec = record
    gyro, acc = np.asarray(rec.gyro), np.asarray(rec.accel_h)
    st_ = gm.run_tilt_kf(cfg.platform, 1.0, gyro, acc, cfg.accel_noise, cfg.gyro_noise,
                         theta_std=1e-2, rate_std=1e-3)
    xs, ps = _numpy_kf(cfg.platform, 1.0, gyro, acc, cfg.accel_noise, cfg.gyro_noise, 1e-2, 1e-3)
    np.testing.assert_allclose(st_.x, xs, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(st_.P, ps, rtol=1e-6, atol=1e-18)
    assert st_.x.shape == (900, 2) and st_.P.shape == (900, 2, 2)
    # the init/update pair by hand gives the same
    kf = gm.tilt_kalman(cfg.platform, 1.0, cfg.accel_noise, cfg.gyro_noise)
    s = kf.init()
    for k in range(3):
        s = kf.update(s, gyro[k], acc[k])
    np.testing.assert_allclose(s.x, xs[2], rtol=1e-10)


def test_tilt_correction_removes_tilt_bias(record):
    _, _, cfg, rec = record
    st_ = gm.run_tilt_kf(cfg.platform, 1.0, rec.gyro, rec.accel_h, cfg.accel_noise,
                         cfg.gyro_noise)
    theta = np.asarray(st_.x[100:, 0])
    true = np.asarray(rec.truth.theta[100:])
    assert np.sqrt(np.mean((theta - true) ** 2)) < 0.6 * np.std(true)
    resid = gm.tilt_correction(st_.x[:, 0], rec.accel_h) - rec.truth.tilt
    bias = float(np.mean(rec.truth.tilt))
    assert abs(bias) > 1.0  # the default platform has a mGal-level constant tilt term
    assert abs(float(np.mean(resid[100:]))) < 0.2 * abs(bias)


def test_tilt_kf_jit_no_retrace_on_noise_sweep(record):
    _, _, cfg, rec = record
    traces = []

    @jax.jit
    def f(sa, sg):
        traces.append(1)
        return gm.run_tilt_kf(cfg.platform, 1.0, rec.gyro, rec.accel_h, sa, sg).x

    f(0.01, 2e-5)
    f(0.02, 1e-5)
    assert len(traces) == 1


# ------------------------------------------------------------------ simulation
def test_simulated_record_composition(record):
    tr, anomaly, cfg, rec = record
    t = rec.truth
    e = jg.eotvos(tr.lat, tr.v_east, tr.v_north)
    np.testing.assert_allclose(t.eotvos, e, rtol=1e-12)
    noise = rec.reading - (anomaly + t.vertical + t.tilt - t.eotvos + cfg.bias_mgal)
    assert 0.8 < np.std(noise) < 1.2
    assert np.max(np.abs(t.vertical)) <= sum(cfg.vertical_amp) / 1e-5 * (1 + 1e-12)
    assert 5000 < np.std(t.vertical) < 10000  # 5–10 cm/s² of swell
    # tilt formula
    gv = jg.normal_gravity(tr.lat) * 1e-5 + t.vertical * 1e-5
    want = (gv * (np.cos(t.theta) - 1) + t.accel_h * np.sin(t.theta)) / 1e-5
    np.testing.assert_allclose(t.tilt, want, rtol=1e-9, atol=1e-9)
    # different keys, different swell phases
    rec2 = gm.simulate_gravimeter(jax.random.key(4), tr, anomaly, cfg)
    assert not np.allclose(rec2.truth.vertical, t.vertical)


def test_simulation_vmaps_over_keys_and_configs(record):
    tr, anomaly, cfg, _ = record
    keys = jax.random.split(jax.random.key(0), 3)
    sim = jax.jit(jax.vmap(gm.simulate_gravimeter, in_axes=(0, None, None, None)))
    out = sim(keys, tr, anomaly, cfg)
    for i in range(3):
        one = gm.simulate_gravimeter(keys[i], tr, anomaly, cfg)
        np.testing.assert_allclose(out.reading[i], one.reading, rtol=1e-12, atol=1e-7)


# ------------------------------------------------------------------ Eötvös
def test_map_based_eotvos_recovers_constant_offset(lp):
    rng = np.random.default_rng(5)
    n = np.arange(1200)
    map_along = 40 * np.sin(2 * np.pi * n / 700) + 10 * np.cos(2 * np.pi * n / 230)
    e_true = 37.5
    raw = map_along - e_true + 2.0 * rng.normal(size=n.size) + 800 * np.sin(0.7 * n)
    y = fir_mod.apply_fir(raw, lp)
    est = gm.eotvos_from_map(y.values, map_along, y.valid)
    assert float(est) == pytest.approx(e_true, abs=0.2)
    # NaN transients are skipped even without the mask; gradients stay finite
    assert float(gm.eotvos_from_map(y.values, map_along)) == pytest.approx(float(est))
    g = jax.grad(lambda m: gm.eotvos_from_map(m, map_along))(y.values)
    assert np.all(np.isfinite(g))


def test_map_vs_velocity_eotvos_end_to_end(record, lp):
    tr, anomaly, cfg, rec = record
    st_ = gm.run_tilt_kf(cfg.platform, 1.0, rec.gyro, rec.accel_h, cfg.accel_noise,
                         cfg.gyro_noise)
    clean = rec.reading - gm.tilt_correction(st_.x[:, 0], rec.accel_h)
    y = fir_mod.apply_fir(clean, lp)
    e_map = gm.eotvos_from_map(y.values, anomaly, y.valid)
    e_vel = jg.eotvos(tr.lat, tr.v_east, tr.v_north)
    assert float(e_map) == pytest.approx(float(jnp.mean(e_vel)), abs=0.5)


# ------------------------------------------------------------------ bad input
def test_bad_design_inputs():
    with pytest.raises(ValueError, match="cutoff must lie in"):
        fir_mod.design_lowpass(0.6)
    with pytest.raises(ValueError, match="cutoff must lie in"):
        fir_mod.design_lowpass(-0.01)
    with pytest.raises(ValueError, match="transition"):
        fir_mod.design_lowpass(0.04, 0.47)
    with pytest.raises(ValueError, match=r"ripple_pass .*-0.01"):
        fir_mod.design_lowpass(ripple_pass=-0.01)
    with pytest.raises(ValueError, match="ripple_stop"):
        fir_mod.design_lowpass(ripple_stop=0.0)
    with pytest.raises(ValueError, match="odd integer"):
        fir_mod.design_lowpass(numtaps=100)
    with pytest.raises(ValueError, match=r"no 21-tap .*achieved δ1="):
        fir_mod.design_lowpass(numtaps=21)
    with pytest.warns(UserWarning, match="outside paper D"):
        fir_mod.design_lowpass(0.1, 0.05, 1e-2, 1e-3)
    with pytest.raises(ValueError, match="map_spacing must be positive"):
        fir_mod.max_speed(-100.0)
    with pytest.raises(ValueError, match="speed must be positive"):
        fir_mod.min_map_spacing(0.0)


@settings(max_examples=20, deadline=None)
@given(st.one_of(st.floats(max_value=0.0), st.floats(min_value=0.5, max_value=1e6)))
def test_cutoff_outside_nyquist_always_rejected(c):
    with pytest.raises(ValueError, match="cutoff"):
        fir_mod.design_lowpass(c)


def test_bad_record_inputs(lp):
    with pytest.raises(ValueError, match=rf"fewer than the filter's {lp.numtaps} taps"):
        fir_mod.apply_fir(np.zeros(lp.numtaps - 1), lp)
    x = np.zeros(400)
    x[7] = np.nan
    with pytest.raises(ValueError, match=r"record must be finite; found .*nan"):
        fir_mod.apply_fir(x, lp)
    with pytest.raises(ValueError, match="1-D record"):
        fir_mod.apply_fir(np.zeros((2, 400)), lp)
    with pytest.raises(ValueError, match="odd length"):
        fir_mod.apply_fir(np.zeros(400), np.ones(4) / 4)


def test_bad_simulation_inputs(record):
    tr, anomaly, cfg, _ = record
    with pytest.raises(ValueError, match="one value per track fix"):
        gm.simulate_gravimeter(jax.random.key(0), tr, anomaly[:-1], cfg)
    bad = anomaly.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="anomaly must be finite"):
        gm.simulate_gravimeter(jax.random.key(0), tr, bad, cfg)
    with pytest.raises(ValueError, match=r"config.vertical_freq .* Nyquist"):
        gm.simulate_gravimeter(jax.random.key(0), tr, anomaly,
                               gm.GravimeterConfig(vertical_freq=(0.1, 0.2, 0.6)))
    t = np.asarray(tr.t).copy()
    t[5] += 0.5
    with pytest.raises(ValueError, match="uniformly increasing"):
        gm.simulate_gravimeter(jax.random.key(0), tr._replace(t=t), anomaly, cfg)
    with pytest.raises(ValueError, match="gyro must be finite"):
        gm.run_tilt_kf(cfg.platform, 1.0, np.full(5, np.nan), np.zeros(5), 0.01, 1e-5)
    with pytest.raises(ValueError, match="equal length"):
        gm.eotvos_from_map(np.zeros(5), np.zeros(4))
