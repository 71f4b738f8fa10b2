"""Paper A's experiments as functions: Table 1 groups and Monte Carlo summaries.

Shared by ``jaxgrav demo`` (small sizes) and ``examples/paper_a_table1.py`` (≥ 1000
tracks). Each function simulates a batch of tracks with
:func:`jaxgrav.scenarios.matching_scenario`, matches them in one jitted, vmapped
call and returns plain NumPy summaries.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav.geodesy import eotvos
from jaxgrav.match.api import config_for
from jaxgrav.match.correlation import match_chains
from jaxgrav.match.dense import match_dense
from jaxgrav.match.scoring import bias_precision, decreasing_weights, score_track
from jaxgrav.scenarios.paper_a import MatchingScenario, matching_scenario
from jaxgrav.sim import DEG_ARC_M, track_error_m

__all__ = ["TABLE1_DRIFTS_DEG", "format_table", "run_batch", "summarize", "table1"]

TABLE1_DRIFTS_DEG = (0.005, 0.0125, 0.02, 0.0275, 0.035)
"""INS drift of the five groups (degrees of arc), spanning paper A's Table 1."""


def run_batch(key, truth_field, match_map, scenario, method, config, *, eotvos_correct=True):
    """Simulate and match ``n`` tracks in one jitted, vmapped call.

    Parameters
    ----------
    key : PRNG key array, shape ``(n,)``
        One key per track.
    truth_field : Grid
        Field the gravimeter senses.
    match_map : Grid
        Map matched against (refined for ``chains``).
    scenario : MatchingScenario
    method : {"dense", "chains"}
    config : DenseConfig or ChainConfig
    eotvos_correct : bool
        Correct readings with the (true) velocity before matching, as a user with
        an INS velocity would.

    Returns
    -------
    dict of str to numpy.ndarray
        Per track: ``ins_err_m``, ``err_m``, ``status``, ``work_unconstrained``,
        ``work_constrained``, and the last run's tracks for plotting.
    """
    fn = match_dense if method == "dense" else match_chains
    slope_n, slope_e = match_map.gradient()

    def one(truth_field, match_map, key, scenario, config):
        run = matching_scenario(key, truth_field, scenario)
        g = run.readings
        if eotvos_correct:
            g = g + eotvos(run.ins_lat, run.truth.v_east, run.truth.v_north)
        r = fn(match_map, run.ins_lat, run.ins_lon, g, config)
        slope = jnp.hypot(slope_n.sample(run.truth.lat, run.truth.lon),
                          slope_e.sample(run.truth.lat, run.truth.lon))
        if method == "dense":  # the score the matcher would give the true track
            w = decreasing_weights(g.shape[0], config.weight_decay)
            prior = bias_precision(w, config.noise_mgal, config.bias_sigma_mgal)
            m = match_map.sample(run.truth.lat, run.truth.lon, config.method)
            true_score = score_track(g, m, w, config.score, prior)[0]
        else:
            true_score = jnp.nan
        return dict(
            ins_err_m=jnp.mean(jnp.hypot(run.drift_north_m, run.drift_east_m)),
            err_m=track_error_m(r.lat, r.lon, run.truth),
            score=r.score,
            true_score=true_score,
            slope_mgal_km=1e3 * jnp.mean(slope),
            status=r.status,
            work_unconstrained=r.work_unconstrained,
            work_constrained=r.work_constrained,
            true_lat=run.truth.lat, true_lon=run.truth.lon,
            ins_lat=run.ins_lat, ins_lon=run.ins_lon, lat=r.lat, lon=r.lon,
        )

    batched = jax.jit(jax.vmap(one, in_axes=(None, None, 0, None, None)))
    out = batched(truth_field, match_map, key, scenario, config)
    return {k: np.asarray(v) for k, v in out.items()}


def summarize(out, success_deg=0.01):
    """Summary statistics of a batch from :func:`run_batch` (errors in metres and degrees).

    Returns
    -------
    dict
        Medians and means of INS and matched errors, their ratio, the success rate
        ``error < success_deg``, the fraction of tracks improved over the INS, the
        failure rate (error above a third of the INS error) overall and by mean map
        slope along the track, and among failures the fraction whose chosen track
        scores no worse than the true one (ambiguity, not a search failure).
    """
    ins, err = out["ins_err_m"], out["err_m"]
    wu = out["work_unconstrained"]
    wc = out["work_constrained"]
    failed = err > ins / 3
    slope = out["slope_mgal_km"]
    bands = {}
    for lo, hi in ((0, 1), (1, 2), (2, 4), (4, np.inf)):
        sel = (slope >= lo) & (slope < hi)
        bands[f"{lo}-{hi}"] = dict(runs=int(sel.sum()), failure_rate=float(np.mean(failed[sel]))
                                   if sel.any() else None)
    return dict(
        runs=int(err.size),
        failure_rate=float(np.mean(failed)),
        failures_preferred_over_truth=float(np.mean(out["score"][failed]
                                                    <= out["true_score"][failed]))
        if failed.any() and np.isfinite(out["true_score"]).all() else None,
        failure_rate_by_slope_mgal_km=bands,
        ins_error_deg_mean=float(np.mean(ins) / DEG_ARC_M),
        error_deg_mean=float(np.mean(err) / DEG_ARC_M),
        ins_error_m_median=float(np.median(ins)),
        error_m_median=float(np.median(err)),
        median_ratio=float(np.median(err) / np.median(ins)),
        success_rate=float(np.mean(err < success_deg * DEG_ARC_M)),
        improved_rate=float(np.mean(err < ins)),
        flagged_rate=float(np.mean(out["status"] != 0)),
        work_unconstrained_median=float(np.median(wu)),
        work_constrained_median=float(np.median(wc)),
    )


def table1(key, truth_field, match_map, *, method, runs_per_group, base=None,
           drifts_deg=TABLE1_DRIFTS_DEG, score=None, selection=None):
    """Table-1-like rows: one per INS drift level, each a batch of ``runs_per_group`` tracks.

    Returns
    -------
    list of dict
        :func:`summarize` of each group plus its ``drift_deg``.
    """
    base = MatchingScenario() if base is None else base
    rows = []
    for i, drift in enumerate(drifts_deg):
        scen = dataclasses.replace(base, drift_deg=drift)
        cfg = config_for(method, match_map, 1.05 * drift * DEG_ARC_M,
                         noise_mgal=max(float(base.noise_mgal), 0.1), score=score,
                         step_m=scen.step_m)
        if selection is not None:
            cfg = dataclasses.replace(cfg, selection=selection)
        keys = jax.random.split(jax.random.fold_in(key, i), runs_per_group)
        rows.append(dict(drift_deg=drift, **summarize(run_batch(keys, truth_field, match_map,
                                                                 scen, method, cfg))))
    return rows


def format_table(rows, title):
    """Markdown table of Table-1-like rows."""
    head = ("| INS drift (°) | INS error (°) | matched error (°), mean | median error (m) | "
            "success < 0.01° | ∏N_i (median) | constrained (median) | runs |")
    lines = [f"**{title}**", "", head, "|" + "---|" * 8]
    for r in rows:
        lines.append(
            f"| {r['drift_deg']:.4f} | {r['ins_error_deg_mean']:.4f} | {r['error_deg_mean']:.4f} "
            f"| {r['error_m_median']:.0f} | {100 * r['success_rate']:.0f} % "
            f"| {_sci(r['work_unconstrained_median'])} | {_sci(r['work_constrained_median'])} "
            f"| {r['runs']} |")
    return "\n".join(lines)


def _sci(x):
    if not np.isfinite(x) or x <= 0:
        return str(x)
    e = math.floor(math.log10(x))
    return f"{x / 10**e:.1f}e{e}"
