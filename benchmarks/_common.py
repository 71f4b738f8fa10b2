"""Shared timing helpers for the benchmark scripts (not part of the library)."""

import argparse
import json
import os
import platform
import time

import jax


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
    """Print one JSON line in the DESIGN.md benchmark format.

    ``baseline_s`` None (the baseline did not finish) gives ``ratio`` None: no ratio is
    invented.
    """
    row = {
        "bench": bench,
        "case": case,
        "n": n,
        "jaxgrav_s": round(jaxgrav_s, 6),
        "baseline": baseline,
        "baseline_s": None if baseline_s is None else round(baseline_s, 6),
        "ratio": None if baseline_s is None else round(baseline_s / jaxgrav_s, 2),
        "machine": f"{platform.machine()} {os.cpu_count()} cores",
        **extra,
    }
    print(json.dumps(row), flush=True)


def batch_timings(entry, pm, voyages, cfg, repeats):
    """Best times (s) of a navigation entry point over a batch of voyages, three ways.

    ``entry(pm, voyage, cfg)`` is a jitted single-voyage function; ``voyages`` has a
    leading voyage axis. Returns ``(vmap, loop, lax_map)``: one call batched with
    ``jax.vmap``, a Python loop of compiled single-voyage calls, one call running the
    voyages one after another with ``lax.map``; each is called once before timing.
    """
    n = jax.tree.leaves(voyages)[0].shape[0]
    batch = jax.jit(jax.vmap(entry, in_axes=(None, 0, None)))
    seq = jax.jit(lambda pm, vs, cfg: jax.lax.map(lambda v: entry(pm, v, cfg), vs))
    one = [jax.tree.map(lambda a, i=i: a[i], voyages) for i in range(n)]

    def run_batch():
        jax.block_until_ready(batch(pm, voyages, cfg))

    def run_loop():
        for v in one:
            jax.block_until_ready(entry(pm, v, cfg))

    def run_seq():
        jax.block_until_ready(seq(pm, voyages, cfg))

    for f in (run_batch, run_loop, run_seq):
        f()
    return tuple(best_time(f, repeats) for f in (run_batch, run_loop, run_seq))
