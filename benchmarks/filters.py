"""How many Monte Carlo runs per second do the paper D filters handle, against filterpy?

Paper D's filtering experiment (:func:`jaxgrav.scenarios.filter_scenario`, the
defaults of :class:`~jaxgrav.scenarios.FilterScenario`): 2 h at 5 m/s over the
three-point-mass map (:func:`jaxgrav.fields.pointmass.paper_d`), the 13-state INS
error model, a step every 2 s and a gravimeter reading every 10 s (NaN between),
1 mGal noise and bias. 1000 runs × 3600 steps (``--quick``: 50 × 600).

* ``ukf-float64``: ``jax.jit`` of :func:`~jaxgrav.filters.run_filter` with
  ``every=5`` (update only on the reading steps, prediction in between) of
  :func:`~jaxgrav.filters.ukf` (α = 0.5, β = 2, κ = 0; the map evaluated at the 5
  distinct sigma positions, one modified Cholesky per update), vmapped over runs in
  chunks of 25 (``lax.map(batch_size=25)``, a scan over vmapped chunks, which keeps each
  step's working set in cache; ``--quick``: one vmap).
* ``ukf-float64-every1``: the same filter updating on every step (NaN readings
  masked), as a user without the stride would run it.
* ``ukf-float32``: ``ukf-float64`` on the runs cast to float32 with ``jax_enable_x64``
  off, and its difference from float64.
* ``ekf-float64``: :func:`~jaxgrav.filters.ekf` (``jax.jacfwd`` Jacobian), ``every=5``.
* ``pmf-float64``: :func:`~jaxgrav.filters.run_filter` of :func:`~jaxgrav.filters.pmf`
  (default 61 × 61 grid, its error model at each run's mean latitude, one update per
  reading), on fewer runs (``n``); runs/s is what scales.
* ``pmf-float64-spread32``: the same with its spread's two matrix products in float32
  (``pmf(spread_dtype=jnp.float32)``; weights, likelihood and moments in float64), and
  its largest position difference from ``pmf-float64`` (``vs_pmf_float64_max_diff_m``).

Baseline: filterpy's ``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints(13, α, β,
κ)``, ``fx = F x``, the same Q and R, and ``hx`` the same point-mass measurement
written in NumPy (exact ECEF, as the library's); ``predict()`` every step,
``update()`` on readings. A Python loop over 1000 × 3600 steps would take about half
an hour, so filterpy is timed on a few runs and its time per run scaled to ``n``
(field ``note``). The first run's position estimates of both are compared
(``max_diff_sigma``: largest difference over the run, in units of the filter's own σ;
``max_diff_m`` in metres). Every line's baseline is the filterpy UKF.

jaxgrav's compile time is separate (``compile_s``); timed calls are compiled already,
with the XLA options the Monte Carlo runner gives the method
(:func:`jaxgrav.montecarlo.spec.cpu_options_for`: LLVM ``-O2`` with XLA's elemental
kernel emitters for the Kalman filters, with its fusion emitters for the point-mass
filter; field ``cpu_options``). ``--filters`` runs some of them only.
``--profile`` adds lines (bench ``filters_profile``) with the cost per run-step of the
parts of a filter step (prediction, factorisation, map evaluations, a whole update,
the generic 27-point update), timed as scans over 600 steps of all runs, and XLA's
``cost_analysis`` of one update and one prediction.

Run ``python benchmarks/filters.py [--quick] [--profile]``. Absolute times on a
shared machine are noise; compare within one run. Progress goes to stderr. (The
filters factor P with plain-JAX code: batched LAPACK calls under vmap could deadlock
XLA's CPU thread pool.)
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

from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter  # noqa: E402

from jaxgrav import constants as c  # noqa: E402
from jaxgrav import filters as fl  # noqa: E402
from jaxgrav import scenarios as sc  # noqa: E402
from jaxgrav._linalg import modified_cholesky  # noqa: E402
from jaxgrav.fields.pointmass import paper_d  # noqa: E402
from jaxgrav.filters import kalman  # noqa: E402
from jaxgrav.geodesy import geodetic_to_ecef  # noqa: E402
from jaxgrav.montecarlo.spec import cpu_options_for  # noqa: E402
from jaxgrav.xla_options import compiler_options  # noqa: E402

BENCH = "filters"
CHUNK = 25  # runs per vmapped chunk (divides 1000: no remainder program to compile)
ALPHA, BETA, KAPPA = 0.5, 2.0, 0.0
FILTERS = ("ukf", "ekf", "pmf", "ukf-float32")


_T0 = time.perf_counter()


def progress(msg):
    """A timestamped line on stderr (the JSON lines go to stdout)."""
    print(f"[{time.perf_counter() - _T0:7.1f} s] {msg}", file=sys.stderr, flush=True)


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="CI-sized run (~1–2 min)")
    p.add_argument("--profile", action="store_true", help="time the parts of a UKF step")
    p.add_argument("--filters", nargs="+", choices=FILTERS, default=list(FILTERS),
                   help="these filters only (default: all)")
    return p.parse_args()


# --------------------------------------------------------------------------- runs


def simulate(field, scenario, n_runs, seed=0):
    """``n_runs`` runs of the scenario: per-run Dynamics, Steps (leading axes (R, T))."""

    @jax.jit
    def sim(keys):
        def one(key):
            return sc.run_steps(sc.filter_scenario(key, field, scenario), scenario)

        return jax.vmap(one)(keys)

    return jax.block_until_ready(sim(jax.random.split(jax.random.key(seed), n_runs)))


def as_float32(tree):
    return jax.tree.map(lambda a: jnp.asarray(np.asarray(a), jnp.float32), tree)


def first(tree, n=1):
    return jax.tree.map(lambda a: np.asarray(a[:n]), tree)


# --------------------------------------------------------------------------- filterpy


class NumpyPointMassH:
    """filterpy's ``hx(x, lat, lon)``: map anomaly at the INS position minus the error + bias.

    The library's measurement (:func:`jaxgrav.filters.gravity_measurement` on
    :class:`~jaxgrav.fields.pointmass.PointMasses`) in NumPy: exact ECEF positions, the
    downward component of ∇T in the local frame, in mGal.
    """

    def __init__(self, masses):
        xm = np.stack([np.asarray(v) for v in geodetic_to_ecef(
            masses.lat, masses.lon, -np.asarray(masses.depth))], -1)  # (K, 3)
        gm = c.G_NEWTON * np.asarray(masses.mass)
        self.masses = [(*map(float, p), float(g)) for p, g in zip(xm, gm, strict=True)]

    def anomaly(self, lat, lon):
        """Scalar math (faster than NumPy on 3 masses): the fairest plain-Python baseline."""
        sp, cp = math.sin(math.radians(lat)), math.cos(math.radians(lat))
        sl, cl = math.sin(math.radians(lon)), math.cos(math.radians(lon))
        n = c.WGS84_A / math.sqrt(1.0 - c.WGS84_E2 * sp * sp)
        x, y, z = n * cp * cl, n * cp * sl, n * (1.0 - c.WGS84_E2) * sp
        ux, uy = cp * cl, cp * sl
        down = 0.0
        for mx, my, mz, gm in self.masses:
            dx, dy, dz = x - mx, y - my, z - mz
            inv_l = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
            down += gm * inv_l**3 * (dx * ux + dy * uy + dz * sp)
        return down / c.MGAL

    def __call__(self, x, lat, lon):
        sp, cp = math.sin(math.radians(lat)), math.cos(math.radians(lat))
        w = 1.0 - c.WGS84_E2 * sp * sp
        m_rad = c.WGS84_A * (1.0 - c.WGS84_E2) / w**1.5
        n_rad = c.WGS84_A / math.sqrt(w)
        true_lat = lat - x[0] / m_rad / c.DEG
        true_lon = lon - x[1] / (n_rad * cp) / c.DEG
        return np.array([self.anomaly(true_lat, true_lon) + x[12]])


def filterpy_run(hx, f, q, x0, p0, steps, dt):
    """One run of filterpy's UKF; returns position estimates and their σ, shape (T, 2)."""
    n = f.shape[0]
    points = MerweScaledSigmaPoints(n, alpha=ALPHA, beta=BETA, kappa=KAPPA)
    ukf = UnscentedKalmanFilter(n, 1, dt, hx=hx, fx=lambda x, dt: f @ x, points=points)
    ukf.x, ukf.P, ukf.Q = x0.copy(), p0.copy(), q
    ukf.R = np.array([[steps.r[0]]])
    lat, lon, z = (a.tolist() for a in (steps.lat, steps.lon, steps.z))
    t = len(z)
    pos, sig = np.empty((t, 2)), np.empty((t, 2))
    for k in range(t):
        ukf.predict()
        if math.isfinite(z[k]):
            ukf.update(np.array([z[k]]), lat=lat[k], lon=lon[k])
        pos[k] = ukf.x[:2]
        sig[k] = np.sqrt(np.diag(ukf.P)[:2])
    return pos, sig


def time_filterpy(field, dyn, steps, x0, p0, dt, n_runs):
    """Per-run time of filterpy on the first ``n_runs`` runs, and the first run's output."""
    hx = NumpyPointMassH(field)
    dyn, steps = first(dyn, n_runs), first(steps, n_runs)
    x0, p0 = np.asarray(x0, float), np.asarray(p0, float)
    outs = []
    t0 = time.perf_counter()
    for i in range(n_runs):
        s = jax.tree.map(lambda a, i=i: a[i], steps)
        outs.append(filterpy_run(hx, dyn.f[i], dyn.q[i], x0, p0, s, dt))
    return (time.perf_counter() - t0) / n_runs, outs[0]


# --------------------------------------------------------------------------- jaxgrav


def over_runs(fn, xs, chunk):
    """``vmap(fn)`` over the leading axis of ``xs``: all at once (``chunk=None``) or
    ``chunk`` runs at a time (``lax.map(batch_size=chunk)``: a scan over vmapped chunks)."""
    if chunk is None:
        return jax.vmap(fn)(xs)
    return jax.lax.map(fn, xs, batch_size=chunk)


def _summary(infos):
    return infos.x[..., :2], infos.sigma[..., :2], jnp.bitwise_or.reduce(infos.status, axis=-1)


def monte_carlo(filt, chunk=None, every=1):
    """jit(vmap(run_filter)) returning position estimates, their σ and the OR of the flags."""

    @jax.jit
    def mc(field, dyn, x0, p0, steps):
        def one(args):
            return _summary(fl.run_filter(filt, field, args[0], x0, p0, args[1], every)[1])

        return over_runs(one, (dyn, steps), chunk)

    return mc


def monte_carlo_pmf(filt, dt, every, chunk=None):
    @jax.jit
    def mc(field, x0, p0, steps):
        def one(s):
            dyn = filt.dynamics(jnp.mean(s.lat), dt)
            return _summary(fl.run_filter(filt, field, dyn, x0, p0, s, every)[1])

        return over_runs(one, steps, chunk)

    return mc


def time_compiled(fn, args, repeats, kind="ukf"):
    """(compile_s, best run s, output), compiled with the options the runner gives
    the method ``kind``."""
    t0 = time.perf_counter()
    options = compiler_options(cpu_options=cpu_options_for(kind))  # as the runner does
    compiled = fn.lower(*args).compile(options or None)
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = jax.block_until_ready(compiled(*args))
    first_s = time.perf_counter() - t0
    if repeats > 1:
        first_s = min(first_s, best_time(lambda: jax.block_until_ready(compiled(*args)),
                                         repeats - 1))
    return compile_s, first_s, jax.tree.map(np.asarray, out)


def flags(status):
    """Names of the flags set in any run, with the number of runs."""
    names = {}
    for name, bit in fl.STATUS_FILTER.items():
        k = int(np.sum((status & bit) != 0)) if bit else 0
        if k:
            names[name] = k
    return names


def agreement(pos, sig, ref_pos, ref_sig):
    return {
        "max_diff_sigma": float(f"{np.max(np.abs(pos - ref_pos) / ref_sig):.3g}"),
        "max_diff_m": float(f"{np.max(np.abs(pos - ref_pos)):.3g}"),
        "max_sigma_rel_diff": float(f"{np.max(np.abs(sig / ref_sig - 1.0)):.3g}"),
    }


# --------------------------------------------------------------------------- profile


def _generic_gravity(field, x, lat, lon):
    """The gravity measurement as an opaque callable: the UKF's generic 27-point path."""
    return fl.gravity_measurement(field, x, lat, lon)


def profile(field, dyn, steps, x0, p0, every, dtype, repeats):
    """Per run-step cost of the parts of a filter step (runs in chunks of CHUNK)."""
    r, t = steps.z.shape
    ukf = fl.ukf(alpha=ALPHA, beta=BETA, kappa=KAPPA)
    ukf_generic = fl.ukf(_generic_gravity, alpha=ALPHA, beta=BETA, kappa=KAPPA)
    ekf = fl.ekf()

    def scan_vmap(body):
        def f(field, dyn, x0, p0, steps):
            def one(d, s):
                def b(st, s1):
                    return body(st, s1, field, d)

                return jax.lax.scan(b, fl.FilterState(x0, p0), s)[1]

            return over_runs(lambda a: one(*a), (dyn, steps), CHUNK)

        return f

    def predict_body(st, s, field, d):
        st = kalman.predict(st, d.f, d.q)
        return st, st.x[:2] + st.p[0, :2]

    def predict_info_body(st, s, field, d):
        st, info = ukf.predict(st, s, field, d)
        return st, info.x[:2] + info.sigma[:2]

    def chol_body(st, s, field, d):
        st = kalman.predict(st, d.f, d.q)
        return st, modified_cholesky(st.p)[0][:2, 0]

    def map5_body(st, s, field, d):
        st = kalman.predict(st, d.f, d.q)
        pos = st.x[:2] + jnp.arange(5.0, dtype=st.x.dtype)[:, None]
        zs = jax.vmap(lambda p: fl.map_at_error(field, p, s.lat, s.lon))(pos)
        return st, st.x[:2] + zs.sum()

    def update_body(filt):
        def body(st, s, field, d):
            st, info = filt.update(st, s, field, d)
            return st, info.x[:2]

        return body

    args = (field, dyn, x0, p0, steps)
    parts = [
        ("predict x, P", scan_vmap(predict_body)),
        ("predict + step info (predict-only step)", scan_vmap(predict_info_body)),
        ("predict + modified cholesky", scan_vmap(chol_body)),
        ("predict + 5 map evaluations", scan_vmap(map5_body)),
        ("ukf update, every step (5 map points, 1 cholesky)", scan_vmap(update_body(ukf))),
        ("ukf update, every step, generic 27-point measurement",
         scan_vmap(update_body(ukf_generic))),
        ("ekf update, every step", scan_vmap(update_body(ekf))),
    ]
    for name, fn in parts:
        progress(f"profile {dtype}: {name}")
        _, secs, _ = time_compiled(jax.jit(fn), args, repeats)
        print_profile(name, r, t, secs, dtype)
    for name, filt in [(f"ukf run_filter every={every}", ukf),
                       (f"ekf run_filter every={every}", ekf)]:
        progress(f"profile {dtype}: {name}")
        _, secs, _ = time_compiled(monte_carlo(filt, CHUNK, every), args, repeats)
        print_profile(name, r, t, secs, dtype)

    # XLA's count for one update with a reading and one prediction (unvmapped)
    st = fl.FilterState(x0, p0)
    s1 = jax.tree.map(lambda a: a[0, every - 1], steps)
    d1 = jax.tree.map(lambda a: a[0], dyn)
    for name, fn in [("ukf update", ukf.update), ("ukf update, generic", ukf_generic.update),
                     ("ekf update", ekf.update), ("predict-only step", ukf.predict)]:
        cost = jax.jit(fn).lower(st, s1, field, d1).compile().cost_analysis()
        cost = cost[0] if isinstance(cost, list) else cost
        print(json.dumps({"bench": f"{BENCH}_profile", "part": f"cost_analysis: {name}",
                          "dtype": dtype, "flops": cost.get("flops"),
                          "transcendentals": cost.get("transcendentals"),
                          "bytes_accessed": cost.get("bytes accessed")}), flush=True)


def print_profile(part, r, t, secs, dtype, **extra):
    print(json.dumps({"bench": f"{BENCH}_profile", "part": part, "dtype": dtype, "n": r,
                      "steps": t,
                      "seconds": round(secs, 4), "us_per_run_step": round(secs / r / t * 1e6, 3),
                      "runs_per_s_at_3600": round(r / secs * t / 3600, 2), **extra}), flush=True)


# --------------------------------------------------------------------------- main


def cname(case, chunk):
    return case + (f"-chunk{chunk}" if chunk else "")


def main():
    args = parse_args()
    n_runs, n_steps = (50, 600) if args.quick else (1000, 3600)
    n_fp = 2 if args.quick else 3
    n_pmf = 10 if args.quick else 100
    repeats = 2 if args.quick else 1
    scenario = sc.FilterScenario(n_steps=n_steps + 1)
    dt, every = float(scenario.dt), scenario.reading_every
    field = paper_d()
    x0, p0 = sc.initial_state(scenario)
    progress(f"simulating {n_runs} runs × {n_steps} steps")
    dyn, steps = simulate(field, scenario, n_runs)
    progress(f"filterpy on {n_fp} runs")
    note = (f"filterpy timed on {n_fp} runs, its time per run scaled to n; filterpy's hx is "
            "the same point-mass measurement in NumPy")
    common = {"steps": n_steps, "reading_every": every}

    fp_per_run, (fp_pos, fp_sig) = time_filterpy(field, dyn, steps, x0, p0, dt, n_fp)
    base = f"filterpy UnscentedKalmanFilter loop (MerweScaledSigmaPoints, alpha={ALPHA})"

    def line(case, n, secs, compile_s, out, **extra):
        status = out[2]
        emit(BENCH, case, n, secs, base, fp_per_run * n, runs_per_s=round(n / secs, 2),
             baseline_runs_per_s=round(1.0 / fp_per_run, 3), compile_s=round(compile_s, 2),
             flags=flags(status), note=note, **common, **extra)

    # UKF, float64: updates on the reading steps, then on every step --------------
    ukf = fl.ukf(alpha=ALPHA, beta=BETA, kappa=KAPPA)
    args64 = (field, dyn, x0, p0, steps)
    # chunks pay off only for large batches (cache); --quick runs one vmap
    chunk_best = CHUNK if n_runs >= 10 * CHUNK else None
    ukf_opts = dict(cpu_options=str(cpu_options_for("ukf")))
    out64 = None
    if {"ukf", "ekf", "ukf-float32"} & set(args.filters):
        progress("ukf-float64")
        compile_s, secs, out64 = time_compiled(monte_carlo(ukf, chunk_best, every), args64,
                                               repeats)
        line(cname("ukf-float64", chunk_best), n_runs, secs, compile_s, out64, chunk=chunk_best,
             every=every, **agreement(out64[0][0], out64[1][0], fp_pos, fp_sig), **ukf_opts)
    if "ukf" in args.filters:
        progress("ukf-float64-every1")
        compile_s, secs, out1 = time_compiled(monte_carlo(ukf, chunk_best, 1), args64, repeats)
        line(cname("ukf-float64-every1", chunk_best), n_runs, secs, compile_s, out1,
             chunk=chunk_best, every=1, **agreement(out1[0][0], out1[1][0], fp_pos, fp_sig),
             every5_vs_every1_max_diff_m=float(f"{np.max(np.abs(out64[0] - out1[0])):.3g}"),
             **ukf_opts)

    # EKF, float64 -----------------------------------------------------------------
    if "ekf" in args.filters:
        progress("ekf")
        compile_s, secs, oute = time_compiled(monte_carlo(fl.ekf(), chunk_best, every), args64,
                                              repeats, kind="ekf")
        line(cname("ekf-float64", chunk_best), n_runs, secs, compile_s, oute, chunk=chunk_best,
             every=every, ekf_vs_ukf_max_diff_sigma=float(
                 f"{np.max(np.abs(oute[0] - out64[0]) / out64[1]):.3g}"),
             cpu_options=str(cpu_options_for("ekf")))

    # PMF, float64 -----------------------------------------------------------------
    if "pmf" in args.filters:
        progress("pmf")
        sub = jax.tree.map(lambda a: a[:n_pmf], steps)
        pmf_chunk = CHUNK if n_pmf > CHUNK else None
        compile_s, secs, outp = time_compiled(monte_carlo_pmf(fl.pmf(), dt, every, pmf_chunk),
                                              (field, x0, p0, sub), repeats, kind="pmf")
        line(cname("pmf-float64", pmf_chunk), n_pmf, secs, compile_s, outp, chunk=pmf_chunk,
             pmf_grid="61 x 61 cells of 200 m", cpu_options=str(cpu_options_for("pmf")))
        progress("pmf, spread in float32")
        compile_s, secs, out32 = time_compiled(
            monte_carlo_pmf(fl.pmf(spread_dtype=jnp.float32), dt, every, pmf_chunk),
            (field, x0, p0, sub), repeats, kind="pmf")
        line(cname("pmf-float64-spread32", pmf_chunk), n_pmf, secs, compile_s, out32,
             chunk=pmf_chunk, pmf_grid="61 x 61 cells of 200 m",
             cpu_options=str(cpu_options_for("pmf")),
             vs_pmf_float64_max_diff_m=float(f"{np.max(np.abs(out32[0] - outp[0])):.3g}"))

    # the profile runs on at most 600 steps of the timed runs
    prof_t = min(n_steps, 600)
    prof_steps = jax.tree.map(lambda a: a[:, :prof_t], steps)
    prof_repeats = 3 if args.quick else 2
    if args.profile:
        profile(field, dyn, prof_steps, x0, p0, every, "float64", prof_repeats)

    # UKF, float32 -----------------------------------------------------------------
    if "ukf-float32" not in args.filters:
        return
    progress("ukf float32")
    jax.config.update("jax_enable_x64", False)
    try:
        a32 = as_float32(args64)
        compile_s, secs, out32 = time_compiled(monte_carlo(ukf, chunk_best, every), a32,
                                               repeats)
        diff = np.abs(out32[0] - out64[0])
        line(cname("ukf-float32", chunk_best), n_runs, secs, compile_s, out32, chunk=chunk_best,
             every=every, **agreement(out32[0][0], out32[1][0], fp_pos, fp_sig),
             f32_vs_f64_max_diff_m=float(f"{diff.max():.3g}"),
             f32_vs_f64_median_max_diff_m=float(f"{np.median(diff.max(axis=(1, 2))):.3g}"),
             f32_vs_f64_max_diff_sigma=float(f"{np.max(diff / out64[1]):.3g}"), **ukf_opts)
        if args.profile:
            profile(*as_float32((field, dyn, prof_steps, x0, p0)), every, "float32",
                    prof_repeats)
    finally:
        jax.config.update("jax_enable_x64", True)


if __name__ == "__main__":
    main()
