"""jaxgrav's particle and point-mass filters against Stone Soup's (a reference library).

* A short linear-Gaussian case (3 states, a reading of the first): both Stone Soup's SIR
  particle filter (``ParticlePredictor`` / ``ParticleUpdater``, ESS-triggered systematic
  resampling) and :func:`jaxgrav.filters.pf` with many particles approach the exact
  Kalman posterior mean, within Monte Carlo tolerance.
* A 2-state random walk with a smooth non-linear reading (a two-mode posterior), the
  same initial 81 × 81 grid (100 m points, ±4 σ of the prior):
  :func:`jaxgrav.filters.pmf` (``ins=None``) and Stone Soup's ``PointMassPredictor`` /
  ``PointMassUpdater`` give the same posterior after the first reading (same points),
  then both follow the exact posterior (a 10 m grid): jaxgrav's fixed cells within
  2 % of its σ, Stone Soup's grid, rebuilt every step along the covariance's
  eigenvectors at ±4 σ and interpolated, within 20 % (about 80 m off here).
"""

import datetime

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from stonesoup.base import Property
from stonesoup.functions import grid_creation
from stonesoup.models.base import GaussianModel
from stonesoup.models.measurement.base import MeasurementModel
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.models.transition.linear import LinearGaussianTransitionModel
from stonesoup.predictor.particle import ParticlePredictor
from stonesoup.predictor.pointmass import PointMassPredictor
from stonesoup.resampler.particle import ESSResampler, SystematicResampler
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import ParticleState, PointMassState
from stonesoup.updater.particle import ParticleUpdater
from stonesoup.updater.pointmass import PointMassUpdater

from jaxgrav import filters as fl
from jaxgrav.filters.model import Dynamics, Step
from jaxgrav.sim.ins import N_STATES

T0 = datetime.datetime(2020, 1, 1)


class MatrixTransition(LinearGaussianTransitionModel):
    """``x ← F x + w``, ``w ~ N(0, Q)`` with given matrices."""

    f: np.ndarray = Property(doc="F")
    q: np.ndarray = Property(doc="Q")

    @property
    def ndim_state(self):
        return self.f.shape[0]

    def matrix(self, **kwargs):
        return self.f

    def covar(self, **kwargs):
        return CovarianceMatrix(self.q)


def _smooth_np(dn, de):
    return 3.0 * np.sin(dn / 700.0) + 2.0 * np.cos(de / 900.0) + 1e-3 * de


def _smooth_jax(field, x, lat, lon):
    del field, lat, lon
    return 3.0 * jnp.sin(x[0] / 700.0) + 2.0 * jnp.cos(x[1] / 900.0) + 1e-3 * x[1]


class SmoothMeasurement(MeasurementModel, GaussianModel):
    """``z = h(d) + v`` on the first two states, vectorised over the columns."""

    r: float = Property(doc="noise variance")

    @property
    def ndim_meas(self):
        return 1

    def function(self, state, noise=False, **kwargs):
        x = np.asarray(state.state_vector, float)
        return StateVectors(np.atleast_2d(_smooth_np(x[0], x[1])))

    def covar(self, **kwargs):
        return CovarianceMatrix([[self.r]])


def _linear_case():
    f = np.array([[1.0, 1.0, 0.0], [0.0, 0.95, 0.0], [0.0, 0.0, 1.0]])
    q = np.diag([0.05, 0.02, 0.0])  # a noise-free constant, as the INS sensor biases
    x0 = np.array([0.0, 0.5, 0.0])
    p0 = np.diag([1.0, 0.25, 1.0])
    h = np.array([1.0, 0.0, 1.0])  # position plus the constant (as map plus bias)
    r = 0.3
    rng = np.random.default_rng(3)
    x = x0 + np.sqrt(np.diag(p0)) * rng.standard_normal(3)
    zs = []
    for _ in range(8):
        x = f @ x + np.sqrt(np.diag(q)) * rng.standard_normal(3)
        zs.append(h @ x + np.sqrt(r) * rng.standard_normal())
    return f, q, x0, p0, h, r, np.array(zs)


def _kalman(f, q, x0, p0, h, r, zs):
    x, p = x0.copy(), p0.copy()
    for z in zs:
        x, p = f @ x, f @ p @ f.T + q
        s = h @ p @ h + r
        k = p @ h / s
        x, p = x + k * (z - h @ x), p - np.outer(k, k) * s
    return x, p


@pytest.mark.long
def test_particle_filters_approach_the_kalman_posterior():
    f, q, x0, p0, h, r, zs = _linear_case()
    x_kf, p_kf = _kalman(f, q, x0, p0, h, r, zs)
    sd = np.sqrt(np.diag(p_kf))
    # a filter that ignored the readings would be far off: the test can tell
    x_free = np.linalg.matrix_power(f, zs.size) @ x0
    assert np.max(np.abs(x_free - x_kf) / sd) > 1.0
    n = 20000

    # Stone Soup: SIR with ESS < N/2 systematic resampling
    np.random.seed(0)  # noqa: NPY002 (Stone Soup's samplers use the global state)
    rng = np.random.default_rng(0)
    parts = x0[:, None] + np.sqrt(np.diag(p0))[:, None] * rng.standard_normal((3, n))
    state = ParticleState(StateVectors(parts), log_weight=np.full(n, -np.log(n)), timestamp=T0)
    predictor = ParticlePredictor(MatrixTransition(f=f, q=q))
    updater = ParticleUpdater(measurement_model=None,
                              resampler=ESSResampler(resampler=SystematicResampler()))
    meas = _SumModel(ndim_state=3, mapping=(0,), noise_covar=np.array([[r]]), h=h)
    for k, z in enumerate(zs):
        t = T0 + datetime.timedelta(seconds=k + 1)
        state = predictor.predict(state, timestamp=t)
        det = Detection(StateVector([z]), timestamp=t, measurement_model=meas)
        state = updater.update(SingleHypothesis(state, det))
    x_ss = np.asarray(state.mean, float).ravel()

    # jaxgrav: the same model, the reading as a callable measurement
    filt = fl.pf(n, measurement=lambda field, x, lat, lon: x[0] + x[2], roughening=0.0)
    steps = Step(jnp.zeros(zs.size), jnp.zeros(zs.size), jnp.asarray(zs),
                 jnp.full(zs.size, r))
    _, infos = fl.run_filter(filt, None, Dynamics(jnp.asarray(f), jnp.asarray(q)),
                             jnp.asarray(x0), jnp.asarray(p0), steps,
                             key=jax.random.PRNGKey(1))
    x_jg = np.asarray(infos.x[-1])

    # Monte Carlo error ~ sd / sqrt(N_eff) (N_eff a few thousand after resampling): 0.1 sd is
    # several of them
    np.testing.assert_array_less(np.abs(x_ss - x_kf) / sd, 0.1)
    np.testing.assert_array_less(np.abs(x_jg - x_kf) / sd, 0.1)


class _SumModel(LinearGaussian):
    """Stone Soup linear Gaussian reading ``z = h · x`` (one row) with a given ``h``."""

    h: np.ndarray = Property(doc="h over the whole state")

    def matrix(self, **kwargs):
        return self.h[None, :]


@pytest.mark.long
def test_pmf_matches_stonesoup_point_mass_filter():
    sigma, n_cells, q_pos, dt, r = 1000.0, 81, 20.0, 10.0, 0.25
    cell = 8.0 * sigma / (n_cells - 1)  # Stone Soup's ±4σ grid of the prior: the same points
    rng = np.random.default_rng(5)
    d = np.array([600.0, -400.0])
    zs = []
    for _ in range(6):
        d = d + np.sqrt(q_pos * dt) * rng.standard_normal(2)
        zs.append(_smooth_np(d[0], d[1]) + np.sqrt(r) * rng.standard_normal())
    zs = np.array(zs)

    # Stone Soup
    npa = np.array([n_cells, n_cells])
    cov = sigma**2 * np.eye(2)
    grid, delta, dims, centre, eig = grid_creation(np.zeros((2, 1)), cov, 4.0, 2, npa)
    w = np.exp(-0.5 * np.sum(grid**2, 0) / sigma**2)
    w = w / (w.sum() * np.prod(delta))
    state = PointMassState(state_vector=StateVectors(grid), weight=w, grid_delta=delta,
                           grid_dim=dims, center=centre, eigVec=eig, Npa=npa, timestamp=T0)
    assert np.allclose(delta, cell)
    predictor = PointMassPredictor(MatrixTransition(f=np.eye(2), q=q_pos * dt * np.eye(2)))
    updater = PointMassUpdater(measurement_model=None)
    ss_means = []
    for k, z in enumerate(zs):
        t = T0 + datetime.timedelta(seconds=dt * (k + 1))
        state = predictor.predict(state, timestamp=t)
        det = Detection(StateVector([z]), timestamp=t,
                        measurement_model=SmoothMeasurement(ndim_state=2, mapping=(0, 1), r=r))
        state = updater.update(SingleHypothesis(state, det))
        ss_means.append(np.asarray(state.mean, float).ravel()[:2])
    ss_means = np.array(ss_means)

    # jaxgrav: the classic PMF (random walk, no INS model), the bias known (zero)
    x0 = np.zeros(N_STATES)
    p0 = np.eye(N_STATES)
    p0[:2, :2] = cov
    p0[12, 12] = 1e-12
    filt = fl.pmf(n_cells, cell, q_pos=q_pos, ins=None, measurement=_smooth_jax)
    steps = Step(jnp.zeros(zs.size), jnp.zeros(zs.size), jnp.asarray(zs), jnp.full(zs.size, r))
    _, infos = fl.run_filter(filt, None, filt.dynamics(0.0, dt), jnp.asarray(x0),
                             jnp.asarray(p0), steps)
    jg_means = np.asarray(infos.x[:, :2])

    ref_means, ref_sd = _fine_grid_reference(sigma, q_pos * dt, r, zs)
    # the posterior has moved well away from the prior: a real test
    assert np.linalg.norm(ref_means[-1]) > 200.0
    # the first update is on the same 81 x 81 points in both: the same posterior
    np.testing.assert_allclose(jg_means[0], ss_means[0], atol=2.0)
    # then the grids differ; both follow the exact posterior (a 10 m grid), jaxgrav's
    # fixed cells closely, Stone Soup's ±4σ grid rebuilt on a two-mode posterior less so
    np.testing.assert_allclose(jg_means, ref_means, atol=0.02 * ref_sd.min())
    np.testing.assert_allclose(ss_means, ref_means, atol=0.2 * ref_sd.min())
    jg_sd = np.sqrt(np.diag(np.asarray(infos.p_pos[-1])))
    np.testing.assert_allclose(jg_sd, ref_sd, rtol=0.05)
    # (Stone Soup's north σ is 501 m against the exact 721 m here: its ±4σ grid, rebuilt
    # from the covariance, cuts part of the second mode off; not asserted)


def _fine_grid_reference(sigma, q_step, r, zs, step=10.0):
    """The exact filter on a fine grid: posterior means per step, the last one's σ."""
    from scipy.ndimage import gaussian_filter

    g = np.arange(-6000.0, 6000.0 + step / 2, step)
    dn, de = np.meshgrid(g, g, indexing="ij")
    w = np.exp(-0.5 * (dn**2 + de**2) / sigma**2)
    h = _smooth_np(dn, de)
    means = []
    for z in zs:
        w = gaussian_filter(w, np.sqrt(q_step) / step, mode="constant")
        w = w * np.exp(-0.5 * (z - h) ** 2 / r)
        w = w / w.sum()
        means.append([np.sum(w * dn), np.sum(w * de)])
    m = means[-1]
    sd = np.sqrt([np.sum(w * (dn - m[0]) ** 2), np.sum(w * (de - m[1]) ** 2)])
    return np.array(means), sd
