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
Entries larger than :data:`MAX_ENTRY_BYTES` are removed when the cache is turned on
(:func:`prune_large_entries`): such an executable carries a large array baked in as a
constant, and XLA:CPU has crashed (segmentation fault) deserialising one.

The same switch keeps the commands' compiled entry points themselves in
``executables/`` inside that folder (:mod:`jaxgrav.executables`): the XLA cache saves
compiling, but a new process still traces and lowers a program before it can look its
compile up, about a second for a matcher; a kept executable skips all three.
"""

import os
import sys
from pathlib import Path

import jax
from filelock import FileLock

from jaxgrav import executables

__all__ = ["MAX_BYTES", "MAX_ENTRY_BYTES", "MIN_COMPILE_SECONDS", "cache_dir",
           "enable_cache", "prune_large_entries", "unusable"]

MAX_BYTES = 2 * 2**30
"""Size bound of the cache folder (bytes); also what turns JAX's file lock on."""
MIN_COMPILE_SECONDS = 0.0
"""Programs that compile faster than this are not cached (s): 0, since a matcher call
compiles some 40 small programs of ~0.1 s each, which add up to seconds."""
MAX_ENTRY_BYTES = 8 * 2**20
"""Largest cache entry kept (bytes, compressed): jaxgrav's own programs take the map as an
argument and stay well below it (the largest of the test suite's is about 1 MB)."""


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
        try:
            return Path(env["JAXGRAV_CACHE_DIR"]).expanduser()
        except RuntimeError:  # "~name/..." of an unknown user: was a traceback, exit 1
            raise ValueError(f"JAXGRAV_CACHE_DIR={env['JAXGRAV_CACHE_DIR']!r}: its '~' names "
                             "no home folder") from None
    base = env.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "jaxgrav" / "xla"


def unusable(folder):
    """Why ``folder`` cannot hold the cache (it is made if missing), or None if it can.

    Parameters
    ----------
    folder : pathlib.Path

    Returns
    -------
    str or None
    """
    if folder.exists() and not folder.is_dir():
        return "it is a file, not a folder"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        return f"it cannot be made ({err.strerror or err})"
    if not os.access(folder, os.W_OK | os.X_OK):
        return "it is not writable"
    return None


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
    try:
        folder = None if off else cache_dir()
        why = None if folder is None else unusable(folder)
    except ValueError as err:
        folder, why = None, str(err)
    if why is not None:  # a file, a folder under a file, read-only: JAX warned at each
        # compile ("Error reading persistent compilation cache entry"), a dozen tracebacks
        where = f"folder {str(folder)!r}" if folder else "folder"
        print(f"warning: the compilation cache {where} is not usable: {why}; compiled programs "
              "are not kept (set JAXGRAV_CACHE_DIR to a writable folder, or JAXGRAV_CACHE=off)",
              file=sys.stderr)
        folder = None
    executables.use_folder(None if folder is None else folder / "executables")
    if current:  # configured by the caller or JAX_COMPILATION_CACHE_DIR: keep it
        return current
    if folder is None:
        return None
    prune_large_entries(folder)
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_compilation_cache_max_size", MAX_BYTES)
    return str(folder)


def prune_large_entries(folder, max_entry_bytes=MAX_ENTRY_BYTES):
    """Remove the entries of a JAX compilation cache folder above a size.

    A program that closes over a large array (a refined map) is compiled with the array as
    a constant; its cache entry runs to tens of MB and loading it has crashed XLA:CPU.
    Runs under the cache's own file lock, so a concurrent process never loses an entry it
    is reading.

    Parameters
    ----------
    folder : str or pathlib.Path
        The cache folder (need not exist).
    max_entry_bytes : int
        Entries larger than this (bytes, as stored) are removed.

    Returns
    -------
    list of str
        The names of the removed entries.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    with FileLock(str(folder / ".lockfile"), timeout=60):
        removed = []
        for entry in folder.glob("*-cache"):
            try:
                if entry.stat().st_size <= max_entry_bytes:
                    continue
                entry.unlink()
                folder.joinpath(entry.name.removesuffix("-cache") + "-atime").unlink(
                    missing_ok=True)
            except FileNotFoundError:  # removed by the cache's own eviction meanwhile
                continue
            removed.append(entry.name)
    return removed
