"""How does the Monte Carlo runner scale with devices and chunk size, and is memory bounded?

Method ``dense`` (paper A's dense-offset matcher on the shipped 2.5′ ``ryukyu`` map,
30 fixes, 0.035° drift; :mod:`jaxgrav.montecarlo.methods`) run by
:func:`jaxgrav.montecarlo.run` in float64. Every case is a fresh subprocess with
``XLA_FLAGS=--xla_force_host_platform_device_count=D`` (the flag must be set before
JAX starts). Virtual CPU devices share the machine's cores: more devices than cores
cannot add compute, only let XLA run the shards' work in parallel.

Lines (JSON, ``_common.emit``):

* ``montecarlo_scaling``: wall time of ``n`` runs (compiled already) for D = 1, 2, 8
  devices and several chunk sizes; baseline = 1 device with the smallest chunk;
  ``runs_per_s``.
* ``montecarlo_compile``: the first call of the entry point (trace + compile + one
  chunk) against a second call with *new parameter values* (another noise level):
  ``compile_s`` is their difference, ``recompiled`` whether the second call traced or
  compiled anything (``jax.monitoring`` trace and compile events, counted in
  ``traces_second_call`` and ``compiles_second_call``: a retrace shows as a trace event
  even when the persistent cache below would supply its executable), for
  ``dense`` and ``ukf`` (the full run: every method of
  :data:`jaxgrav.montecarlo.methods.BUILDERS`; the filters over paper D's point masses).
* ``montecarlo_memory``: peak RSS (``ru_maxrss`` of the subprocess) for ``n`` = 4, 16
  (not with ``--quick``) and 64 chunks against the same ``n`` in one chunk (baseline;
  for 64 chunks, which would need GBs in one chunk, against the previous chunked
  case); ``maxrss_one_chunk_mb`` is
  the chunked process's peak after its first (compiling) chunk, so a flat memory shows
  as a small ``growth_after_first_chunk_mb`` whatever ``n`` (a process that had to
  compile peaks during compilation, which hides the chunk; compare the growth).

All subprocesses share a persistent compilation cache in a temporary folder (a case
with the shape of an earlier one loads its executable). Timed runs exclude
compilation (the key split for each ``n`` is compiled before timing too). The full
run adds float32 cases (``jax_enable_x64`` off).

* ``montecarlo_options`` (``--compile-only``, nothing else): for every method, compile
  (as above) and the run time of one chunk of 16 runs with the method's own XLA options
  (:attr:`jaxgrav.montecarlo.MethodSpec.cpu_options`, what the runner and the command
  use: :mod:`jaxgrav.xla_options`) against another setting — with ``--against defaults``
  XLA's default options (``-O3``, fusion emitters), or jaxgrav's ``CPU_OPTIONS`` for a
  method that keeps XLA's defaults (rbpf); with ``--against emitters`` the method's own
  options with the other kernel emitters (``xla_cpu_use_fusion_emitters``) — each in a
  fresh process with its own cache folder; ratio = other / own (> 1: the method's own
  options are faster). ``--methods`` limits the methods. The compile rows split each
  setting's first call into ``*_trace``, ``*_lower`` and ``*_xla`` seconds (JAX's
  ``jax.monitoring`` durations of tracing, lowering to MLIR and XLA's compile, summed over
  every program the call ran, the key split's too), and give the compile's process CPU
  time, ``*_cpu_s`` (first call − second call, both cores: steadier than the wall time on
  a loaded machine; XLA compiles on up to two threads, tracing and lowering on one).

Run ``python benchmarks/montecarlo_scaling.py [--quick | --compile-only [--against
defaults|emitters] [--methods M ...]]``. Absolute
times on a shared machine are noise; compare within one run.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

BENCH = "montecarlo_scaling"
TRACE_EVENT = "/jax/core/compile/jaxpr_trace_duration"
"""``jax.monitoring`` duration event of every trace of a jitted function (any cache aside)."""
LOWER_EVENT = "/jax/core/compile/jaxpr_to_mlir_module_duration"
COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
"""Duration event of XLA compilation; in JAX 0.10 it wraps ``compile_or_get_cached``, so a
load from the persistent cache records it too."""


# ------------------------------------------------------------------ child process
def child(spec):
    import jax

    jax.config.update("jax_enable_x64", spec.get("x64", True))  # a script, not the library
    jax.config.update("jax_compilation_cache_dir", spec["cache"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    events = []  # (event, function) of every trace and every compile-or-cache-load
    seconds = {TRACE_EVENT: 0.0, LOWER_EVENT: 0.0, COMPILE_EVENT: 0.0}  # summed durations
    jax.monitoring.register_event_duration_secs_listener(
        lambda name, secs, fun_name="", **kw: (
            seconds.__setitem__(name, seconds[name] + secs) if name in seconds else None,
            events.append((name, fun_name)) if name in (TRACE_EVENT, COMPILE_EVENT) else None))
    from jaxgrav import montecarlo
    from jaxgrav.montecarlo import methods as montecarlo_methods

    def maxrss_mb():
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    method, chunk, n = spec["method"], spec["chunk"], spec["n"]
    # the matchers' default map; the filters' default is paper D's point masses (None)
    grid = None if method in montecarlo_methods.FILTER_METHODS else \
        montecarlo_methods.default_grid()
    m = montecarlo_methods.build(method, grid)
    key = jax.random.key(0)
    out = {"devices": len(jax.devices())}

    cpu = {}  # process CPU time (s) of the last go(): XLA compiles on both cores

    def go(n_runs, ch, spec_=m):
        t0, c0 = time.perf_counter(), time.process_time()
        # the method's own XLA options, or the other setting (the baseline of
        # --compile-only): XLA's defaults, or level 2 for a method whose own are the defaults
        options = spec_.cpu_options
        if spec.get("other_options") is not None:
            options = tuple(tuple(kv) for kv in spec["other_options"])
        montecarlo.run(spec_.fn, key, n_runs, chunk=ch, progress=False, args=spec_.args,
                       cpu_options=options)
        cpu["s"] = time.process_time() - c0
        return time.perf_counter() - t0

    out["first_s"] = go(chunk, chunk)  # trace + compile + one chunk
    out["first_cpu_s"] = cpu["s"]
    # the first call's share of tracing, lowering and XLA compiling (every program it ran)
    out["first_trace_s"], out["first_lower_s"], out["first_xla_s"] = (
        round(seconds[e], 3) for e in (TRACE_EVENT, LOWER_EVENT, COMPILE_EVENT))
    out["maxrss_one_chunk_mb"] = maxrss_mb()
    if spec.get("compile"):
        other = montecarlo_methods.build(method, grid, noise=1.5)  # new parameter values
        before = len(events)
        out["second_s"] = go(chunk, chunk, other)
        out["second_cpu_s"] = cpu["s"]
        new = events[before:]
        out["traces_second_call"] = sum(e == TRACE_EVENT for e, _ in new)
        out["compiles_second_call"] = sum(e == COMPILE_EVENT for e, _ in new)
        out["traced_second_call"] = sorted({f for e, f in new if e == TRACE_EVENT})
        out["recompiled"] = bool(new)
    if n:
        jax.random.split(key, n).block_until_ready()  # run() splits once: compiled per n
        out["run_s"] = min(go(n, chunk) for _ in range(spec.get("repeats", 1)))
    out["maxrss_mb"] = maxrss_mb()
    print("RESULT " + json.dumps(out), flush=True)


def spawn(devices, **spec):
    env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}",
               JAX_PLATFORMS="cpu")
    env.pop("JAX_NUM_CPU_DEVICES", None)
    proc = subprocess.run([sys.executable, __file__, "--child", json.dumps(spec)], env=env,
                          capture_output=True, text=True, timeout=3600)
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"child {spec} on {devices} devices failed:\n{proc.stderr[-3000:]}")


# ------------------------------------------------------------------------ parent
def montecarlo_methods_names():
    """Every registered method, ``dense`` first (its compile case is the scaling one)."""
    from jaxgrav.montecarlo.methods import BUILDERS

    return ["dense", *(m for m in BUILDERS if m != "dense")]


EMITTERS = "xla_cpu_use_fusion_emitters"


def other_options(own, against):
    """The baseline's XLA options for a method whose own are ``own``, and its label."""
    from jaxgrav import xla_options

    if against == "emitters":  # the same options, the other kernel emitters
        if (EMITTERS, False) in own:
            return tuple(kv for kv in own if kv[0] != EMITTERS), \
                f"{own} without {EMITTERS}=False (XLA's fusion emitters)"
        return (*own, (EMITTERS, False)), f"{own} + {EMITTERS}=False (elemental emitters)"
    if not own:
        return xla_options.CPU_OPTIONS, \
            "jaxgrav's CPU_OPTIONS (this method keeps XLA's defaults)"
    return (), "XLA default options (LLVM -O3, fusion emitters)"


def compile_options_rows(emit, methods, chunk, against):
    """``montecarlo_options`` rows: compile and run time of each method's chunk function
    with its own XLA options (what the runner uses) against another setting."""
    from jaxgrav.montecarlo.spec import cpu_options_for

    with tempfile.TemporaryDirectory(prefix="jaxgrav-cc-") as cache:
        for method in methods:
            r = {}
            own = cpu_options_for(method)
            other, label = other_options(own, against)
            for name, opts in (("jaxgrav", None), ("other", other)):
                r[name] = spawn(1, method=method, chunk=chunk, n=chunk, compile=True,
                                cache=os.path.join(cache, f"{method}-{name}"),
                                other_options=opts)
            jc, xc = (r[k]["first_s"] - r[k]["second_s"] for k in ("jaxgrav", "other"))
            emit("montecarlo_options", f"{method} chunk={chunk} compile", chunk, jc, label, xc,
                 recompiled=r["jaxgrav"]["recompiled"],
                 **{f"{k}_cpu_s": round(r[k]["first_cpu_s"] - r[k]["second_cpu_s"], 3)
                    for k in ("jaxgrav", "other")},
                 **{f"{k}_{part}": r[k][f"first_{part}_s"] for k in ("jaxgrav", "other")
                    for part in ("trace", "lower", "xla")})
            emit("montecarlo_options", f"{method} chunk={chunk} run", chunk,
                 r["jaxgrav"]["run_s"], label, r["other"]["run_s"],
                 runs_per_s=round(chunk / r["jaxgrav"]["run_s"], 2))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="CI-sized run")
    p.add_argument("--compile-only", action="store_true",
                   help="only every method's compile and run time, jaxgrav's XLA options "
                        "against another setting (--against)")
    p.add_argument("--against", choices=("defaults", "emitters"), default="defaults",
                   help="--compile-only's baseline: XLA's defaults, or the method's own "
                        "options with the other kernel emitters (default: %(default)s)")
    p.add_argument("--methods", nargs="+", help="--compile-only: these methods only")
    p.add_argument("--child", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        return child(json.loads(args.child))
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from _common import emit

    if args.compile_only:
        return compile_options_rows(emit, args.methods or montecarlo_methods_names(),
                                    chunk=16, against=args.against)

    if args.quick:
        n, repeats, mem_chunk = 256, 2, 16
        cases = [(1, 16, True), (1, 64, True), (2, 64, True), (8, 64, True)]
        compile_methods = ("dense", "ukf")
    else:
        n, repeats, mem_chunk = 2048, 2, 64
        cases = [(d, c, True) for d in (1, 2, 8) for c in (16, 64, 256)]
        cases += [(1, 64, False), (8, 64, False)]
        compile_methods = tuple(montecarlo_methods_names())
    cmin = min(c for _, c, _ in cases)
    with tempfile.TemporaryDirectory(prefix="jaxgrav-cc-") as cache:
        base = None
        for devices, c, x64 in cases:
            first = base is None
            dtype = "float64" if x64 else "float32"
            r = spawn(devices, method="dense", chunk=c, n=n, repeats=repeats,
                      compile=first, cache=cache, x64=x64)
            if first:
                base = r
                emit("montecarlo_compile", f"dense devices=1 chunk={c}", c,
                     r["second_s"], "first call (trace + compile + run)", r["first_s"],
                     compile_s=round(r["first_s"] - r["second_s"], 3),
                     recompiled=r["recompiled"], traces_second_call=r["traces_second_call"],
                     compiles_second_call=r["compiles_second_call"], dtype=dtype)
            emit(BENCH, f"dense devices={devices} chunk={c} {dtype}", n, r["run_s"],
                 f"devices=1 chunk={cmin} float64", base["run_s"],
                 runs_per_s=round(n / r["run_s"], 1),
                 compile_and_first_chunk_s=round(r["first_s"], 3), dtype=dtype)
        for method in compile_methods[1:]:
            r = spawn(1, method=method, chunk=cmin, n=0, compile=True, cache=cache)
            emit("montecarlo_compile", f"{method} devices=1 chunk={cmin}", cmin,
                 r["second_s"], "first call (trace + compile + run)", r["first_s"],
                 compile_s=round(r["first_s"] - r["second_s"], 3),
                 recompiled=r["recompiled"], traces_second_call=r["traces_second_call"],
                 compiles_second_call=r["compiles_second_call"], dtype="float64")
        runs = {}
        ks = (4, 64) if args.quick else (4, 16, 64)  # quick: 4 chunks of 16 = a cached shape
        for i, k in enumerate(ks):
            nn = k * mem_chunk
            r = runs[k] = spawn(1, method="dense", chunk=mem_chunk, n=nn, cache=cache)
            if k < 64:  # baseline: the same runs in one chunk
                b, label = spawn(1, method="dense", chunk=nn, n=nn, cache=cache), \
                    f"n={nn} in one chunk"
            else:  # one chunk of 64·chunk runs would need GBs: compare with fewer chunks
                b, label = runs[ks[i - 1]], f"n={ks[i - 1] * mem_chunk} chunk={mem_chunk}"
            emit("montecarlo_memory", f"n={nn} chunk={mem_chunk}", nn, r["run_s"], label,
                 b["run_s"], maxrss_mb=round(r["maxrss_mb"], 1),
                 maxrss_one_chunk_mb=round(r["maxrss_one_chunk_mb"], 1),
                 growth_after_first_chunk_mb=round(r["maxrss_mb"] - r["maxrss_one_chunk_mb"], 1),
                 baseline_maxrss_mb=round(b["maxrss_mb"], 1), devices=1, dtype="float64")
    return None


if __name__ == "__main__":
    main()
