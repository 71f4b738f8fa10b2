"""Chain and entropy + ICCP matchers on a map that is not the truth: white vs told the map error.

* **chains**: paper A's tracks (:class:`~jaxgrav.scenarios.MatchingScenario` defaults:
  30 fixes 2 min apart, 10 kn E + 10 kn N, drift 0.035°, 1 mGal noise) on the shipped
  2.5′ ``ryukyu`` map; the chain search on the map refined ×8 (as
  ``examples/paper_a_table1.py``'s realistic setting), sized by
  ``config_for("chains", ..., step_m=...)``; readings Eötvös-corrected with the
  ship's velocity, as the Monte Carlo runner does.
* **entropy+iccp**: paper B's gravity case (:class:`~jaxgrav.scenarios.paper_b.PaperBScenario`:
  60 fixes a minute apart at 10 m/s, INS offset 0.02–0.03° and turned 1.5°, 1 mGal
  noise) on the same 2.5′ map, configs as ``examples/paper_b_entropy_iccp.py``.

The truth of every run is the map plus a correlated error drawn from the run's key
(σ, L below; σ = 0: the perfect map). Each matcher runs with the white-noise score
("white": no ``map_error``) and told the error (``map_error=map_error(σ, L)`` in
``config_for`` / ``iccp_config_for``; at σ = 0 told σ = 0 with the told fix and
thresholds); entropy+ICCP also told with the 3 km test alone over the square grid
("told, 3 km only": its default before 2026-12-07, without the searched disc, the
informativeness test and the no-harm test). Reported: median (error of the mean-track
position / INS error; a rejected fix counts at the INS error), share worse than the
INS, share accepted, and the share of accepted fixes whose truth lies in the 95 %
ellipse of ``covariance_m2``.

Run: ``python examples/map_error_matchers.py [--runs 200] [--sigma 3] [--length 10000]
[--only chains|entropy+iccp] [--seed 0] [--smoke]``. Thresholds are chosen with
``--seed 1`` and reported with ``--seed 0``.
"""

import argparse
import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import datasets
from jaxgrav.fields.map_error import map_error, map_error_key, truth_field
from jaxgrav.geodesy import eotvos, local_offsets_m
from jaxgrav.match.combined import match_entropy_iccp
from jaxgrav.match.correlation import match_chains
from jaxgrav.match.entropy import entropy_config_for
from jaxgrav.match.sizing import (
    CHAIN_MAP_ERROR_INTEGRITY,
    ICCP_MAP_ERROR_INTEGRITY,
    config_for,
    iccp_config_for,
)
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import MatchingScenario, matching_scenario
from jaxgrav.scenarios.paper_b import PaperBScenario, paper_b_scenario
from jaxgrav.sim import DEG_ARC_M

ROTATION_DEG = 1.5


def told_model(sigma, length):
    """The error model the told matcher gets (σ = 0: told the map is perfect)."""
    return map_error(sigma, length)


def chain_runs(grid, sigma, length, keys, fixes=30):
    """Paper A's runs: (INS lat, lon, readings, true lat, true lon) per run."""
    scen = MatchingScenario(n_fixes=fixes)
    model = map_error(sigma, length) if sigma > 0 else None

    def one(grid, key):
        truth = truth_field(map_error_key(key), grid, model) if model is not None else grid
        run = matching_scenario(key, truth, scen)
        g = run.readings + eotvos(run.ins_lat, run.truth.v_east, run.truth.v_north)
        return run.ins_lat, run.ins_lon, g, run.truth.lat, run.truth.lon

    return scen, tuple(np.asarray(x) for x in _map_runs(one, grid, keys))


def iccp_runs(grid, sigma, length, keys):
    """Paper B's gravity runs (60 fixes, offset 0.02–0.03°, 1.5° turn, 1 mGal)."""
    w, e, s, n = grid.extent
    scen = PaperBScenario(region=(s, n, w, e), rotation_deg=ROTATION_DEG, noise=1.0)
    model = map_error(sigma, length) if sigma > 0 else None

    def one(grid, key):
        run = paper_b_scenario(key, grid, scen, map_error=model)
        return run.ins_lat, run.ins_lon, run.readings, run.truth.lat, run.truth.lon

    return scen, tuple(np.asarray(x) for x in _map_runs(one, grid, keys))


def _map_runs(one, grid, xs):
    """``one(grid, x)`` over ``xs`` in batches of 8, with the map an argument of the
    compiled program: closed over, it would be baked into the executable as a constant
    (tens of MB for a refined map, slow to compile and to load from the cache)."""
    return jax.jit(lambda g, xs: jax.lax.map(lambda x: one(g, x), xs, batch_size=8))(grid, xs)


SWEEP = (500.0, 750.0, 1000.0, 1500.0, 2000.0, 3000.0, np.inf)
"""Thresholds on the largest 1-σ (m) reported by the sweep."""


def summarise(results, runs, max_sigma_m=np.inf):
    """Median err/INS, worse than INS, accepted, 95 % coverage on accepted fixes.

    ``max_sigma_m`` rejects more fixes after the fact (exactly what the matcher's
    ``max_sigma_m`` does when its other thresholds are off); a sweep over
    :data:`SWEEP` is included.
    """
    ins_lat, ins_lon, _, t_lat, t_lon = runs
    e_n, e_e = (np.mean(np.asarray(v), -1) for v in local_offsets_m(
        results.lat, results.lon, t_lat, t_lon))
    i_n, i_e = (np.mean(np.asarray(v), -1) for v in local_offsets_m(ins_lat, ins_lon, t_lat,
                                                                      t_lon))
    ins = np.hypot(i_n, i_e)
    cov = np.asarray(results.covariance_m2, float)
    det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
    maha = (cov[:, 1, 1] * e_n**2 - 2 * cov[:, 0, 1] * e_n * e_e + cov[:, 0, 0] * e_e**2) / det
    inside = maha <= 5.991
    sigma = np.sqrt(0.5 * (cov[:, 0, 0] + cov[:, 1, 1]) + np.sqrt(
        0.25 * (cov[:, 0, 0] - cov[:, 1, 1]) ** 2 + cov[:, 0, 1] ** 2))

    def row(t):
        acc = np.asarray(results.accepted) & (sigma <= t if np.isfinite(t) else True)
        ratio = np.where(acc, np.hypot(e_n, e_e), ins) / ins
        return {"median": float(np.median(ratio)), "worse": float(np.mean(ratio > 1 + 1e-9)),
                "accepted": float(np.mean(acc)),
                "coverage": float(np.mean(inside[acc])) if acc.any() else float("nan")}

    out = row(max_sigma_m)
    out["sweep"] = {t: row(t) for t in SWEEP}
    acc = np.asarray(results.accepted)
    out["symmetric_pd"] = bool(np.all(cov[:, 0, 1] == cov[:, 1, 0]) and np.all(det[acc] > 0))
    return out


def run_chains(sigma, length, n, seed):
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    fine8 = grid.refine(8)
    scen, runs = chain_runs(grid, sigma, length, jax.random.split(jax.random.key(seed), n))
    radius = scen.drift_deg * DEG_ARC_M
    white = config_for("chains", fine8, radius, noise_mgal=1.0, step_m=scen.step_m)
    told = config_for("chains", fine8, radius, noise_mgal=1.0, step_m=scen.step_m,
                      map_error=told_model(sigma, length))
    told = dataclasses.replace(told, **CHAIN_MAP_ERROR_INTEGRITY)
    limit = {"white": np.inf, "told": told.max_sigma_m}
    told = dataclasses.replace(told, max_sigma_m=np.inf)  # applied by summarise: a sweep
    out = {}
    for name, cfg in (("white", white), ("told", told)):
        t0 = time.perf_counter()
        res = _map_runs(lambda g, x, cfg=cfg: match_chains(g, *x, cfg), fine8,
                        tuple(jnp.asarray(a) for a in runs[:3]))
        out[name] = summarise(res, runs, limit[name])
        out[name]["seconds"] = time.perf_counter() - t0
    return out


def run_entropy_iccp(sigma, length, n, seed):
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    pm = prepare_map(grid)
    scen, runs = iccp_runs(grid, sigma, length, jax.random.split(jax.random.key(seed), n))
    drift_m = (scen.offset_max_deg + 0.005) * DEG_ARC_M
    ent = entropy_config_for(grid, drift_m, max_half_size=20)
    kw = dict(stage="fine", noise=1.0, max_rotation_deg=ROTATION_DEG + 0.5)
    white = iccp_config_for(grid, drift_m, **kw)
    told = iccp_config_for(grid, drift_m, map_error=told_model(sigma, length), **kw)
    told = dataclasses.replace(told, **ICCP_MAP_ERROR_INTEGRITY)
    only_3km = dataclasses.replace(told, region="square", max_sigma_ratio=np.inf,
                                   max_p_worse=np.inf)
    limit = {"white": np.inf, "told": told.max_sigma_m, "told, 3 km only": told.max_sigma_m}
    told = dataclasses.replace(told, max_sigma_m=np.inf)  # applied by summarise: a sweep
    only_3km = dataclasses.replace(only_3km, max_sigma_m=np.inf)
    out = {}
    for name, cfg in (("white", white), ("told", told), ("told, 3 km only", only_3km)):
        t0 = time.perf_counter()
        res = _map_runs(lambda p, x, cfg=cfg: match_entropy_iccp(p, *x, ent, cfg), pm,
                        tuple(jnp.asarray(a) for a in runs[:3]))
        out[name] = summarise(res, runs, limit[name])
        out[name]["seconds"] = time.perf_counter() - t0
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--sigma", type=float, default=3.0, help="map error σ (mGal)")
    ap.add_argument("--length", type=float, default=10000.0, help="map error L (m)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", choices=("chains", "entropy+iccp"), default=None)
    ap.add_argument("--smoke", action="store_true", help="tiny size for the tests")
    a = ap.parse_args(argv)
    n = 3 if a.smoke else a.runs
    rows = {}
    if a.only in (None, "chains"):
        rows.update({f"chains, {k}": v for k, v in run_chains(a.sigma, a.length, n,
                                                               a.seed).items()})
    if a.only in (None, "entropy+iccp"):
        rows.update({f"entropy+iccp, {k}": v for k, v in run_entropy_iccp(
            a.sigma, a.length, n, a.seed).items()})
    print(f"σ = {a.sigma} mGal, L = {a.length:.0f} m, {n} tracks per matcher")
    print("| matcher | median err/INS | worse than INS | accepted | 95 % coverage (accepted) |")
    print("|---|---|---|---|---|")
    for name, r in rows.items():
        print(f"| {name} | {r['median']:.3f} | {100 * r['worse']:.1f} % | "
              f"{100 * r['accepted']:.1f} % | {100 * r['coverage']:.1f} % | "
              f"({r['seconds']:.0f} s)")
    print("told: the same rows with fixes rejected when the largest 1-σ exceeds t (m):")
    for name, r in rows.items():
        print(f"  {name}: " + "; ".join(
            f"{t:g}: {v['median']:.3f} {100 * v['worse']:.1f}% {100 * v['accepted']:.0f}% "
            f"{100 * v['coverage']:.0f}%" for t, v in r["sweep"].items()))
    return rows


if __name__ == "__main__":
    main()
