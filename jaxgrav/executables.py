"""Compiled programs kept on disk between processes (ahead-of-time executables).

XLA's persistent compilation cache (:mod:`jaxgrav.cli.cache`) saves the *compile* of a
program, but a new process still traces and lowers it before it can look the compile
up: about a second for the dense matcher, paid by every ``jaxgrav match``. :func:`call`
keeps the compiled executable itself, serialised
(:mod:`jax.experimental.serialize_executable`), in a folder, and a later process with
the same program loads it in ~0.1 s without tracing, lowering or compiling.

It is off until a folder is set with :func:`use_folder` (the command line sets
``executables/`` inside its cache folder; ``--no-cache`` and ``JAXGRAV_CACHE=off``
leave it off); off, :func:`call` is the jitted function's own call. An entry is used
only by the same program on the same kind of machine: its key hashes the function's
name, the jaxgrav source (every ``.py`` file of the package), the JAX and jaxlib
versions, the 64-bit flag, the backend, the CPU (model and instruction-set flags) and
``XLA_FLAGS``, the arguments' tree structure (static settings included) and every
leaf's shape and dtype. Entries are written atomically; one that fails to load or to
run is compiled again and replaced. A kept executable is compiled past XLA's cache
(one loaded from there serialises incompletely). Like XLA's own cache, an entry holds
machine code that is run as it is: the folder must be the user's own (the default is in
the user's cache directory).
"""

import hashlib
import os
import pickle
import platform
import tempfile
from pathlib import Path

import jax
import jaxlib
import numpy as np
from jax.experimental import serialize_executable

__all__ = ["MAX_ENTRIES", "MAX_ENTRY_BYTES", "call", "folder", "use_folder"]

MAX_ENTRIES = 64
"""Entries kept in the folder; the least recently used go first."""
MAX_ENTRY_BYTES = 32 * 2**20
"""Executables larger than this (bytes) are not kept (one baking a large constant)."""

_STATE = {"folder": None}  # set by use_folder (the command line), like JAX's cache folder
_SOURCE_HASH = []  # computed once per process


def use_folder(path):
    """Keep executables in ``path`` (created when needed), or stop with None.

    Parameters
    ----------
    path : str, pathlib.Path or None

    Returns
    -------
    pathlib.Path or None
        The folder in use before.
    """
    before = folder()
    _STATE["folder"] = None if path is None else Path(path).expanduser()
    return before


def folder():
    """The folder executables are kept in, or None (off)."""
    return _STATE["folder"]


def call(fn, *args):
    """``fn(*args)``, through an executable kept on disk when a folder is set.

    Parameters
    ----------
    fn : jax.stages.Wrapped
        A :func:`jax.jit`-wrapped function without static arguments (static settings
        travel as pytree auxiliary data, e.g. a config dataclass's static fields).
    *args
        Its arguments, a pytree of arrays and scalars.

    Returns
    -------
    The output of ``fn(*args)``.
    """
    where = folder()
    if where is None:
        return fn(*args)
    leaves, in_tree = jax.tree_util.tree_flatten((args, {}))
    path = where / f"{_key(fn, in_tree, leaves)}.jaxexe"
    compiled = _load(path, in_tree)
    if compiled is not None:
        try:
            return jax.block_until_ready(compiled(*args))
        except (jax.errors.JaxRuntimeError, TypeError, ValueError):
            path.unlink(missing_ok=True)  # an entry that does not run: compile it again
    compiled = _compile_fresh(fn, args)
    _store(path, compiled)
    return compiled(*args)


def _compile_fresh(fn, args):
    """Compile ``fn`` for ``args`` past XLA's persistent cache.

    An executable that XLA:CPU loaded from its own cache serialises incompletely
    (jaxlib 0.10.2: the point-mass filter's program, kept that way, failed when run
    with "Function multiply_bitcast_fusion.2 not found"), so a kept executable is always
    one compiled here. A call of the command line (single-threaded) is the only user.
    """
    before = jax.config.jax_enable_compilation_cache
    jax.config.update("jax_enable_compilation_cache", False)
    try:
        return fn.lower(*args).compile()
    finally:
        jax.config.update("jax_enable_compilation_cache", before)


def _load(path, in_tree):
    """The executable kept at ``path``, or None (absent, or unreadable: then removed)."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    try:
        exe, out_tree = pickle.loads(data)
        compiled = serialize_executable.deserialize_and_load(exe, in_tree, out_tree)
    except Exception:  # a damaged or foreign entry: compile again and replace it
        path.unlink(missing_ok=True)
        return None
    os.utime(path)  # least recently used goes first
    return compiled


def _store(path, compiled):
    """Write ``compiled`` to ``path`` atomically; skipped when it cannot be serialised."""
    try:
        exe, _, out_tree = serialize_executable.serialize(compiled)
    except (ValueError, NotImplementedError):  # e.g. constants baked into the program
        return
    data = pickle.dumps((exe, out_tree))
    if len(data) > MAX_ENTRY_BYTES:
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".jaxexe")
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
        _evict(path.parent)
    except OSError:  # a read-only or full cache folder: run without keeping it
        return


def _evict(where):
    """Remove the least recently used entries beyond :data:`MAX_ENTRIES`."""
    entries = []
    for p in where.glob("*.jaxexe"):
        try:
            entries.append((p.stat().st_mtime, p))
        except FileNotFoundError:  # removed by a concurrent command
            continue
    for _, p in sorted(entries, reverse=True)[MAX_ENTRIES:]:
        p.unlink(missing_ok=True)


def _key(fn, in_tree, leaves):
    """The entry's name: a hash of everything the executable depends on."""
    h = hashlib.sha256()
    name = getattr(fn, "__wrapped__", fn)
    line = getattr(getattr(name, "__code__", None), "co_firstlineno", "")
    for part in (
        f"{name.__module__}.{name.__qualname__}:{line}",  # two lambdas of a module differ
        _source_hash(),
        jax.__version__,
        jaxlib.__version__,
        str(jax.config.jax_enable_x64),
        str(jax.config.jax_default_matmul_precision),
        str(jax.config.jax_default_prng_impl),
        jax.default_backend(),
        str(jax.devices()[0].client.platform_version),
        _cpu(),
        os.environ.get("XLA_FLAGS", ""),
        str(in_tree),
    ):
        h.update(part.encode())
        h.update(b"\0")
    for leaf in leaves:
        a = np.asarray(leaf) if not hasattr(leaf, "dtype") else leaf
        h.update(f"{type(leaf).__name__}{tuple(a.shape)}{a.dtype};".encode())
    return h.hexdigest()[:40]


def _source_hash():
    """Hash of every ``.py`` file of the jaxgrav package (once per process)."""
    if not _SOURCE_HASH:
        h = hashlib.sha256()
        root = Path(__file__).parent
        for p in sorted(root.rglob("*.py")):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
        _SOURCE_HASH.append(h.hexdigest())
    return _SOURCE_HASH[0]


def _cpu():
    """The CPU model and instruction-set flags (an executable is compiled for them)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return f"{platform.machine()} {platform.processor()}"
    keep = [line for line in text.splitlines()
            if line.startswith(("model name", "flags", "Features", "CPU part"))]
    return "\n".join(sorted(set(keep)))
