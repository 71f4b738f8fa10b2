"""Tests of the paper D filters (jaxgrav.filters): UKF, EKF, Gaussian sum, point-mass filter.

References: filterpy's UnscentedKalmanFilter (same sigma points), a NumPy linear Kalman
filter, central finite differences and a brute-force NumPy Bayes grid. The runs are
built here in NumPy (straight tracks over paper D's masses, the INS error propagated
with F, Q from the library's continuous model by SciPy's Van Loan) so that the module
compiles few programs.
"""

import os
import subprocess
import sys

import jax
import jax.extend
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from jaxgrav import filters as fl
from jaxgrav._linalg import modified_cholesky
from jaxgrav.constants import DEG
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.scenarios.paper_d import MASS_LON
from jaxgrav.sim import ins

FLAGS = fl.STATUS_FILTER
DT = 10.0
N_STEPS = 60
LAT_REF = 24.27
FIELD = paper_d()
MODEL = ins.INSErrorModel()

# module-level filters: a Filter is a pair of closures, the static argument of the jits below
UKF = fl.ukf()
EKF = fl.ekf()
PMF_CELL, PMF_Q = 400.0, 400.0  # v = q dt / cell² = 0.025 per 10 s
PMF = fl.pmf(n_cells=15, cell_m=PMF_CELL, q_pos=PMF_Q)

_TRACES = []


def _run_one(filt, field, dynamics, x0, p0, steps):
    _TRACES.append(filt)
    return fl.run_filter(filt, field, dynamics, x0, p0, steps)


# Compiling dominates this module's time: the tests share these few programs (same
# static filter, same argument types), and loops of single steps reuse `update`.
run_one = jax.jit(_run_one, static_argnums=0)
run_batch = jax.jit(
    jax.vmap(fl.run_filter, in_axes=(None, None, None, 0, None, 0)), static_argnums=0
)
run_every = jax.jit(fl.run_filter, static_argnums=(0, 6))
update = jax.jit(
    lambda filt, state, step, field, dyn: filt.update(state, step, field, dyn), static_argnums=0
)
init = jax.jit(lambda filt, x0, p0: filt.init(x0, p0), static_argnums=0)
measure = jax.jit(fl.gravity_measurement)


# --------------------------------------------------------------------------- problem


def _radii(lat):
    a, e2 = 6378137.0, 6.69437999014e-3
    s2 = np.sin(lat * DEG) ** 2
    return a * (1 - e2) / (1 - e2 * s2) ** 1.5, a / np.sqrt(1 - e2 * s2)


def _ins_position(lat, lon, d_n, d_e):
    """Shift a position by a north/east error (m), as the measurement model does in reverse."""
    m, n = _radii(lat)
    return lat + d_n / m / DEG, lon + d_e / (n * np.cos(lat * DEG)) / DEG


@pytest.fixture(scope="module")
def dynamics():
    """F, Q by Van Loan in SciPy (test_ins checks ins.transition against the same)."""
    a, qc = (np.asarray(m) for m in ins.continuous_model(MODEL, LAT_REF))
    n = a.shape[0]
    e = scipy.linalg.expm(np.block([[-a, qc], [np.zeros((n, n)), a.T]]) * DT)
    f = e[n:, n:].T
    q = f @ e[:n, n:]
    return fl.Dynamics(jnp.asarray(f), jnp.asarray(0.5 * (q + q.T)))


@pytest.fixture(scope="module")
def prior():
    p0 = ins.initial_covariance(MODEL, 2000.0 / np.sqrt(2.0), 0.2 / np.sqrt(2.0))
    return jnp.zeros(ins.N_STATES), p0


def _make_runs(dynamics, n_runs, seed, n_steps=N_STEPS, speed=20.0):
    """Straight eastward tracks across the mass line; a reading every other step (NaN between).

    Returns the filter inputs :class:`Step` with leading axes ``(n_runs, n_steps)``
    and the true INS errors ``(n_runs, n_steps + 1, 13)``.
    """
    rng = np.random.default_rng(seed)
    f, q = np.asarray(dynamics.f), np.asarray(dynamics.q)
    w, v = np.linalg.eigh(q)
    root = v * np.sqrt(np.clip(w, 0.0, None))
    lat = rng.uniform(24.15, 24.40, n_runs)[:, None] + np.zeros(n_steps + 1)
    east = speed * DT * np.arange(n_steps + 1)
    lon = MASS_LON - 0.06 + east / (111320.0 * np.cos(lat * DEG))
    err = np.zeros((n_runs, n_steps + 1, ins.N_STATES))
    a_pos, a_vel = rng.uniform(0, 2 * np.pi, (2, n_runs))
    err[:, 0, 0], err[:, 0, 1] = 2000.0 * np.cos(a_pos), 2000.0 * np.sin(a_pos)
    err[:, 0, 2], err[:, 0, 3] = 0.2 * np.cos(a_vel), 0.2 * np.sin(a_vel)
    err[:, 0, 12] = 1.0
    for k in range(n_steps):
        err[:, k + 1] = err[:, k] @ f.T + rng.standard_normal((n_runs, ins.N_STATES)) @ root.T
    ins_lat, ins_lon = _ins_position(lat, lon, err[..., 0], err[..., 1])
    z = np.asarray(fl.map_anomaly(FIELD, lat, lon)) + err[..., 12]
    z = z + rng.standard_normal(z.shape)
    z[:, 1::2] = np.nan
    steps = fl.Step(
        *(jnp.asarray(a[:, 1:]) for a in (ins_lat, ins_lon, z)), jnp.ones((n_runs, n_steps))
    )
    return steps, err


@pytest.fixture(scope="module")
def runs(dynamics):
    return _make_runs(dynamics, 3, seed=0)


def _one(steps, i):
    return jax.tree.map(lambda a, i=i: a[i], steps)


# --------------------------------------------------------------------------- references


def _filterpy_ukf(dynamics, x0, p0, steps, hx, alpha=0.5, beta=2.0, kappa=0.0):
    f, q = np.asarray(dynamics.f), np.asarray(dynamics.q)
    n = f.shape[0]
    points = MerweScaledSigmaPoints(n, alpha=alpha, beta=beta, kappa=kappa)
    u = UnscentedKalmanFilter(n, 1, DT, hx=hx, fx=lambda x, dt: f @ x, points=points)
    u.x, u.P, u.Q = np.array(x0, dtype=float), np.array(p0, dtype=float), q
    xs, ps = [], []
    for k in range(steps.z.shape[0]):
        u.predict()
        z = float(steps.z[k])
        if np.isfinite(z):
            u.update(
                np.array([z]),
                R=np.array([[float(steps.r[k])]]),
                lat=float(steps.lat[k]),
                lon=float(steps.lon[k]),
            )
        xs.append(u.x.copy())
        ps.append(u.P.copy())
    return np.array(xs), np.array(ps)


def _numpy_kalman(dynamics, x0, p0, steps, a, c):
    """Textbook linear Kalman filter for ``z = a·x + c + v``."""
    f, q = np.asarray(dynamics.f), np.asarray(dynamics.q)
    x, p = np.array(x0, dtype=float), np.array(p0, dtype=float)
    xs, ps = [], []
    for k in range(steps.z.shape[0]):
        x, p = f @ x, f @ p @ f.T + q
        z = float(steps.z[k])
        if np.isfinite(z):
            s = a @ p @ a + float(steps.r[k])
            gain = p @ a / s
            x = x + gain * (z - a @ x - c)
            p = p - s * np.outer(gain, gain)
        xs.append(x)
        ps.append(p)
    return np.array(xs), np.array(ps)


def _normalised(x, p, x_ref, p_ref):
    """Max difference of states in σ units and of covariances in correlation units."""
    sd = np.sqrt(np.einsum("...ii->...i", p_ref))
    dx = np.abs(x - x_ref) / sd
    dp = np.abs(p - p_ref) / (sd[..., :, None] * sd[..., None, :])
    return dx.max(), dp.max()


# --------------------------------------------------------------------------- UKF / EKF


def test_sigma_weights_sum_to_one_and_match_filterpy():
    for n, alpha, beta, kappa in [
        (13, 0.5, 2.0, 0.0),
        (13, 1e-3, 2.0, 0.0),
        (5, 0.3, 0.0, 3 - 5),
        (2, 1.0, 2.0, 1.0),
    ]:
        scale, wm, wc = fl.sigma_weights(n, alpha, beta, kappa)
        ref = MerweScaledSigmaPoints(n, alpha=alpha, beta=beta, kappa=kappa)
        np.testing.assert_allclose(float(jnp.sum(wm)), 1.0, rtol=1e-9)
        np.testing.assert_allclose(float(jnp.sum(wc)), 2.0 - alpha**2 + beta, rtol=1e-9)
        np.testing.assert_allclose(np.asarray(wm), ref.Wm, rtol=1e-12)
        np.testing.assert_allclose(np.asarray(wc), ref.Wc, rtol=1e-12)
        np.testing.assert_allclose(float(scale), alpha**2 * (n + kappa), rtol=1e-9)


@pytest.mark.long
def test_ukf_equals_filterpy_on_the_gravity_measurement(dynamics, prior, runs):
    steps = _one(runs[0], 0)
    x0, p0 = prior
    final, infos = run_one(UKF, FIELD, dynamics, x0, p0, steps)
    xs, ps = _filterpy_ukf(
        dynamics,
        x0,
        p0,
        steps,
        lambda x, lat, lon: np.atleast_1d(np.asarray(measure(FIELD, x, lat, lon))),
    )
    assert np.all(
        np.asarray(infos.status) == np.where(np.isfinite(steps.z), 0, FLAGS["no_reading"])
    )
    dx = np.abs(np.asarray(infos.x) - xs) / np.sqrt(np.einsum("kii->ki", ps))
    assert dx.max() < 1e-8, dx.max()
    np.testing.assert_allclose(
        np.asarray(infos.sigma), np.sqrt(np.einsum("kii->ki", ps)), rtol=1e-8
    )
    np.testing.assert_allclose(np.asarray(infos.p_pos), ps[:, :2, :2], rtol=1e-8, atol=1e-6)
    _, dp_final = _normalised(np.asarray(final.x), np.asarray(final.p), xs[-1], ps[-1])
    assert dp_final < 1e-8
    # the readings did move the filter: a nonlinear problem, not a trivial one
    assert np.sqrt(ps[-1, 0, 0]) < 0.5 * np.sqrt(float(p0[0, 0]))


H_LIN = np.zeros(ins.N_STATES)
H_LIN[[2, 3]] = [0.4, 12.6]  # an Eötvös-like velocity-error part (mGal per m/s)


def _with_h_lin(steps):
    """The steps with a known linear part that changes from step to step."""
    scale = 1.0 + 0.1 * np.sin(np.arange(steps.z.shape[0]))
    return steps._replace(h_lin=jnp.asarray(scale[:, None] * H_LIN))


@pytest.mark.long
def test_ukf_linear_part_equals_filterpy_with_it_in_hx(dynamics, prior, runs):
    """Step.h_lin: the structured UKF adds h_lin·x at every sigma point, as filterpy's
    full 27-point UKF does with it written into hx."""
    steps = _with_h_lin(_one(runs[0], 0))
    x0, p0 = prior
    final, infos = run_one(UKF, FIELD, dynamics, x0, p0, steps)
    h_lin = np.asarray(steps.h_lin)

    class Hx:  # filterpy passes the update's keyword arguments to hx
        def __call__(self, x, lat, lon, k):
            return np.atleast_1d(np.asarray(measure(FIELD, x, lat, lon)) + h_lin[k] @ x)

    hx = Hx()
    f, q = np.asarray(dynamics.f), np.asarray(dynamics.q)
    points = MerweScaledSigmaPoints(ins.N_STATES, alpha=0.5, beta=2.0, kappa=0.0)
    u = UnscentedKalmanFilter(ins.N_STATES, 1, DT, hx=hx, fx=lambda x, dt: f @ x, points=points)
    u.x, u.P, u.Q = np.array(x0, dtype=float), np.array(p0, dtype=float), q
    xs, ps = [], []
    for k in range(steps.z.shape[0]):
        u.predict()
        if np.isfinite(float(steps.z[k])):
            u.update(np.array([float(steps.z[k])]), R=np.array([[1.0]]),
                     lat=float(steps.lat[k]), lon=float(steps.lon[k]), k=k)
        xs.append(u.x.copy())
        ps.append(u.P.copy())
    xs, ps = np.array(xs), np.array(ps)
    sd = np.sqrt(np.einsum("kii->ki", ps))
    assert (np.abs(np.asarray(infos.x) - xs) / sd).max() < 1e-8
    np.testing.assert_allclose(np.asarray(infos.sigma), sd, rtol=1e-8)
    # the linear part made a difference: the velocity error is now observed
    _, plain = run_one(UKF, FIELD, dynamics, x0, p0, steps._replace(h_lin=None))
    assert float(infos.sigma[-1, 3]) < 0.8 * float(plain.sigma[-1, 3])
    assert np.all(np.isfinite(np.asarray(final.p)))


def _linear_part_generic(field, x, lat, lon):
    return fl.gravity_measurement(field, x, lat, lon) + jnp.asarray(H_LIN, x.dtype) @ x


EKF_H_LIN = fl.ekf(_linear_part_generic)


@pytest.mark.long
def test_ekf_linear_part_equals_the_measurement_written_with_it(dynamics, prior, runs):
    steps = _one(runs[0], 2)
    x0, p0 = prior
    with_part = steps._replace(h_lin=jnp.broadcast_to(jnp.asarray(H_LIN), (N_STEPS, 13)))
    _, infos = run_one(EKF, FIELD, dynamics, x0, p0, with_part)
    _, ref = run_one(EKF_H_LIN, FIELD, dynamics, x0, p0, steps)
    np.testing.assert_allclose(np.asarray(infos.x), np.asarray(ref.x), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.asarray(infos.sigma), np.asarray(ref.sigma), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(infos.innovation_var),
                               np.asarray(ref.innovation_var), rtol=1e-9)


UKF_CURVED = fl.ukf(curvature_count=40.0)


@pytest.mark.long
def test_ukf_curvature_count_adds_the_map_second_order_variance(dynamics, prior, runs):
    """curvature_count · ½ tr((∇²h P)²), with the Hessian by central differences in NumPy,
    is what the curvature term adds to the reading variance."""
    x0, p0 = prior
    step = _one(_one(runs[0], 0), 0)
    state = init(UKF, x0, p0)
    pred = fl.predict(state, dynamics.f, dynamics.q)
    x, p = np.asarray(pred.x), np.asarray(pred.p)

    def g(d):
        return float(measure(FIELD, jnp.asarray(np.concatenate([d, x[2:]])), step.lat,
                             step.lon)) - x[12]

    h = 5.0  # m
    hess = np.empty((2, 2))
    for i in range(2):
        for j in range(2):
            ei, ej = np.eye(2)[i] * h, np.eye(2)[j] * h
            hess[i, j] = (g(x[:2] + ei + ej) - g(x[:2] + ei - ej) - g(x[:2] - ei + ej)
                          + g(x[:2] - ei - ej)) / (4 * h * h)
    hp = hess @ p[:2, :2]
    extra = 40.0 * 0.5 * np.trace(hp @ hp)
    assert extra > 0.05 * float(step.r)  # the prior is wide: the term matters here
    _, curved = update(UKF_CURVED, state, step, FIELD, dynamics)
    _, inflated = update(UKF, state, step._replace(r=step.r + extra), FIELD, dynamics)
    assert float(curved.innovation_var) == pytest.approx(float(inflated.innovation_var),
                                                         rel=1e-5)
    np.testing.assert_allclose(np.asarray(curved.x), np.asarray(inflated.x), rtol=1e-5,
                               atol=1e-6)


@pytest.mark.long
def test_pmf_takes_a_linear_part(dynamics, prior, runs):
    """The point-mass filter with Step.h_lin (its update against NumPy: test_pmf.py): a
    reading's linear part moves the velocity error beyond its regression on the grid."""
    steps = _with_h_lin(_one(runs[0], 0))
    x0, p0 = prior
    state = PMF.init(x0, p0)
    dyn = PMF.dynamics(LAT_REF, DT)
    step = _one(steps, int(np.flatnonzero(np.isfinite(np.asarray(steps.z)))[0]))
    with_part, info = PMF.update(state, step, FIELD, dyn)
    without, _ = PMF.update(state, step._replace(h_lin=None), FIELD, dyn)
    assert np.all(np.isfinite(np.asarray(info.x)))
    assert np.abs(np.asarray(with_part.x)[2:4] - np.asarray(without.x)[2:4]).max() > 1e-4


LIN_A = np.zeros(ins.N_STATES)
LIN_A[[0, 1, 2, 12]] = [2e-3, -1.5e-3, 0.3, 1.0]
LIN_C = 5.0


def _linear_h(field, x, lat, lon):
    return jnp.asarray(LIN_A, x.dtype) @ x + LIN_C


UKF_LIN = fl.ukf(_linear_h)
EKF_LIN = fl.ekf(_linear_h)


@pytest.mark.parametrize("which", ["ukf", "ekf"])
def test_linear_measurement_equals_the_kalman_filter(which, dynamics, prior, runs):
    filt = UKF_LIN if which == "ukf" else EKF_LIN
    x0, p0 = prior
    steps = _one(runs[0], 1)
    _, err = runs
    z = LIN_A @ err[1, 1:].T + LIN_C + np.random.default_rng(1).standard_normal(N_STEPS)
    steps = steps._replace(z=jnp.where(jnp.isfinite(steps.z), z, jnp.nan))
    _, infos = run_one(filt, None, dynamics, x0, p0, steps)
    xs, ps = _numpy_kalman(dynamics, x0, p0, steps, LIN_A, LIN_C)
    sd = np.sqrt(np.einsum("kii->ki", ps))
    np.testing.assert_allclose(np.asarray(infos.x) / sd, xs / sd, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(
        np.asarray(infos.sigma), np.sqrt(np.einsum("kii->ki", ps)), rtol=1e-8
    )
    np.testing.assert_allclose(np.asarray(infos.p_pos), ps[:, :2, :2], rtol=1e-8, atol=1e-6)
    assert np.sqrt(ps[-1, 0, 0]) < 0.8 * np.sqrt(float(p0[0, 0]))


@pytest.mark.parametrize("map_kind", ["pointmass", "grid"])
def test_ekf_jacobian_equals_finite_differences(map_kind, smooth_grid):
    if map_kind == "pointmass":
        field, lat, lon = FIELD, 24.2, MASS_LON + 0.03
    else:
        field, lat, lon = smooth_grid, 30.05, 130.1
    x = jnp.zeros(ins.N_STATES).at[0].set(700.0).at[1].set(-400.0).at[12].set(1.0)
    jac = np.asarray(jax.jit(jax.jacfwd(fl.gravity_measurement, argnums=1))(field, x, lat, lon))
    h = measure
    eps = 1.0  # m (and mGal for the bias)
    fd = np.zeros(ins.N_STATES)
    for i in range(ins.N_STATES):
        e = jnp.zeros(ins.N_STATES).at[i].set(eps)
        fd[i] = (float(h(field, x + e, lat, lon)) - float(h(field, x - e, lat, lon))) / (2 * eps)
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-9)
    assert np.all(jac[2:12] == 0.0) and jac[12] == 1.0 and np.all(jac[:2] != 0.0)


@pytest.fixture(scope="module")
def still():
    """F = I, Q = 0: the predicted P is exactly the P a test gives, and "unchanged" is exact."""
    n = ins.N_STATES
    return fl.Dynamics(jnp.eye(n), jnp.zeros((n, n)))


def _recover_h(state, new, info):
    """The H an update used, from its gain: K = P Hᵀ / S and x⁺ − x = K ν  ⇒  H = S P⁻¹ K."""
    k = (np.asarray(new.x) - np.asarray(state.x)) / float(info.innovation)
    return float(info.innovation_var) * np.linalg.solve(np.asarray(state.p), k)


def _correlated_p(p0, seed=7):
    """p0's variances with random correlations (a well-conditioned correlation matrix)."""
    a = np.random.default_rng(seed).standard_normal((ins.N_STATES, ins.N_STATES))
    c = a @ a.T + ins.N_STATES * np.eye(ins.N_STATES)
    d = np.sqrt(np.diag(np.asarray(p0)) / np.diag(c))
    return jnp.asarray(c * np.outer(d, d))


@pytest.mark.parametrize("map_kind", ["pointmass", "grid"])
@pytest.mark.long
def test_ekf_update_uses_the_finite_difference_jacobian(map_kind, prior, still, smooth_grid):
    """ekf().update's H (recovered from its gain) is the central-difference H at the mean."""
    if map_kind == "pointmass":
        field, lat, lon = FIELD, 24.2, MASS_LON + 0.03
    else:
        field, lat, lon = smooth_grid, 30.05, 130.1
    _, p0 = prior
    x = jnp.zeros(ins.N_STATES).at[0].set(700.0).at[1].set(-400.0).at[12].set(1.0)
    state = fl.FilterState(x, _correlated_p(p0))
    z = float(measure(field, x, lat, lon)) + 3.0
    new, info = update(EKF, state, _one_step(z, lat, lon, r=2.0), field, still)
    assert int(info.status) == 0
    np.testing.assert_allclose(float(info.innovation), 3.0, rtol=1e-12)
    eps = 1.0  # m (and mGal for the bias)
    fd = np.array([(float(measure(field, x + e, lat, lon)) - float(measure(field, x - e, lat, lon)))
                   / (2 * eps) for e in eps * np.eye(ins.N_STATES)])
    # in mGal per 1-σ of each state (the states span metres to rad/s)
    p = np.asarray(state.p)
    sd = np.sqrt(np.diag(p))
    h = _recover_h(state, new, info)
    np.testing.assert_allclose(h * sd, fd * sd, rtol=1e-6, atol=1e-9 * np.abs(fd * sd).max())
    assert np.all(fd[:2] != 0.0) and fd[12] == pytest.approx(1.0)
    # ... and the same H in S and in the Joseph covariance update
    np.testing.assert_allclose(float(info.innovation_var), fd @ p @ fd + 2.0, rtol=1e-6)
    k = p @ fd / (fd @ p @ fd + 2.0)
    ikh = np.eye(ins.N_STATES) - np.outer(k, fd)
    np.testing.assert_allclose(np.asarray(new.p) / np.outer(sd, sd),
                               (ikh @ p @ ikh.T + 2.0 * np.outer(k, k)) / np.outer(sd, sd),
                               atol=1e-6)


@pytest.mark.parametrize("filt", [UKF, EKF], ids=["ukf", "ekf"])
def test_indefinite_covariance_fails_and_leaves_the_state(filt, prior, still):
    """P with positive variances but indefinite (|corr| > 1): covariance_failed, no update."""
    _, p0 = prior
    p = np.asarray(p0).copy()
    p[0, 1] = p[1, 0] = 1.5 * np.sqrt(p[0, 0] * p[1, 1])
    assert np.linalg.eigvalsh(p).min() < 0 and np.all(np.diag(p) > 0)
    state = fl.FilterState(jnp.zeros(ins.N_STATES).at[0].set(300.0).at[12].set(0.5),
                           jnp.asarray(p))
    z = float(measure(FIELD, state.x, 24.25, MASS_LON + 0.02)) + 3.0
    new, info = update(filt, state, _one_step(z), FIELD, still)
    assert int(info.status) == FLAGS["covariance_failed"] | FLAGS["covariance_repaired"]
    np.testing.assert_array_equal(np.asarray(new.x), np.asarray(state.x))
    np.testing.assert_array_equal(np.asarray(new.p), p)


@pytest.mark.parametrize("filt", [UKF_LIN, EKF_LIN], ids=["ukf", "ekf"])
def test_semidefinite_covariance_is_repaired_and_updates(filt, prior, still):
    """A zero-variance state: covariance_repaired only, and the textbook Kalman update."""
    _, p0 = prior
    p = np.asarray(p0).copy()
    p[2, :] = p[:, 2] = 0.0  # north velocity known exactly (the measurement depends on it)
    x = np.zeros(ins.N_STATES)
    x[[0, 2, 12]] = [300.0, 0.05, 0.5]
    state = fl.FilterState(jnp.asarray(x), jnp.asarray(p))
    z, r = LIN_A @ x + LIN_C + 4.0, 1.0
    new, info = update(filt, state, _one_step(z, r=r), None, still)
    assert int(info.status) == FLAGS["covariance_repaired"]
    s = LIN_A @ p @ LIN_A + r
    gain = p @ LIN_A / s
    sd = np.sqrt(np.diag(np.asarray(p0)))
    np.testing.assert_allclose((np.asarray(new.x) - (x + 4.0 * gain)) / sd, 0.0, atol=1e-9)
    np.testing.assert_allclose((np.asarray(new.p) - (p - s * np.outer(gain, gain)))
                               / np.outer(sd, sd), 0.0, atol=1e-9)
    assert abs(float(new.x[2]) - x[2]) < 1e-12 and np.abs(np.asarray(new.p)[2]).max() < 1e-12


@pytest.mark.parametrize("filt", [UKF_LIN, EKF_LIN], ids=["ukf", "ekf"])
def test_negative_innovation_variance_fails_explicitly(filt, prior, still):
    """S = H P Hᵀ + R < 0 (here R < 0): covariance_failed (not gated), no update, no NaN."""
    _, p0 = prior
    x = jnp.zeros(ins.N_STATES).at[0].set(300.0)
    state = fl.FilterState(x, p0)
    hph = LIN_A @ np.asarray(p0) @ LIN_A
    z = float(LIN_A @ np.asarray(x)) + LIN_C + 4.0
    new, info = update(filt, state, _one_step(z, r=-2.0 * hph), None, still)
    assert int(info.status) == FLAGS["covariance_failed"]
    np.testing.assert_allclose(float(info.innovation_var), -hph, rtol=1e-9)
    np.testing.assert_array_equal(np.asarray(new.x), np.asarray(x))
    np.testing.assert_array_equal(np.asarray(new.p), np.asarray(p0))


def _assert_same_state(state, ref):
    """Equal to rounding (the jitted update may fuse the prediction's arithmetic)."""
    dx, dp = _normalised(
        np.asarray(state.x), np.asarray(state.p), np.asarray(ref.x), np.asarray(ref.p)
    )
    assert dx < 1e-13 and dp < 1e-13, (dx, dp)


def _one_step(z, lat=24.25, lon=MASS_LON + 0.02, r=1.0):
    """One Step of float64 scalars (the types of a slice of a run: no recompiles)."""
    return fl.Step(*(jnp.asarray(v, dtype=jnp.float64) for v in (lat, lon, z, r)))


@pytest.mark.parametrize("filt", [UKF, EKF], ids=["ukf", "ekf"])
def test_nan_reading_leaves_the_prediction(filt, dynamics, prior):
    x0, p0 = prior
    state = fl.FilterState(x0.at[0].set(300.0).at[3].set(0.1), p0)
    new, info = update(filt, state, _one_step(jnp.nan), FIELD, dynamics)
    pred = fl.predict(state, dynamics.f, dynamics.q)
    _assert_same_state(new, pred)
    assert int(info.status) == FLAGS["no_reading"]
    assert np.isnan(float(info.innovation))
    # ... and a reading does change it
    z = float(fl.gravity_measurement(FIELD, pred.x, 24.25, MASS_LON + 0.02)) + 3.0
    moved, info = update(filt, state, _one_step(z), FIELD, dynamics)
    assert int(info.status) == 0 and not np.allclose(np.asarray(moved.x), np.asarray(pred.x))


@pytest.mark.parametrize("filt", [UKF, EKF], ids=["ukf", "ekf"])
def test_off_map_position_skips_the_update(filt, dynamics, prior, smooth_grid):
    x0, p0 = prior
    state = fl.FilterState(x0, p0)
    pred = fl.predict(state, dynamics.f, dynamics.q)
    # INS off the map (EKF's mean and UKF's centre point), and at the edge, where
    # only the UKF's spread sigma points leave it
    cases = [(30.6, 130.0), (30.0, 130.49)] if filt is UKF else [(30.6, 130.0), (29.0, 131.0)]
    for lat, lon in cases:
        new, info = update(filt, state, _one_step(10.0, lat, lon), smooth_grid, dynamics)
        assert int(info.status) & FLAGS["off_map"], (lat, lon)
        _assert_same_state(new, pred)
    # well inside: an ordinary update
    new, info = update(filt, state, _one_step(10.0, 30.0, 130.0), smooth_grid, dynamics)
    assert int(info.status) == 0
    assert not np.allclose(np.asarray(new.x), np.asarray(pred.x))


def _generic_gravity(field, x, lat, lon):
    """The gravity measurement as an opaque callable: the UKF's generic 27-point path."""
    return fl.gravity_measurement(field, x, lat, lon)


UKF_GENERIC = fl.ukf(_generic_gravity)


@pytest.mark.parametrize("map_kind", ["pointmass", "grid"])
@pytest.mark.long
def test_structured_ukf_equals_the_generic_ukf(map_kind, dynamics, prior, runs, smooth_grid):
    """MapPlusBias: the map at the 5 distinct sigma positions gives the 27-point numbers."""
    x0, p0 = prior
    steps = _one(runs[0], 1)
    field = FIELD
    if map_kind == "grid":  # the track mirrored onto the grid, starting near its east edge
        field = smooth_grid
        steps = steps._replace(lat=steps.lat - 24.27 + 30.0, lon=130.41 + MASS_LON - steps.lon,
                               z=steps.z * 0.5)
    assert isinstance(fl.gravity_measurement, fl.MapPlusBias)
    final, infos = run_one(UKF, field, dynamics, x0, p0, steps)
    final_g, infos_g = run_one(UKF_GENERIC, field, dynamics, x0, p0, steps)
    sd = np.asarray(infos_g.sigma)
    assert np.max(np.abs(np.asarray(infos.x) - np.asarray(infos_g.x)) / sd) < 1e-10
    np.testing.assert_allclose(np.asarray(infos.sigma), sd, rtol=1e-10)
    np.testing.assert_allclose(np.asarray(final.p), np.asarray(final_g.p), rtol=1e-9,
                               atol=1e-12 * float(p0[0, 0]))
    np.testing.assert_allclose(np.asarray(infos.innovation_var),
                               np.asarray(infos_g.innovation_var), rtol=1e-10)
    np.testing.assert_array_equal(np.asarray(infos.status), np.asarray(infos_g.status))
    # the readings moved the filter (and, on the grid, some sigma points left the map)
    assert float(final.p[0, 0]) < 0.8 * float(p0[0, 0])
    if map_kind == "grid":
        assert np.any(np.asarray(infos.status) & FLAGS["off_map"])


def _dots(jaxpr, shape):
    """dot_general equations with this output shape in a jaxpr and its sub-jaxprs."""
    n = 0
    for eqn in jaxpr.eqns:
        n += eqn.primitive.name == "dot_general" and eqn.outvars[0].aval.shape == shape
        for sub in jax.extend.core.jaxprs_in_params(eqn.params):
            n += _dots(sub, shape)
    return n


@pytest.mark.parametrize("filt", [UKF, EKF], ids=["ukf", "ekf"])
def test_a_grid_is_prepared_once_outside_the_scan(filt, dynamics, prior, runs, smooth_grid):
    """run_filter computes the bicubic coefficients (a spline solve over the whole map,
    ny × nx dots) before its scan, not in the step (traced only, nothing compiled)."""
    x0, p0 = prior
    jaxpr = jax.make_jaxpr(lambda g: fl.run_filter(filt, g, dynamics, x0, p0, _one(runs[0], 0)))(
        smooth_grid).jaxpr
    shape = tuple(smooth_grid.values.shape)
    (scan,) = [e for e in jaxpr.eqns if e.primitive.name == "scan"]
    assert _dots(jaxpr, shape) == 3 and _dots(scan.params["jaxpr"].jaxpr, shape) == 0


def test_map_plus_bias_checks_its_layout():
    with pytest.raises(ValueError, match="n_position"):
        fl.MapPlusBias(fl.map_at_error, bias_index=1, n_position=2)


GSF3 = fl.gaussian_sum(UKF, per_axis=3)


@pytest.mark.parametrize(("which", "n_steps"), [  # a length that is not a multiple of
    ("ukf", N_STEPS), ("ukf", N_STEPS - 1), ("ekf", N_STEPS - 1), ("gsf", N_STEPS)])  # every
@pytest.mark.long
def test_update_only_on_reading_steps_equals_every_step(which, n_steps, dynamics, prior, runs):
    """run_filter(every=2) — predictions between readings — equals the every-step run."""
    filt = {"ukf": UKF, "ekf": EKF, "gsf": GSF3}[which]
    x0, p0 = prior
    steps = jax.tree.map(lambda a: a[:n_steps], _one(runs[0], 2))  # readings on odd steps
    final_1, infos_1 = run_one(filt, FIELD, dynamics, x0, p0, steps)  # every=1, shared
    final_2, infos_2 = run_every(filt, FIELD, dynamics, x0, p0, steps, 2)
    _assert_trees_close(final_2, final_1, rtol=1e-9, atol=1e-9)
    for name in ("x", "sigma", "p_pos", "status"):
        np.testing.assert_allclose(np.asarray(getattr(infos_2, name)),
                                   np.asarray(getattr(infos_1, name)), rtol=1e-9, atol=1e-9,
                                   err_msg=name)
    reading = np.isfinite(np.asarray(steps.z))
    assert reading[1::2].all() and not reading[0::2].any()
    np.testing.assert_allclose(np.asarray(infos_2.innovation)[reading],
                               np.asarray(infos_1.innovation)[reading], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.asarray(infos_2.innovation_var)[reading],
                               np.asarray(infos_1.innovation_var)[reading], rtol=1e-9)
    # between readings: the prediction only, no innovation variance
    assert np.all(np.isnan(np.asarray(infos_2.innovation_var)[~reading]))
    assert np.all(np.asarray(infos_2.status)[~reading] == FLAGS["no_reading"])


def test_every_k_is_causal_and_flags_ignored_readings(dynamics, prior, runs):
    """Steps before a reading show the prediction; a reading off the stride is not used."""
    x0, p0 = prior
    steps = _one(runs[0], 0)
    _, infos = run_every(UKF, FIELD, dynamics, x0, p0, steps, 4)
    state = fl.FilterState(x0, p0)
    for k in range(3):  # steps 0..2 predict only (step 1's reading is ignored), step 3 updates
        state = fl.predict(state, dynamics.f, dynamics.q)
        np.testing.assert_allclose(np.asarray(infos.x[k]), np.asarray(state.x), rtol=1e-12,
                                   atol=1e-9)
        np.testing.assert_allclose(np.asarray(infos.p_pos[k]), np.asarray(state.p[:2, :2]),
                                   rtol=1e-12)
    assert int(infos.status[1]) == FLAGS["no_reading"] | FLAGS["reading_ignored"]
    assert int(infos.status[3]) == 0
    assert not np.allclose(np.asarray(infos.x[3]), np.asarray(state.x))
    with pytest.raises(ValueError, match="every"):
        fl.run_filter(UKF, FIELD, dynamics, x0, p0, steps, every=0)


def _spd(rng, n, scales):
    a = rng.standard_normal((n, n))
    return (a @ a.T + 0.1 * np.eye(n)) * np.outer(scales, scales)


def test_modified_cholesky_equals_lapack_and_flags_non_pd(prior):
    chol = jax.jit(modified_cholesky)
    rng = np.random.default_rng(5)
    _, p0 = prior
    scales = np.sqrt(np.diag(np.asarray(p0)))  # metres next to rad/s: 1e3 … 1e-8
    for a in [_spd(rng, 13, np.ones(13)), _spd(rng, 13, scales), _spd(rng, 4, [1, 2, 3, 4]),
              np.asarray(p0)]:
        low, repaired, failed = chol(jnp.asarray(a))
        ref = np.linalg.cholesky(a)
        row = np.abs(ref).max(axis=1, keepdims=True)  # rows scale with their state's units
        np.testing.assert_allclose(np.asarray(low) / row, ref / row, rtol=1e-10, atol=1e-12)
        assert not bool(repaired) and not bool(failed)
    # positive semi-definite, rank 12: the last pivot is zero up to rounding, whose sign
    # depends on the compiler (XLA 0.10.1 and 0.10.2 differ); either way usable, not failed
    v = rng.standard_normal((13, 12))
    a = v @ v.T
    low, repaired, failed = chol(jnp.asarray(a))
    assert not bool(failed)
    np.testing.assert_allclose(np.asarray(low @ low.T), a, atol=1e-6 * np.abs(a).max())
    # a noise-free state (zero row and column): its pivot is exactly zero, so it is
    # clamped and flagged repaired, and the factor is still usable
    a = _spd(rng, 13, np.ones(13))
    a[4, :] = a[:, 4] = 0.0
    low, repaired, failed = chol(jnp.asarray(a))
    assert bool(repaired) and not bool(failed)
    np.testing.assert_allclose(np.asarray(low @ low.T), a, atol=1e-6 * np.abs(a).max())
    # a pivot slightly negative, within the relative jitter: clamped, repaired, usable
    near = jnp.asarray([[1.0, 1.0], [1.0, 1.0 - 1e-12]])
    low, repaired, failed = jax.jit(modified_cholesky)(near)
    assert bool(repaired) and not bool(failed) and np.all(np.isfinite(np.asarray(low)))
    # indefinite, and NaN: failed, zero factor
    b = _spd(rng, 13, np.ones(13)) - 50.0 * np.eye(13)
    for bad in (b, np.where(np.eye(13) > 0, np.nan, a)):
        low, repaired, failed = chol(jnp.asarray(bad))
        assert bool(failed) and bool(repaired) and np.all(np.asarray(low) == 0.0)


# --------------------------------------------------------------------------- point-mass filter
# (the filter's own tests are in test_pmf.py)


def test_pmf_off_map(prior, smooth_grid):
    x0, p0 = prior
    state = init(PMF, x0, p0)
    # the whole grid off the map: no update (the prediction, as without a reading), flagged
    new, info = update(PMF, state, _one_step(5.0, 35.0, 130.0), smooth_grid, DT)
    pred, _ = update(PMF, state, _one_step(jnp.nan, 35.0, 130.0), smooth_grid, DT)
    np.testing.assert_allclose(np.asarray(new.w), np.asarray(pred.w), rtol=1e-12, atol=1e-18)
    assert int(info.status) & FLAGS["off_map"]
    assert np.isnan(float(info.innovation)) and np.isnan(float(info.innovation_var))  # unused
    # partly off (INS near the east edge): flagged; the off-map cells are not ruled out,
    # they keep their prior share of the mass (the reading cannot tell whether the
    # vehicle is beyond the map's edge), while the reading reweights the cells on the map
    new, info = update(PMF, state, _one_step(5.0, 30.0, 130.49), smooth_grid, DT)
    pred, _ = update(PMF, state, _one_step(jnp.nan, 30.0, 130.49), smooth_grid, DT)
    assert int(info.status) & FLAGS["off_map"]
    # cell (i, j) is offset east by de_j; true lon = INS lon − de_j/(N cos φ): cells with
    # a large negative de are east of the INS, off the grid
    w, w0 = np.asarray(new.w), np.asarray(pred.w)
    assert w0[:, 0].sum() > 1e-6
    np.testing.assert_allclose(w[:, 0].sum(), w0[:, 0].sum(), rtol=1e-9)
    assert np.abs(w[:, -1] - w0[:, -1]).max() > 1e-6 * w0[:, -1].max()  # on the map: moved
    np.testing.assert_allclose(w.sum(), 1.0, rtol=1e-12)


# --------------------------------------------------------------------------- batching, jit


def _assert_trees_close(a, b, **tol):
    for u, v in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(u), np.asarray(v), **tol)


def _stack(infos):
    return jax.tree.map(lambda *a: np.stack(a), *infos)


@pytest.mark.parametrize("filt", [UKF, EKF], ids=["ukf", "ekf"])
@pytest.mark.long
def test_batched_equals_loop(filt, dynamics, prior, runs):
    """vmap(run_filter) over runs equals a Python loop over runs and steps of ``update``."""
    steps = runs[0]
    x0, p0 = prior
    x0s = jnp.stack([x0.at[12].set(b) for b in (0.0, 0.5, -0.5)])
    final_b, infos_b = run_batch(filt, FIELD, dynamics, x0s, p0, steps)
    assert infos_b.x.shape == (3, N_STEPS, ins.N_STATES)
    for i in range(3):
        state, infos = init(filt, x0s[i], p0), []
        for k in range(N_STEPS):
            state, info = update(filt, state, _one(_one(steps, i), k), FIELD, dynamics)
            infos.append(info)
        _assert_trees_close(
            jax.tree.map(lambda a, i=i: a[i], final_b), state, rtol=1e-8, atol=1e-12
        )
        _assert_trees_close(
            jax.tree.map(lambda a, i=i: a[i], infos_b), _stack(infos), rtol=1e-8, atol=1e-12
        )


def test_jit_does_not_retrace_on_new_values(dynamics, prior):
    x0, p0 = prior
    steps_a, _ = _make_runs(dynamics, 1, seed=11)
    steps_b, _ = _make_runs(dynamics, 1, seed=12)
    run_one(UKF, FIELD, dynamics, x0, p0, _one(steps_a, 0))
    n = len(_TRACES)
    other = fl.Dynamics(dynamics.f * 1.0, dynamics.q * 2.0)
    field2 = jax.tree.map(lambda a: a * 1.1, FIELD)
    steps2 = _one(steps_b, 0)._replace(r=2.0 * steps_b.r[0])
    run_one(UKF, field2, other, x0.at[0].set(50.0), 2.0 * p0, steps2)
    assert len(_TRACES) == n


def test_sigma_point_parameters_sweep_without_recompiling(dynamics, prior, runs):
    """α, β, κ are closure constants of ``ukf``; built inside jit they are traced values."""
    traces = []

    @jax.jit
    def final_sigma(alpha, x0, p0, steps):
        traces.append(1)
        final, _ = fl.run_filter(fl.ukf(alpha=alpha), FIELD, dynamics, x0, p0, steps)
        return jnp.sqrt(final.p[0, 0])

    x0, p0 = prior
    steps = _one(runs[0], 2)
    a = final_sigma(0.5, x0, p0, steps)
    b = final_sigma(0.9, x0, p0, steps)
    assert len(traces) == 1 and float(a) != float(b)
    _, infos = run_one(UKF, FIELD, dynamics, x0, p0, steps)
    np.testing.assert_allclose(float(a), float(infos.sigma[-1, 0]), rtol=1e-10)


# --------------------------------------------------------------------------- Gaussian sum


def test_gaussian_sum_with_one_component_equals_its_base(dynamics, prior, runs):
    steps = _one(runs[0], 0)
    x0, p0 = prior
    gs = fl.gaussian_sum(UKF, per_axis=1)
    _, infos_gs = run_one(gs, FIELD, dynamics, x0, p0, steps)
    _, infos = run_one(UKF, FIELD, dynamics, x0, p0, steps)
    for name in fl.StepInfo._fields:
        a, b = np.asarray(getattr(infos, name)), np.asarray(getattr(infos_gs, name))
        # equal but for rounding: the base runs inside a vmap over one component
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9, err_msg=name)


@pytest.mark.parametrize(("per_axis", "spacing"), [(5, 0.8), (3, 0.5), (7, 0.6)])
def test_split_prior_preserves_mean_and_covariance(per_axis, spacing, prior):
    x0, p0 = prior
    x0 = x0.at[0].set(150.0).at[1].set(-80.0).at[12].set(0.3)
    x, p, log_w = jax.jit(fl.split_prior, static_argnums=2)(x0, p0, per_axis, spacing)
    assert x.shape == (per_axis**2, ins.N_STATES) and p.shape == (per_axis**2, 13, 13)
    w = np.exp(np.asarray(log_w))
    np.testing.assert_allclose(w.sum(), 1.0, rtol=1e-12)
    x, p = np.asarray(x), np.asarray(p)
    mean = w @ x
    cov = np.einsum("m,mi,mj->ij", w, x - mean, x - mean) + np.einsum("m,mij->ij", w, p)
    np.testing.assert_allclose(mean, np.asarray(x0), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(
        cov[:2, :2], np.asarray(p0)[:2, :2], rtol=1e-10, atol=1e-12 * float(p0[0, 0])
    )
    # p0 is diagonal: the whole mixture covariance is p0
    sd = np.sqrt(np.diag(np.asarray(p0)))
    np.testing.assert_allclose(
        cov / np.outer(sd, sd), np.asarray(p0) / np.outer(sd, sd), atol=1e-10
    )
    assert np.all(np.linalg.eigvalsh(p[:, :2, :2]) > 0)


def test_pad_to_stride_puts_the_readings_on_the_update_steps():
    """Readings every 3rd step from step 0: shifted by 2 steps, padded to whole strides."""
    t, every = 7, 3
    z = np.full(t, np.nan)
    z[[0, 3, 6]] = [1.0, 2.0, 3.0]
    steps = fl.Step(np.arange(t) + 20.0, np.arange(t) + 120.0, z, np.arange(t) + 1.0)
    padded, start = fl.pad_to_stride(steps, every, first=0)
    assert start == 2 and padded.z.shape == (9,)
    for name in ("lat", "lon", "r"):  # the ends repeat the first and last step
        np.testing.assert_array_equal(np.asarray(getattr(padded, name)),
                                      np.asarray(getattr(steps, name))[[0, 0, *range(t)]])
    zp = np.asarray(padded.z)
    np.testing.assert_array_equal(zp[start:start + t], z)
    assert np.isnan(zp[:start]).all()
    assert np.all(np.flatnonzero(np.isfinite(zp)) % every == every - 1)
    # already on the stride: only the end is padded
    padded, start = fl.pad_to_stride(jax.tree.map(lambda a: a[1:6], steps), every)
    zp = np.asarray(padded.z)
    assert start == 0 and zp.shape == (6,) and np.isnan(zp[5])
    np.testing.assert_array_equal(np.flatnonzero(np.isfinite(zp)), [2])


def _float32_problem(t=4):
    """float32 dynamics, prior and steps of a short run (x64 on)."""
    f32 = jnp.float32
    model = ins.INSErrorModel()
    f, q = ins.transition(model, 24.3, 10.0)
    dyn = fl.Dynamics(f.astype(f32), q.astype(f32), jnp.asarray(10.0, f32))
    p0 = ins.initial_covariance(model, 1414.0, 0.14).astype(f32)
    steps = fl.Step(jnp.full(t, 24.3, f32), jnp.full(t, 123.0, f32), jnp.ones(t, f32),
                    jnp.ones(t, f32))
    return dyn, p0, steps


def _ramp(lat, lon):
    """A map rising 0.005 mGal per metre north (mGal)."""
    return 0.005 * (lat - 24.3) * 111000.0


def test_float32_inputs_under_x64_run_in_the_updates_precision():
    """float32 state and dynamics with x64 on: the update promotes them (float64
    geodesy), and run_filter starts its scan in that precision instead of failing on
    the carry's type (review of 2026-12-06, helper-30)."""
    dyn, p0, steps = _float32_problem()
    for filt in (fl.ekf(), fl.ukf()):
        state, infos = fl.run_filter(filt, _ramp, dyn, jnp.zeros(13, jnp.float32), p0, steps)
        assert state.x.dtype == jnp.float64 and np.all(np.isfinite(np.asarray(infos.x)))


@pytest.mark.long
def test_float32_inputs_under_x64_run_in_the_particle_filters():
    """The same for the particle filters (the PF's resampling branch refused the mixed
    dtypes: review of the nineteenth session, helper-43)."""
    dyn, p0, steps = _float32_problem()
    for filt in (fl.pf(64), fl.rbpf(64)):
        _, infos = fl.run_filter(filt, _ramp, dyn, jnp.zeros(13, jnp.float32), p0, steps,
                                 key=jax.random.PRNGKey(0))
        assert infos.x.dtype == jnp.float64 and np.all(np.isfinite(np.asarray(infos.x)))


_SMALL_ALPHA = """
import jax, jax.numpy as jnp
from jaxgrav import filters as fl
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.sim import ins
assert not jax.config.jax_enable_x64


def update(alpha):  # one program (op by op it took 4 s more): the check runs as it traces
    m = ins.INSErrorModel()
    f, q = ins.transition(m, 24.27, 10.0)
    dyn = fl.Dynamics(f, q, jnp.asarray(10.0))
    p0 = ins.initial_covariance(m, 1414.0, 0.14)
    step = fl.Step(jnp.asarray(24.27), jnp.asarray(122.95), jnp.asarray(1.0), jnp.asarray(1.0))
    return fl.ukf(alpha=alpha).update(fl.ukf().init(jnp.zeros(13), p0), step, paper_d(), dyn)


jax.block_until_ready(jax.jit(update, static_argnums=0)(0.1))
try:
    jax.jit(update, static_argnums=0)(0.01)
except ValueError as e:
    print("refused:", e)
"""


def test_a_small_alpha_is_refused_in_float32():
    """α = 1e-3 in float32 put the sigma points closer to the mean than float32 positions
    resolve (innovation variance 70 × too large, no flag): refused by name."""
    env = {**os.environ, "JAX_ENABLE_X64": "0"}
    proc = subprocess.run([sys.executable, "-c", _SMALL_ALPHA], capture_output=True,
                          text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "refused: ukf(alpha=0.01) in float32: alpha must be at least 0.1" in proc.stdout
