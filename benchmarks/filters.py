"""How many Monte Carlo runs per second do the paper D filters handle, against filterpy?

Paper D's filtering experiment (:func:`jaxgrav.match.filters.filter_scenario`, the
defaults of :class:`~jaxgrav.match.filters.FilterScenario`): 2 h at 5 m/s over the
three-point-mass map (:func:`jaxgrav.fields.pointmass.paper_d`), the 13-state INS
error model, a step every 2 s and a gravimeter reading every 10 s (NaN between),
1 mGal noise and bias. 1000 runs × 3600 steps (``--quick``: 50 × 600).

* ``ukf-float64``: ``jax.jit(jax.vmap(run_filter))`` of
  :func:`~jaxgrav.match.filters.ukf` (α = 0.5, β = 2, κ = 0) over all runs at once;
  ``ukf-float64-chunk25`` the same in chunks of 25 runs (``lax.map(batch_size=25)``, a
  scan over vmapped chunks), which keeps each step's working set in cache (full run
  only: at 50 runs there is nothing to chunk).
* ``ukf-float32``: the same runs cast to float32 with ``jax_enable_x64`` off, and its
  difference from float64.
* ``ekf-float64``: :func:`~jaxgrav.match.filters.ekf` (``jax.jacfwd`` Jacobian), same runs.
* ``pmf-float64``: :func:`~jaxgrav.match.filters.run_pmf` (default 61 × 61 grid, one
  update per reading), on fewer runs (``n``); runs/s is what scales.

The full run's EKF, PMF and float32 cases run chunked too (case name ``-chunk25``).

Baseline: filterpy's ``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints(13, α, β,
κ)``, ``fx = F x``, the same Q and R, and ``hx`` the same point-mass measurement
written in NumPy (exact ECEF, as the library's); ``predict()`` every step,
``update()`` on readings. A Python loop over 1000 × 3600 steps would take about half
an hour, so filterpy is timed on a few runs and its time per run scaled to ``n``
(field ``note``). The first run's position estimates of both are compared
(``max_diff_sigma``: largest difference over the run, in units of the filter's own σ;
``max_diff_m`` in metres). Every line's baseline is the filterpy UKF.

jaxgrav's compile time is separate (``compile_s``); timed calls are compiled already.
``--profile`` adds lines (bench ``filters_profile``) with the cost of the parts of a
UKF step and of prototype restructurings (not library code): updating only on the
steps that have a reading, evaluating the map at the 5 distinct sigma-point positions
instead of 27, and one Cholesky factorisation per update instead of two; each reports
its largest difference from the library's estimates.

Run ``python benchmarks/filters.py [--quick] [--profile]``. Absolute times on a
shared machine are noise; compare within one run. Progress goes to stderr. (Before
the filters factored P with plain-JAX code, batched LAPACK calls under vmap could
deadlock XLA's CPU thread pool; the profile uses the same plain-JAX Cholesky.)
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
from jaxgrav._linalg import cholesky as small_cholesky  # noqa: E402
from jaxgrav.fields.pointmass import paper_d  # noqa: E402
from jaxgrav.geodesy import geodetic_to_ecef  # noqa: E402
from jaxgrav.match import filters as fl  # noqa: E402
from jaxgrav.match.filters import kalman  # noqa: E402

BENCH = "filters"
CHUNK = 25  # runs per vmapped chunk (divides 1000: no remainder program to compile)
ALPHA, BETA, KAPPA = 0.5, 2.0, 0.0


_T0 = time.perf_counter()


def progress(msg):
    """A timestamped line on stderr (the JSON lines go to stdout)."""
    print(f"[{time.perf_counter() - _T0:7.1f} s] {msg}", file=sys.stderr, flush=True)


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="CI-sized run (~1–2 min)")
    p.add_argument("--profile", action="store_true", help="time the parts of a UKF step")
    return p.parse_args()


# --------------------------------------------------------------------------- runs


def simulate(field, scenario, n_runs, seed=0):
    """``n_runs`` runs of the scenario: per-run Dynamics, Steps (leading axes (R, T))."""

    @jax.jit
    def sim(keys):
        def one(key):
            return fl.run_steps(fl.filter_scenario(key, field, scenario), scenario)

        return jax.vmap(one)(keys)

    return jax.block_until_ready(sim(jax.random.split(jax.random.key(seed), n_runs)))


def as_float32(tree):
    return jax.tree.map(lambda a: jnp.asarray(np.asarray(a), jnp.float32), tree)


def first(tree, n=1):
    return jax.tree.map(lambda a: np.asarray(a[:n]), tree)


# --------------------------------------------------------------------------- filterpy


class NumpyPointMassH:
    """filterpy's ``hx(x, lat, lon)``: map anomaly at the INS position minus the error + bias.

    The library's measurement (:func:`jaxgrav.match.filters.gravity_measurement` on
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


def monte_carlo(filt, chunk=None):
    """jit(vmap(run_filter)) returning position estimates, their σ and the OR of the flags."""

    @jax.jit
    def mc(field, dyn, x0, p0, steps):
        def one(args):
            return _summary(fl.run_filter(filt, field, args[0], x0, p0, args[1])[1])

        return over_runs(one, (dyn, steps), chunk)

    return mc


def monte_carlo_pmf(filt, dt, every, chunk=None):
    @jax.jit
    def mc(field, x0, p0, steps):
        def one(s):
            return _summary(fl.run_pmf(filt, field, dt, x0, p0, s, every)[1])

        return over_runs(one, steps, chunk)

    return mc


def time_compiled(fn, args, repeats):
    """(compile_s, best run s, output)."""
    t0 = time.perf_counter()
    compiled = fn.lower(*args).compile()
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


def _ukf5_update(state, step, field, dynamics, cholesky=kalman._robust_cholesky):
    """Prototype (not library code): the library's UKF update with the map evaluated only at
    the 5 distinct sigma-point positions.

    With the position states first and a lower Cholesky factor L, only columns 0 and 1 of
    L move the position; the other 22 sigma points sit at the mean position and differ
    in h only through the bias state, which enters linearly: h = map(pos) + x[12].
    """
    pred = kalman.predict(state, dynamics.f, dynamics.q)
    n = pred.x.shape[0]
    scale, wm, wc = kalman.sigma_weights(n, ALPHA, BETA, KAPPA)
    chol, repaired, failed = cholesky(pred.p)
    delta = jnp.sqrt(scale) * chol.T
    points = jnp.concatenate([pred.x[None], pred.x + delta, pred.x - delta])
    pos = jnp.concatenate([pred.x[None, :2], pred.x[:2] + delta[:2, :2],
                           pred.x[:2] - delta[:2, :2]])
    zero = jnp.zeros(n, pred.x.dtype)
    g5 = jax.vmap(lambda p: fl.gravity_measurement(field, zero.at[:2].set(p), step.lat,
                                                   step.lon))(pos)
    rest = jnp.full(n - 2, g5[0])
    zs = jnp.concatenate([g5[:3], rest, g5[3:], rest]) + points[:, 12]
    off_map = ~jnp.all(jnp.isfinite(zs))
    zs = jnp.where(jnp.isfinite(zs), zs, 0.0)
    z_hat = wm @ zs
    dz = zs - z_hat
    s = wc @ dz**2 + step.r
    pxz = (wc * dz) @ (points - pred.x)
    z = jnp.where(jnp.isfinite(step.z), step.z, z_hat)
    nu = z - z_hat
    k = pxz / s
    flags_, skip = kalman._flags(step.z, s, nu, jnp.inf, off_map)
    flags_ = flags_ | jnp.where(repaired, fl.STATUS_FILTER["covariance_repaired"], 0)
    flags_ = flags_ | jnp.where(failed, fl.STATUS_FILTER["covariance_failed"], 0)
    nu_out = jnp.where(jnp.isfinite(step.z), nu, jnp.nan)
    return kalman._finish(pred, pred.x + k * nu, pred.p - s * jnp.outer(k, k), nu_out, s,
                          flags_, skip | failed)


def _ukf5_single_cholesky_update(state, step, field, dynamics):
    """Prototype: the 5-point update with one plain Cholesky instead of the robust pair."""

    def plain(p):
        low = small_cholesky(p)
        failed = ~jnp.all(jnp.isfinite(low))
        return jnp.where(failed, 0.0, low), False, failed

    return _ukf5_update(state, step, field, dynamics, plain)


def _reading_rate_run(update, field, dyn, x0, p0, steps, every):
    """Prototype: scan over blocks of ``every`` steps, ``every − 1`` pure predictions
    (what the library's update computes on a NaN reading) then one full update."""
    t = steps.z.shape[0]
    blocks = jax.tree.map(lambda a: a.reshape(t // every, every), steps)

    def block(state, bs):
        def pred_only(st, _):
            st = kalman.predict(st, dyn.f, dyn.q)
            return st, st.x[:2]

        state, xs = jax.lax.scan(pred_only, state, None, length=every - 1)
        state, info = update(state, jax.tree.map(lambda a: a[-1], bs), field, dyn)
        return state, jnp.concatenate([xs, info.x[None, :2]])

    state, xs = jax.lax.scan(block, fl.FilterState(x0, p0), blocks)
    return state, xs.reshape(t, 2)


def profile(field, dyn, steps, x0, p0, every, ref_pos, dtype, repeats):
    """Per run-step cost of the UKF's parts and of the prototypes (runs in chunks of CHUNK)."""
    r, t = steps.z.shape
    ukf = fl.ukf(alpha=ALPHA, beta=BETA, kappa=KAPPA)

    def scan_vmap(body):
        def f(field, dyn, x0, p0, steps):
            def one(d, s):
                def b(st, s1):
                    return body(st, s1, field, d)

                return jax.lax.scan(b, fl.FilterState(x0, p0), s)

            return over_runs(lambda a: one(*a), (dyn, steps), CHUNK)

        return f

    def predict_body(st, s, field, d):
        st = kalman.predict(st, d.f, d.q)
        return st, st.x[:2] + st.p[0, :2]

    def chol_body(st, s, field, d):
        st = kalman.predict(st, d.f, d.q)
        low = small_cholesky(st.p)
        return st, low[:2, 0]

    def robust_body(st, s, field, d):
        st = kalman.predict(st, d.f, d.q)
        low = kalman._robust_cholesky(st.p)[0]
        return st, low[:2, 0]

    def measure_body(st, s, field, d):
        st = kalman.predict(st, d.f, d.q)
        pts = st.x + jnp.arange(27.0, dtype=st.x.dtype)[:, None] * jnp.ones_like(st.x)
        zs = jax.vmap(lambda xi: fl.gravity_measurement(field, xi, s.lat, s.lon))(pts)
        return st, st.x[:2] + zs.sum()

    def ukf_body(st, s, field, d):
        st, info = ukf.update(st, s, field, d)
        return st, info.x[:2]

    def ukf5_body(st, s, field, d):
        st, info = _ukf5_update(st, s, field, d)
        return st, info.x[:2]

    args = (field, dyn, x0, p0, steps)
    parts = [
        ("predict x, P", scan_vmap(predict_body)),
        ("predict + 1 cholesky", scan_vmap(chol_body)),
        ("predict + robust cholesky (library: 2 factorisations)", scan_vmap(robust_body)),
        ("predict + 27 map evaluations", scan_vmap(measure_body)),
        ("ukf (library), every step", scan_vmap(ukf_body)),
        ("prototype: 5 map evaluations", scan_vmap(ukf5_body)),
    ]
    for name, fn in parts:
        progress(f"profile {dtype}: {name}")
        _, secs, _ = time_compiled(jax.jit(fn), args, repeats)
        print_profile(name, r, t, secs, dtype)

    def proto(update):
        def f(field, dyn, x0, p0, steps):
            return over_runs(
                lambda a: _reading_rate_run(update, field, a[0], x0, p0, a[1], every)[1],
                (dyn, steps), CHUNK)

        return jax.jit(f)

    for name, update in [("prototype: update only on readings", ukf.update),
                         ("prototype: readings only + 5 map evaluations", _ukf5_update),
                         ("prototype: readings only + 5 map evaluations + 1 cholesky",
                          _ukf5_single_cholesky_update)]:
        _, secs, pos = time_compiled(proto(update), args, repeats)
        print_profile(name, r, t, secs, dtype,
                      max_diff_vs_library_m=float(f"{np.max(np.abs(pos - ref_pos)):.3g}"))

    # XLA's count for one update with a reading (loops are not counted by cost_analysis)
    st = fl.FilterState(x0, p0)
    s1 = jax.tree.map(lambda a: a[0, every - 1], steps)
    d1 = jax.tree.map(lambda a: a[0], dyn)
    for name, upd in [("ukf update", ukf.update), ("prototype 5-point update", _ukf5_update),
                      ("predict", lambda st, s, f, d: kalman.predict(st, d.f, d.q))]:
        cost = jax.jit(lambda st, s, f, d, u=upd: u(st, s, f, d)).lower(st, s1, field, d1)
        cost = cost.compile().cost_analysis()
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
    scenario = fl.FilterScenario(n_steps=n_steps + 1)
    dt, every = float(scenario.dt), scenario.reading_every
    field = paper_d()
    x0, p0 = fl.initial_state(scenario)
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

    # UKF, float64: all runs in one vmap, then in chunks --------------------------
    ukf = fl.ukf(alpha=ALPHA, beta=BETA, kappa=KAPPA)
    args64 = (field, dyn, x0, p0, steps)
    # chunks pay off only for large batches (cache); --quick runs one vmap
    big = n_runs >= 10 * CHUNK
    chunk_best = CHUNK if big else None
    out64 = None
    for chunk in (None, CHUNK) if big else (None,):
        case = cname("ukf-float64", chunk)
        progress(case)
        compile_s, secs, out = time_compiled(monte_carlo(ukf, chunk), args64, repeats)
        line(case, n_runs, secs, compile_s, out, chunk=chunk,
             **agreement(out[0][0], out[1][0], fp_pos, fp_sig))
        out64 = out if out64 is None else out64

    # EKF, float64 -----------------------------------------------------------------
    progress("ekf")
    compile_s, secs, oute = time_compiled(monte_carlo(fl.ekf(), chunk_best), args64, repeats)
    line(cname("ekf-float64", chunk_best), n_runs, secs, compile_s, oute, chunk=chunk_best,
         ekf_vs_ukf_max_diff_sigma=float(f"{np.max(np.abs(oute[0] - out64[0]) / out64[1]):.3g}"))

    # PMF, float64 -----------------------------------------------------------------
    progress("pmf")
    sub = jax.tree.map(lambda a: a[:n_pmf], steps)
    pmf_chunk = CHUNK if n_pmf > CHUNK else None
    compile_s, secs, outp = time_compiled(monte_carlo_pmf(fl.pmf(), dt, every, pmf_chunk),
                                          (field, x0, p0, sub), repeats)
    line(cname("pmf-float64", pmf_chunk), n_pmf, secs, compile_s, outp, chunk=pmf_chunk,
         pmf_grid="61 x 61 cells of 200 m")

    # the profile runs on at most 600 steps of the timed runs
    prof_t = min(n_steps, 600)
    prof_steps = jax.tree.map(lambda a: a[:, :prof_t], steps)
    prof_repeats = 3 if args.quick else 2
    if args.profile:
        profile(field, dyn, prof_steps, x0, p0, every, out64[0][:, :prof_t], "float64",
                prof_repeats)

    # UKF, float32 -----------------------------------------------------------------
    progress("ukf float32")
    jax.config.update("jax_enable_x64", False)
    try:
        a32 = as_float32(args64)
        compile_s, secs, out32 = time_compiled(monte_carlo(ukf, chunk_best), a32, repeats)
        diff = np.abs(out32[0] - out64[0])
        line(cname("ukf-float32", chunk_best), n_runs, secs, compile_s, out32, chunk=chunk_best,
             **agreement(out32[0][0], out32[1][0], fp_pos, fp_sig),
             f32_vs_f64_max_diff_m=float(f"{diff.max():.3g}"),
             f32_vs_f64_median_max_diff_m=float(f"{np.median(diff.max(axis=(1, 2))):.3g}"),
             f32_vs_f64_max_diff_sigma=float(f"{np.max(diff / out64[1]):.3g}"))
        if args.profile:
            profile(*as_float32((field, dyn, prof_steps, x0, p0)), every,
                    out64[0][:, :prof_t], "float32", prof_repeats)
    finally:
        jax.config.update("jax_enable_x64", True)


if __name__ == "__main__":
    main()
