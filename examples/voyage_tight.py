"""Tightly coupled navigation over 12 h patrols: the UKF (or EKF, Gaussian sum) on every reading.

The voyage issue's setting, as ``examples/voyage_loose.py``: ``patrol-12h`` on the
shipped 2.5′ ``ryukyu`` map (10 kn, a reading every 10 s with 1 mGal noise,
navigation-grade INS started 500 m off), each voyage's truth the map plus a correlated
map error (σ, L below; the ``markov2`` family) drawn from its key. The filter
(:func:`jaxgrav.navigate.navigate_tight`) corrects Eötvös with the INS velocity and
carries the Eötvös effect of the velocity error in its measurement. Settings, on the
same voyages:

- ``perfect map`` — truth = map, no map-error state (best case, inverse crime);
- ``map error, told`` — the filter carries a Gauss–Markov map-error state of the
  true σ and L (``--order 2``: the second-order state, the exact match of ``markov2``;
  ``--order 1``: first order, L doubled to the same integral scale);
- ``map error, not told`` — the same readings, the filter without a map-error state;
- ``map error, told, Eötvös velocity ignored`` — told, but the Eötvös effect of the
  velocity error left out of the measurement (as a filter fed Eötvös-corrected
  readings without it would be).

Printed, one JSON line per setting: the figures of
:func:`jaxgrav.navigate.voyage_summary` (hourly RMS of the navigation solution and of
the free INS, last-hour ratio, last over second hour, share of voyages worse than the
free INS in some hour from the second on, NEES), the share of readings used, runs/s.
With ``--bound``, for the perfect map and the told map error, the posterior Cramér–Rao
bound along each voyage (:func:`jaxgrav.navigate.voyage_bound`: the same model, the
measurement row at the true position): its hourly RMS over voyages, its last hour over
the free INS's and over its second hour, the filter's last hour over it (and the median
voyage's), and the share of voyages whose bound exceeds the free INS's error in some
hour from the second on — where no estimator is expected to beat the INS.

Run: ``python examples/voyage_tight.py [--runs 100] [--method ukf|ekf|gsf|rbpf] [--order 1|2]
[--sigma 3] [--length 10000] [--ins navigation|strategic] [--png FILE] [--tracks-png FILE]
[--bound] [--smoke]``.
"""

import argparse
import dataclasses
import json
import time

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

from jaxgrav import datasets
from jaxgrav.fields.map_error import map_error
from jaxgrav.filters import matched_state
from jaxgrav.navigate import (
    TIGHT_METHODS,
    TightConfig,
    hourly_rms,
    loose_config,
    navigate_tight,
    voyage_bound,
    voyage_errors,
    voyage_summary,
)
from jaxgrav.plot import plot_map, plot_voyage_errors, save_figure
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import INS_GRADES, voyage_preset, voyage_scenario

EVERY = 60
"""Steps between the samples of the error series kept for the figure (10 min)."""

SETTINGS = ("perfect map", "map error, told", "map error, not told",
            "map error, told, Eötvös velocity ignored")


def _one(pm, grid, key, scenario, model, config, bound):
    voyage = voyage_scenario(key, grid, scenario, model)
    res = navigate_tight(pm, voyage, config, jax.random.fold_in(key, 1))  # rbpf's draws
    err = voyage_errors(voyage, res.nav, res.cov_north_east)
    sigma = jnp.sqrt(jnp.trace(res.cov_north_east, axis1=1, axis2=2))
    used = jnp.mean((res.status == 0) & jnp.isfinite(voyage.gravity))  # status 0: updated
    series = (err.nav_m[::EVERY], err.free_m[::EVERY], sigma[::EVERY])
    # the bound's RMS per hour (its mean square over the hour, as hourly_rms of an error)
    # (without: a placeholder of one value; a zero-size output breaks lax.map's batches)
    bound_h = (hourly_rms(voyage_bound(pm, voyage, config).position_rms, scenario.dt)
               if bound else jnp.zeros(1))
    return (hourly_rms(err.nav_m, scenario.dt), hourly_rms(err.free_m, scenario.dt),
            err.nees.mean(), used, series, bound_h)


def run(grid, scenario, model, config, keys, batch=50, bound=False):
    """Simulate and filter voyages in one compiled call, ``batch`` voyages at a time
    batched with ``vmap`` (4 × a loop on the 2-core machine, ``benchmarks/voyage_tight.py``);
    with ``bound``, each voyage's Cramér–Rao bound per hour too (m)."""
    pm = prepare_map(grid)
    f = jax.jit(lambda pm, grid, ks: jax.lax.map(
        lambda k: _one(pm, grid, k, scenario, model, config, bound), ks, batch_size=batch))
    return jax.tree.map(np.asarray, f(pm, grid, keys))


def bound_figures(nav, free, bound):
    """The bound beside the filter and the free INS (hourly RMS over voyages)."""
    rms = lambda a: np.sqrt(np.mean(a**2, axis=0))  # noqa: E731
    b, f, n = rms(bound), rms(free), rms(nav)
    return {"bound_hourly_rms_m": np.round(b, 1).tolist(),
            "bound_last_hour_ratio": float(b[-1] / f[-1]),
            "bound_last_over_second_hour": float(b[-1] / b[1]) if b.size > 1 else None,
            "nav_over_bound_last_hour": float(n[-1] / b[-1]),
            "median_voyage_nav_over_bound_last_hour": float(np.median(nav[:, -1] / bound[:, -1])),
            # a voyage whose bound exceeds its free INS's error: no estimator is expected
            # to beat the INS there, however it is built
            "bound_above_free_some_hour": float(np.mean(np.any(bound[:, 1:] > free[:, 1:],
                                                               axis=1)))}


def tracks_figure(grid, scenario, model, config, key, path, title, force):
    """One voyage on the map: the truth, the free INS and the tightly coupled solution."""
    voyage = voyage_scenario(key, grid, scenario, model)
    res = navigate_tight(prepare_map(grid), voyage, config, jax.random.fold_in(key, 1))
    tracks = {"truth": (voyage.truth.lat, voyage.truth.lon),
              "free INS": (voyage.ins.lat, voyage.ins.lon),
              "navigation": (res.nav.lat, res.nav.lon)}
    lats = np.concatenate([np.asarray(a) for a, _ in tracks.values()])
    lons = np.concatenate([np.asarray(b) for _, b in tracks.values()])
    pad = 0.05
    window = (lats.min() - pad, lats.max() + pad, lons.min() - pad, lons.max() + pad)
    fig, ax = plt.subplots(figsize=(7, 6), layout="constrained")
    plot_map(grid, ax, tracks=tracks, window=window, scale_bar=True, title=title)
    save_figure(fig, path, force=force)


def config_for(setting, ins, model, method, order, reacquire=None, **pmf):
    """The filter of one setting (see the module notes); ``pmf``: TightConfig's pmf_* fields;
    ``reacquire``: None, or a dict of TightConfig's ``reacquire_*`` settings (the loop's
    dense matcher told the setting's map error, its fix not weighed by the filter's prior)."""
    cfg = TightConfig(ins=ins, method=method, **pmf)
    told = setting in ("map error, told", "map error, told, Eötvös velocity ignored")
    if told:
        cfg = dataclasses.replace(cfg, map_error=matched_state(model, order))
    if reacquire is not None:
        loop = loose_config(ins, float(model.sigma) if told else 0.0, float(model.length_m),
                            cfg.noise_mgal, fix_prior=False)
        cfg = dataclasses.replace(cfg, reacquire=loop, **reacquire)
    if setting == "map error, told, Eötvös velocity ignored":
        cfg = dataclasses.replace(cfg, eotvos_velocity=False)
    return cfg


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=100)
    p.add_argument("--method", choices=TIGHT_METHODS, default="ukf")
    p.add_argument("--order", type=int, choices=(1, 2), default=2,
                   help="order of the filter's map-error state")
    p.add_argument("--sigma", type=float, default=3.0, help="map error sigma (mGal)")
    p.add_argument("--length", type=float, default=10000.0, help="map error L (m)")
    p.add_argument("--ins", choices=sorted(INS_GRADES), default="navigation")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--settings", nargs="+", choices=SETTINGS, default=list(SETTINGS))
    p.add_argument("--png", default=None,
                   help="error-against-time figure of the 'map error, told' runs")
    p.add_argument("--tracks-png", default=None,
                   help="the first voyage of 'map error, told' on the map: truth, free INS, "
                        "navigation")
    p.add_argument("--force", action="store_true", help="overwrite --png and --tracks-png")
    p.add_argument("--bound", action="store_true",
                   help="the posterior Cramér–Rao bound along each voyage beside the filter "
                        "(settings 'perfect map' and 'map error, told')")
    p.add_argument("--smoke", action="store_true", help="2 voyages of 2 h")
    p.add_argument("--reacquire", action="store_true",
                   help="ukf/ekf: check the filter every hour with the loop's dense matcher over "
                        "the last 2 h and reset it to the fix where it is lost")
    p.add_argument("--reacquire-sigma", type=float, nargs="+", default=None,
                   help="--reacquire: the position sigma (m) opened for each stage's window "
                        "(default: TightConfig's)")
    p.add_argument("--reacquire-gate", type=float, default=None,
                   help="--reacquire: chi2(2) above which a fix resets the filter")
    p.add_argument("--reacquire-ratio", type=float, default=None,
                   help="--reacquire: filter sigma over fix sigma above which a fix resets it")
    p.add_argument("--pmf-cell", type=float, default=100.0,
                   help="--method pmf: the (first) cell size, m (default 100)")
    p.add_argument("--pmf-span", type=float, default=4.0,
                   help="--method pmf: sigma its adaptive grid spans per side; 0: fixed grid")
    a = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # geodesy and 12 h of INS error in float64
    runs, hours = (2, 2.0) if a.smoke else (a.runs, 12.0)
    ins = INS_GRADES[a.ins]
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    scenario = voyage_preset("patrol-12h", ins=ins, hours=hours)
    keys = jax.random.split(jax.random.key(a.seed), runs)
    model = map_error(a.sigma, a.length)
    reacquire = None
    if a.reacquire:
        reacquire = {k: v for k, v in (
            ("reacquire_sigma_m", None if a.reacquire_sigma is None else tuple(a.reacquire_sigma)),
            ("reacquire_gate", a.reacquire_gate), ("reacquire_ratio", a.reacquire_ratio))
            if v is not None}
    rows = {}
    for setting in a.settings:
        truth = None if setting == "perfect map" else model
        cfg = config_for(setting, ins, model, a.method, a.order, reacquire,
                         pmf_cell_m=a.pmf_cell, pmf_span=a.pmf_span)
        t0 = time.perf_counter()
        bound = a.bound and setting in ("perfect map", "map error, told")
        nav, free, nees, used, series, bound_h = run(grid, scenario, truth, cfg, keys,
                                                     bound=bound)
        seconds = time.perf_counter() - t0
        row = {"setting": setting, "method": a.method, "ins": a.ins, "runs": runs,
               **({"reacquire": {k: np.asarray(getattr(cfg, k)).tolist() for k in (
                   "reacquire_sigma_m", "reacquire_sigma_vel", "reacquire_gate",
                   "reacquire_ratio")}} if a.reacquire else {}),
               "hours": hours, "map_error_mgal": 0.0 if truth is None else a.sigma,
               "map_error_length_m": a.length, "order": a.order,
               **({"pmf_cell_m": a.pmf_cell, "pmf_span": a.pmf_span} if a.method == "pmf"
                  else {}),
               **voyage_summary(nav, free, nees),
               **(bound_figures(nav, free, bound_h) if bound else {}),
               "readings_used": float(np.mean(used)), "seconds": round(seconds, 1),
               "runs_per_s": round(runs / seconds, 2)}
        print(json.dumps(row))
        rows[setting] = row
        if a.png and setting == "map error, told":
            t_h = np.arange(series[0].shape[1]) * EVERY * scenario.dt / 3600.0
            fig = plot_voyage_errors(
                t_h, *series, title=f"tightly coupled ({a.method}), {runs} patrols of "
                f"{hours:g} h, {a.ins} INS, map error {a.sigma:g} mGal / "
                f"{a.length / 1e3:g} km told")
            save_figure(fig, a.png, force=a.force)
        if a.tracks_png and setting == "map error, told":
            tracks_figure(grid, scenario, truth, cfg, keys[0], a.tracks_png,
                          f"voyage 1: tightly coupled ({a.method}), {hours:g} h, map error "
                          f"{a.sigma:g} mGal told", a.force)
    return rows


if __name__ == "__main__":
    main()
