"""Tests of the INS error model (jaxgrav.sim.ins): discretisation, Schuler dynamics, sampling."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

from jaxgrav.constants import MGAL, WGS84_MEAN_RADIUS
from jaxgrav.geodesy import normal_gravity
from jaxgrav.sim import ins

GM_STATES = {"gyro": [7, 8, 9], "accel": [10, 11], "grav": [12]}

# one compiled program each instead of op-by-op dispatch (the expm alone is ~100 ops)
transition = jax.jit(ins.transition)
continuous_model = jax.jit(ins.continuous_model)
simulate_errors = jax.jit(ins.simulate_errors, static_argnames="n_steps")
sample_initial_error = jax.jit(ins.sample_initial_error)


def _model(**kw):
    """A model whose every Gauss–Markov state has a finite correlation time."""
    return ins.INSErrorModel(**{"gravimeter_tau": 300.0, **kw})


@pytest.mark.parametrize("dt", [1.0, 10.0, 600.0])
def test_gauss_markov_variance_is_exact_not_euler(dt):
    m = _model()
    f, q = (np.asarray(a) for a in transition(m, 24.0, dt))
    params = {
        "gyro": (m.gyro_sigma, m.gyro_tau),
        "accel": (m.accel_sigma, m.accel_tau),
        "grav": (m.gravimeter_sigma, m.gravimeter_tau),
    }
    for name, idx in GM_STATES.items():
        sigma, tau = params[name]
        exact = sigma**2 * (1.0 - np.exp(-2.0 * dt / tau))
        np.testing.assert_allclose(np.diag(q)[idx], exact, rtol=1e-9, err_msg=name)
        np.testing.assert_allclose(np.diag(f)[idx], np.exp(-dt / tau), rtol=1e-12, err_msg=name)
        # the states are driven only by their own noise: no cross terms among them
        np.testing.assert_allclose(
            q[np.ix_(idx, idx)], np.diag(np.full(len(idx), exact)), rtol=1e-9, atol=1e-12 * exact
        )
    if dt == 600.0:  # Euler 2σ²Δt/τ = 4σ² for the gravimeter: far from σ²(1 − e⁻⁴)
        euler = 2 * m.gravimeter_sigma**2 * dt / m.gravimeter_tau
        assert abs(q[12, 12] - euler) > 3.0 * q[12, 12]


def test_random_constant_has_no_process_noise():
    m = ins.INSErrorModel(gyro_tau=np.inf, accel_tau=np.inf, gravimeter_tau=np.inf)
    f, q = (np.asarray(a) for a in transition(m, 24.0, 10.0))
    for idx in GM_STATES.values():
        np.testing.assert_array_equal(np.diag(q)[idx], 0.0)
        np.testing.assert_allclose(np.diag(f)[idx], 1.0, rtol=0, atol=1e-13)
    a, qc = continuous_model(m, 24.0)
    assert np.all(np.isfinite(np.asarray(a))) and np.all(np.isfinite(np.asarray(qc)))
    # the default gravimeter bias is a random constant too
    _, q_default = transition(ins.INSErrorModel(), 24.0, 10.0)
    assert float(q_default[12, 12]) == 0.0


def test_schuler_period_and_amplitude():
    """An east velocity error at the equator (no Coriolis/Foucault coupling) is a pure Schuler
    oscillation: d_e(t) = v/ω_s sin(ω_s t), ω_s = √(g/R), period ≈ 84.5 min."""
    dt, v = 10.0, 0.2
    f, _ = transition(ins.INSErrorModel(), 0.0, dt)
    x0 = jnp.zeros(ins.N_STATES).at[3].set(v)

    def step(x, _):
        x = f @ x
        return x, x

    _, xs = jax.lax.scan(step, x0, None, length=3 * 1024)
    d_e = np.concatenate([[0.0], np.asarray(xs[:, 1])])
    t = np.arange(d_e.size) * dt
    # zero crossings, interpolated linearly between steps
    i = np.flatnonzero(np.sign(d_e[1:-1]) != np.sign(d_e[2:])) + 1
    t0 = t[i] - d_e[i] * dt / (d_e[i + 1] - d_e[i])
    period = 2.0 * np.mean(np.diff(t0))
    g = float(normal_gravity(0.0)) * MGAL
    w_s = np.sqrt(g / WGS84_MEAN_RADIUS)
    assert 84.0 * 60 < period < 85.0 * 60
    np.testing.assert_allclose(period, 2 * np.pi / w_s, rtol=1e-3)
    np.testing.assert_allclose(np.abs(d_e).max(), v / w_s, rtol=2e-3)  # ≈ 161 m
    np.testing.assert_allclose(d_e, v / w_s * np.sin(w_s * t), atol=1e-3 * v / w_s)
    np.testing.assert_allclose(np.asarray(xs[:, 0]), 0.0, atol=1e-12)  # north channel untouched


def test_schuler_at_mid_latitude_keeps_the_period():
    """At 24°N the Coriolis coupling modulates the oscillation but the size stays ≈ v/ω_s."""
    dt, v = 10.0, 0.2
    f, _ = (np.asarray(a) for a in transition(ins.INSErrorModel(), 24.0, dt))
    x = np.zeros(ins.N_STATES)
    x[2] = v
    radial = []
    for _ in range(1014):  # ≈ 2 Schuler periods
        x = f @ x
        radial.append(np.hypot(x[0], x[1]))
    w_s = np.sqrt(float(normal_gravity(24.0)) * MGAL / WGS84_MEAN_RADIUS)
    np.testing.assert_allclose(max(radial), v / w_s, rtol=0.02)


@pytest.mark.parametrize("lat", [0.0, 24.0, -60.0])
def test_transition_equals_scipy_expm(lat):
    dt = 10.0
    a, _ = continuous_model(_model(), lat)
    f, _ = transition(_model(), lat, dt)
    ref = scipy.linalg.expm(np.asarray(a) * dt)
    np.testing.assert_allclose(np.asarray(f), ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())


def test_process_noise_symmetric_psd_and_equals_the_integral():
    dt = 60.0
    m = _model()
    a, qc = (np.asarray(v) for v in continuous_model(m, 24.0))
    _, q = transition(m, 24.0, dt)
    q = np.asarray(q)
    np.testing.assert_array_equal(q, q.T)
    d = np.sqrt(np.diag(q))
    corr = q / np.outer(d, d)
    assert np.linalg.eigvalsh(corr).min() > -1e-9
    # Q = ∫₀^Δt e^{As} Q_c e^{Aᵀs} ds, by adaptive quadrature
    ref, _ = scipy.integrate.quad_vec(
        lambda s: scipy.linalg.expm(a * s) @ qc @ scipy.linalg.expm(a.T * s),
        0.0,
        dt,
        epsabs=0.0,
        epsrel=1e-11,
    )
    np.testing.assert_allclose(q / np.outer(d, d), ref / np.outer(d, d), atol=1e-8)


def test_simulate_errors_statistics_match_propagated_covariance():
    dt, n_steps, n_runs = 120.0, 16, 4000
    m = ins.INSErrorModel()
    f, q = transition(m, 24.0, dt)
    p0 = ins.initial_covariance(m, sigma_pos=300.0, sigma_vel=0.1)
    m0 = jnp.zeros(ins.N_STATES).at[0].set(100.0).at[3].set(-0.05).at[12].set(1.0)
    l0 = jnp.linalg.cholesky(p0)

    def one(key):
        k0, k1 = jax.random.split(key)
        x0 = m0 + l0 @ jax.random.normal(k0, (ins.N_STATES,))
        return simulate_errors(k1, f, q, x0, n_steps)

    xs = np.asarray(jax.jit(jax.vmap(one))(jax.random.split(jax.random.key(0), n_runs)))
    assert xs.shape == (n_runs, n_steps, ins.N_STATES)
    f, q = np.asarray(f), np.asarray(q)
    mean, cov = np.asarray(m0), np.asarray(p0)
    for k in range(n_steps):
        if k:
            mean, cov = f @ mean, f @ cov @ f.T + q
        if k in (1, n_steps // 2, n_steps - 1):
            # compare in whitened coordinates, where every element has a known spread
            chol = np.linalg.cholesky(cov)
            white = np.linalg.solve(chol, (xs[:, k] - mean).T).T
            np.testing.assert_allclose(white.mean(0), 0.0, atol=5.0 / np.sqrt(n_runs))
            np.testing.assert_allclose(
                np.cov(white.T), np.eye(ins.N_STATES), atol=6.0 * np.sqrt(2.0 / n_runs)
            )


def test_simulate_errors_without_noise_is_the_transition():
    f, _ = transition(ins.INSErrorModel(), 24.0, 10.0)
    x0 = sample_initial_error(jax.random.key(3), ins.INSErrorModel())
    xs = simulate_errors(jax.random.key(1), f, jnp.zeros_like(f), x0, 5)
    np.testing.assert_array_equal(np.asarray(xs[0]), np.asarray(x0))
    ref = np.asarray(x0)
    for k in range(1, 5):
        ref = np.asarray(f) @ ref
        np.testing.assert_allclose(np.asarray(xs[k]), ref, rtol=1e-12, atol=1e-15)


def test_sample_initial_error_sizes_are_exact_and_directions_uniform():
    m = ins.INSErrorModel()
    keys = jax.random.split(jax.random.key(7), 4000)
    x = np.asarray(jax.vmap(lambda k: sample_initial_error(k, m))(keys))
    np.testing.assert_allclose(np.hypot(x[:, 0], x[:, 1]), 2000.0, rtol=1e-13)
    np.testing.assert_allclose(np.hypot(x[:, 2], x[:, 3]), 0.2, rtol=1e-13)
    other = sample_initial_error(jax.random.key(0), m, pos_error=500.0, vel_error=1.5)
    np.testing.assert_allclose(np.hypot(*np.asarray(other[:2])), 500.0, rtol=1e-13)
    np.testing.assert_allclose(np.hypot(*np.asarray(other[2:4])), 1.5, rtol=1e-13)
    # uniform directions: mean of the unit vector ≈ 0, E[cos²] = 1/2
    unit = x[:, :2] / 2000.0
    np.testing.assert_allclose(unit.mean(0), 0.0, atol=4.0 / np.sqrt(2 * x.shape[0]))
    np.testing.assert_allclose((unit**2).mean(0), 0.5, atol=0.03)
    # position and velocity directions are independent
    assert abs(np.corrcoef(np.arctan2(x[:, 1], x[:, 0]), np.arctan2(x[:, 3], x[:, 2]))[0, 1]) < 0.06
    # the other states are Gaussian with the model's σ
    sd = np.sqrt(np.diag(np.asarray(ins.initial_covariance(m))))[4:]
    np.testing.assert_allclose(x[:, 4:].std(0) / sd, 1.0, atol=0.06)
