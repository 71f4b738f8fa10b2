"""The command line's persistent XLA compilation cache.

Every ``jaxgrav`` command compiles its programs with XLA; without a cache each call pays
that again (4–12 s for a matcher or filter). The command keeps compiled programs in
``$JAXGRAV_CACHE_DIR``, else ``$XDG_CACHE_HOME/jaxgrav/xla`` (``~/.cache/jaxgrav/xla``),
so that a second call with the same shapes loads them instead. ``JAXGRAV_CACHE=off`` (or
``jaxgrav --no-cache``) turns it off; a cache the caller already configured (JAX's own
``JAX_COMPILATION_CACHE_DIR``, or ``jax.config`` in a program that calls
:func:`jaxgrav.cli.main`) is kept as it is. Entries are read and written under JAX's
file lock (the ``filelock`` package), so concurrent commands never read a half-written
program; the folder is bounded to :data:`MAX_BYTES` (least recently used entries go).
"""

import os
from pathlib import Path

import jax

__all__ = ["MAX_BYTES", "MIN_COMPILE_SECONDS", "cache_dir", "enable_cache"]

MAX_BYTES = 2 * 2**30
"""Size bound of the cache folder (bytes); also what turns JAX's file lock on."""
MIN_COMPILE_SECONDS = 0.0
"""Programs that compile faster than this are not cached (s): 0, since a matcher call
compiles some 40 small programs of ~0.1 s each, which add up to seconds."""


def cache_dir(environ=None):
    """The folder the command line caches compiled programs in, or None when turned off.

    Parameters
    ----------
    environ : mapping, optional
        The environment (default ``os.environ``).

    Returns
    -------
    pathlib.Path or None
    """
    env = os.environ if environ is None else environ
    if env.get("JAXGRAV_CACHE", "").strip().lower() in ("off", "0", "no", "false"):
        return None
    if env.get("JAXGRAV_CACHE_DIR"):
        return Path(env["JAXGRAV_CACHE_DIR"]).expanduser()
    base = env.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "jaxgrav" / "xla"


def enable_cache(off=False):
    """Turn the persistent compilation cache on for this process (the CLI's entry point).

    Parameters
    ----------
    off : bool
        ``--no-cache``: leave it off.

    Returns
    -------
    str or None
        The cache folder in use (possibly the caller's own), or None.
    """
    current = jax.config.jax_compilation_cache_dir
    if current:  # configured by the caller or JAX_COMPILATION_CACHE_DIR: keep it
        return current
    folder = None if off else cache_dir()
    if folder is None:
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_compilation_cache_max_size", MAX_BYTES)
    return str(folder)
