"""Paper D's "no harm" goal: guarding filter corrections in weakly observed directions.

Issue 6 asks that in *every* run the filter's RMS position error over the second
hour be at most 1.05× the free INS's. The UKF and the Gaussian-sum UKF of
``examples/paper_d_ukf.py`` miss this in about 2 % of runs. This script runs those
filters on the same experiment (same seeds, same scenario), computes the free INS
covariance of each run (predict-only, same model and prior) and applies the guard
of :mod:`jaxgrav.filters.guard` after the fact — the guard is a per-step,
causal function of the filter output, so it needs no second filter run — for a
grid of thresholds fixed before looking at any result:

* ``eig t``: hard threshold, a direction's correction passes if its posterior/free
  variance ratio λ ≤ t, for t = 0.1 … 0.9;
* ``smooth t``: smoothstep from full (λ ≤ t − 0.15) to none (λ ≥ t + 0.15);
* ``+nis c``: also hold everything back while the mean NIS of the last 30 readings
  (5 min) exceeds c (c = 2, 3);
* ``risk a``: at each step shrink the correction ``x`` along itself, ``g x`` with the
  largest ``g ≤ 1`` for which the filter's own posterior ``N(x, P)`` gives the corrected
  position a probability ≤ a of being more than 1.05 × the free INS's error away
  (the set where that happens is, nearly, the half-plane ``e·x̂ < g|x|/2.05``:
  ``g = 2.05 (1 + Φ⁻¹(a) s/|x|)``, ``s² = x̂ᵀ P x̂``), for a = 0.3 … 0.001.

For the Gaussian sum the guard sees the mixture covariance, which contains the
spread of the component means: while the modes disagree (the sign of the east
error before the turn), λ along the disagreement stays high and that part of the
correction is held back — no separate mode-disagreement test is needed.

Selection rule (fixed in advance): on the *selection* seed (``--select-seed``, default
1), take the configuration with the fewest runs above 1.05 among those whose mean
ratio stays ≤ 0.6 (ties: lower mean); report it, and the whole grid, on the *test*
seed (``--seed``, default 0 — the seed of ``examples/paper_d_ukf.py``).

With ``--map-error SIGMA`` the runs are those of ``jaxgrav montecarlo --method
ukf|gsf --map ryukyu --map-error SIGMA --map-error-length L`` (the shipped 2.5′ map, the
readings from the map + a drawn second-order Gauss–Markov error, the filters told a
matched second-order map-error state; :func:`jaxgrav.montecarlo.methods.filter_builder`), and
the same grid of guards and the same selection rule are applied to them: the map-error
issue asks for a mean ratio ≤ 0.6 with no run above 1.05 there too.

Run::

    python examples/paper_d_noharm.py --runs 1000 --methods ukf,gsf-ukf --cache /tmp/noharm
    python examples/paper_d_noharm.py --runs 200 --map-error 3 --cache /tmp/noharm
    python examples/paper_d_noharm.py --smoke   # 16 runs of 20 min, UKF only
"""

import argparse
import os
import time

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import jax
import jax.numpy as jnp
import numpy as np
from scipy.special import ndtri

from jaxgrav import datasets
from jaxgrav.fields.map_error import map_error
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.filters import StepInfo, gaussian_sum, gravity_measurement, run_filter, ukf
from jaxgrav.filters.guard import GuardConfig, free_covariance, guard_infos
from jaxgrav.filters.map_state import augment
from jaxgrav.montecarlo.methods import filter_builder
from jaxgrav.scenarios import FilterScenario, filter_scenario, initial_state, run_steps

WINDOW = 30  # readings in the NIS window (5 min at one reading per 10 s)


def _filter(method, meas=gravity_measurement):
    return {"ukf": ukf(meas), "gsf-ukf": gaussian_sum(ukf(meas), 3, 1.0)}[method]


_COLLECTORS = {}


def _collector(method, scenario, error=None, told=None):
    """One jitted simulate-and-filter program per method (shared by both seeds).

    ``error`` (a map-error model) and ``told`` (a ``ToldMapError``) as in
    :func:`jaxgrav.montecarlo.methods.filter_builder`'s arguments; None: the map is the truth."""
    if (method, scenario, error is None) in _COLLECTORS:
        return _COLLECTORS[method, scenario, error is None]

    def one(key, field, error, told):
        run = filter_scenario(key, field, scenario, error)
        dynamics, steps = run_steps(run, scenario)
        x0, p0 = initial_state(scenario)
        meas = gravity_measurement
        if told is not None:
            dynamics, x0, p0, meas = augment(told.state, dynamics, x0, p0, scenario.speed)
        _, info = run_filter(_filter(method, meas), field, dynamics, x0, p0, steps)
        t = info.x.shape[0]  # robust to filters that report fewer steps than states
        p_free = free_covariance(dynamics, p0, t)
        turned = jnp.abs(run.truth.lat[-1] - run.truth.lat[0]) > 0.05
        return dict(
            e=run.errors[1 : t + 1, :2], x=info.x[:, :2], p=info.p_pos, nu=info.innovation,
            s=info.innovation_var, p_free=p_free, turned=turned,
        )

    fn = jax.jit(jax.vmap(one, in_axes=(0, None, None, None)))
    _COLLECTORS[method, scenario, error is None] = fn
    return fn


def collect(method, seed, runs, scenario, chunk=250, field=None, error=None, told=None):
    """Simulate and filter ``runs`` runs; per-step position output, truth and free covariance.

    ``field`` default paper D's point masses; ``error``, ``told`` as :func:`_collector`."""
    fn = _collector(method, scenario, error, told)
    keys = jax.random.split(jax.random.key(seed), runs)
    field = paper_d() if field is None else field
    parts = [jax.tree.map(np.asarray, fn(keys[i : i + chunk], field, error, told))
             for i in range(0, runs, chunk)]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def configs():
    """The a-priori grid: name -> (GuardConfig or None)."""
    out = {"unguarded": None}
    for nis in (float("inf"), 2.0, 3.0):
        tag = "" if nis == float("inf") else f" +nis {nis:g}"
        if nis != float("inf"):
            out[f"nis only{tag}"] = GuardConfig(2.0, 2.0, nis)
        for t in (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9):
            out[f"eig {t:.1f}{tag}"] = GuardConfig(t, t, nis)
        for t in (0.3, 0.5, 0.7):
            out[f"smooth {t:.1f}{tag}"] = GuardConfig(t - 0.15, t + 0.15, nis)
    for a in RISKS:
        out[f"risk {a:g}"] = ("risk", a)
    return out


RISKS = (0.3, 0.1, 0.05, 0.02, 0.01, 0.003, 0.001)
"""Harm probabilities of the ``risk`` guards."""


def _risk_guarded(x, p, a, k=1.05):
    """``risk a`` (module notes): the correction ``x`` ``(R, T, 2)`` shrunk along itself."""
    nx = np.linalg.norm(x, axis=-1)
    u = x / np.maximum(nx, 1e-9)[..., None]
    s = np.sqrt(np.einsum("rti,rtij,rtj->rt", u, p, u))
    g = np.clip((1.0 + k) * (1.0 + ndtri(a) * s / np.maximum(nx, 1e-9)), 0.0, 1.0)
    return g[..., None] * x


@jax.jit
@jax.vmap
def _scores(e, x, p, nu, s, p_free, config):
    info = StepInfo(x, jnp.zeros_like(x), p, nu, s, jnp.zeros(x.shape[0], jnp.int32))
    info = guard_infos(info, p_free, config, WINDOW)
    return _ratio_nees(e, info)


@jax.jit
@jax.vmap
def _scores_raw(e, x, p):
    return _ratio_nees(e, StepInfo(x, x, p, None, None, None))


def _ratio_nees(e, info):
    half = e.shape[0] // 2
    err = e[half:] - info.x[half:]
    pp = info.p_pos[half:]
    det = pp[:, 0, 0] * pp[:, 1, 1] - pp[:, 0, 1] ** 2
    nees = (pp[:, 1, 1] * err[:, 0] ** 2 - 2 * pp[:, 0, 1] * err[:, 0] * err[:, 1]
            + pp[:, 0, 0] * err[:, 1] ** 2) / det
    ratio = jnp.sqrt(jnp.mean(jnp.sum(err**2, -1)) / jnp.mean(jnp.sum(e[half:] ** 2, -1)))
    return ratio, jnp.mean(nees)


def evaluate(data, config):
    """Per-run ratio (filter / INS RMS over the second half) and mean position NEES."""
    e, x, p = (jnp.asarray(data[k]) for k in ("e", "x", "p"))
    if isinstance(config, tuple):  # ("risk", a): no covariance of its own, so no NEES
        x = jnp.asarray(_risk_guarded(data["x"], data["p"], config[1]))
        ratio, _ = _scores_raw(e, x, p)
        return np.asarray(ratio), np.full(ratio.shape, np.nan)
    if config is None:
        ratio, nees = _scores_raw(e, x, p)
    else:
        n = e.shape[0]
        cfg = GuardConfig(*(jnp.full(n, float(c)) for c in (config.lo, config.hi,
                                                              config.nis_max)))
        ratio, nees = _scores(e, x, p, *(jnp.asarray(data[k]) for k in ("nu", "s", "p_free")),
                              cfg)
    return np.asarray(ratio), np.asarray(nees)


def row(name, ratio, nees, turned, sel):
    """One table line: test-seed scores, then the selection seed's (runs > 1.05, mean)."""
    out = (f"{name:20s} {np.mean(ratio):6.3f} {np.median(ratio):6.3f} {np.max(ratio):6.3f} "
           f"{np.sum(ratio > 1.05):5d} {np.mean(nees):5.2f}")
    if turned.any() and (~turned).any():
        out += f" {np.mean(ratio[~turned]):6.3f} / {np.mean(ratio[turned]):.3f}"
    return out + f"  | {sel[0]:5d} {sel[1]:6.3f}"


HEADER = (f"{'guard':20s} {'mean':>6s} {'median':>6s} {'worst':>6s} {'>1.05':>5s} {'NEES':>5s} "
          f"{'E-W / N-then-E':>15s}  | {'>1.05':>5s} {'mean':>6s}")


def load_or_collect(method, seed, runs, scenario, cache, tag="", **setting):
    path = (None if cache is None else
            os.path.join(cache, f"{method}{tag}_seed{seed}_{runs}.npz"))
    if path and os.path.exists(path):
        return dict(np.load(path))
    t0 = time.perf_counter()
    data = collect(method, seed, runs, scenario, **setting)
    print(f"# {method} seed {seed}: {runs} runs filtered in {time.perf_counter() - t0:.0f} s",
          flush=True)
    if path:
        os.makedirs(cache, exist_ok=True)
        np.savez(path, **data)
    return data


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=1000)
    p.add_argument("--methods", default=None,
                   help="comma-separated ukf, gsf-ukf (default both; --smoke: ukf)")
    p.add_argument("--seed", type=int, default=0, help="test seed (paper_d_ukf.py's)")
    p.add_argument("--select-seed", type=int, default=1, help="seed the threshold is chosen on")
    p.add_argument("--cache", default=None, help="directory for per-run filter output (.npz)")
    p.add_argument("--collect-only", action="store_true")
    p.add_argument("--map-error", type=float, default=None, metavar="SIGMA",
                   help="the ryukyu map-error runs: truth = the shipped 2.5' map + a drawn "
                        "markov2 error of SIGMA mGal, the filters told a matched state")
    p.add_argument("--map-error-length", type=float, default=10e3, metavar="L",
                   help="the map error's correlation length (m, default 10000)")
    p.add_argument("--smoke", action="store_true",
                   help="a quick check: 16 runs of 20 minutes, UKF only")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)

    n_steps = 121 if args.smoke else 721
    runs = 16 if args.smoke else args.runs
    methods = args.methods or ("ukf" if args.smoke else "ukf,gsf-ukf")
    scenario = FilterScenario(dt=10.0, reading_every=1, n_steps=n_steps)
    setting, tag = {}, ""
    if args.map_error is not None:
        if not (np.isfinite(args.map_error) and args.map_error > 0):
            p.error(f"--map-error must be a finite number > 0 (mGal), got {args.map_error}")
        if not (np.isfinite(args.map_error_length) and args.map_error_length > 0):
            p.error("--map-error-length must be a finite number > 0 (m), got "
                    f"{args.map_error_length}")
        spec = filter_builder(datasets.load("ryukyu")["anomaly_2p5min"], kind="ukf",
                              n_fixes=n_steps,
                              map_error=map_error(args.map_error, args.map_error_length))
        field, scenario, error, told = spec.args
        setting = dict(field=field, error=error, told=told)
        tag = f"_ryukyu_me{args.map_error:g}_{args.map_error_length:g}"
    grid = configs()
    for method in methods.split(","):
        sel = load_or_collect(method, args.select_seed, runs, scenario, args.cache, tag, **setting)
        test = load_or_collect(method, args.seed, runs, scenario, args.cache, tag, **setting)
        if args.collect_only:
            continue
        print(f"\n{method}: {runs} runs, selection seed {args.select_seed}, "
              f"test seed {args.seed}")
        scores = {}
        for name, cfg in grid.items():
            r, _ = evaluate(sel, cfg)
            scores[name] = (int(np.sum(r > 1.05)), float(np.mean(r)))
        ok = [n for n in grid if scores[n][1] <= 0.6]
        chosen = min(ok, key=lambda n: scores[n]) if ok else None
        if chosen is None:
            print(f"no guard keeps the mean ratio <= 0.6 on seed {args.select_seed}: none chosen")
        else:
            print(f"chosen on seed {args.select_seed}: {chosen!r} (runs > 1.05: "
                  f"{scores[chosen][0]}, mean {scores[chosen][1]:.3f})")
        test_head, sel_head = f"test seed {args.seed}", f"seed {args.select_seed}"
        print(f"{'':20s} {test_head:^51s}  | {sel_head:^12s}")
        print(HEADER)
        # paper D's geometries (east-west, north-then-east); the map's tracks are straight
        turned = (test["turned"].astype(bool) if args.map_error is None
                  else np.zeros(test["turned"].shape, bool))
        for name, cfg in grid.items():
            r, nees = evaluate(test, cfg)
            mark = "  <- chosen" if name == chosen else ""
            print(row(name, r, nees, turned, scores[name]) + mark, flush=True)


if __name__ == "__main__":
    main()
