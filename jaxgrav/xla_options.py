"""The XLA compiler options jaxgrav compiles its programs with.

XLA's CPU backend hands every kernel to LLVM at its most aggressive level by default
(``xla_backend_optimization_level`` 3, LLVM's ``-O3``). For jaxgrav's programs level 2
compiles faster and runs as fast or faster: on the 2-core machine (jax 0.10.1, every
Monte Carlo method's chunk function, same results to rounding) compile took 0.2–3.5 s
less, and the Kalman filters' runs took less than half the time (UKF 0.49 → 0.21 s,
EKF 0.28 → 0.13 s for 64 and 32 of paper D's runs; ``-O3`` unrolls and vectorises
their 13 × 13 loops into slower code), the point-mass filter 6 % less; the particle
filter ran as fast, the matchers within ±10 % (dense 0.039 → 0.041 s for 256 runs in a
paired A/B), and the Rao–Blackwellised particle filter 7–15 % slower (its random numbers: JAX's
threefry and float64 inverse-error-function normals vectorise better at ``-O3``). So
jaxgrav compiles at level 2 on CPU where it compiles a program itself: the Monte Carlo
runner (:func:`jaxgrav.montecarlo.run`; a method whose runs are long and slower at level
2, the RBPF's, asks for XLA's defaults with :data:`XLA_DEFAULTS`) and the command
line's programs (:mod:`jaxgrav.executables`; one command's run is short next to its
compile, so level 2 is used there for every method, the RBPF's too). Other platforms keep
XLA's defaults (not measured). An option XLA does not know fails when the program is
compiled (``jax.errors.JaxRuntimeError``: "No such compile option").

A program of your own that calls jaxgrav inside its ``jax.jit`` is compiled with
*your* options: pass ``jax.jit(f, compiler_options=compiler_options())`` for the same.
"""

import jax

__all__ = ["CPU_OPTIONS", "XLA_DEFAULTS", "check_cpu_options", "compiled", "compiler_options"]

CPU_OPTIONS = (("xla_backend_optimization_level", 2),)
"""``(name, value)`` pairs of the XLA options on CPU (a tuple: immutable, hashable)."""

XLA_DEFAULTS = ()
"""No options: XLA's own defaults, for programs measured to run faster with them."""


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
        The options on CPU (:data:`CPU_OPTIONS`, or :data:`XLA_DEFAULTS`).

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
    return dict(check_cpu_options(cpu_options)) if platform == "cpu" else {}


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
    return fn.lower(*args).compile(compiler_options() or None)
