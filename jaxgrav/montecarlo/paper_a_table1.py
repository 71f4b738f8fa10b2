"""Paper A's experiments as functions: Table 1 groups and Monte Carlo summaries.

Shared by ``jaxgrav demo`` (small sizes) and ``examples/paper_a_table1.py`` (≥ 1000
tracks). :func:`run_batch` runs :func:`dense_table_run` or :func:`chains_table_run`
(one simulated and matched track, :func:`~jaxgrav.montecarlo.matcher_runs.paper_a_match`)
over many keys with the Monte Carlo runner :func:`jaxgrav.montecarlo.run`, so repeated
batches of the same shapes reuse the compiled code; :func:`summarize` and
:func:`table1` turn the runs into plain summaries.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav.match.api import config_for
from jaxgrav.match.correlation import match_chains
from jaxgrav.match.dense import match_dense
from jaxgrav.match.scoring import bias_precision, decreasing_weights, score_track
from jaxgrav.montecarlo.fix_metrics import fix_summary
from jaxgrav.montecarlo.matcher_runs import matcher_record, paper_a_match
from jaxgrav.montecarlo.runner import run
from jaxgrav.scenarios import MatchingScenario
from jaxgrav.sim import DEG_ARC_M

__all__ = ["REJECTED_BITS", "TABLE1_DRIFTS_DEG", "TABLE_RUNS", "chains_table_run",
           "dense_table_run", "format_table", "run_batch", "summarize", "table1"]

REJECTED_BITS = 512 | 1024 | 2048 | 4096
"""Status bits of a rejected fix (:data:`jaxgrav.match.STATUS`)."""

TABLE1_DRIFTS_DEG = (0.005, 0.0125, 0.02, 0.0275, 0.035)
"""INS drift of the five groups (degrees of arc), spanning paper A's Table 1."""


def _table_record(run, r, slope_n, slope_e, true_score):
    slope = jnp.hypot(slope_n.sample(run.truth.lat, run.truth.lon),
                      slope_e.sample(run.truth.lat, run.truth.lon))
    return matcher_record(
        run, r, true_score=true_score, slope_mgal_km=1e3 * jnp.mean(slope),
        work_unconstrained=r.work_unconstrained, work_constrained=r.work_constrained,
        true_lat=run.truth.lat, true_lon=run.truth.lon,
        ins_lat=run.ins_lat, ins_lon=run.ins_lon, lat=r.lat, lon=r.lon)


def dense_table_run(key, truth_field, match_map, slope_n, slope_e, scenario, config,
                    map_error=None):
    """One track of a Table-1 batch matched by :func:`~jaxgrav.match.dense.match_dense`.

    Parameters
    ----------
    key : PRNG key
    truth_field, match_map : Grid
        Field the gravimeter senses and map matched against (mGal).
    slope_n, slope_e : Grid
        ``match_map.gradient()`` (mGal/m), for the mean map slope along the track.
    scenario : MatchingScenario
    config : DenseConfig
    map_error : CorrelatedMapError, TruthGrid or None, optional
        Map error of the readings, drawn per run on ``truth_field``
        (:func:`~jaxgrav.montecarlo.matcher_runs.paper_a_match`).

    Returns
    -------
    dict
        :func:`~jaxgrav.montecarlo.matcher_runs.matcher_record` (``ins_err_m``,
        ``err_m`` in m, ``status``, ``score``) and ``true_score`` (the score the
        matcher gives the true track), ``slope_mgal_km`` (mean map slope along the true
        track, mGal/km), ``work_unconstrained``, ``work_constrained``, and the tracks
        ``true_lat``, ``true_lon``, ``ins_lat``, ``ins_lon``, ``lat``, ``lon``
        (degrees, shape ``(n_fixes,)``).
    """
    run, g, r = paper_a_match(match_dense, key, truth_field, match_map, scenario, config,
                              map_error)
    w = decreasing_weights(g.shape[0], config.weight_decay)
    prior = bias_precision(w, config.noise_mgal, config.bias_sigma_mgal)
    m = match_map.sample(run.truth.lat, run.truth.lon, config.method)
    true_score = score_track(g, m, w, config.score, prior)[0]
    return _table_record(run, r, slope_n, slope_e, true_score)


def chains_table_run(key, truth_field, match_map, slope_n, slope_e, scenario, config,
                     map_error=None):
    """One track of a Table-1 batch matched by
    :func:`~jaxgrav.match.correlation.match_chains` (``config`` a ChainConfig); as
    :func:`dense_table_run`, with ``true_score`` NaN."""
    run, _, r = paper_a_match(match_chains, key, truth_field, match_map, scenario, config,
                              map_error)
    return _table_record(run, r, slope_n, slope_e, jnp.nan)


TABLE_RUNS = {"dense": dense_table_run, "chains": chains_table_run}
"""Matcher name -> per-track function of :func:`run_batch`."""


def run_batch(key, n_runs, truth_field, match_map, scenario, method, config, *, chunk=None,
              progress=False, map_error=None):
    """Simulate and match ``n_runs`` tracks with the Monte Carlo runner.

    Parameters
    ----------
    key : PRNG key
        One key; track ``i`` gets ``jax.random.split(key, n_runs)[i]``.
    n_runs : int
        Number of tracks.
    truth_field : Grid
        Field the gravimeter senses.
    match_map : Grid
        Map matched against (refined for ``chains``).
    scenario : MatchingScenario
    method : {"dense", "chains"}
    config : DenseConfig or ChainConfig
    chunk : int, optional
        Tracks per compiled call; None: all ``n_runs`` in one call, the batch the
        README's Table-1 numbers were computed with. A smaller chunk bounds memory;
        floats may then differ in the last digits (another XLA programme).
    progress : bool
        Show the runner's progress bar.
    map_error : CorrelatedMapError, TruthGrid or None, optional
        Map error of the readings, drawn per track from its key on ``truth_field``;
        None (default): the readings come from ``truth_field`` itself, as before.

    Returns
    -------
    dict of str to numpy.ndarray
        :func:`dense_table_run`'s values, each with a leading axis of ``n_runs``.
        Readings are Eötvös-corrected with the true velocity before matching, as a
        user with an INS velocity would.
    """
    if method not in TABLE_RUNS:
        raise ValueError(f"method must be one of {sorted(TABLE_RUNS)}; got {method!r}")
    slope_n, slope_e = match_map.gradient()
    return run(TABLE_RUNS[method], key, n_runs, chunk=n_runs if chunk is None else chunk,
               progress=progress,
               args=(truth_field, match_map, slope_n, slope_e, scenario, config, map_error))


def summarize(out, success_deg=0.01):
    """Summary statistics of a batch from :func:`run_batch` (errors in metres and degrees).

    Returns
    -------
    dict
        Medians and means of INS and matched errors, their ratio, the success rate
        ``error < success_deg``, the fractions of tracks improved over the INS and made
        worse than it, the fraction of fixes accepted (no integrity bit, see
        :data:`REJECTED_BITS`; a rejected fix is the INS track), the share of
        accepted fixes whose 95 % ellipse covers the truth (``coverage95_accepted``, NaN
        for a matcher without covariance, :mod:`~jaxgrav.montecarlo.fix_metrics`), the
        failure rate (error above a third of the INS error) overall and by mean map
        slope along the track, and among failures the fraction whose chosen track
        scores no worse than the true one (ambiguity, not a search failure).
    """
    ins, err = out["ins_err_m"], out["err_m"]
    wu = out["work_unconstrained"]
    wc = out["work_constrained"]
    failed = ~np.isfinite(err) | (err > ins / 3)  # no error to show: failed
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
        improved_rate=float(np.mean(err < ins * (1 - 1e-9))),  # a returned INS track: not
        # improved (it equals the INS only to rounding, ~1e-13, either side)
        worse_rate=float(np.mean(~np.isfinite(err) | (err > ins * (1 + 1e-9)))),  # NaN: worse,
        # as in jaxgrav montecarlo's summary; a returned INS track: not worse
        accepted_rate=float(np.mean((np.asarray(out["status"]) & REJECTED_BITS) == 0)),
        coverage95_accepted=fix_summary(out).get("coverage95_accepted", float("nan")),
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
                         step_m=scen.step_m, region="square")  # paper A's window
        if selection is not None:
            cfg = dataclasses.replace(cfg, selection=selection)
        out = run_batch(jax.random.fold_in(key, i), runs_per_group, truth_field, match_map,
                        scen, method, cfg)
        rows.append(dict(drift_deg=drift, **summarize(out)))
    return rows


def format_table(rows, title):
    """Markdown table of Table-1-like rows."""
    head = ("| INS drift (°) | INS error (°) | matched error (°), mean | median error (m) | "
            "median ÷ INS median | worse than INS | error < 0.01° | ∏N_i (median) | "
            "constrained (median) | accepted | 95 % ellipse covers (accepted) | runs |")
    lines = [f"**{title}**", "", head, "|" + "---|" * 12]
    for r in rows:
        lines.append(
            f"| {r['drift_deg']:.4f} | {r['ins_error_deg_mean']:.4f} | {r['error_deg_mean']:.4f} "
            f"| {r['error_m_median']:.0f} | {r['median_ratio']:.2f} "
            f"| {100 * r['worse_rate']:.0f} % | {100 * r['success_rate']:.0f} % "
            f"| {_sci(r['work_unconstrained_median'])} | {_sci(r['work_constrained_median'])} "
            f"| {100 * r['accepted_rate']:.0f} % | {_percent(r.get('coverage95_accepted'))} "
            f"| {r['runs']} |")
    return "\n".join(lines)


def _percent(x):
    return "n/a" if x is None or not np.isfinite(x) else f"{100 * x:.0f} %"


def _sci(x):
    if not np.isfinite(x) or x <= 0:
        return str(x)
    e = math.floor(math.log10(x))
    return f"{x / 10**e:.1f}e{e}"
