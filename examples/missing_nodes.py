"""Maps with missing (NaN) nodes: what a hole costs the interpolant and the dense matcher.

Part 1, the interpolant: random rectangular holes (2–11 nodes a side) in the shipped
2.5′ ``ryukyu`` map; the bicubic interpolant of the holey map
(:func:`jaxgrav.interp.bicubic_coefficients`: missing nodes filled only for the spline
slopes, then masked) against the complete map's, by the distance (nodes) from the cell's
nearest corner to the hole. This is what the user loses next to land: the neighbours'
slopes no longer see the hidden nodes.

Part 2, the dense matcher: paper A's tracks (:class:`~jaxgrav.scenarios.MatchingScenario`
defaults: 30 fixes, drift 0.035°, 1 mGal noise) on the 2.5′ map; in every run an
"island" of 3 × 3 to 5 × 5 nodes (14–23 km) is cut out of the map inside the searched
region, but not under the true track ("land": the ship cannot be there, so the mask is
information), and, separately, holes over part of the true track ("missing data"): a
wide one (3–5 nodes a side) and a narrow one (1–2 nodes). Each holey map is matched
three times: as land (``missing="land"``: candidates touching the hole are dropped),
as survey gaps (``missing="gaps"``: each candidate scored on its fixes over present
cells, :mod:`jaxgrav.match.gaps`) and as the default decides (``missing="auto"``: gaps
when the INS track itself crosses the hole, else land). The same
readings are matched on the complete and the holey maps: median error / INS error,
share worse than the INS,
share flagged (status 8192), share whose fit the χ² test of ``jaxgrav match`` calls
implausible (p < 10⁻³). Rows for a perfect map and for a map error of σ = 3 mGal,
L = 10 km (truth = map + a correlated error, the matcher told it: GLS).

Run: ``python examples/missing_nodes.py [--runs 200] [--trials 20] [--smoke]``; one JSON
line per row.
"""

import argparse
import dataclasses
import json
import warnings

import jax
import jax.numpy as jnp
import numpy as np
from scipy.ndimage import distance_transform_cdt

from jaxgrav import datasets, interp
from jaxgrav.cli.sanity import fit_check
from jaxgrav.fields.map_error import map_error
from jaxgrav.match import match_track
from jaxgrav.match.api import MASKED
from jaxgrav.scenarios import MatchingScenario, matching_scenario
from jaxgrav.sim import DEG_ARC_M, track_error_m


def interpolant_cost(values, trials, rng):
    """RMS and max change (mGal) of the interpolant by distance from a hole."""
    dist, err = [], []
    coef_full = interp.bicubic_coefficients(jnp.asarray(values))
    for _ in range(trials):
        r0, c0 = rng.integers(40, values.shape[0] - 50, 2)
        h, w = rng.integers(2, 12, 2)
        holey = values.copy()
        holey[r0:r0 + h, c0:c0 + w] = np.nan
        iy = rng.uniform(r0 - 12, r0 + h + 12, 40000)
        ix = rng.uniform(c0 - 12, c0 + w + 12, 40000)
        a = np.asarray(interp.bicubic(interp.bicubic_coefficients(jnp.asarray(holey)), iy, ix))
        b = np.asarray(interp.bicubic(coef_full, iy, ix))
        d = distance_transform_cdt(np.isfinite(holey), metric="chessboard")
        ri, ci = np.floor(iy).astype(int), np.floor(ix).astype(int)
        dist.append(np.min([d[ri, ci], d[ri + 1, ci], d[ri, ci + 1], d[ri + 1, ci + 1]], 0))
        err.append(np.abs(a - b))
    dist, err = np.concatenate(dist), np.concatenate(err)
    step = float(np.std(np.diff(values, axis=1)))
    for k in range(1, 7):
        e = err[dist == k]
        yield {"part": "interpolant", "nodes_from_hole": k,
               "rms_mgal": round(float(np.sqrt(np.mean(e**2))), 4),
               "max_mgal": round(float(e.max()), 4),
               "rms_over_node_step": round(float(np.sqrt(np.mean(e**2))) / step, 4),
               "node_step_std_mgal": round(step, 3)}


def _under_truth(grid, run, rng, sides=(3, 5)):
    """A hole of ``sides`` nodes a side over part of the true track (missing survey data)."""
    h, w = rng.integers(sides[0], sides[1] + 1, 2)
    i = rng.integers(0, np.size(run.truth.lat))
    r0 = int(np.floor((float(run.truth.lat[i]) - grid.lat0) / grid.dlat)) - h // 2
    c0 = int(np.floor((float(run.truth.lon[i]) - grid.lon0) / grid.dlon)) - w // 2
    v = np.array(grid.values)
    v[r0:r0 + h, c0:c0 + w] = np.nan
    return dataclasses.replace(grid, values=jnp.asarray(v))


def _island(grid, run, radius_m, rng):
    """A hole of 3–5 nodes a side inside the searched region, off the true track's cells."""
    lat, lon = np.asarray(grid.lat), np.asarray(grid.lon)
    t_lat, t_lon = np.asarray(run.truth.lat), np.asarray(run.truth.lon)
    i_lat, i_lon = np.asarray(run.ins_lat), np.asarray(run.ins_lon)
    r_deg = radius_m / DEG_ARC_M
    for _ in range(200):
        h, w = rng.integers(3, 6, 2)
        la = rng.uniform(i_lat.min() - r_deg, i_lat.max() + r_deg)
        lo = rng.uniform(i_lon.min() - r_deg, i_lon.max() + r_deg)
        r0 = int(np.searchsorted(lat, la)) - h // 2
        c0 = int(np.searchsorted(lon, lo)) - w // 2
        # the cells the true track passes through must keep all four corners
        rows = np.floor((t_lat - grid.lat0) / grid.dlat).astype(int)
        cols = np.floor((t_lon - grid.lon0) / grid.dlon).astype(int)
        hit = ((rows + 1 >= r0) & (rows <= r0 + h - 1) & (cols + 1 >= c0)
               & (cols <= c0 + w - 1))
        if not hit.any():
            v = np.array(grid.values)
            v[r0:r0 + h, c0:c0 + w] = np.nan
            return dataclasses.replace(grid, values=jnp.asarray(v))
    return None


def matcher_cost(grid, runs, sigma, length, rng):
    """Dense matcher on the complete and the holey map, same readings."""
    scen = MatchingScenario()
    radius = scen.drift_deg * DEG_ARC_M
    model = map_error(sigma, length) if sigma > 0 else None
    keys = jax.random.split(jax.random.key(11), runs)
    simulate = jax.jit(lambda k, g: matching_scenario(k, g, scen, map_error=model))
    names = ("complete", "hole off the truth (land), as land",
             "hole off the truth (land), as gaps", "hole off the truth (land), auto",
             "wide hole under the truth, as land",
             "wide hole under the truth, as gaps", "wide hole under the truth, auto",
             "narrow hole under the truth, as land",
             "narrow hole under the truth, as gaps", "narrow hole under the truth, auto")
    missing = ("land", "land", "gaps", "auto", "land", "gaps", "auto", "land", "gaps", "auto")
    ratio = {name: [] for name in names}
    flagged = {name: 0 for name in names}
    implausible = {name: 0 for name in names}
    used = 0
    for key in keys:
        run = simulate(key, grid)
        holey = _island(grid, run, radius, rng)
        if holey is None:
            continue
        used += 1
        ins = float(track_error_m(run.ins_lat, run.ins_lon, run.truth))
        wide, narrow = _under_truth(grid, run, rng), _under_truth(grid, run, rng, (1, 2))
        maps = (grid, holey, holey, holey, wide, wide, wide, narrow, narrow, narrow)
        for name, g, miss in zip(names, maps, missing, strict=True):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                r = match_track(g, run.ins_lat, run.ins_lon, run.readings,
                                drift_radius_m=radius, noise=scen.noise_mgal, warn=False,
                                missing=miss,
                                **({"map_error": model} if model else {}))
            ratio[name].append(float(track_error_m(r.lat, r.lon, run.truth)) / ins)
            flagged[name] += bool(int(r.status) & MASKED)
            implausible[name] += fit_check(r.chi2_per_dof, np.size(run.ins_lat) - 3,
                                           scen.noise_mgal)[1] is not None
            assert np.isfinite(np.asarray(r.lat)).all()
    setting = f"map error {sigma:g} mGal, L {length / 1e3:g} km" if sigma else "perfect map"
    for name, rs in ratio.items():
        rs = np.asarray(rs)
        yield {"part": "dense matcher", "setting": setting, "map": name, "runs": used,
               "median_ratio": round(float(np.median(rs)), 3),
               "worse_than_ins": round(float(np.mean(rs > 1.0)), 3),
               "flagged_8192": round(flagged[name] / max(used, 1), 3),
               "fit_implausible": round(implausible[name] / max(used, 1), 3)}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=200)
    p.add_argument("--trials", type=int, default=20)
    p.add_argument("--smoke", action="store_true", help="4 runs, 2 trials")
    a = p.parse_args(argv)
    if a.smoke:
        a.runs, a.trials = 4, 2
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    rng = np.random.default_rng(0)
    for row in interpolant_cost(np.asarray(grid.values, float), a.trials, rng):
        print(json.dumps(row), flush=True)
    for sigma in (0.0, 3.0):
        for row in matcher_cost(grid, a.runs, sigma, 10e3, rng):
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
