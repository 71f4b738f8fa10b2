"""``jaxgrav montecarlo``: Monte Carlo runs of a named method on every device.

Wire into :mod:`jaxgrav.cli` with ``add_parser(sub)``; the command function is
:func:`cmd_montecarlo`.
"""

import json
import os
import sys
import time
from pathlib import Path

import jax
import numpy as np

from jaxgrav import __version__, montecarlo
from jaxgrav._io import check_outputs
from jaxgrav.cli.inputs import check_map_field, check_out_format, whole_number
from jaxgrav.cli.montecarlo_options import (
    check_drift,
    check_options,
    check_results_size,
    told_from_args,
)
from jaxgrav.cli.montecarlo_summary import (
    fix_lines,
    format_summary,
    summarize,
    worse_rate,
)
from jaxgrav.cli.montecarlo_voyage import (
    add_loop_options,
    plot_voyage_tracks,
    plot_voyages,
    tracks_path,
    voyage_attrs,
    voyage_lines,
    voyage_options,
)
from jaxgrav.cli.simulate import (
    DEFAULT_MAP_ERROR_LENGTH_M,
    add_map_error_options,
    describe_map_error,
    map_error_from_args,
)
from jaxgrav.datasets import load_map
from jaxgrav.montecarlo.draws import variable_attrs
from jaxgrav.montecarlo.filter_runs import MAP_ERROR_TOLD
from jaxgrav.montecarlo.fix_metrics import fix_summary
from jaxgrav.montecarlo.matcher_runs import MISSING_MAP_START_TRIES
from jaxgrav.montecarlo.methods import (
    BUILDERS,
    DEPRECATED_METHODS,
    FILTER_METHODS,
    METRICS,
    VOYAGE_METHODS,
    build,
    default_grid,
    resolve_method,
)
from jaxgrav.plot import plot_error_summary, save_figure
from jaxgrav.scenarios import INS_GRADES

__all__ = ["add_parser", "cmd_montecarlo", "format_summary", "summarize"]

MASKED_MAP_METHODS = ("dense", "chains", "entropy", "iccp", "entropy+iccp", *FILTER_METHODS,
                      *VOYAGE_METHODS)
"""Methods whose runs take a map with missing (land) nodes: a run's start (a voyage's
route) is drawn again until its true track reads none (:data:`MISSING_MAP_START_TRIES`
tries)."""

TOLD_MATCHERS = ("dense", "chains", "entropy+iccp")
"""Matchers that take ``--told-map-error`` (and are told ``--map-error`` by default)."""


def add_parser(subparsers):
    """Add the ``montecarlo`` sub-command to an ``argparse`` sub-parser set."""
    m = subparsers.add_parser("montecarlo", help="Monte Carlo runs of a method on all devices")
    m.add_argument("--method", required=True, choices=[*sorted(BUILDERS), *DEPRECATED_METHODS],
                   metavar="{" + ",".join(sorted(BUILDERS)) + "}",
                   help="dense: paper A's dense-offset matcher (formerly 'correlation', still "
                        "accepted); chains: paper A's iso-point chains (map refined to 0.005 deg "
                        "nodes); entropy, iccp, entropy+iccp: paper B's stages alone and "
                        "combined; ukf, ekf, gsf (Gaussian-sum UKF), pmf (grid point-mass "
                        "filter), pf (SIR particle filter, 2000 particles), rbpf "
                        "(Rao-Blackwellised particle filter, 1000 particles) and the guarded "
                        "ukf-guard, gsf-guard: paper D's filters (over its three point masses, or "
                        "over --map); voyage-dense, voyage-chains, voyage-entropy+iccp (loosely "
                        "coupled, hourly fixes of that matcher), voyage-ukf, voyage-ekf, "
                        "voyage-gsf, voyage-rbpf, voyage-pmf (tightly coupled; voyage-rbpf: 500 "
                        "particles): 12 h patrols (--hours) navigated with a navigation-grade "
                        "INS (--ins)")
    m.add_argument("--runs", type=whole_number, required=True,
                   help="number of simulated runs (e.g. 1000 or 1e6); from 10000 runs their "
                        "memory and file size are estimated first, and refused beyond 80 %% "
                        "of the machine's memory or the disk's free space")
    m.add_argument("--chunk", type=whole_number, default=None,
                   help="runs per compiled call (bounds memory; default 256)")
    m.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    m.add_argument("--devices", type=whole_number, default=None,
                   help="use this many devices, at most --runs (default all; on a CPU the "
                        "host is split into this many when JAX has not started yet)")
    m.add_argument("--map", default=None,
                   help="map simulated and matched or filtered, a NetCDF grid or shipped "
                        "map (mGal); matchers: default ryukyu, the 2.5' EGM2008 anomaly; "
                        "filters: default paper-d, paper D's three point masses; over a map "
                        "straight tracks in random directions inside it")
    m.add_argument("--drift", type=float, default=None,
                   help="INS error (degrees of arc); dense: drift radius (default 0.035, also "
                        "chains); entropy, iccp, entropy+iccp: offset uniform in [2/3, 1] x drift "
                        "(default 0.03); filters: initial position error (default 0.018 = 2 km); "
                        "voyage-*: initial position error (size; default 0.0045 = 500 m), not "
                        "the INS drift over the hours (that is --ins); below half the map's "
                        "shorter side (paper D's point masses: 0.35)")
    m.add_argument("--noise", type=float, default=None,
                   help="reading noise sigma (mGal, > 0, default 1)")
    m.add_argument("--fixes", type=whole_number, default=None,
                   help="fixes per track (default 30 dense and chains, 60 entropy, "
                        "iccp and entropy+iccp); "
                        "filters: readings 10 s apart, start included (default 721 = 2 h); "
                        "with --chunk, refused beyond 80 %% of the machine's memory")
    m.add_argument("--out", required=True,
                   help="results NetCDF (one value per run); a PNG of the errors is written "
                        "next to it with suffix .png")
    add_map_error_options(m)
    m.add_argument("--told-map-error", default=None, metavar="WHAT",
                   help="what the method is told about --map-error / --truth-map. Filters: "
                        "state (default: a Gauss-Markov map-error state; the point-mass "
                        "filter's is per cell), white (white noise of the same sigma) or none. "
                        "dense, chains, entropy+iccp: SIGMA[,L] (GLS score, posterior-mean "
                        "fix, fixes with a 1-sigma above 3 km rejected; dense and "
                        "entropy+iccp: over the searched disc, also above 0.9 x the disc's "
                        "own; SIGMA in map units, L in m, default "
                        "--map-error-length or 10000) or 0 / none (the white-noise matcher); "
                        "default the --map-error model itself, or for --truth-map an estimate "
                        "from --map alone (fields.map_error_estimate)")
    m.add_argument("--map-error-order", type=int, default=None, metavar="{1,2}",
                   help="filters only: order of the map-error state, 1 (first-order "
                        "Gauss-Markov, length 2 L for the second-order map error) or 2 "
                        "(second order, matched exactly); default the map error's own order "
                        "(2), 1 for pmf (which has no order 2)")
    m.add_argument("--hours", type=float, default=None,
                   help="voyage methods: length of each patrol (h, default 12)")
    m.add_argument("--ins", choices=sorted(INS_GRADES), default=None,
                   help="voyage methods: the INS, navigation (0.01 deg/h, 25 ug, default) or "
                        "strategic (jaxgrav's default INSErrorModel)")
    add_loop_options(m)
    m.add_argument("--no-progress", action="store_true", help="no progress bar")
    m.add_argument("--force", action="store_true", help="overwrite existing outputs")
    m.set_defaults(func=cmd_montecarlo)

    return m


def _plot_errors(results, summary, title, path, force, label="matched",
                 xlabel="mean track error (m)"):
    fig = plot_error_summary(results["ins_err_m"], results["err_m"], title=title, label=label,
                             xlabel=xlabel, failure_ratio=summary["failure_ratio"])
    save_figure(fig, path, force=force)


def _in_map_units(key, grid):
    """A setting's name with its unit suffix in the map's units: ``noise_mgal`` is
    ``noise_nt`` on a magnetic (nT) map (the value was nT, the name said mGal)."""
    if grid is not None and grid.units == "nT" and key.endswith("_mgal"):
        return key[:-len("_mgal")] + "_nt"
    return key


def _split_cpu(n):
    """Ask for ``n`` CPU devices if JAX has not started its backend yet (else no-op)."""
    if "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", ""):
        return
    try:
        if n > 1:
            jax.config.update("jax_num_cpu_devices", n)
    except RuntimeError:  # the backend already runs (e.g. called from Python); keep it
        pass


def _command(args):
    opts = [("--method", args.method), ("--runs", args.runs), ("--chunk", args.chunk),
            ("--seed", args.seed), ("--devices", args.devices), ("--map", args.map),
            ("--drift", args.drift), ("--noise", args.noise), ("--fixes", args.fixes),
            ("--map-error", args.map_error), ("--map-error-length", args.map_error_length),
            ("--truth-map", args.truth_map), ("--told-map-error", args.told_map_error),
            ("--map-error-order", args.map_error_order), ("--hours", args.hours),
            ("--ins", args.ins)]
    return "jaxgrav montecarlo " + " ".join(f"{k} {v}" for k, v in opts if v is not None)


def cmd_montecarlo(args):
    """Run ``jaxgrav montecarlo`` (x64 is enabled by the CLI entry point)."""
    if args.method in DEPRECATED_METHODS:
        print(f"jaxgrav montecarlo: --method {args.method} is deprecated; use --method "
              f"{DEPRECATED_METHODS[args.method]}", file=sys.stderr)
        args.method = resolve_method(args.method)
    check_options(args)
    if args.devices is not None:
        _split_cpu(args.devices)
    out = Path(args.out)
    png = out.with_suffix(".png")
    if out.suffix == ".png":
        raise ValueError(f"--out must be a NetCDF file (the PNG goes next to it); got {out}")
    kind = ("filter" if args.method in FILTER_METHODS else
            "voyage" if args.method in VOYAGE_METHODS else "matcher")
    targets = {"--out": out, "the PNG next to --out": png}
    if kind == "voyage":
        targets["the tracks PNG next to --out"] = tracks_path(out)
    # folders, inputs and repeats first; then every existing output named
    check_outputs(list(targets.values()), force=args.force, names=list(targets),
                  inputs={"--map": args.map, "--truth-map": args.truth_map})
    check_out_format(out, "NetCDF")
    if args.map is not None:
        map_name = str(args.map)
    else:  # the method's default (jaxgrav.montecarlo.build)
        map_name = "paper-d" if kind == "filter" else "ryukyu"
    # every method draws each run's start (a voyage's route) again until its track reads
    # no missing node (MISSING_MAP_START_TRIES)
    masked_ok = args.method in MASKED_MAP_METHODS
    grid = (None if args.map is None or (kind == "filter" and args.map == "paper-d")
            else load_map(args.map, None, allow_nan=masked_ok))
    if grid is None and (kind == "voyage" or (kind == "matcher" and args.truth_map)):
        grid = default_grid()
    if grid is not None and kind != "matcher":  # a gravimeter's bias and Eötvös, over nT
        check_map_field(grid, "gravity", args.map)
    check_drift(args, default_grid() if grid is None and kind == "matcher" else grid, kind)
    # alone, --map-error-length is the length of --told-map-error SIGMA (dense)
    model = map_error_from_args(args, grid, allow_nan=masked_ok,
                                length_alone=args.told_map_error is not None)
    if model is not None and grid is None and kind == "filter":
        raise ValueError(f"--map-error and --truth-map need --map MAP with --method "
                         f"{args.method}: paper D's point masses have no grid to draw a map "
                         "error on")
    extra = {}
    for name, value in (("--hours", args.hours), ("--ins", args.ins),
                        ("--segment-error", args.segment_error), ("--fix-prior", args.fix_prior),
                        ("--first-n-fixes", args.first_n_fixes),
                        ("--shape-update", args.shape_update)):
        if value is not None and kind != "voyage":
            raise ValueError(f"{name} is an option of the voyage methods "
                             f"({', '.join(VOYAGE_METHODS)}); got --method {args.method}")
    if kind == "voyage":
        extra.update(voyage_options(args))
    elif kind == "filter":
        if args.told_map_error is not None:
            if args.told_map_error not in MAP_ERROR_TOLD:
                raise ValueError(f"--told-map-error must be one of {', '.join(MAP_ERROR_TOLD)} "
                                 f"with --method {args.method}; got {args.told_map_error!r}")
            extra["map_error_told"] = args.told_map_error
        if args.map_error_order not in (None, 1, 2):
            raise ValueError(f"--map-error-order must be 1 or 2; got {args.map_error_order}")
        if args.map_error_order is not None and model is None:  # was ignored, silently
            raise ValueError(f"--map-error-order {args.map_error_order} is the order of the "
                             "map-error state the filters are told, and the runs draw no map "
                             "error: add --map-error SIGMA or --truth-map MAP, or leave it out")
        if args.map_error_order is not None:
            extra["map_error_order"] = args.map_error_order
    else:
        if args.map_error_order is not None:
            raise ValueError(f"--map-error-order is a filter option; got --method {args.method}")
        if args.told_map_error is not None:
            if args.method not in TOLD_MATCHERS:
                raise ValueError(f"--told-map-error is used by the filters and --method "
                                 f"{', '.join(TOLD_MATCHERS)} only; got --method {args.method}")
            extra["map_error_told"] = told_from_args(args)
    spec = build(args.method, grid, drift_deg=args.drift, noise=args.noise, n_fixes=args.fixes,
                 map_error=model, **extra)
    check_results_size(args, spec, out)
    n_dev = args.devices or len(jax.devices())
    setting = describe_map_error(args)
    print(f"jaxgrav montecarlo: {args.method} ({spec.settings['description']}), {args.runs} "
          f"runs on {n_dev} {jax.devices()[0].platform} device(s), "
          + ("paper D's point masses" if map_name == "paper-d" else f"map {map_name}")
          + f", {setting}")
    t0 = time.perf_counter()
    results = montecarlo.run(spec.fn, jax.random.key(args.seed), args.runs, chunk=args.chunk,
                             devices=args.devices, progress=not args.no_progress,
                             args=spec.args, cpu_options=spec.cpu_options)
    seconds = time.perf_counter() - t0
    missing = [k for k in METRICS if k not in results]
    if missing:
        raise ValueError(f"method {args.method!r} does not return {missing}")
    summary = summarize(results, kind)
    print(f"readings: {setting}")
    print(format_summary(summary, spec.status_bits))
    if "told_map_error_sigma" in spec.settings:
        told_sigma = spec.settings["told_map_error_sigma"]
        print("matcher told: " + ("no map error (white-noise score)" if not told_sigma else
                                  f"map error {told_sigma:.3g} (map units), L = "
                                  f"{spec.settings['told_map_error_length_m'] / 1000:.3g} km")
              + f" ({spec.settings['told_map_error_source']})")
    for line in fix_lines(results):
        print(line)
    if grid is not None and grid.n_missing and "readings_on_map" in results:
        print(f"clear starts: {int(np.sum(results['readings_on_map']))} of {args.runs} runs "
              f"found, within {MISSING_MAP_START_TRIES} tries, a true track that reads no "
              f"missing map node ({grid.n_missing} of the map's nodes are missing)")
    if "readings_on_map" in results and not np.all(results["readings_on_map"]):
        bad = int(np.sum(~np.asarray(results["readings_on_map"], bool)))
        print(f"warning: {bad} of {args.runs} runs found no start in "
              f"{MISSING_MAP_START_TRIES} tries whose track reads no missing map node; their "
              "readings hold NaN and they count as failures (the map is mostly missing?)",
              file=sys.stderr)
    if kind == "voyage":
        print(voyage_lines(results))
    print(f"{args.runs} runs in {seconds:.1f} s ({args.runs / seconds:.1f} runs/s, "
          "compilation included)")
    attrs = dict(
        title=f"jaxgrav montecarlo --method {args.method}", method=args.method,
        runs=args.runs, seed=args.seed, chunk=args.chunk or montecarlo.DEFAULT_CHUNK,
        devices=n_dev, map=map_name, map_error_setting=setting,
        map_error_sigma=float(args.map_error or 0.0),
        map_error_length_m=float(DEFAULT_MAP_ERROR_LENGTH_M if args.map_error_length is None
                                 else args.map_error_length),
        truth_map=str(args.truth_map or map_name),
        seconds=round(seconds, 3),
        jax_version=jax.__version__, jaxgrav_version=__version__,
        command=_command(args),
        status_bits=json.dumps({str(k): v for k, v in spec.status_bits.items()}),
        **{f"setting_{_in_map_units(k, grid)}": v for k, v in spec.settings.items()},
        **{f"summary_{k}": v for k, v in summary.items() if not isinstance(v, dict)},
        **{f"summary_{k}": v for k, v in fix_summary(results).items()},
        **({"summary_worse_rate": worse_rate(results)} if kind == "matcher" else {}),
        **(voyage_attrs(results) if kind == "voyage" else {}),
        **{f"summary_{k}_{c}": v for k, d in summary.items() if isinstance(d, dict)
           for c, v in d.items()},
    )
    ds = montecarlo.to_dataset(results)
    for name, var_attrs in variable_attrs(kind).items():
        if name in ds:
            ds[name].attrs.update(var_attrs)
    montecarlo.write_netcdf(ds, out, attrs=attrs, force=args.force)
    if kind == "voyage":
        plot_voyages(results, f"{args.method}: {args.runs} voyages, {setting}", png, args.force)
        plot_voyage_tracks(spec, jax.random.key(args.seed), args.runs,
                           f"{args.method}: run 1 of {args.runs}, {setting}", tracks_path(out),
                           args.force)
        png = f"{png} and {tracks_path(out)}"
    elif kind == "filter":
        _plot_errors(results, summary, f"{args.method}: {args.runs} runs, {setting}", png,
                     args.force, label="filtered",
                     xlabel="RMS position error, second half of the run (m)")
    else:
        _plot_errors(results, summary, f"{args.method}: {args.runs} runs, {setting}", png,
                     args.force)
    print(f"wrote {out} and {png}")
