"""Test configuration: the suite runs in float64 (x64 on, as the library's precision
notes say); XLA executables are cached on disk between runs; shared fixtures."""

import os

# XLA compiles the suite's programs with jaxgrav's own CPU options
# (jaxgrav.xla_options.CPU_OPTIONS: LLVM -O2 and XLA's elemental kernel emitters, what the
# command line and the Monte Carlo runner use) instead of XLA's defaults (-O3, the MLIR
# fusion emitters): most of the fast tier's time is compiling, and this cut its CPU
# time by about a quarter (2026-12-07). Added to the environment before JAX starts its
# backend, so the commands the tests start as subprocesses compile the same way; a flag
# already in XLA_FLAGS is left as it is.
_TEST_XLA_FLAGS = {"xla_backend_optimization_level": "2", "xla_cpu_use_fusion_emitters": "false"}
_flags = os.environ.get("XLA_FLAGS", "")
os.environ["XLA_FLAGS"] = " ".join([_flags] + [f"--{k}={v}" for k, v in _TEST_XLA_FLAGS.items()
                                               if f"--{k}=" not in _flags]).strip()

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

# Persistent compilation cache: off by default. With it on (JAXGRAV_TEST_CACHE=DIR) a
# second run of the suite, and the example scripts the tests start as subprocesses
# (through the environment), load compiled programs instead of compiling them again; but
# XLA:CPU (jaxlib 0.10.2) has segfaulted while deserialising an executable from it, rarely
# and not reproducibly (twice in full runs, each time in a different small program), and
# pytest-xdist then hung with both workers idle: a CI run that never ends. A size bound
# turns on JAX's file lock around every cache read and write (needs `filelock`), so two
# processes never read a half-written entry; entries above
# jaxgrav.cli.cache.MAX_ENTRY_BYTES (a program that closed over a map) are removed first.
_CACHE = os.environ.get("JAXGRAV_TEST_CACHE", "off")
if _CACHE == "off":  # the command line's own cache (jaxgrav.cli.cache) too, in-process and
    os.environ.setdefault("JAXGRAV_CACHE", "off")  # in the commands the tests start
else:
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", _CACHE)
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")
    os.environ.setdefault("JAX_COMPILATION_CACHE_MAX_SIZE", str(4 * 2**30))
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs",
                      float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]))
    jax.config.update("jax_compilation_cache_max_size",
                      int(os.environ["JAX_COMPILATION_CACHE_MAX_SIZE"]))

jax.config.update("jax_enable_x64", True)

import jaxgrav as jg  # noqa: E402
from jaxgrav.cli.cache import prune_large_entries  # noqa: E402

if _CACHE != "off":
    prune_large_entries(os.environ["JAX_COMPILATION_CACHE_DIR"])


@pytest.fixture(scope="module")
def smooth_grid():
    """A smooth, information-rich synthetic anomaly field (mGal) on a 0.01° grid."""
    lat = np.linspace(29.5, 30.5, 101)
    lon = np.linspace(129.5, 130.5, 101)
    y, x = np.meshgrid(lat - 30, lon - 130, indexing="ij")
    v = (40 * np.sin(45 * x + 2) * np.cos(35 * y) + 25 * np.cos(60 * x * y + 50 * y)
         + 20 * np.sin(70 * x - 30 * y) + 15 * x)
    return jg.Grid.from_arrays(lat, lon, v, units="mGal")


def _check_clear_message(msg, path, phrases=()):
    """A bad-input message: one line, naming the file, no library syntax, with phrases."""
    assert str(path) in msg and "\n" not in msg and "np." not in msg, msg
    for phrase in phrases:
        assert phrase in msg, (phrase, msg)


@pytest.fixture(scope="session")
def clear_message():
    """``clear_message(msg, path, phrases)`` asserts a one-line error naming ``path``."""
    return _check_clear_message
