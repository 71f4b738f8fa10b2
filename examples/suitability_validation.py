"""Does the suitability map rank start cells as the dense matcher fares? A Monte Carlo check.

The Monte Carlo ``dense`` method's scenario (paper A, :func:`jaxgrav.montecarlo.
methods.build` ``"dense"``) on the shipped 2.5′ ``ryukyu`` map: 30 fixes 2 min apart
at 10 kn east + 10 kn north (heading 45°, 873 m apart), 1 mGal noise, INS drift
0.035°, random starts. For each run the predicted precision at its start node
(:func:`jaxgrav.match.suitability.suitability` with the same heading, fixes, spacing
and noise; the map error the readings carry; interpolated bilinearly in its
logarithm) is set against the realised error of the
matcher. Printed, one JSON line per setting: the Spearman rank correlation between
prediction and error (goal ≥ 0.6), the median error of the runs whose start is in the
best tenth by prediction against the median of all runs (random cells; goal: ≥ 3 ×
lower), and the same for the standard deviation of the map over the window (the usual
descriptor), for comparison.

Settings: ``perfect map`` (readings from the map itself; best case), ``map error`` (the
readings see the map + a drawn σ = 3 mGal, L = 10 km ``markov2`` error; the matcher
and the prediction are told it). The prediction models the matcher's own estimator:
its reading-bias prior (σ_b = 3 mGal in this scenario) is passed to the bound.

How well can *any* prediction from the start cell rank the realised error? A run's
error also depends on its own draws of noise, drift direction and map error, which no
map-based prediction can know. ``--oracle-draws K`` measures that ceiling: every run's
start is matched K more times with fresh draws (``MatchingScenario.start_lat,
start_lon``), and the mean of those K errors — an oracle that knows each start's
expected error up to K-draw noise — is ranked against the run's own error, beside the
prediction on the same runs.

Run: ``python examples/suitability_validation.py [--runs 2000] [--seed 0]
[--oracle-draws 8] [--smoke]``.
"""

import argparse
import dataclasses
import json
import time

import jax
import numpy as np
from scipy.interpolate import RegularGridInterpolator
from scipy.stats import spearmanr

from jaxgrav.datasets import load_map
from jaxgrav.fields.map_error import map_error
from jaxgrav.match.suitability import suitability
from jaxgrav.montecarlo import methods
from jaxgrav.scenarios import matching_scenario


def node_values(grid, field, lat, lon):
    """``field`` (ny, nx) at points, bilinear in its logarithm (NaN if a corner is)."""
    interp = RegularGridInterpolator((np.asarray(grid.lat), np.asarray(grid.lon)),
                                     np.log(field), bounds_error=False)
    return np.exp(interp(np.stack([lat, lon], -1)))


def ranking(pred, err, better_is_low=True):
    """Spearman ρ of prediction and error, and the median-error cut of the best tenth."""
    ok = np.isfinite(pred) & np.isfinite(err)
    pred, err = pred[ok], err[ok]
    rho = spearmanr(pred if better_is_low else -pred, err).statistic
    order = np.argsort(pred if better_is_low else -pred)
    best = err[order[: max(1, len(order) // 10)]]
    return dict(spearman=round(float(rho), 3), median_err_best_tenth_m=round(float(
        np.median(best)), 1), median_err_all_m=round(float(np.median(err)), 1),
        cut=round(float(np.median(err) / np.median(best)), 2), runs=int(ok.sum()))


def oracle_errors(spec, keys, lat0, lon0, draws):
    """Errors (m) of every start matched ``draws`` more times with fresh keys, (runs, draws)."""
    grid, scen, *rest = spec.args
    runs = len(lat0)
    fresh = jax.vmap(lambda k: jax.vmap(lambda j: jax.random.fold_in(k, j))(
        1 + jax.numpy.arange(draws)))(keys).reshape(runs * draws)
    lat0, lon0 = np.repeat(lat0, draws), np.repeat(lon0, draws)

    @jax.jit
    def batch(keys, lat0, lon0):
        def one(a):
            k, la, lo = a
            return spec.fn(k, grid, dataclasses.replace(scen, start_lat=la, start_lon=lo),
                           *rest)["err_m"]

        return jax.lax.map(one, (keys, lat0, lon0), batch_size=50)

    return np.asarray(batch(fresh, lat0, lon0)).reshape(runs, draws)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=2000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--oracle-draws", type=int, default=0, metavar="K",
                   help="also rank by the mean error of K more draws at each start (the "
                        "ceiling of any start-cell prediction; K x the runs' matching time)")
    p.add_argument("--smoke", action="store_true", help="40 runs (the tests)")
    a = p.parse_args()
    if a.oracle_draws < 0:
        p.error(f"--oracle-draws must be >= 0; got {a.oracle_draws}")
    jax.config.update("jax_enable_x64", True)
    runs = 40 if a.smoke else a.runs
    grid = load_map("ryukyu")
    keys = jax.random.split(jax.random.key(a.seed), runs)
    for name, me in (("perfect map", None), ("map error", map_error(3.0, 10e3))):
        t0 = time.perf_counter()
        spec = methods.build("dense", grid, map_error=me)
        _, scen, cfg, _ = spec.args
        spacing = float(np.hypot(scen.v_east, scen.v_north) * scen.dt)
        heading = float(np.degrees(np.arctan2(scen.v_east, scen.v_north)))
        suit = suitability(grid, heading_deg=heading, n_fixes=scen.n_fixes, spacing_m=spacing,
                           noise_mgal=scen.noise_mgal,
                           map_error_mgal=0.0 if me is None else float(me.sigma),
                           map_error_length_m=10e3 if me is None else float(me.length_m),
                           bias_prior_sigma=float(cfg.bias_sigma_mgal))

        @jax.jit
        def batch(keys, args, fn=spec.fn):
            def one(k):
                run = matching_scenario(k, args[0], args[1])  # the matcher run's start
                out = fn(k, *args)
                return out["err_m"], out["ins_err_m"], run.truth.lat[0], run.truth.lon[0]

            return jax.lax.map(one, keys, batch_size=50)

        err, ins, lat0, lon0 = (np.asarray(v) for v in batch(keys, spec.args))
        pred = node_values(grid, suit.precision_m, lat0, lon0)
        std = node_values(grid, suit.descriptors["std"], lat0, lon0)
        extra = {}
        if a.oracle_draws:
            more = oracle_errors(spec, keys, lat0, lon0, a.oracle_draws)
            extra = dict(oracle_draws=a.oracle_draws, oracle=ranking(more.mean(axis=1), err))
        print(json.dumps(dict(
            setting=name, heading_deg=round(heading, 1), spacing_m=round(spacing, 1),
            n_fixes=scen.n_fixes, median_ratio_to_ins=round(float(np.median(err / ins)), 3),
            crlb=ranking(pred, err), std_descriptor=ranking(std, err, better_is_low=False),
            bias_prior_sigma_mgal=float(cfg.bias_sigma_mgal), **extra,
            seconds=round(time.perf_counter() - t0, 1))), flush=True)


if __name__ == "__main__":
    main()
