"""``jaxgrav demo``: paper A's experiment on the shipped ``ryukyu`` maps.

1. A Table-1-like table of five INS-drift groups in the paper's setting: the 0.5°
   (degree-359) map refined ×100 to 0.005°, readings taken from that same refined
   map, matched by the paper's constrained chain search.
2. A Monte Carlo summary in a realistic setting: the 2.5′ (degree-2159) map, 30
   fixes two minutes apart at 10 kn east + 10 kn north, 1 mGal noise, INS drift
   0.035°, matched by the default dense-offset matcher.
3. A figure of the map with one true, INS and matched track.
"""

import dataclasses
import json
import time
from pathlib import Path

import jax
import matplotlib.pyplot as plt
import numpy as np

from jaxgrav import datasets
from jaxgrav._io import atomic_output, check_outputs
from jaxgrav.cli.inputs import whole_number
from jaxgrav.cli.simulate import check_seed
from jaxgrav.fields.map_error import map_error
from jaxgrav.match.api import config_for
from jaxgrav.montecarlo import paper_a_table1
from jaxgrav.plot import plot_map, save_figure
from jaxgrav.scenarios import MatchingScenario
from jaxgrav.sim import DEG_ARC_M

__all__ = ["MAX_DEMO_RUNS", "run_demo"]

OUTPUTS = ("table1.md", "summary.json", "tracks.png")


DEMO_MAP_ERROR_MGAL = 3.0
"""σ of the demo's realistic map error (mGal): a marine map against a shipborne gravimeter."""

DEMO_MAP_ERROR_LENGTH_M = 10e3
"""Correlation length of the demo's map error (m)."""


def _realistic_table(rows, title):
    """Markdown table of the realistic-setting batches (one row per setting)."""
    lines = [f"**{title}**", "", "| setting | median error (m) | median ÷ INS median | "
             "worse than INS | fixes accepted | error < 0.01° |", "|" + "---|" * 6]
    for r in rows:
        lines.append(f"| {r['setting']} | {r['error_m_median']:.0f} | {r['median_ratio']:.2f} | "
                     f"{100 * r['worse_rate']:.0f} % | {100 * r['accepted_rate']:.0f} % | "
                     f"{100 * r['success_rate']:.0f} % |")
    lines.append("")
    lines.append("The last row is the headline: a real map is wrong by a few mGal; the first "
                 "row is the best case. A rejected fix keeps the INS track (its error counts).")
    return "\n".join(lines)


def _plot(grid, out, path, force, setting):
    fig, axes = plt.subplots(1, 2, figsize=(14, 5.8), layout="constrained")
    i = int(np.argmin(np.abs(out["err_m"] - np.median(out["err_m"]))))  # a typical run
    tracks = {"true": (out["true_lat"][i], out["true_lon"][i]),
              "INS": (out["ins_lat"][i], out["ins_lon"][i]),
              "matched": (out["lat"][i], out["lon"][i])}
    plot_map(grid, axes[0], tracks=tracks, scale_bar=True,
             title="ryukyu gravity anomaly, EGM2008 to degree 2159")
    lat = np.concatenate([t[0] for t in tracks.values()])
    lon = np.concatenate([t[1] for t in tracks.values()])
    pad = 0.05
    plot_map(grid, axes[1], tracks=tracks, scale_bar=True,
             window=(lat.min() - pad, lat.max() + pad, lon.min() - pad, lon.max() + pad),
             title=(f"{setting}\nthe run with the median error: INS {out['ins_err_m'][i]:.0f} m, "
                    f"matched {out['err_m'][i]:.0f} m (colours: this window's range)"))
    save_figure(fig, path, force=force)


def run_demo(out_dir, *, force=False, runs=200, seed=0, smoke=False, option=None):
    """Run the demo and write ``table1.md``, ``summary.json`` and ``tracks.png`` to ``out_dir``.

    Parameters
    ----------
    out_dir : Path
        Output folder (created if needed).
    force : bool
        Overwrite existing outputs.
    runs : int
        Monte Carlo tracks in the realistic setting; the table uses ``runs // 5``
        (at least 8) per group.
    seed : int
        PRNG seed.
    smoke : bool
        The same steps at toy sizes, for tests (numbers meaningless): the 0.5° map
        refined ×10 instead of ×100, 6 fixes per track in the table and 10 in the
        Monte Carlo, and at least 2 (not 8) tracks per group.
    option : str, optional
        The command-line option that named ``out_dir`` (``--out``), for messages.
    """
    out_dir = Path(out_dir)
    if runs < 5:
        raise ValueError(f"runs must be at least 5; got {runs}")
    # every one that exists named; --out named too (was "'/proc/x/table1.md': a file cannot
    # be created ...", no word of the option)
    check_outputs([out_dir / f for f in OUTPUTS], force=force, names=[option] * len(OUTPUTS))
    t0 = time.perf_counter()
    key = jax.random.key(seed)
    maps = datasets.load("ryukyu")
    coarse, fine_map = maps["anomaly_0p5deg"], maps["anomaly_2p5min"]

    print("jaxgrav demo: paper A, correlation-extremum gravity matching on EGM2008 (ryukyu)"
          + (" (smoke run: toy sizes, numbers meaningless)" if smoke else ""))
    factor, n_table, n_real, min_group = (10, 6, 10, 2) if smoke else (100, 16, 30, 8)
    refined = coarse.refine(factor)
    paper = MatchingScenario(n_fixes=n_table, noise_mgal=0.0, truth_method="bilinear")
    rows = paper_a_table1.table1(jax.random.fold_in(key, 1), refined, refined, method="chains",
                              runs_per_group=max(runs // 5, min_group), base=paper)
    table = paper_a_table1.format_table(
        rows, f"Paper setting: 0.5° map refined ×{factor}, readings from the same map, no "
              f"noise, {n_table} fixes, chain search (difference score, nearest of the 5 best)")
    print(table)

    real = MatchingScenario(n_fixes=n_real, noise_mgal=1.0)
    radius = 1.2 * real.drift_deg * DEG_ARC_M
    white = config_for("dense", fine_map, radius, noise_mgal=1.0, bias_sigma_mgal=3.0)
    error = map_error(DEMO_MAP_ERROR_MGAL, DEMO_MAP_ERROR_LENGTH_M)
    told = config_for("dense", fine_map, radius, noise_mgal=1.0, bias_sigma_mgal=3.0,
                      map_error=error)
    settings = (  # (name, readings' map error, matcher config)
        ("perfect map (best case: readings from the map itself)", None, white),
        (f"map error {DEMO_MAP_ERROR_MGAL:g} mGal, L {DEMO_MAP_ERROR_LENGTH_M / 1e3:g} km; "
         "white-noise matcher", error, white),
        (f"map error {DEMO_MAP_ERROR_MGAL:g} mGal, L {DEMO_MAP_ERROR_LENGTH_M / 1e3:g} km; "
         "matcher told the map error (GLS posterior, integrity)", error, told),
    )
    realistic, batches = [], []
    for name, err_model, cfg in settings:  # the same tracks and map errors in each row
        mc = paper_a_table1.run_batch(jax.random.fold_in(key, 2), runs, fine_map, fine_map,
                                      real, "dense", cfg, map_error=err_model)
        realistic.append(dict(setting=name, **paper_a_table1.summarize(mc)))
        batches.append(mc)
    real_table = _realistic_table(realistic, (
        f"Realistic setting: 2.5' map, 1 mGal noise, {n_real} fixes, drift "
        f"{real.drift_deg:g}°, {runs} random tracks per row, dense-offset matcher"))
    print("\n" + real_table)

    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_output(out_dir / "table1.md", force=force) as tmp:
        tmp.write_text(table + "\n\n" + real_table + "\n")
    with atomic_output(out_dir / "summary.json", force=force) as tmp:
        tmp.write_text(json.dumps(dict(
            paper_setting=rows, realistic_setting=realistic[-1], realistic_settings=realistic,
            headline=realistic[-1]["setting"],
            realistic_config={k: (v if isinstance(v, str | int) else float(v))
                              for k, v in dataclasses.asdict(told).items()
                              if not isinstance(v, tuple | type(None))},
            seed=seed, smoke=smoke, seconds=round(time.perf_counter() - t0, 1)), indent=1))
    _plot(fine_map, batches[-1], out_dir / "tracks.png", force, realistic[-1]["setting"])
    print(f"\nwrote {out_dir / 'table1.md'}, {out_dir / 'summary.json'} and "
          f"{out_dir / 'tracks.png'} ({time.perf_counter() - t0:.0f} s)")


MAX_DEMO_RUNS = 100_000
"""Most Monte Carlo runs ``jaxgrav demo --runs`` takes (500 x the default's)."""


def add_parser(subparsers):
    """Add the ``demo`` sub-command to an ``argparse`` sub-parser set."""
    d = subparsers.add_parser("demo", help="run the main job on the shipped data")
    d.add_argument("--out", default="demo_output", help="output folder (default demo_output)")
    d.add_argument("--runs", type=whole_number, default=200,
                   help=f"Monte Carlo runs (default 200, from 5 to {MAX_DEMO_RUNS}, e.g. 1e4)")
    d.add_argument("--seed", type=int, default=0, help="PRNG seed")
    d.add_argument("--force", action="store_true", help="overwrite existing outputs")
    d.add_argument("--smoke", action="store_true",
                   help="the same steps at toy sizes (about a minute; numbers meaningless)")
    d.set_defaults(func=_cmd_demo)
    return d


def _cmd_demo(args):
    """Run ``jaxgrav demo``: its options checked by name (the library's ``runs must be at
    least 5``, a negative seed run, an --out file ended in "[Errno 17] File exists")."""
    if args.runs < 5:
        raise ValueError(f"--runs must be at least 5 Monte Carlo runs; got {args.runs}")
    if args.runs > MAX_DEMO_RUNS:  # --runs 1000000000 started, silently, for years
        raise ValueError(f"--runs must be at most {MAX_DEMO_RUNS} for the demo (its realistic "
                         f"table runs them three times; the default 200 take about a minute); "
                         f"got {args.runs:.3g}; for larger studies use jaxgrav montecarlo, which "
                         "checks their memory and disk space first")
    check_seed(args.seed)
    if Path(args.out).exists() and not Path(args.out).is_dir():
        raise ValueError(f"--out {args.out!r} is a file; expected a folder (the demo writes "
                         f"{', '.join(OUTPUTS)} into it)")
    run_demo(Path(args.out), force=args.force, runs=args.runs, seed=args.seed, smoke=args.smoke,
             option="--out")
