"""The XLA compiler options jaxgrav compiles its programs with.

XLA's CPU backend hands every kernel to LLVM at its most aggressive level by default
(``xla_backend_optimization_level`` 3, LLVM's ``-O3``). For jaxgrav's programs level 2
compiles faster and runs as fast or faster: on the 2-core machine (jax 0.10.1, every
Monte Carlo method's chunk function, same results to rounding) compile took 0.2–3.5 s
less, and the Kalman filters' runs took less than half the time (UKF 0.49 → 0.21 s,
EKF 0.28 → 0.13 s for 64 and 32 of paper D's runs; ``-O3`` unrolls and vectorises
their 13 × 13 loops into slower code), the point-mass filter 6 % less; the particle
filters and the matchers ran within ±10 %.

Most of what is left of a compile is XLA's per-kernel code generation: XLA's newer MLIR
fusion emitters spend ~20 ms of MLIR passes on every kernel, even an 8-operation one
(a ``jax.profiler`` trace of ``entropy+iccp``'s compile: 439 kernels, 9.4 s of
``FusionCompiler::Compile`` over the two cores). ``xla_cpu_use_fusion_emitters=False``
selects XLA's older elemental emitters: 27–42 % less compile time for every Monte Carlo
method (each method's 16-run chunk function in a fresh process, compile without
tracing, 2026-12-06: dense 4.4 → 2.6 s, entropy+iccp 6.6 → 4.2 s, ukf 2.7 → 1.6 s,
voyage-dense 7.1 → 4.3 s), runs as fast (±5 %) and results equal to rounding — except
the point-mass filter's runs, 28 % slower (1.70 → 2.19 s for 16 of paper D's runs,
twice) and the Rao–Blackwellised particle filter's, 65 % slower (16 patrols; since its
predicted readings are one product, 2026-12-07, paper D's RBPF runs faster with the
elemental emitters; since its steps no longer join positions and means into one array,
2026-12-08, the voyages' RBPF is 16 % slower with them on 12 h patrols).

So :data:`CPU_OPTIONS` (``-O2``, elemental emitters) is what jaxgrav compiles with on
CPU where it compiles a program itself: the Monte Carlo runner
(:func:`jaxgrav.montecarlo.run`; the point-mass filter's methods and ``voyage-rbpf``
ask for :data:`FUSION_EMITTER_OPTIONS`,
:func:`jaxgrav.montecarlo.spec.cpu_options_for`) and the command line's programs
(:mod:`jaxgrav.executables`; one command's run is short next to its compile, so
:data:`CPU_OPTIONS` is used there for every method). Other platforms keep XLA's
defaults (not measured). An option XLA does not know fails when the program is compiled
(``jax.errors.JaxRuntimeError``: "No such compile option") — except in jaxgrav's own
two sets: should a later XLA drop one of their options, it is left out (each probed
once per process by compiling an identity, ~10 ms) rather than fail.

A program of your own that calls jaxgrav inside its ``jax.jit`` is compiled with
*your* options: pass ``jax.jit(f, compiler_options=compiler_options())`` for the same.

Before XLA compiles a program, JAX traces and lowers it in Python, creating a few
hundred thousand short-lived objects (tracers, equations, MLIR operations); Python's
cyclic garbage collector then runs hundreds of times over them and over everything
else alive, about a quarter of the tracing and lowering time of a Monte Carlo chunk
(``entropy+iccp``: tracing 1.4–1.5 → 1.0–1.2 s CPU, lowering 0.60–0.65 → 0.43 s;
``voyage-dense`` and ``voyage-entropy+iccp``: tracing 0.7 s less, 2026-12-07, load ~10).
:func:`gc_paused` pauses it while jaxgrav's own entry points trace, lower and compile
(:func:`compiled`, the Monte Carlo runner); reference cycles made meanwhile wait for
the collector, which runs again as soon as the block ends.
"""

import contextlib
import functools
import gc

import jax
import numpy as np

__all__ = ["CPU_OPTIONS", "FUSION_EMITTER_OPTIONS", "XLA_DEFAULTS", "check_cpu_options",
           "compiled", "compiler_options", "gc_paused"]

CPU_OPTIONS = (("xla_backend_optimization_level", 2), ("xla_cpu_use_fusion_emitters", False))
"""``(name, value)`` pairs of the XLA options on CPU (a tuple: immutable, hashable):
LLVM ``-O2`` and XLA's elemental kernel emitters."""

FUSION_EMITTER_OPTIONS = (("xla_backend_optimization_level", 2),)
"""LLVM ``-O2`` with XLA's (default) MLIR fusion emitters, for the point-mass and the
voyages' Rao–Blackwellised particle filters, whose runs are slower with the elemental
emitters."""

XLA_DEFAULTS = ()
"""No options: XLA's own defaults (``-O3``, fusion emitters), for a program measured to
run faster with them (none of jaxgrav's Monte Carlo methods today)."""


def check_cpu_options(cpu_options):
    """``cpu_options`` (pairs or a dict) as a tuple of ``(name, value)`` pairs, or a
    ValueError naming it."""
    try:
        if isinstance(cpu_options, dict):
            cpu_options = sorted(cpu_options.items(), key=lambda kv: str(kv[0]))
        pairs = tuple((str(k), v) for k, v in cpu_options)
        hash(pairs)  # a key of the runner's cache of compiled functions
    except (TypeError, ValueError):
        raise ValueError(f"cpu_options must be (name, value) pairs of XLA options with "
                         f"hashable values, e.g. "
                         f"{CPU_OPTIONS}; got {cpu_options!r}") from None
    if any(not k.startswith("xla_") for k, _ in pairs):
        raise ValueError(f"cpu_options must name XLA options (xla_...); got {cpu_options!r}")
    return pairs


def compiler_options(platform=None, cpu_options=CPU_OPTIONS):
    """The XLA compiler options for ``platform``.

    Parameters
    ----------
    platform : str, jax.Device or None
        ``"cpu"``, ``"gpu"``, …, a device (its platform), or None for
        :func:`jax.default_backend` at the time of the call.
    cpu_options : tuple of (str, value)
        The options on CPU (:data:`CPU_OPTIONS`, :data:`FUSION_EMITTER_OPTIONS` or
        :data:`XLA_DEFAULTS`; of jaxgrav's own two, only those this XLA knows).

    Returns
    -------
    dict
        For ``jax.jit(..., compiler_options=...)`` or ``Lowered.compile(...)``; empty
        off CPU.
    """
    if platform is None:
        platform = jax.default_backend()
    elif not isinstance(platform, str):
        platform = platform.platform
    if platform != "cpu":
        return {}
    pairs = check_cpu_options(cpu_options)
    if pairs in (CPU_OPTIONS, FUSION_EMITTER_OPTIONS):  # ours: leave out what XLA dropped
        pairs = tuple(p for p in pairs if _cpu_xla_knows(p))
    return dict(pairs)


@functools.cache
def _cpu_xla_knows(option):
    """Whether this XLA's CPU compiler takes ``option`` (a ``(name, value)`` pair)."""
    # a shape on a CPU device, not an array: no data, and callable inside a trace too
    x = jax.ShapeDtypeStruct((), np.float32,
                             sharding=jax.sharding.SingleDeviceSharding(jax.devices("cpu")[0]))
    try:
        jax.jit(lambda v: v).lower(x).compile(dict([option]))
    except jax.errors.JaxRuntimeError as err:
        if "No such compile option" in str(err):
            return False
        raise
    return True


def compiled(fn, *args):
    """``fn`` lowered for ``args`` and compiled with :func:`compiler_options`.

    JAX keeps both steps in memory, so a second call with arguments of the same
    shapes costs only the lookup.

    Parameters
    ----------
    fn : jax.stages.Wrapped
        A :func:`jax.jit`-wrapped function.
    *args
        Its arguments.

    Returns
    -------
    jax.stages.Compiled
        Call it with arguments of the same tree and shapes.
    """
    with gc_paused():
        return fn.lower(*args).compile(compiler_options() or None)


@contextlib.contextmanager
def gc_paused():
    """A block in which Python's cyclic garbage collector does not run (:func:`gc.disable`).

    For tracing, lowering and compiling a program (see the module notes); the collector
    is enabled again at the end of the block, unless it was off before it. Reference
    counting frees objects as usual meanwhile; only cycles wait for the block's end.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()
