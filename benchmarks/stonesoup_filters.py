"""How fast are jaxgrav's particle and point-mass filters against Stone Soup's?

Paper D's filtering scenario as :mod:`particle_filters` builds it
(:func:`jaxgrav.scenarios.filter_scenario`, :func:`~jaxgrav.scenarios.run_steps`,
:func:`~jaxgrav.scenarios.initial_state`): 2 h at 5 m/s over the three point masses, a
10 s step with a reading every step (721 steps), the 13-state INS error model, 1 mGal
noise. ``n`` runs (default 100, ``--quick`` 10). Reference: Stone Soup (PyPI
``stonesoup``, a test-only dependency), one Python call per step as its tracker does.

* ``pf``: :func:`~jaxgrav.filters.pf` (1000 particles over all 13 states, systematic
  resampling at ESS < N/2, ``roughening=0``) against Stone Soup's ``ParticlePredictor``
  + ``ParticleUpdater`` with an ``ESSResampler(SystematicResampler())`` (threshold
  N/2) and no regulariser: the same algorithm. The SAME model: a
  ``LinearGaussianTransitionModel`` whose ``matrix()`` / ``covar()`` are the run's
  ``F`` / ``Q`` (:class:`MatrixTransition`), and a measurement model
  (:class:`GravityMeasurement`) whose ``function()`` is, vectorised over the particles
  in NumPy, paper D's point-mass anomaly at the INS position minus the particle's
  position error plus its gravimeter-bias state, noise variance ``r``. jaxgrav's
  roughening is off here because Stone Soup's only regulariser (an MCMC move) is a
  different algorithm.
* ``rbpf``: :func:`~jaxgrav.filters.rbpf` (1000 particles over the position error,
  a Kalman filter for the other 11 states, library defaults) against the same Stone
  Soup particle filter: Stone Soup has no Rao–Blackwellised filter for this model.
* ``pmf``: :func:`~jaxgrav.filters.pmf` against Stone Soup's ``PointMassPredictor`` /
  ``PointMassUpdater``. The models cannot be identical: Stone Soup's point-mass filter
  grids the WHOLE state (13 states × 61 points is out of reach) and needs an invertible
  ``F`` and ``Q``, while jaxgrav's grids the position error only and carries the other
  12 states as Gaussians (the INS drift, a per-cell bias filter). Both run the classic
  2-state model instead: the position error as a random walk of density ``q_pos``
  (``pmf(ins=None)``; for Stone Soup ``F = I``, ``Q = q_pos·dt·I``), the gravimeter
  bias known (its true initial value ``bias_mgal``; jaxgrav's per-cell bias prior
  variance 1e-12), the same likelihood, 61 × 61 points, the same Gaussian prior.
  What still differs: jaxgrav's grid has fixed 200 m cells (±6 km) that follow the
  mean, and spreads mass with an exact discrete diffusion kernel; Stone Soup rebuilds
  its grid every step along the eigenvectors of the predicted covariance at ±4σ
  (``sFactor``), interpolates the density linearly onto it and convolves with the
  Gaussian transition density on the new points (FFT). Its predictor gets its prior's
  covariance symmetrised (:class:`SymmetricPointMassPredictor`): without it the
  equal variances make ``numpy.linalg.eig`` return complex eigenvectors and the first
  prediction is NaN. The true INS error drifts (Schuler), which neither filter models
  here (the random walk stands in for it), so these errors are not the library's
  drift-aware ``pmf``'s. The point-mass filters are deterministic: on the same run
  their errors differ by the grids only.
  A second line, ``pmf-61-spread32``, times the same filter with its spread's two matrix
  products in float32 (``pmf(spread_dtype=float32)``; the rest in float64).

Stone Soup is timed on a few runs and scaled per run (field ``note``); both are scored
on those runs: RMS position error over the second hour (``err_m``; different random
numbers, so equal within Monte Carlo noise, not to the digit). jaxgrav's compile time is
separate (``compile_s``); each filter is compiled with the XLA options the Monte Carlo
runner gives its method (:func:`jaxgrav.montecarlo.spec.cpu_options_for`).

Run ``python benchmarks/stonesoup_filters.py [--quick] [--filters pf pmf]``; JSON lines on stdout,
progress on stderr. Compare ratios within one run (shared machine).
"""

import argparse
import datetime
import math
import sys
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np
from _common import best_time, emit

jax.config.update("jax_enable_x64", True)  # a script, not the library

from particle_filters import (  # noqa: E402
    NumpyAnomaly,
    paper_d_runs,
    second_half_rms,
    true_position,
)
from stonesoup.base import Property  # noqa: E402
from stonesoup.models.base import GaussianModel  # noqa: E402
from stonesoup.models.measurement.base import MeasurementModel  # noqa: E402
from stonesoup.models.transition.linear import LinearGaussianTransitionModel  # noqa: E402
from stonesoup.predictor.particle import ParticlePredictor  # noqa: E402
from stonesoup.predictor.pointmass import PointMassPredictor  # noqa: E402
from stonesoup.resampler.particle import ESSResampler, SystematicResampler  # noqa: E402
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors  # noqa: E402
from stonesoup.types.detection import Detection  # noqa: E402
from stonesoup.types.hypothesis import SingleHypothesis  # noqa: E402
from stonesoup.types.state import ParticleState, PointMassState  # noqa: E402
from stonesoup.updater.particle import ParticleUpdater  # noqa: E402
from stonesoup.updater.pointmass import PointMassUpdater  # noqa: E402

from jaxgrav import filters as fl  # noqa: E402
from jaxgrav.montecarlo.spec import cpu_options_for  # noqa: E402
from jaxgrav.sim.ins import GRAV  # noqa: E402
from jaxgrav.xla_options import compiler_options  # noqa: E402

BENCH = "stonesoup_filters"
N_PARTICLES = 1000
N_CELLS = 61
CELL_M = 200.0
Q_POS = 50.0  # m²/s: the random-walk density of the point-mass comparison
CHUNK = 25
_T0 = time.perf_counter()
_EPOCH = datetime.datetime(2020, 1, 1)


def progress(msg):
    print(f"[{time.perf_counter() - _T0:7.1f} s] {msg}", file=sys.stderr, flush=True)


class MatrixTransition(LinearGaussianTransitionModel):
    """Stone Soup transition ``x ← F x + w``, ``w ~ N(0, Q)``, with given ``F`` and ``Q``."""

    f: np.ndarray = Property(doc="Transition matrix of one step")
    q: np.ndarray = Property(doc="Process noise covariance of one step")

    @property
    def ndim_state(self):
        return self.f.shape[0]

    def matrix(self, **kwargs):
        return self.f

    def covar(self, **kwargs):
        return CovarianceMatrix(self.q)


class GravityMeasurement(MeasurementModel, GaussianModel):
    """Stone Soup measurement: the anomaly at the INS position minus the position error.

    ``z = Δg(INS − d) + b + v``, ``v ~ N(0, r)``: ``d`` the state's first two entries
    (north, east, m), ``b`` the state at ``bias_index`` or, when it is None, the
    constant ``bias``. ``function()`` is vectorised over the columns (particles or grid
    points) in NumPy.
    """

    anomaly: object = Property(doc="NumpyAnomaly: (lat, lon) -> mGal")
    lat: float = Property(doc="INS latitude (degrees)")
    lon: float = Property(doc="INS longitude (degrees)")
    r: float = Property(doc="Noise variance (mGal²)")
    bias_index: int = Property(default=None, doc="State index of the bias, or None")
    bias: float = Property(default=0.0, doc="Known bias (mGal) when bias_index is None")

    @property
    def ndim_meas(self):
        return 1

    def function(self, state, noise=False, **kwargs):
        x = np.asarray(state.state_vector, float)
        tl, tn = true_position(self.lat, self.lon, x[0], x[1])
        b = self.bias if self.bias_index is None else x[self.bias_index]
        z = self.anomaly(tl, tn) + b
        if noise is True:
            z = z + self.rvs(num_samples=z.size)
        return StateVectors(np.atleast_2d(z))

    def covar(self, **kwargs):
        return CovarianceMatrix([[self.r]])


class SymmetricPointMassState(PointMassState):
    """``PointMassState`` whose ``covar()`` is symmetrised: ``(P + Pᵀ) / 2``.

    Stone Soup's ``covar()`` (``chip_w @ chip_.T``) is symmetric only up to rounding,
    and ``grid_creation`` takes its eigenvectors with the general ``numpy.linalg.eig``.
    With equal variances (our isotropic prior, and the random walk's ``Q ∝ I``) the
    rounding (off-diagonals +2.2e-12 / -2.6e-12 m²) makes the eigenvalues a complex
    pair and the eigenvectors complex; cast to real they are ``[[0, 0], [0.74, 0.74]]``,
    a singular rotation that collapses the grid onto a line, and the first prediction
    is already NaN. Symmetrising changes nothing else.
    """

    def covar(self):
        p = super().covar()
        return CovarianceMatrix((p + p.T) / 2)


class SymmetricPointMassPredictor(PointMassPredictor):
    """Stone Soup's ``PointMassPredictor``, its prior's covariance symmetrised (above)."""

    def predict(self, prior, timestamp=None, **kwargs):
        prior = SymmetricPointMassState(
            state_vector=prior.state_vector, weight=prior.weight,
            grid_delta=prior.grid_delta, grid_dim=prior.grid_dim, center=prior.center,
            eigVec=prior.eigVec, Npa=prior.Npa, timestamp=prior.timestamp)
        return super().predict(prior, timestamp=timestamp, **kwargs)


def stonesoup_pf(anomaly, f, q, x0, p0, lat, lon, z, r, n, dt, seed):
    """Stone Soup's SIR particle filter over a run; returns (T, 2) position means."""
    np.random.seed(seed)  # noqa: NPY002 (Stone Soup's samplers use the global state)
    rng = np.random.default_rng(seed)
    vals, vecs = np.linalg.eigh(p0)
    x = x0[:, None] + (vecs * np.sqrt(np.clip(vals, 0.0, None))) @ rng.standard_normal(
        (x0.size, n))
    state = ParticleState(StateVectors(x), log_weight=np.full(n, -math.log(n)),
                          timestamp=_EPOCH)
    predictor = ParticlePredictor(MatrixTransition(f=f, q=q))
    updater = ParticleUpdater(measurement_model=None, resampler=None)
    resampler = ESSResampler(resampler=SystematicResampler())  # threshold N/2
    out = np.empty((z.size, 2))
    for k in range(z.size):
        t = _EPOCH + datetime.timedelta(seconds=dt * (k + 1))
        state = predictor.predict(state, timestamp=t)
        if math.isfinite(z[k]):
            model = GravityMeasurement(ndim_state=x0.size, mapping=(0, 1, GRAV),
                                       anomaly=anomaly, lat=lat[k], lon=lon[k], r=r,
                                       bias_index=GRAV)
            det = Detection(StateVector([z[k]]), timestamp=t, measurement_model=model)
            state = updater.update(SingleHypothesis(state, det))
        out[k] = np.asarray(state.mean, float).ravel()[:2]  # the posterior, before resampling
        state = resampler.resample(state)
    return out


def stonesoup_pmf(anomaly, x0, p0, lat, lon, z, r, bias, dt):
    """Stone Soup's point-mass filter (2-state random walk); returns (T, 2) means."""
    from stonesoup.functions import grid_creation

    npa = np.array([N_CELLS, N_CELLS])
    mean, cov = x0[:2].reshape(-1, 1), p0[:2, :2]
    grid, delta, dims, centre, eig = grid_creation(mean, cov, 4.0, 2, npa)
    d = grid - mean
    w = np.exp(-0.5 * np.sum(d * (np.linalg.inv(cov) @ d), 0))
    w = w / (w.sum() * np.prod(delta))
    state = PointMassState(state_vector=StateVectors(grid), weight=w, grid_delta=delta,
                           grid_dim=dims, center=centre, eigVec=eig, Npa=npa,
                           timestamp=_EPOCH)
    predictor = SymmetricPointMassPredictor(
        MatrixTransition(f=np.eye(2), q=Q_POS * dt * np.eye(2)))
    updater = PointMassUpdater(measurement_model=None)
    out = np.empty((z.size, 2))
    for k in range(z.size):
        t = _EPOCH + datetime.timedelta(seconds=dt * (k + 1))
        state = predictor.predict(state, timestamp=t)
        if math.isfinite(z[k]):
            model = GravityMeasurement(ndim_state=2, mapping=(0, 1), anomaly=anomaly,
                                       lat=lat[k], lon=lon[k], r=r, bias=bias)
            det = Detection(StateVector([z[k]]), timestamp=t, measurement_model=model)
            state = updater.update(SingleHypothesis(state, det))
        out[k] = np.asarray(state.mean, float).ravel()[:2]
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="10 runs, 1 Stone Soup run per case")
    p.add_argument("--runs", type=int, default=None, help="runs for jaxgrav (default 100)")
    p.add_argument("--filters", nargs="+", choices=("pf", "pmf"), default=("pf", "pmf"),
                   help="which comparisons (pf: the particle filters, both against Stone "
                        "Soup's; pmf: the point-mass filter); default both")
    a = p.parse_args()
    n_runs = a.runs or (10 if a.quick else 100)
    n_ss = 1 if a.quick else 3
    repeats = 1 if a.quick else 2
    field, scen, dyn, steps, truth, x0, p0 = paper_d_runs(n_runs)
    anomaly = NumpyAnomaly(field)
    ctx = (field, dyn, steps, truth, x0, p0, n_ss, repeats)

    # the Stone Soup particle filter is timed once and compared with both jaxgrav filters
    if "pf" in a.filters:
        def ss_pf(i, seed):
            return stonesoup_pf(anomaly, np.asarray(dyn.f[i]), np.asarray(dyn.q[i]),
                                np.asarray(x0), np.asarray(p0), np.asarray(steps.lat[i]),
                                np.asarray(steps.lon[i]), np.asarray(steps.z[i]),
                                float(steps.r[i, 0]), N_PARTICLES, float(dyn.dt[i]), seed)

        ss = stonesoup_time(ss_pf, truth, n_ss, "pf")
        bench_one("pf", fl.pf(N_PARTICLES, roughening=0.0), ctx, ss, "stonesoup-pf",
                  "same algorithm and model: SIR, systematic resampling at ESS < N/2, no "
                  "roughening in either")
        bench_one("rbpf", fl.rbpf(N_PARTICLES), ctx, ss, "stonesoup-pf",
                  "Stone Soup has no Rao-Blackwellised filter for this model: compared with "
                  "its SIR filter (same model, 1000 particles over all 13 states)")

    if "pmf" not in a.filters:
        return
    # point-mass: the classic 2-state random-walk model in both (see the docstring)
    bias = float(scen.bias_mgal)
    x0_pm = np.asarray(x0).copy()
    x0_pm[GRAV] = bias
    p0_pm = np.asarray(p0).copy()
    p0_pm[GRAV, :] = 0.0
    p0_pm[:, GRAV] = 0.0
    p0_pm[GRAV, GRAV] = 1e-12

    def ss_pmf(i, seed):
        del seed
        return stonesoup_pmf(anomaly, x0_pm, p0_pm, np.asarray(steps.lat[i]),
                             np.asarray(steps.lon[i]), np.asarray(steps.z[i]),
                             float(steps.r[i, 0]), bias, float(dyn.dt[i]))

    ss = stonesoup_time(ss_pmf, truth, n_ss, "pmf")
    filt = fl.pmf(N_CELLS, CELL_M, q_pos=Q_POS, ins=None)
    dyn_pm = jax.vmap(lambda d: filt.dynamics(0.0, d))(dyn.dt)
    ctx_pm = (field, dyn_pm, steps, truth, x0_pm, p0_pm, n_ss, repeats)
    bench_one("pmf", filt, ctx_pm, ss, "stonesoup-pmf",
              f"classic 2-state model in both: position random walk {Q_POS} m2/s, bias "
              f"known ({bias} mGal), {N_CELLS}x{N_CELLS} points, same prior and likelihood; "
              f"jaxgrav: fixed {CELL_M:.0f} m cells following the mean, exact discrete "
              "diffusion; Stone Soup: grid rebuilt each step along the covariance "
              "eigenvectors at +-4 sigma, linear interpolation, FFT convolution with the "
              "Gaussian transition density", keyed=False)
    filt32 = fl.pmf(N_CELLS, CELL_M, q_pos=Q_POS, ins=None, spread_dtype=jnp.float32)
    bench_one("pmf", filt32, ctx_pm, ss, "stonesoup-pmf",
              "as pmf-61, the spread's two matrix products in float32 (pmf(spread_dtype="
              "float32); weights, likelihood and moments in float64)", keyed=False,
              case="pmf-61-spread32")


def stonesoup_time(run_one, truth, n_ss, kind):
    """Seconds per run of a Stone Soup filter over the first ``n_ss`` runs, its errors and
    the runs they come from, and the failures."""
    errs, done, failed, seconds = [], [], [], 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for i in range(n_ss):
            t0 = time.perf_counter()
            try:
                out = run_one(i, 100 + i)
            except (np.linalg.LinAlgError, FloatingPointError) as exc:
                # Stone Soup's own numerics gave up on this run: counted, not timed
                failed.append(f"run {i}: {type(exc).__name__}: {exc}")
                progress(f"stone soup {kind}: run {i} failed ({failed[-1]})")
                continue
            seconds += time.perf_counter() - t0  # successful runs only
            errs.append(second_half_rms(out, np.asarray(truth[i])))
            done.append(i)
    if not errs:
        return None, [], [], failed
    per_run = seconds / len(errs)
    progress(f"stone soup {kind}: {per_run:.2f} s per run, err {np.round(errs, 1)}")
    return per_run, errs, done, failed


def bench_one(kind, filt, ctx, ss, baseline, note, keyed=True, case=None):
    """Time one jaxgrav filter over all runs against Stone Soup's per-run time."""
    field, dyn, steps, truth, x0, p0, n_ss, repeats = ctx
    ss_per_run, ss_err, ss_done, ss_failed = ss
    n_runs = truth.shape[0]

    @jax.jit
    def mc(field, dyn, steps, fkeys):
        def one(args):
            d, s, k = args
            return fl.run_filter(filt, field, d, x0, p0, s, key=k if keyed else None)[1].x[:, :2]

        return jax.lax.map(one, (dyn, steps, fkeys), batch_size=CHUNK)

    args = (field, dyn, steps, jax.random.split(jax.random.PRNGKey(1), n_runs))
    t0 = time.perf_counter()
    # the XLA options the Monte Carlo runner gives this method (jaxgrav.xla_options)
    compiled = mc.lower(*args).compile(compiler_options(cpu_options=cpu_options_for(kind))
                                       or None)
    compile_s = time.perf_counter() - t0
    est = np.asarray(jax.block_until_ready(compiled(*args)))
    jax_s = best_time(lambda: jax.block_until_ready(compiled(*args)), repeats)
    progress(f"{kind}: jaxgrav {jax_s:.2f} s for {n_runs} runs")
    err = [second_half_rms(est[i], np.asarray(truth[i])) for i in range(n_runs)]
    case = case or f"{kind}-{N_PARTICLES if kind != 'pmf' else N_CELLS}"
    if ss_per_run is None:  # no Stone Soup run finished: no ratio
        emit(BENCH, case, n_runs, jax_s, baseline, None, compile_s=round(compile_s, 2),
             baseline_failed=ss_failed, err_m_jaxgrav_all=round(float(np.mean(err)), 1))
        return
    emit(BENCH, case, n_runs, jax_s, baseline,
         ss_per_run * n_runs, runs_per_s=round(n_runs / jax_s, 2),
         stonesoup_runs_per_s=round(1.0 / ss_per_run, 3), compile_s=round(compile_s, 2),
         err_m_jaxgrav=round(float(np.mean(np.asarray(err)[ss_done])), 1),
         err_m_stonesoup=round(float(np.mean(ss_err)), 1),
         err_m_jaxgrav_all=round(float(np.mean(err)), 1),
         stonesoup_failed_runs=len(ss_failed),
         note=f"{note}; Stone Soup timed on {len(ss_err)} of {n_ss} run(s)"
              + (" (the others failed inside Stone Soup)" if ss_failed else "")
              + f", scaled to {n_runs}; err_m over those runs (second-hour RMS, different "
              "random numbers)")


if __name__ == "__main__":
    main()
