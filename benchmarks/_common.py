"""Shared timing helpers for the benchmark scripts (not part of the library)."""

import argparse
import json
import os
import platform
import time


def parse_args(description):
    """Standard benchmark arguments: ``--quick`` for a CI-sized run."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--quick", action="store_true", help="small sizes and few repeats")
    return p.parse_args()


def best_time(fn, repeats):
    """Best wall time (s) of ``fn()`` over ``repeats`` calls; ``fn`` must block until done."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def emit(bench, case, n, jaxgrav_s, baseline, baseline_s, **extra):
    """Print one JSON line in the DESIGN.md benchmark format."""
    row = {
        "bench": bench,
        "case": case,
        "n": n,
        "jaxgrav_s": round(jaxgrav_s, 6),
        "baseline": baseline,
        "baseline_s": round(baseline_s, 6),
        "ratio": round(baseline_s / jaxgrav_s, 2),
        "machine": f"{platform.machine()} {os.cpu_count()} cores",
        **extra,
    }
    print(json.dumps(row), flush=True)
