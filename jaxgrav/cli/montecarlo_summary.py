"""The summary ``jaxgrav montecarlo`` prints and stores: per-run errors over runs, the
fix lines, the share of runs worse than the INS."""

import numpy as np

from jaxgrav.montecarlo.fix_metrics import fix_summary

__all__ = ["FAILURE_RATIO", "PERCENTILES", "fix_lines", "format_summary", "short_label",
           "status_rates", "summarize", "worse_rate"]

PERCENTILES = (5, 25, 50, 75, 95)
"""Percentiles of the summary table."""

FAILURE_RATIO = {"matcher": 1.0 / 3.0, "filter": 1.05, "voyage": 1.0}
"""A run fails when its error exceeds this multiple of the INS error: a matcher
must cut the error to a third (paper A's goal), a filter must do no harm (paper D's
"at most 1.05x the INS"), a voyage's last hour must not be worse than the free INS's."""


def summarize(results, kind="matcher"):
    """Summary of per-run errors.

    Parameters
    ----------
    results : dict
        ``ins_err_m``, ``err_m`` (m) and ``status``, each of shape ``(n_runs,)``;
        for filters also ``nees``; optionally ``readings_on_map`` (bool).
    kind : {"matcher", "filter", "voyage"}
        Picks the failure criterion, :data:`FAILURE_RATIO`.

    Returns
    -------
    dict
        ``runs``; ``ins_err_m``, ``err_m`` and ``ratio`` (error / INS error, per run),
        each a dict of ``mean`` and ``p5 … p95`` over finite values; ``failure_ratio``
        and ``failure_rate`` (error > failure_ratio × INS, or not finite, or the run's
        ``readings_on_map`` false when given: it found no clear start),
        ``flagged_rate`` (status ≠ 0; for a loosely coupled voyage, a fix event other than
        "accepted") and ``status_rates`` (each bit set in some run, as a string, → the
        share of runs with it: a flag may only inform, :func:`format_summary` names
        them), ``improved_rate`` (error < INS; a returned INS
        track, equal to it up to rounding, is not improved), ``nonfinite``
        (count: left out of the statistics, counted as failures); with ``nees`` in
        ``results`` also ``nees`` (its statistics) and ``nees_nonfinite``; with
        ``bound_m`` (the PCRLB) its statistics and ``rms_to_bound``, the RMS error over
        runs divided by the RMS bound (≥ 1 up to Monte Carlo noise; 1 is efficient);
        with ``implausible_blocks`` (a filter's blocks of innovations that fail their χ²
        test, :func:`~jaxgrav.navigate.innovation_blocks`) ``implausible_rate`` (runs
        with one) and ``implausible_failed_rate`` (that share among the failed runs; NaN
        without any).
    """
    if kind not in FAILURE_RATIO:
        raise ValueError(f"kind must be one of {sorted(FAILURE_RATIO)}; got {kind!r}")
    limit = FAILURE_RATIO[kind]
    ins = np.asarray(results["ins_err_m"], float)
    err = np.asarray(results["err_m"], float)
    status = np.asarray(results["status"])
    ratio = err / np.where(ins > 0, ins, np.nan)

    def stats(v):
        v = v[np.isfinite(v)]
        if not v.size:
            return {"mean": float("nan"), **{f"p{p}": float("nan") for p in PERCENTILES}}
        return {"mean": float(v.mean()),
                **{f"p{p}": float(q) for p, q in zip(PERCENTILES, np.percentile(v, PERCENTILES),
                                                     strict=True)}}

    finite = np.isfinite(err)
    if "fix_event" in results:  # a loose voyage: bit k says fix event k happened; bit 0
        status = status & ~1  # is "accepted", which flags nothing
    # a run whose true track read a missing map node (no clear start found) fails
    on_map = np.asarray(results.get("readings_on_map", np.ones(err.shape, bool)), bool)
    failed = ~finite | (err > limit * ins) | ~on_map
    out = dict(
        runs=int(err.size),
        ins_err_m=stats(ins),
        err_m=stats(err),
        ratio=stats(ratio),
        failure_ratio=float(limit),
        failure_rate=float(np.mean(failed)),
        flagged_rate=float(np.mean(status != 0)),
        status_rates=status_rates(status),
        improved_rate=float(np.mean(finite & (err < ins * (1 - 1e-9)))),  # INS track: not
        nonfinite=int((~finite).sum()),
    )
    if "nees" in results:
        nees = np.asarray(results["nees"], float)
        out["nees"] = stats(nees)
        out["nees_nonfinite"] = int((~np.isfinite(nees)).sum())
    if "implausible_blocks" in results:
        flagged = np.asarray(results["implausible_blocks"]) > 0
        out["implausible_rate"] = float(np.mean(flagged))
        out["implausible_failed_rate"] = (float(np.mean(flagged[failed])) if failed.any()
                                          else float("nan"))
    if "bound_m" in results:
        bound = np.asarray(results["bound_m"], float)
        out["bound_m"] = stats(bound)
        ok = np.isfinite(err) & np.isfinite(bound)
        out["rms_to_bound"] = (float(np.sqrt(np.mean(err[ok] ** 2) / np.mean(bound[ok] ** 2)))
                               if ok.any() else float("nan"))
    return out


def status_rates(status):
    """``{str(bit): share of runs with it}`` for every bit set in some run, in bit order.

    Parameters
    ----------
    status : array of int, shape ``(n_runs,)``
    """
    status = np.asarray(status).astype(np.int64)
    seen = int(np.bitwise_or.reduce(status)) if status.size else 0
    return {str(1 << b): float(np.mean(status & (1 << b) != 0))
            for b in range(seen.bit_length()) if seen & (1 << b)}


def short_label(text, width=90):
    """The first clause of a status bit's message (up to ``;`` or `` (``), at most
    ``width`` characters."""
    head = text.split(";")[0].split(" (")[0].strip()
    return head if len(head) <= width else head[:width - 1].rstrip() + "…"


def format_summary(s, status_bits=None):
    """A fixed-width table of :func:`summarize`'s output; with ``status_bits`` (bit →
    meaning, the method's :attr:`~jaxgrav.montecarlo.spec.MethodSpec.status_bits`) a
    line naming each flag raised and its share of runs."""
    cols = ["mean", *[f"p{p}" for p in PERCENTILES]]
    head = f"{'':<16}" + "".join(f"{'median' if c == 'p50' else c:>10}" for c in cols)
    rows = [head]
    for label, key, fmt in (("INS error (m)", "ins_err_m", "{:>10.0f}"),
                            ("error (m)", "err_m", "{:>10.0f}"),
                            ("error / INS", "ratio", "{:>10.3f}")):
        rows.append(f"{label:<16}" + "".join(fmt.format(s[key][c]) for c in cols))
    if "nees" in s:
        rows.append(f"{'position NEES':<16}" + "".join(f"{s['nees'][c]:>10.2f}" for c in cols)
                    + "   (2 expected)")
    if "bound_m" in s:
        rows.append(f"{'PCRLB (m)':<16}" + "".join(f"{s['bound_m'][c]:>10.0f}" for c in cols)
                    + f"   (RMS error / RMS bound {s['rms_to_bound']:.2f})")
    limit = s["failure_ratio"]
    bound = "INS/3" if abs(limit - 1 / 3) < 1e-12 else f"{limit:g} x INS"
    rows.append(f"failure rate (error > {bound} or not finite): {100 * s['failure_rate']:.1f} %; "
                f"improved on the INS: {100 * s['improved_rate']:.1f} %; "
                f"status flagged: {100 * s['flagged_rate']:.1f} %")
    rates = s.get("status_rates") or {}
    if rates:
        names = {str(k): v for k, v in (status_bits or {}).items()}
        rows.append("  flags raised (share of runs): " + "; ".join(
            f"{bit}" + (f" {short_label(names[bit])}" if bit in names else "")
            + f" {100 * r:.1f} %" for bit, r in rates.items()))
    if "implausible_rate" in s:
        failed = round(s["failure_rate"] * s["runs"])
        rows.append(f"innovations implausible (a block of 60 readings fails chi-square, p < "
                    f"1e-3; a consistent filter fails one block in 1000): "
                    f"{100 * s['implausible_rate']:.1f} % of runs"
                    + (f", {100 * s['implausible_failed_rate']:.0f} % of the {failed} failed "
                       "runs" if failed else ""))
    bad = [f"{s[k]} {what}" for k, what in (("nonfinite", "without a finite error (failures)"),
                                           ("nees_nonfinite", "without a finite NEES"))
           if s.get(k)]
    if bad:
        rows.append(f"runs left out of the statistics above: {', '.join(bad)}")
    return "\n".join(rows)


def fix_lines(results):
    """The fix lines of the summary: accepted share, coverage, worse than the INS (empty
    for a method without fixes)."""
    fs = fix_summary(results)
    if not fs:
        return []
    cov = fs["coverage95_accepted"]
    none = ("no accepted fix" if not np.any(np.asarray(results["accepted"])) else
            "no covariance")
    return [f"accepted fixes: {100 * fs['accepted_rate']:.1f} % (a rejected fix keeps the INS "
            "track); 95 % ellipse covers the truth on accepted fixes: "
            + (f"n/a ({none})" if not np.isfinite(cov) else f"{100 * cov:.1f} %")
            + f"; worse than the INS: {100 * worse_rate(results):.1f} %"]


def worse_rate(results):
    """Share of runs whose error exceeds the INS's (a returned INS track is not worse)."""
    err, ins = (np.asarray(results[k], float) for k in ("err_m", "ins_err_m"))
    return float(np.mean(~np.isfinite(err) | (err > ins * (1 + 1e-9))))
