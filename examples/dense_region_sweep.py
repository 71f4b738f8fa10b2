"""The dense matcher's searched region and integrity thresholds, swept after one run.

The Monte Carlo ``dense`` method (``jaxgrav montecarlo --method dense``: paper A's tracks
on the shipped 2.5′ ``ryukyu`` map, the matcher told the map error) is run once per
searched region (the whole square window, the disc) with every integrity threshold
off, so every fix and its largest 1-σ are recorded; the tests are then applied
afterwards: σ ≤ ``--max-sigma`` and σ ≤ ratio × the region's own spread
(:func:`~jaxgrav.match.integrity.region_sigma`). A rejected fix counts at the INS
error. Printed: median error / INS, share worse than the INS, share accepted and the
95 % ellipse coverage on accepted fixes, one line per region and test.

Run: ``python examples/dense_region_sweep.py [--runs 1000] [--sigma 3] [--length 10000]
[--fixes 30] [--smoke]``.
"""

import argparse
import dataclasses

import jax
import numpy as np

from jaxgrav import datasets, montecarlo
from jaxgrav.fields.map_error import map_error
from jaxgrav.match.integrity import region_spread

RATIOS = (0.7, 0.8, 0.9, 1.0, np.inf)


def sweep(runs, sigma, length, n_fixes, seed=0, max_sigma=3000.0):
    """Rows ``(region, ratio, median, worse, accepted, coverage)`` (see the module notes)."""
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    rows = []
    for region in ("square", "disc"):
        spec = montecarlo.build("dense", grid, n_fixes=n_fixes,
                                map_error=map_error(sigma, length))
        *rest, cfg, model = spec.args
        off = dataclasses.replace(cfg, region=region, max_sigma_m=np.inf,
                                  max_sigma_ratio=np.inf)
        spec = dataclasses.replace(spec, args=(*rest, off, model))
        out = montecarlo.run(spec.fn, jax.random.key(seed), runs, args=spec.args,
                             progress=False, cpu_options=spec.cpu_options)
        err, ins, sig, acc, cov = (np.asarray(out[k]) for k in (
            "err_m", "ins_err_m", "sigma_max_m", "accepted", "covered95"))
        spread = float(region_spread(off))
        for ratio in RATIOS:
            a = acc & (sig <= max_sigma) & (sig <= ratio * spread)
            r = np.where(a, err, ins) / ins
            rows.append((region, ratio, float(np.median(r)), float(np.mean(r > 1)),
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
    print("| region | sigma <= 3 km and <= ratio x the region's 1-sigma | median error / INS "
          "| worse than INS | accepted | coverage (accepted) |")
    print("|---|---|---|---|---|---|")
    for region, ratio, med, worse, acc, cov in rows:
        print(f"| {region} | {ratio:g} | {med:.3f} | {100 * worse:.1f} % | {100 * acc:.1f} % "
              f"| {100 * cov:.1f} % |")
    return rows


if __name__ == "__main__":
    main()
