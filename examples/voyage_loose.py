"""Loosely coupled navigation over 12 h patrols: dense-matcher fixes into the INS error KF.

The voyage issue's setting: ``patrol-12h`` on the shipped 2.5′ ``ryukyu`` map (10 kn, a
reading every 10 s with 1 mGal noise, navigation-grade INS started 500 m off), each
voyage's truth the map plus a correlated map error (σ, L below) drawn from its key, and
the same voyages on a perfect map (best case). The loop (:func:`jaxgrav.navigate.
navigate_loose`) matches a 2 h segment (60 fixes, each the mean of 12 readings) every
hour, the first after 2 h; the matcher is told the map error and the Eötvös error of
the filter's velocity (the dense matcher: the segment's Eötvös and stretch errors given
its offset, ``LooseConfig.segment_error``, and its readings then update the rest of the
state given the fix, ``LooseConfig.shape_update``; the others: at its along-track
Schuler length, :func:`jaxgrav.navigate.loose_match.told_error`).

Printed, one JSON line per setting: hourly RMS radial error of the navigation solution
and of the free INS (m), the last-hour ratio nav/free and last/second hour, the share
of voyages worse than the free INS in some hour from the second on, the worst such
ratio, the position NEES (2 expected), the fix events and runs per second.

``--calibrate`` measures the fixes alone instead: on each voyage an ideal filter (fed
honest 500 m fixes of the true segment-mean error every hour) gives the state a good
loop would have; each hour's segment, corrected with it, is matched as the loop does
and the fix compared with the true residual: error, fix NEES (2 expected; median 1.39)
and the share within the fix's 95 % ellipse (coverage, 0.95 expected), over every fix
(a rejected one as no correction with the matcher's covariance) and over the accepted
ones, by quartile of the matcher's edge mass; and the ideal filter's own hourly RMS
error and NEES.

The loop's settings are :func:`jaxgrav.navigate.loose_config`'s (for the dense matcher
:data:`jaxgrav.navigate.DENSE_LOOP`: 2 h segments every hour, the first after 2 h, the
segment's error told given its offset, the filter's prior, the lattice's cell told, the
segment's readings updating the state given the fix, a run of failed fixes widening the
filter's covariance);
``--segment-error markov|linear|conditional``, ``--[no-]fix-prior``, ``--[no-]cell-error``,
``--n-fixes``, ``--stride``, ``--first-n-fixes`` (0: none), ``--fix-cov-scale`` and
``--[no-]shape-update`` (the segment's readings update the state given the fix,
:mod:`jaxgrav.navigate.loose_shape`), ``--reacquire-after`` (0: never) and
``--reacquire-inflation`` (a run of failed fixes widens the covariance,
:mod:`jaxgrav.navigate.loose_reacquire`) change them (``--segment-error markov`` alone: the
old loop, 1 h segments, × 3).

Run: ``python examples/voyage_loose.py [--runs 100] [--seed 0] [--sigma 3] [--length 10000]
[--ins navigation|strategic] [--calibrate] [--smoke] [--matcher dense|chains|entropy+iccp]
[--segment-error markov] [--no-fix-prior] [--no-cell-error] [--n-fixes 60 --stride 30]
[--first-n-fixes 30] [--fix-cov-scale 1] [--reacquire-after 0]``.
"""

import argparse
import json
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import datasets
from jaxgrav.fields.map_error import map_error
from jaxgrav.navigate import (
    FIX_EVENTS,
    LOOSE_MATCHERS,
    SEGMENT_ERRORS,
    LooseConfig,
    error_kf_tables,
    first_segment_ends,
    first_tables,
    fix_segment,
    fix_update,
    hourly_rms,
    loose_config,
    loose_map,
    navigate_loose,
    voyage_errors,
    voyage_summary,
)
from jaxgrav.plot import plot_voyage_errors, save_figure
from jaxgrav.scenarios import INS_GRADES, voyage_preset, voyage_scenario
from jaxgrav.sim.ins import initial_covariance

CHI2_2_95 = 5.991
"""95 % point of χ²(2): a fix whose NEES is below it is covered by its 95 % ellipse."""

EVERY = 60
"""Steps between the samples of the error series kept for the figure (10 min)."""


def _one(pm, grid, key, scenario, model, config):
    voyage = voyage_scenario(key, grid, scenario, model)
    res = navigate_loose(pm, voyage, config)
    err = voyage_errors(voyage, res.nav, res.cov_north_east)
    sigma = jnp.sqrt(jnp.trace(res.cov_north_east, axis1=1, axis2=2))
    series = (err.nav_m[::EVERY], err.free_m[::EVERY], sigma[::EVERY])
    return (hourly_rms(err.nav_m, scenario.dt), hourly_rms(err.free_m, scenario.dt),
            err.nees.mean(), res.fix_event, series, res.fix_time)


def run(pm, grid, scenario, model, config, keys, batch=1):
    """Simulate on ``grid`` and navigate on ``pm`` (:func:`~jaxgrav.navigate.loose_map`)
    voyages, one after another inside one compiled call (``vmap`` runs both sides of the
    matcher's branches: slower on a CPU, see ``benchmarks/voyage_loose.py``); per-voyage
    hourly errors, NEES, fix events."""
    f = jax.jit(lambda pm, grid, ks: jax.lax.map(
        lambda k: _one(pm, grid, k, scenario, model, config), ks, batch_size=batch))
    return tuple(np.asarray(a) for a in f(pm, grid, keys))


def figure(path, out, scenario, title, force):
    """The error-against-time figure of one setting."""
    *_, events, (nav, free, sigma), fix_time = out
    t_h = np.arange(nav.shape[1]) * EVERY * scenario.dt / 3600.0
    fig = plot_voyage_errors(t_h, nav, free, sigma, title=title, fix_t_h=fix_time[0] / 3600.0,
                             fix_accepted=events == 0)
    save_figure(fig, path, force=force)


def summarise(nav, free, nees, events, *_):
    """The figures of one setting (see the module notes)."""
    return {**voyage_summary(nav, free, nees),
            "fix_events": {FIX_EVENTS[k]: int(np.sum(events == k)) for k in FIX_EVENTS}}


def calibrate(pm, grid, scenario, model, config, keys, fix_sigma=500.0):
    """Fix errors and NEES against the truth along an ideal filter's states (see notes);
    arguments as :func:`run`."""
    steps = config.stride * config.fix_every
    n_seg = (scenario.n_steps - 1) // steps
    # segment ends before n_fixes fixes exist: on the first segments' span, if set
    n_first = first_segment_ends(config, n_seg)

    def one(pm, grid, key):
        voyage = voyage_scenario(key, grid, scenario, model)
        tables = error_kf_tables(config.ins, voyage.ins.lat.mean(), scenario.dt, steps,
                                 config.n_fixes * config.fix_every)
        p0 = initial_covariance(config.ins, config.sigma_pos_m, config.sigma_vel)
        noise = fix_sigma * jax.random.normal(jax.random.fold_in(key, 1), (n_seg, 2))

        def body(seg):  # seg: the tables of the segment's span (the first ones' shorter)
            def step(carry, j):
                x, p = carry
                x = tables.step_f @ x
                p = tables.step_f @ p @ tables.step_f.T + tables.step_q
                end = (j + 1) * steps
                res, _, _ = fix_segment(config, seg, pm, voyage.ins, voyage.gravity, x, p, end)
                truth = seg.h_mean @ voyage.ins_error[end]
                resid = truth - seg.h_mean @ x
                e = -jnp.stack([res.offset_north_m, res.offset_east_m]) - resid
                fix_nees = e @ jnp.linalg.solve(res.covariance_m2, e)
                z = truth + noise[j] - seg.h_mean @ x
                x, p, _ = fix_update(x, p, z, fix_sigma**2 * jnp.eye(2), seg.h_mean, True)
                d = voyage.ins_error[end, :2] - x[:2]
                return (x, p), (jnp.hypot(*e), fix_nees, res.edge_mass, res.accepted,
                                jnp.hypot(*d), d @ jnp.linalg.solve(p[:2, :2], d))
            return step

        carry, outs = (jnp.zeros(p0.shape[0]), p0), []
        for seg, js in ((first_tables(config, tables) if n_first else None, range(n_first)),
                        (tables, range(n_first, n_seg))):
            if len(js):
                carry, o = jax.lax.scan(body(seg), carry, jnp.arange(js.start, js.stop))
                outs.append(o)
        return jax.tree.map(lambda *a: jnp.concatenate(a), *outs)

    f = jax.jit(lambda pm, grid, ks: jax.lax.map(lambda k: one(pm, grid, k), ks))
    err, nees, edge, accepted, kf_err, kf_nees = (np.asarray(a) for a in f(pm, grid, keys))
    quart = np.quantile(edge, [0.25, 0.5, 0.75])
    bins = np.digitize(edge, quart)
    by_edge = [{"edge_mass_upto": float(q),
                "fix_err_rms_m": float(np.sqrt(np.mean(err[bins == b] ** 2))),
                "fix_nees_median": float(np.median(nees[bins == b]))}
               for b, q in enumerate([*quart, edge.max()])]
    acc = accepted.astype(bool)
    return {"fix_err_median_m": float(np.median(err)), "fix_nees_median": float(np.median(nees)),
            "fix_coverage_95": float(np.mean(nees <= CHI2_2_95)),
            "accepted": float(np.mean(accepted)),
            "accepted_fix_err_median_m": float(np.median(err[acc])),
            "accepted_fix_nees_median": float(np.median(nees[acc])),
            "accepted_fix_coverage_95": float(np.mean(nees[acc] <= CHI2_2_95)),
            "by_edge_mass": by_edge,
            "ideal_filter_hourly_rms_m": np.sqrt(np.mean(kf_err**2, 0)).round(0).tolist(),
            "ideal_filter_nees": float(np.mean(kf_nees))}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=100)
    p.add_argument("--sigma", type=float, default=3.0, help="map error sigma (mGal)")
    p.add_argument("--length", type=float, default=10000.0, help="map error L (m)")
    p.add_argument("--ins", choices=sorted(INS_GRADES), default="navigation")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--calibrate", action="store_true", help="measure the fixes alone")
    p.add_argument("--png", default=None, help="error-against-time figure of the map-error runs")
    p.add_argument("--force", action="store_true", help="overwrite --png")
    p.add_argument("--smoke", action="store_true", help="2 voyages of 2 h")
    p.add_argument("--matcher", choices=LOOSE_MATCHERS, default="dense",
                   help="the loop's matcher (default dense)")
    p.add_argument("--segment-error", choices=SEGMENT_ERRORS, default=None,
                   help="dense: how the filter's own error is told (default conditional, "
                   "loose_config's; markov: the old loop)")
    p.add_argument("--fix-prior", action=argparse.BooleanOptionalAction, default=None,
                   help="dense: weigh the offsets by the filter's prior")
    p.add_argument("--cell-error", action=argparse.BooleanOptionalAction, default=None,
                   help="dense, linear/conditional: tell the lattice's cell")
    p.add_argument("--n-fixes", type=int, default=None, help="fixes per segment")
    p.add_argument("--stride", type=int, default=None, help="fixes between segment ends "
                   "(default --n-fixes, or loose_config's)")
    p.add_argument("--first-n-fixes", type=int, default=None,
                   help="fixes of the segments before --n-fixes exist (0: not matched)")
    p.add_argument("--fix-cov-scale", type=float, default=None)
    p.add_argument("--shape-update", action=argparse.BooleanOptionalAction, default=None,
                   help="dense: the segment's readings update the state given the fix")
    p.add_argument("--reacquire-after", type=int, default=None,
                   help="failed fixes in a row after which each widens the covariance "
                   "(0: never; dense default 1)")
    p.add_argument("--reacquire-inflation", type=float, default=None,
                   help="the covariance's factor per such failure (dense default 16)")
    a = p.parse_args(argv)
    given = {"segment_error": a.segment_error, "fix_prior": a.fix_prior,
             "cell_error": a.cell_error, "n_fixes": a.n_fixes,
             "stride": a.stride or a.n_fixes, "fix_cov_scale": a.fix_cov_scale,
             "shape_update": a.shape_update}
    loop = {k: v for k, v in given.items() if v is not None}
    if a.first_n_fixes is not None:
        loop["first_n_fixes"] = a.first_n_fixes or None
    if a.reacquire_after is not None:
        loop["reacquire_after"] = a.reacquire_after or None
    if a.reacquire_inflation is not None:
        loop["reacquire_inflation"] = a.reacquire_inflation
    jax.config.update("jax_enable_x64", True)  # geodesy and 12 h of INS error in float64
    runs, hours = (2, 2.0) if a.smoke else (a.runs, 12.0)
    ins = INS_GRADES[a.ins]
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    scenario = voyage_preset("patrol-12h", ins=ins, hours=hours)
    keys = jax.random.split(jax.random.key(a.seed), runs)
    nav_map = loose_map(grid, a.matcher)  # chains: the map refined to 0.005° nodes
    step = scenario.speed * LooseConfig.fix_every * scenario.dt  # between fixes (m)
    rows = {}
    for name, sigma in (("perfect map", 0.0), ("map error, told", a.sigma)):
        model = map_error(a.sigma, a.length) if sigma > 0 else None
        # the matcher told the map error
        cfg = loose_config(ins, sigma, a.length, matcher=a.matcher, grid=nav_map, step_m=step,
                           **loop)
        t0 = time.perf_counter()
        if a.calibrate:
            row = {"setting": name, "ins": a.ins, "runs": runs, "calibrate": True,
                   **calibrate(nav_map, grid, scenario, model, cfg, keys)}
            print(json.dumps(row))
            rows[name] = row
            continue
        out = run(nav_map, grid, scenario, model, cfg, keys)
        seconds = time.perf_counter() - t0
        settings = {k: getattr(cfg, k) for k in ("segment_error", "fix_prior", "cell_error",
                                                 "n_fixes", "stride", "first_n_fixes",
                                                 "fix_cov_scale", "shape_update",
                                                 "reacquire_after", "reacquire_inflation")}
        row = {"setting": name, "ins": a.ins, "matcher": a.matcher, "runs": runs, "hours": hours,
               "seed": a.seed, "map_error_mgal": sigma, **settings, **summarise(*out),
               "seconds": round(seconds, 1), "runs_per_s": round(runs / seconds, 2)}
        print(json.dumps(row))
        rows[name] = row
        if a.png and sigma > 0:
            figure(a.png, out, scenario, f"loosely coupled, {runs} patrols of {hours:g} h, "
                   f"{a.ins} INS, map error {a.sigma:g} mGal / {a.length / 1e3:g} km told",
                   a.force)
    return rows


if __name__ == "__main__":
    main()
