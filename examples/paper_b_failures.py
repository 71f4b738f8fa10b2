"""Paper B: why entropy + ICCP is sometimes worse than entropy alone, and a rejected fix.

On 1.6–5 % of tracks (``examples/paper_b_entropy_iccp.py``) entropy + ICCP ends farther
from the truth than the entropy track it started from. This script looks at those
tracks. For each of ``--n`` tracks of the issue's scenario (60 fixes a minute apart at
10 m/s, INS offset 0.02–0.03° and rotated 1.5°; the matchers are told drift ≤ 0.035° and
heading error ≤ 2°), it runs the library's combined matcher
:func:`~jaxgrav.match.combined.match_entropy_iccp` (its decision: the significance test
``Δχ² ≥ --accept-chi2``, the integrity test and the far-fix rejection, status bit
:data:`~jaxgrav.match.combined.FAR_FIX`, beyond ``IccpConfig.max_offset_m`` = 1.5 drift
radii; a rejected fix is the INS track), and beside it the entropy stage and ICCP from
the entropy stage's best offsets and the INS track (the matcher also starts from the
coarse fix, which here, without a map error and so without a posterior fix, is the best
offset again), keeping every start's fit, and reports:

- on the tracks where the combined match is worse than entropy alone: the normalised
  misfit ``N·m/σ²`` of the truth and of the returned fix, and whether any ICCP start
  ended within 500 m of the truth;
- a multi-start ambiguity test on top of the library's decision: where the matcher
  took an ICCP fix, keep the entropy track instead when another start ends more than
  ``D`` m from that fix with ``N·Δm/σ² < A``, for a few ``(D, A)`` (the entropy track
  is then taken as the matcher would keep it, without re-running its integrity test).

``--accept-chi2 A`` sets ``IccpConfig.accept_chi2`` (default the library's, 7.81): the
README's acceptance-threshold table. Run ``python examples/paper_b_failures.py
[--n 1000] [--seed 0] [--case gravity|magnetic] [--accept-chi2 7.81] [--smoke]``
(about 30 s per 1000 tracks on 2 cores after compilation; ``magnetic`` needs ``ppigrf``).
"""

import argparse
import dataclasses
import math
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)  # a script, not the library

from jaxgrav import datasets  # noqa: E402
from jaxgrav.geodesy import local_offsets_m  # noqa: E402
from jaxgrav.match.combined import FAR_FIX, match_entropy_iccp  # noqa: E402
from jaxgrav.match.entropy import coarse_offsets, entropy_config_for  # noqa: E402
from jaxgrav.match.iccp import IccpConfig, iccp_result  # noqa: E402
from jaxgrav.match.sizing import iccp_config_for  # noqa: E402
from jaxgrav.prepared import prepare_map  # noqa: E402
from jaxgrav.scenarios.paper_b import PaperBScenario, paper_b_scenario  # noqa: E402
from jaxgrav.sim import (  # noqa: E402
    DEG_ARC_M,
    track_error_m,
)

CHUNK = 250
OFFSETS_DEG = (0.02, 0.03)
RULES = ((1000.0, 3.84), (1000.0, 7.81), (2000.0, 3.84), (2000.0, 7.81), (1000.0, 11.3))


def every_start(key, grid, scenario, entropy, fine):
    """One track: the combined match, the entropy match and ICCP from each start.

    Parameters
    ----------
    key : PRNG key
    grid : Grid
        Map, also the field sensed.
    scenario : PaperBScenario
    entropy : EntropyConfig
    fine : IccpConfig
        The combined matcher's ICCP stage (its ``accept_chi2`` and ``max_offset_m``
        make the decision).

    Returns
    -------
    dict
        Errors (m) and misfits (map units²) of the combined fix (``comb_*``, with its
        ``status``, ``chosen`` and ``accepted``), the entropy track, the truth and
        every ICCP start's fit (``fit_*``, offsets ``fit_n``/``fit_e`` in m).
    """
    run = paper_b_scenario(key, grid, scenario)
    lat, lon, z = run.ins_lat, run.ins_lon, run.readings
    pm = prepare_map(grid)  # once for every stage
    both = match_entropy_iccp(pm, lat, lon, z, entropy, fine)  # the library's decision
    sample = pm.sampler(entropy.method)
    misfit = lambda la, lo: jnp.mean((z - sample(la, lo)) ** 2)  # noqa: E731
    error = lambda la, lo: track_error_m(la, lo, run.truth)  # noqa: E731
    coarse, _, _, top_n, top_e = coarse_offsets(sample, lat, lon, z, entropy)
    coef = pm.patches()
    fits = jax.vmap(lambda a, b: iccp_result(coef, pm.grid, lat, lon, z, fine, a, b))(
        jnp.append(top_n, 0.0), jnp.append(top_e, 0.0))
    off_n, off_e = jax.vmap(lambda la, lo: local_offsets_m(la, lo, lat, lon))(fits.lat, fits.lon)
    return dict(comb_err=error(both.lat, both.lon), comb_mis=both.score,
                comb_n=both.offset_north_m, comb_e=both.offset_east_m,
                status=both.status, chosen=both.chosen, accepted=both.accepted,
                entropy_err=error(coarse.lat, coarse.lon),
                truth_mis=misfit(run.truth.lat, run.truth.lon), fit_mis=fits.score,
                fit_err=jax.vmap(error)(fits.lat, fits.lon),
                fit_n=off_n.mean(-1), fit_e=off_e.mean(-1))


def iccp_taken(r):
    """Tracks where the matcher accepted its ICCP fix (``chosen`` 1), from
    :func:`every_start`'s outputs."""
    return r["accepted"] & (r["chosen"] == 1)


def combine(r, n_fix, sigma2, rule=None):
    """Per-track error of the library's combined decision, with a rival rule on top.

    Parameters
    ----------
    r : dict
        :func:`every_start`'s outputs over the tracks (NumPy arrays).
    n_fix : int
        Fixes per track.
    sigma2 : float
        Reading noise variance (map units²).
    rule : tuple of float, optional
        ``(D, A)``: where the matcher took an ICCP fix, keep the entropy track when
        another start ends more than ``D`` m from that fix with ``N·Δm/σ² < A``.

    Returns
    -------
    ndarray
        Mean-track error (m) per track.
    """
    err = r["comb_err"]
    if rule is None:
        return err
    dist_max, chi2_max = rule
    fine = iccp_taken(r)
    mis = np.where(np.isfinite(r["fit_mis"]), r["fit_mis"], np.inf)
    dist = np.hypot(r["fit_n"] - r["comb_n"][:, None], r["fit_e"] - r["comb_e"][:, None])
    rival = (dist > dist_max) & (n_fix * (mis - r["comb_mis"][:, None]) / sigma2 < chi2_max)
    return np.where(fine & np.any(rival, 1), r["entropy_err"], err)


def main():
    default_chi2 = IccpConfig().accept_chi2
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000, help="tracks")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--case", choices=("gravity", "magnetic"), default="gravity")
    p.add_argument("--accept-chi2", type=float, default=default_chi2, metavar="A",
                   help="the combined matcher's acceptance test N·Δm/σ² ≥ A "
                        f"(IccpConfig.accept_chi2; finite, ≥ 0; default {default_chi2})")
    p.add_argument("--smoke", action="store_true", help="32 tracks (a quick check)")
    args = p.parse_args()
    if args.smoke:
        args.n = 32
    if args.n < 1:
        p.error(f"--n must be a positive number of tracks, got {args.n}")
    if not (math.isfinite(args.accept_chi2) and args.accept_chi2 >= 0):
        p.exit(2, f"{p.prog}: error: --accept-chi2 must be a finite number >= 0, "
                  f"got {args.accept_chi2}\n")
    if args.case == "gravity":
        grid, noise = datasets.load("ryukyu")["anomaly_2p5min"], 1.0
    else:
        from jaxgrav.fields.magnetic import magnetic_map
        grid, noise = magnetic_map().total, 10.0
    w, e, s, nn = grid.extent
    scenario = PaperBScenario(region=(s, nn, w, e), offset_min_deg=OFFSETS_DEG[0],
                              offset_max_deg=OFFSETS_DEG[1], noise=noise)
    drift_m = (OFFSETS_DEG[1] + 0.005) * DEG_ARC_M
    entropy = entropy_config_for(grid, drift_m, max_half_size=20)
    fine = iccp_config_for(grid, drift_m, stage="fine", noise=noise, max_rotation_deg=2.0)
    fine = dataclasses.replace(fine, accept_chi2=args.accept_chi2)
    f = jax.jit(jax.vmap(every_start, in_axes=(0, None, None, None, None)))
    keys = jax.random.split(jax.random.key(args.seed), args.n)
    t0 = time.perf_counter()
    parts = [f(keys[i:i + CHUNK], grid, scenario, entropy, fine) for i in range(0, args.n, CHUNK)]
    r = {k: np.concatenate([np.asarray(part[k]) for part in parts]) for k in parts[0]}
    n_fix, sigma2 = 60, noise**2
    print(f"{args.case}, seed {args.seed}, {args.n} tracks, Δχ² ≥ {args.accept_chi2:g} "
          f"({time.perf_counter() - t0:.0f} s); entropy alone: median "
          f"{np.median(r['entropy_err']):.0f} m")
    far = (r["status"] & FAR_FIX) != 0
    fine_taken = iccp_taken(r)
    print(f"combined matcher: ICCP fix on {fine_taken.sum()}, entropy track on "
          f"{(r['accepted'] & (r['chosen'] == 0)).sum()}, rejected (INS track) on "
          f"{(~r['accepted']).sum()} tracks ({far.sum()} of them a far fix, beyond "
          f"{fine.max_offset_m:.0f} m)")

    comb = combine(r, n_fix, sigma2)
    worse = comb > r["entropy_err"] + 1.0
    near = np.any(r["fit_err"] < 500.0, 1)
    print(f"worse than entropy by > 1 m: {worse.sum()} tracks")
    if worse.any():
        q = lambda v: np.percentile(v, [0, 50, 100]).round(0)  # noqa: E731
        print(f"  N·misfit/σ² of the truth {q(n_fix * r['truth_mis'][worse] / sigma2)}, "
              f"of the matcher's fix {q(n_fix * r['comb_mis'][worse] / sigma2)} "
              f"(min/median/max; a rejected fix's too)")
        print(f"  the matcher's fix fits at least as well as the truth on "
              f"{np.mean(r['comb_mis'][worse] <= r['truth_mis'][worse]) * 100:.0f} %; "
              f"some ICCP start within 500 m of the truth on {np.mean(near[worse]) * 100:.0f} %")

    print(f"\n{'rule':<34}{'median':>8}{'RMS':>8}{'worse >1 m':>12}{'>500 m':>9}")
    for rule in (None, *RULES):
        c = combine(r, n_fix, sigma2, rule)
        label = f"library decision (Δχ² ≥ {args.accept_chi2:g})" if rule is None else \
            f"+ rival > {rule[0]:.0f} m, Δχ² < {rule[1]}"
        print(f"{label:<34}{np.median(c):>8.0f}{np.sqrt(np.mean(c**2)):>8.0f}"
              f"{np.mean(c > r['entropy_err'] + 1) * 100:>11.1f}%"
              f"{np.mean(c > r['entropy_err'] + 500) * 100:>8.1f}%")


if __name__ == "__main__":
    main()
