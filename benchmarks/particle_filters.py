"""How fast are jaxgrav's particle filters against the same filters written in plain NumPy?

Paper D's filtering scenario as the Monte Carlo methods ``pf`` / ``rbpf`` run it
(:func:`jaxgrav.montecarlo.filter_runs.filter_builder`): 2 h at 5 m/s over the three
point masses, a 10 s step with a reading every step (721 steps), the 13-state INS error
model, 1 mGal noise. ``n`` runs (default 100, ``--quick`` 10).

* ``rbpf``: :func:`~jaxgrav.filters.rbpf` (1000 particles over the position error, one
  shared Kalman covariance for the other 11 states), ``jit`` of
  :func:`~jaxgrav.filters.run_filter`, runs batched by ``lax.map(batch_size=25)`` over
  ``vmap``;
* ``pf``: :func:`~jaxgrav.filters.pf` (1000 particles over all 13 states), the same way.

Baseline: the same algorithms in NumPy, the particles vectorised as NumPy arrays and a
Python loop over the steps (the plain NumPy way a user would write them): the same
moves, likelihoods, systematic resampling at ESS < N/2 and moment-preserving
regularisation (the RBPF's of positions and means together), the point-mass anomaly
vectorised over particles. Timed on a few runs and scaled per run (field ``note``).
Both are scored on those runs: RMS position error over the second hour (``err_m``;
different random numbers, so equal within Monte Carlo noise, not to the digit).
jaxgrav's compile time is separate (``compile_s``); each filter is compiled with the XLA
options the Monte Carlo runner gives its method
(:func:`jaxgrav.montecarlo.spec.cpu_options_for`).

A ``particle_filters_profile`` line per filter gives how often it resamples (the share
of steps at which a run does, and at which one of a batch of 25 does).

Run ``python benchmarks/particle_filters.py [--quick]``; JSON lines on stdout, progress
on stderr. Compare ratios within one run (shared machine).
"""

import argparse
import json
import math
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import best_time, emit

jax.config.update("jax_enable_x64", True)  # a script, not the library

from jaxgrav import constants as c  # noqa: E402
from jaxgrav import filters as fl  # noqa: E402
from jaxgrav import scenarios as sc  # noqa: E402
from jaxgrav.fields.pointmass import paper_d  # noqa: E402
from jaxgrav.filters.particles import kernel_bandwidth  # noqa: E402
from jaxgrav.geodesy import geodetic_to_ecef  # noqa: E402
from jaxgrav.montecarlo.spec import cpu_options_for  # noqa: E402
from jaxgrav.sim.ins import GRAV  # noqa: E402
from jaxgrav.xla_options import compiler_options  # noqa: E402

BENCH = "particle_filters"
N_PARTICLES = 1000
CHUNK = 25
ROUGHENING = {"rbpf": 1.0, "pf": 0.5}  # the library defaults (shares of the optimal)
_T0 = time.perf_counter()


def progress(msg):
    print(f"[{time.perf_counter() - _T0:7.1f} s] {msg}", file=sys.stderr, flush=True)


class NumpyAnomaly:
    """Paper D's point-mass anomaly (mGal) at arrays of points, in NumPy (exact ECEF)."""

    def __init__(self, masses):
        self.xm = np.stack([np.asarray(v) for v in geodetic_to_ecef(
            masses.lat, masses.lon, -np.asarray(masses.depth))], -1)  # (K, 3)
        self.gm = c.G_NEWTON * np.asarray(masses.mass)

    def __call__(self, lat, lon):
        sp, cp = np.sin(np.radians(lat)), np.cos(np.radians(lat))
        sl, cl = np.sin(np.radians(lon)), np.cos(np.radians(lon))
        n = c.WGS84_A / np.sqrt(1.0 - c.WGS84_E2 * sp * sp)
        p = np.stack([n * cp * cl, n * cp * sl, n * (1.0 - c.WGS84_E2) * sp], -1)[..., None, :]
        d = p - self.xm  # (..., K, 3)
        up = np.stack([cp * cl, cp * sl, sp], -1)[..., None, :]
        inv_l3 = np.sum(d * d, -1) ** -1.5
        return np.sum(self.gm * inv_l3 * np.sum(d * up, -1), -1) / c.MGAL


def true_position(lat, lon, dn, de):
    sp = math.sin(math.radians(lat))
    w = 1.0 - c.WGS84_E2 * sp * sp
    m_rad = c.WGS84_A * (1.0 - c.WGS84_E2) / w**1.5
    n_rad = c.WGS84_A / math.sqrt(w)
    return lat - dn / m_rad / c.DEG, lon - de / (n_rad * math.cos(math.radians(lat))) / c.DEG


def _systematic(rng, w):
    n = w.size
    idx = np.searchsorted(np.cumsum(w) / np.sum(w), (rng.random() + np.arange(n)) / n, "right")
    return np.minimum(idx, n - 1)


def _roughen(rng, x, mean, cov, h):
    a = math.sqrt(1.0 - h * h)
    vals, vecs = np.linalg.eigh(cov)
    root = vecs * np.sqrt(np.clip(vals, 0.0, None))
    return a * x + (1.0 - a) * mean + h * rng.standard_normal(x.shape) @ root.T


def numpy_rbpf(anomaly, f, q, x0, p0, lat, lon, z, r, n, rng):
    """The library's Rao–Blackwellised filter in NumPy; returns (T, 2) position means."""
    pos = x0[:2] + rng.standard_normal((n, 2)) @ np.linalg.cholesky(p0[:2, :2]).T
    gain = p0[2:, :2] @ np.linalg.inv(p0[:2, :2])
    m = x0[2:] + (pos - x0[:2]) @ gain.T
    p = p0[2:, 2:] - gain @ p0[2:, :2].T
    logw = np.full(n, -math.log(n))
    cvec = np.zeros(x0.size - 2)
    cvec[GRAV - 2] = 1.0
    h = ROUGHENING["rbpf"] * kernel_bandwidth(n, x0.size)
    out = np.empty((z.size, 2))
    for k in range(z.size):
        mu = pos @ f[:, :2].T + m @ f[:, 2:].T
        s = f[:, 2:] @ p @ f[:, 2:].T + q
        s = 0.5 * (s + s.T)
        s_pp = s[:2, :2] + 1e-9 * np.trace(s[:2, :2]) * np.eye(2)  # as the library
        gain = s[2:, :2] @ np.linalg.inv(s_pp)
        new = mu[:, :2] + rng.standard_normal((n, 2)) @ np.linalg.cholesky(s_pp).T
        m = mu[:, 2:] + (new - mu[:, :2]) @ gain.T
        p = s[2:, 2:] - gain @ s[2:, :2].T
        p = 0.5 * (p + p.T)
        pos = new
        if math.isfinite(z[k]):
            tl, tn = true_position(lat[k], lon[k], pos[:, 0], pos[:, 1])
            resid = z[k] - (anomaly(tl, tn) + m @ cvec)
            pc = p @ cvec
            sv = cvec @ pc + r
            kg = pc / sv
            logw = logw - 0.5 * resid**2 / sv
            logw -= np.logaddexp.reduce(logw)
            m = m + resid[:, None] * kg
            p = p - sv * np.outer(kg, kg)
            p = 0.5 * (p + p.T)
        w = np.exp(logw)
        out[k] = w @ pos
        if 1.0 / np.sum(w**2) < 0.5 * n:
            x = np.concatenate([pos, m], 1)  # positions and means roughened together
            mean = w @ x
            cov = (w[:, None] * (x - mean)).T @ (x - mean)
            x = _roughen(rng, x[_systematic(rng, w)], mean, cov, h)
            pos, m = x[:, :2], x[:, 2:]
            logw = np.full(n, -math.log(n))
    return out


def numpy_pf(anomaly, f, q, x0, p0, lat, lon, z, r, n, rng):
    """The library's SIR filter in NumPy; returns (T, 2) position means."""
    def root(a):
        vals, vecs = np.linalg.eigh(a)
        return vecs * np.sqrt(np.clip(vals, 0.0, None))

    x = x0 + rng.standard_normal((n, x0.size)) @ root(p0).T
    q_root = root(q)
    logw = np.full(n, -math.log(n))
    h = ROUGHENING["pf"] * kernel_bandwidth(n, x0.size)
    out = np.empty((z.size, 2))
    for k in range(z.size):
        x = x @ f.T + rng.standard_normal(x.shape) @ q_root.T
        if math.isfinite(z[k]):
            tl, tn = true_position(lat[k], lon[k], x[:, 0], x[:, 1])
            resid = z[k] - (anomaly(tl, tn) + x[:, GRAV])
            logw = logw - 0.5 * resid**2 / r
            logw -= np.logaddexp.reduce(logw)
        w = np.exp(logw)
        out[k] = w @ x[:, :2]
        if 1.0 / np.sum(w**2) < 0.5 * n:
            mean = w @ x
            cov = (w[:, None] * (x - mean)).T @ (x - mean)
            x = _roughen(rng, x[_systematic(rng, w)], mean, cov, h)
            logw = np.full(n, -math.log(n))
    return out


def second_half_rms(est, truth):
    half = truth.shape[0] // 2
    return float(np.sqrt(np.mean(np.sum((truth[half:] - est[half:]) ** 2, -1))))


def paper_d_runs(n_runs):
    """Paper D's ``n_runs`` runs (seed 0) as the benchmarks filter them.

    Returns
    -------
    field, scen, dyn, steps, truth, x0, p0
        The point masses, the scenario, the runs' dynamics and steps (leading axis:
        run), the true position errors ``(n_runs, T − 1, 2)`` (m) and the filters' prior.
    """
    field = paper_d()
    scen = sc.FilterScenario(dt=10.0, reading_every=1, n_steps=721)
    x0, p0 = sc.initial_state(scen)

    @jax.jit
    def simulate(keys):
        def one(key):
            run = sc.filter_scenario(key, field, scen)
            dyn, steps = sc.run_steps(run, scen)
            return dyn, steps, run.errors[1:, :2]

        return jax.vmap(one)(keys)

    keys = jax.random.split(jax.random.key(0), n_runs)
    dyn, steps, truth = jax.block_until_ready(simulate(keys))
    progress(f"{n_runs} runs simulated")
    return field, scen, dyn, steps, truth, x0, p0


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="10 runs, 1 NumPy run per filter")
    p.add_argument("--runs", type=int, default=None, help="runs for jaxgrav (default 100)")
    a = p.parse_args()
    n_runs = a.runs or (10 if a.quick else 100)
    n_np = 1 if a.quick else 3
    field, _, dyn, steps, truth, x0, p0 = paper_d_runs(n_runs)
    anomaly = NumpyAnomaly(field)
    for kind, make, ref in (("rbpf", fl.rbpf, numpy_rbpf), ("pf", fl.pf, numpy_pf)):
        bench_one(kind, make(N_PARTICLES), ref, field, anomaly, dyn, steps, truth, x0, p0,
                  n_np, 1 if a.quick else 2)
        resampling_shares(kind, make(N_PARTICLES), field, dyn, steps, x0, p0)


def resampling_shares(kind, filt, field, dyn, steps, x0, p0):
    """How often the filter resamples: the share of steps at which a run resamples, and
    at which at least one run of a batch of ``CHUNK`` does (what a batched resampling
    that runs every run whenever one needs it would pay). A JSON line of its own."""
    n = min(CHUNK, steps.z.shape[0])

    @jax.jit
    def flags(field, dyn, steps, keys):
        def one(d, s, k):
            def body(state, step):
                state, _ = filt.update(state, step, field, d)
                return state, jnp.max(state.log_w) == jnp.min(state.log_w)  # reset weights

            return jax.lax.scan(body, filt.init(x0, p0, key=k), s)[1]

        return jax.vmap(one)(dyn, steps, keys)

    def first(tree):
        return jax.tree.map(lambda v: v[:n], tree)

    done = np.asarray(flags(field, first(dyn), first(steps),
                            jax.random.split(jax.random.PRNGKey(1), n)))
    print(json.dumps({"bench": f"{BENCH}_profile", "case": f"{kind}-resampling", "n": n,
                      "share_of_steps_a_run_resamples": round(float(done.mean()), 4),
                      f"share_of_steps_one_of_{n}_runs_resamples":
                          round(float(done.any(0).mean()), 4)}), flush=True)


def bench_one(kind, filt, ref, field, anomaly, dyn, steps, truth, x0, p0, n_np, repeats):
    """Time one particle filter against its NumPy loop; print the JSON line."""
    n_runs = truth.shape[0]

    @jax.jit
    def mc(field, dyn, steps, fkeys):
        def one(args):
            d, s, k = args
            return fl.run_filter(filt, field, d, x0, p0, s, key=k)[1].x[:, :2]

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
    rng = np.random.default_rng(1)
    np_err, t0 = [], time.perf_counter()
    for i in range(n_np):
        out = ref(anomaly, np.asarray(dyn.f[i]), np.asarray(dyn.q[i]), np.asarray(x0),
                  np.asarray(p0), np.asarray(steps.lat[i]), np.asarray(steps.lon[i]),
                  np.asarray(steps.z[i]), float(steps.r[i, 0]), N_PARTICLES, rng)
        np_err.append(second_half_rms(out, np.asarray(truth[i])))
    np_per_run = (time.perf_counter() - t0) / n_np
    progress(f"{kind}: numpy {np_per_run:.2f} s per run")
    err = [second_half_rms(est[i], np.asarray(truth[i])) for i in range(n_runs)]
    emit(BENCH, f"{kind}-{N_PARTICLES}", n_runs, jax_s, f"numpy-{kind}-loop",
         np_per_run * n_runs, runs_per_s=round(n_runs / jax_s, 2),
         compile_s=round(compile_s, 2), err_m_jaxgrav=round(float(np.mean(err[:n_np])), 1),
         err_m_numpy=round(float(np.mean(np_err)), 1),
         err_m_jaxgrav_all=round(float(np.mean(err)), 1),
         note=f"numpy timed on {n_np} run(s), scaled to {n_runs}; err_m over those runs "
              "(second hour RMS, different random numbers)")

if __name__ == "__main__":
    main()
