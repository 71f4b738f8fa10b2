"""Dense matcher on a map that is not the truth: white score vs GLS best vs GLS posterior.

The GLS posterior (the default told a map error) is over the disc of the search's reach
with the 3 km, ``max_sigma_ratio`` and no-harm (``max_p_worse``) tests;
``gls-posterior-ratio`` is the same without the no-harm test (the default before
2026-12-07), ``gls-posterior-square`` over the whole square window with the 3 km test
alone (the default before the disc).

Paper A's tracks (:class:`~jaxgrav.scenarios.MatchingScenario` defaults: 30 fixes 2 min
apart, 10 kn E + 10 kn N, drift 0.035°, 1 mGal noise) on the shipped 2.5′ ``ryukyu``
map; the truth of every run is the map plus a correlated error drawn from the run's key
(:func:`~jaxgrav.fields.map_error.truth_field`, σ, L below). For each variant: median
(output error / INS error) over all tracks (a rejected fix counts at the INS error),
share worse than the INS, share accepted, 95 % ellipse coverage on accepted fixes, and
the rank correlation of each test statistic with the realised error.

Run: ``python examples/map_error_dense.py [--runs 500] [--sigma 3] [--length 10000]
[--fixes 30] [--radius-factor 1] [--smoke]``.
"""

import argparse
import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import datasets
from jaxgrav.fields.map_error import map_error, map_error_key, truth_field
from jaxgrav.match.dense import lattice_table, match_dense
from jaxgrav.match.dense_batch import match_dense_batch
from jaxgrav.match.integrity import region_spread
from jaxgrav.match.sizing import config_for
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import MatchingScenario, matching_scenario
from jaxgrav.sim import DEG_ARC_M


def variants(grid, scen, sigma, length, radius_factor=1.0):
    """The matchers compared: name -> DenseConfig (window sized for ``radius_factor`` ×
    the drift radius)."""
    radius = radius_factor * scen.drift_deg * DEG_ARC_M
    white = config_for("dense", grid, radius)
    gls = config_for("dense", grid, radius, map_error=map_error(sigma, length))
    best = dataclasses.replace(gls, fix="best")
    inf = float("inf")
    ratio = dataclasses.replace(gls, max_p_worse=inf)  # before the no-harm test
    return {"white": white,
            "gls-best": dataclasses.replace(best, max_sigma_m=inf, max_sigma_ratio=inf,
                                            max_p_worse=inf),
            "gls-posterior": gls,
            "gls-posterior-ratio": ratio,
            "gls-posterior-3km": dataclasses.replace(ratio, max_sigma_ratio=inf),
            "gls-posterior-all": dataclasses.replace(ratio, max_sigma_m=inf,
                                                     max_sigma_ratio=inf),
            # before the disc: the whole square window, the 3 km test alone
            "gls-posterior-square": dataclasses.replace(ratio, region="square",
                                                        max_sigma_ratio=inf)}


def simulate(grid, scen, sigma, length, keys):
    """Per-run truth (map + error) and readings: INS fixes, readings, mean drift (m)."""
    model = map_error(sigma, length)

    def one(grid, key):
        truth = truth_field(map_error_key(key), grid, model)
        run = matching_scenario(key, truth, scen)
        return run.ins_lat, run.ins_lon, run.readings, jnp.stack(
            [jnp.mean(run.drift_north_m), jnp.mean(run.drift_east_m)])

    # the map is an argument of the compiled program, not a constant baked into it
    return jax.jit(lambda g, k: jax.lax.map(lambda kk: one(g, kk), k, batch_size=16))(
        grid, keys)


def evaluate(prepared, table, sims, config):
    """Per-track error ratio, worse-than-INS, accepted, inside-95 % and statistics."""
    lat, lon, g, drift = sims
    r = jax.jit(lambda p, t, xs: jax.lax.map(lambda x: match_dense(p, *x, config, t), xs,
                                             batch_size=64))(prepared, table, (lat, lon, g))
    err = np.stack([np.asarray(r.offset_north_m), np.asarray(r.offset_east_m)], -1) + drift
    ins = np.hypot(drift[:, 0], drift[:, 1])
    e = np.hypot(err[:, 0], err[:, 1])
    acc = np.asarray(r.accepted)
    out = np.where(acc, e, ins)
    cov = np.asarray(r.covariance_m2)
    det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
    maha = (cov[:, 1, 1] * err[:, 0] ** 2 - 2 * cov[:, 0, 1] * err[:, 0] * err[:, 1]
            + cov[:, 0, 0] * err[:, 1] ** 2) / det
    inside = maha <= 5.991
    sig = np.sqrt(0.5 * (cov[:, 0, 0] + cov[:, 1, 1]) + np.sqrt(
        0.25 * (cov[:, 0, 0] - cov[:, 1, 1]) ** 2 + cov[:, 0, 1] ** 2))
    stats = {"sigma_max": sig, "n_effective": np.asarray(r.n_effective),
             "second_mode": np.asarray(r.second_mode_ratio),
             "edge_mass": np.asarray(r.edge_mass), "chi2_per_dof": np.asarray(r.chi2_per_dof)}
    sweep = {}
    for t in (500, 750, 1000, 1250, 1500, 2000, 2500, 3000, np.inf):
        a2 = np.asarray(r.accepted) & (sig <= t) if np.isfinite(t) else np.asarray(r.accepted)
        o2 = np.where(a2, e, ins)
        sweep[t] = (np.median(o2 / ins), np.mean(o2 > ins), np.mean(a2),
                    np.mean(inside[a2]) if a2.any() else np.nan)
    # the disc's informativeness test: σ ≤ ratio × the searched region's own 1-σ (and 3 km)
    spread = float(region_spread(config))
    ratio_sweep = {}
    for q in (0.7, 0.8, 0.9, 1.0, np.inf):
        a2 = np.asarray(r.accepted) & (sig <= 3000.0) & (sig <= q * spread)
        o2 = np.where(a2, e, ins)
        ratio_sweep[q] = (np.median(o2 / ins), np.mean(o2 > ins), np.mean(a2),
                          np.mean(inside[a2]) if a2.any() else np.nan)
    return {"sweep": sweep, "ratio_sweep": ratio_sweep, "median": np.median(out / ins),
            "worse": np.mean(out > ins),
            "accepted": np.mean(acc), "coverage": np.mean(inside[acc]) if acc.any() else np.nan,
            "rank": {k: _spearman(v, e) for k, v in stats.items()}}


def bench(prepared, table, sims, configs, n=1000, repeat=2):
    """Tracks per second of :func:`match_dense_batch` (``n`` tracks) for each config."""
    lat, lon, g, _ = (np.resize(x, (n, *x.shape[1:])) for x in sims)
    out = {}
    for name, cfg in configs.items():
        f = jax.jit(lambda a, b, c, cfg=cfg: match_dense_batch(prepared, a, b, c, cfg, table))
        jax.block_until_ready(f(lat, lon, g))
        t0 = time.perf_counter()
        for _ in range(repeat):
            jax.block_until_ready(f(lat, lon, g))
        out[name] = n * repeat / (time.perf_counter() - t0)
    return out


def _spearman(x, y):
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return np.nan
    rx, ry = (np.argsort(np.argsort(a[ok])) for a in (x, y))
    return float(np.corrcoef(rx, ry)[0, 1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--sigma", type=float, default=3.0, help="map error σ (mGal)")
    ap.add_argument("--length", type=float, default=10000.0, help="map error L (m)")
    ap.add_argument("--fixes", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--smoke", action="store_true", help="tiny size for the tests")
    ap.add_argument("--radius-factor", type=float, default=1.0,
                    help="the search window sized for this many times the drift radius")
    ap.add_argument("--bench", action="store_true",
                    help="only time match_dense_batch on 1000 tracks, white vs GLS")
    a = ap.parse_args(argv)
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    runs = 4 if a.smoke else a.runs
    scen = MatchingScenario(n_fixes=a.fixes)
    prepared = prepare_map(grid)
    table = lattice_table(prepared)
    t0 = time.perf_counter()
    sims = simulate(grid, scen, a.sigma, a.length, jax.random.split(jax.random.key(a.seed), runs))
    sims = tuple(np.asarray(x) for x in sims)
    print(f"simulated {runs} runs in {time.perf_counter() - t0:.1f} s "
          f"(σ = {a.sigma} mGal, L = {a.length:.0f} m, {a.fixes} fixes)")
    if a.bench:
        cfgs = variants(grid, scen, max(a.sigma, 1e-3), a.length)
        # "auto" compiles both scores and evaluates the white one beside the GLS one
        cfgs["gls-posterior-auto"] = dataclasses.replace(cfgs["gls-posterior"],
                                                         score_model="auto")
        speed = bench(prepared, table, sims, {k: cfgs[k] for k in (
            "white", "gls-posterior", "gls-posterior-auto")})
        for name, v in speed.items():
            print(f"{name}: {v:.0f} tracks/s")
        print(f"GLS / white time: {speed['white'] / speed['gls-posterior']:.2f} "
              f"(score_model='auto': {speed['white'] / speed['gls-posterior-auto']:.2f})")
        return speed
    rows = {}
    for name, cfg in variants(grid, scen, max(a.sigma, 1e-3) if a.sigma > 0 else 1.0,
                              a.length, a.radius_factor).items():
        if a.sigma == 0 and name != "white":  # σ = 0: GLS told the map is perfect = white
            cfg = dataclasses.replace(cfg, map_error_mgal=0.0)
        t0 = time.perf_counter()
        rows[name] = evaluate(prepared, table, sims, cfg)
        rows[name]["seconds"] = time.perf_counter() - t0
    print("| matcher | median err/INS | worse than INS | accepted | 95 % coverage (accepted) |")
    print("|---|---|---|---|---|")
    for name, r in rows.items():
        print(f"| {name} | {r['median']:.3f} | {100 * r['worse']:.1f} % | "
              f"{100 * r['accepted']:.1f} % | {100 * r['coverage']:.1f} % |")
    for name, r in rows.items():
        print(f"  {name}: max_sigma_m sweep (median, worse, accepted, coverage): " + "; ".join(
            f"{t:g}: {m:.3f} {100 * w:.1f}% {100 * ac:.0f}% {100 * c:.0f}%"
            for t, (m, w, ac, c) in r["sweep"].items()))
    for name, r in rows.items():
        print(f"  {name}: max_sigma_ratio sweep with σ ≤ 3 km (median, worse, accepted, "
              "coverage): " + "; ".join(
                  f"{q:g}: {m:.3f} {100 * w:.1f}% {100 * ac:.0f}% {100 * c:.0f}%"
                  for q, (m, w, ac, c) in r["ratio_sweep"].items()))
    print("rank correlation of each statistic with the realised error:")
    for name, r in rows.items():
        print(f"  {name}: " + ", ".join(f"{k} {v:+.2f}" for k, v in r["rank"].items()))
    return rows


if __name__ == "__main__":
    main()
