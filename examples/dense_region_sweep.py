"""The dense matcher's searched region and integrity thresholds, swept after one run.

The Monte Carlo ``dense`` method (``jaxgrav montecarlo --method dense``: paper A's tracks
on the shipped 2.5′ ``ryukyu`` map, the matcher told the map error) is run once per
searched region (the whole square window, the disc) with every integrity threshold
off, so every fix, its largest 1-σ and its chance of being worse than the INS track
(:func:`~jaxgrav.match.integrity.p_worse_than_ins`) are recorded; the tests are then
applied afterwards: σ ≤ ``--max-sigma``, σ ≤ ratio × the region's own spread
(:func:`~jaxgrav.match.integrity.region_sigma`) and, in a second table, that chance ≤
``max_p_worse`` (the no-harm test, 0.3 by default with a map error). A rejected fix
counts at the INS error. Printed: median error / INS, share worse than the INS, share
accepted and the 95 % ellipse coverage on accepted fixes, one line per region and test.

Run: ``python examples/dense_region_sweep.py [--runs 1000] [--sigma 3] [--length 10000]
[--fixes 30] [--smoke]``.
"""

import argparse
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import datasets, montecarlo
from jaxgrav.fields.map_error import map_error
from jaxgrav.match.dense import match_dense
from jaxgrav.match.integrity import p_worse_than_ins, region_spread
from jaxgrav.montecarlo.matcher_runs import matcher_record, paper_a_match

RATIOS = (0.7, 0.8, 0.9, 1.0, np.inf)
P_WORSE = (0.1, 0.2, 0.3, np.inf)


def dense_run_p_worse(key, grid, scenario, config, model=None):
    """The Monte Carlo ``dense`` run, its record with ``p_worse`` (the fix's chance of
    being worse than the INS track under its own covariance)."""
    run, _, r = paper_a_match(match_dense, key, grid, grid, scenario, config, model)
    offset = jnp.stack([r.offset_north_m, r.offset_east_m])
    return matcher_record(run, r, p_worse=p_worse_than_ins(offset, r.covariance_m2))


def sweep(runs, sigma, length, n_fixes, seed=0, max_sigma=3000.0):
    """Rows ``(region, ratio, max_p_worse, median, worse, accepted, coverage)`` (see the
    module notes); ``max_p_worse`` is inf but on the disc at the default ratio 0.9."""
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    rows = []
    for region in ("square", "disc"):
        spec = montecarlo.build("dense", grid, n_fixes=n_fixes,
                                map_error=map_error(sigma, length))
        *rest, cfg, model = spec.args
        off = dataclasses.replace(cfg, region=region, max_sigma_m=np.inf,
                                  max_sigma_ratio=np.inf, max_p_worse=np.inf)
        out = montecarlo.run(dense_run_p_worse, jax.random.key(seed), runs,
                             args=(*rest, off, model), progress=False,
                             cpu_options=spec.cpu_options)
        err, ins, sig, acc, cov, p_worse = (np.asarray(out[k]) for k in (
            "err_m", "ins_err_m", "sigma_max_m", "accepted", "covered95", "p_worse"))
        spread = float(region_spread(off))
        tests = [(ratio, np.inf) for ratio in RATIOS]
        if region == "disc":
            tests += [(0.9, p) for p in P_WORSE[:-1]]
        for ratio, p_max in tests:
            a = acc & (sig <= max_sigma) & (sig <= ratio * spread) & (p_worse <= p_max)
            r = np.where(a, err, ins) / ins
            rows.append((region, ratio, p_max, float(np.median(r)), float(np.mean(r > 1)),
                         float(np.mean(a)), float(np.mean(cov[a])) if a.any() else np.nan))
        print(f"{region}: R = {off.half_size * off.spacing_m:.0f} m, its own 1-sigma "
              f"{spread:.0f} m")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--sigma", type=float, default=3.0, help="map error sigma (mGal)")
    ap.add_argument("--length", type=float, default=10000.0, help="map error L (m)")
    ap.add_argument("--fixes", type=int, default=30)
    ap.add_argument("--smoke", action="store_true", help="8 tracks")
    a = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # as the montecarlo command
    rows = sweep(8 if a.smoke else a.runs, a.sigma, a.length, a.fixes)
    print("| region | sigma <= 3 km and <= ratio x the region's 1-sigma | chance worse than "
          "INS <= | median error / INS | worse than INS | accepted | coverage (accepted) |")
    print("|---|---|---|---|---|---|---|")
    for region, ratio, p_max, med, worse, acc, cov in rows:
        print(f"| {region} | {ratio:g} | {p_max:g} | {med:.3f} | {100 * worse:.1f} % "
              f"| {100 * acc:.1f} % | {100 * cov:.1f} % |")
    return rows


if __name__ == "__main__":
    main()
