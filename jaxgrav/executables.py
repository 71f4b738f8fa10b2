"""Compiled programs kept on disk between processes (ahead-of-time executables).

XLA's persistent compilation cache (:mod:`jaxgrav.cli.cache`) saves the *compile* of a
program, but a new process still traces and lowers it before it can look the compile
up: about a second for the dense matcher, paid by every ``jaxgrav match``. :func:`call`
keeps the compiled executable itself, serialised
(:mod:`jax.experimental.serialize_executable`), in a folder, and a later process with
the same program loads it in ~0.1 s without tracing, lowering or compiling.

It is off until a folder is set with :func:`use_folder` (the command line sets
``executables/`` inside its cache folder; ``--no-cache`` and ``JAXGRAV_CACHE=off``
leave it off); off, :func:`call` compiles the jitted function in memory, with
:func:`jaxgrav.xla_options.compiler_options` as every entry is. An entry is used
only by the same program on the same kind of machine: its key hashes the function's
name, the jaxgrav source (every ``.py`` file of the package), the JAX and jaxlib
versions, the 64-bit flag, the backend, the CPU (model and instruction-set flags) and
``XLA_FLAGS``, the arguments' tree structure (static settings included) and every
leaf's shape and dtype; a program whose settings hold a closure or a lambda is not kept.

How an entry is made (jaxlib 0.10.2, XLA:CPU): an executable serialised in a process
that has run other programs can lack kernels it shares by name with them (kept that
way, the dense matcher failed when run: "Function broadcast_multiply_fusion.4 not
found"), and some serialised executables crash XLA:CPU when run (the loosely coupled
voyage loop: a segmentation fault, which no caller can catch). So the first call runs
the program the usual way and leaves a detached process (``python -m
jaxgrav.executables``) that compiles only this program, then has a third process load
it and run it on zeros; only an entry that passed is kept. Entries are written
atomically; one that fails to load or to run is removed. A program whose trial or kept
entry failed gets a ``.failed`` mark and is not compiled in the background again (until
the source or JAX changes its key). Like XLA's own cache, an entry
holds machine code that is run as it is: the folder must be the user's own (the default
is in the user's cache directory).
"""

import hashlib
import importlib
import os
import pickle
import platform
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import jaxlib
import numpy as np
from jax.experimental import serialize_executable

from jaxgrav._io import atomic_output
from jaxgrav.xla_options import compiled as compiled_for

__all__ = ["MAX_ENTRIES", "MAX_ENTRY_BYTES", "call", "folder", "use_folder"]

MAX_ENTRIES = 64
"""Entries kept in the folder; the least recently used go first."""
MAX_ENTRY_BYTES = 32 * 2**20
"""Executables larger than this (bytes) are not kept (one baking a large constant)."""

_FUNCTION_ADDRESS = re.compile(r"<function ([\w.<>]+) at 0x[0-9a-fA-F]+>")
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
    The output of ``fn(*args)``: from the kept executable when there is one, else from
    ``fn`` compiled in memory with :func:`jaxgrav.xla_options.compiled` (a detached
    process then keeps it for the next call).
    """
    where = folder()
    leaves, in_tree = jax.tree_util.tree_flatten((args, {}))
    # None: off, or settings that cannot be told apart between processes
    key = None if where is None else _key(fn, in_tree, leaves)
    if key is not None:
        path = where / f"{key}.jaxexe"
        compiled = _load(path, in_tree)
        if compiled is not None:
            try:
                return jax.block_until_ready(compiled(*args))
            except (jax.errors.JaxRuntimeError, TypeError, ValueError):
                path.unlink(missing_ok=True)  # an entry that does not run: removed
                _mark_failed(path)
        if not path.with_suffix(".failed").exists():  # else: kept before, did not run
            _keep_later(fn, in_tree, leaves, path)
    return compiled_for(fn, *args)(*args)


def _mark_failed(path):
    """Remember that the program of ``path`` does not survive being kept (not tried again).

    The key hashes the package's source and the JAX version, so a new version tries again.
    """
    try:
        path.with_suffix(".failed").touch()
    except OSError:
        return


def _keep_later(fn, in_tree, leaves, path):
    """Compile ``fn`` for these arguments' shapes and keep it, in a process of its own.

    An executable serialised in a process that has compiled or loaded other programs
    may lack kernels it shares by name with them (jaxlib 0.10.2, XLA:CPU: kept that way,
    the dense matcher failed when run with "Function broadcast_multiply_fusion.4 not
    found"). A fresh process that compiles only this program writes a complete one. It
    runs detached, after this call has its result the usual way; nothing depends on it.
    """
    pending = path.with_suffix(".pending")
    try:
        if pending.exists() and time.time() - pending.stat().st_mtime < 600:
            return  # already being compiled
        structs = [_struct(leaf) for leaf in leaves]
        name = getattr(fn, "__wrapped__", fn)
        job = pickle.dumps({"module": name.__module__, "name": name.__qualname__,
                            "tree": in_tree, "leaves": structs, "path": str(path),
                            "x64": bool(jax.config.jax_enable_x64)})
        path.parent.mkdir(parents=True, exist_ok=True)
        pending.write_bytes(job)
        subprocess.Popen([sys.executable, "-m", "jaxgrav.executables", str(pending)],
                         stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL, start_new_session=True)
    except (OSError, pickle.PicklingError, TypeError, ValueError):
        return  # run without keeping it


def _struct(leaf):
    """``(shape, dtype, weak_type)`` of an argument leaf, as the program was traced with."""
    if isinstance(leaf, np.ndarray | np.generic):
        return tuple(leaf.shape), np.dtype(leaf.dtype).str, False
    a = leaf if hasattr(leaf, "weak_type") else jax.numpy.asarray(leaf)
    return tuple(a.shape), np.dtype(a.dtype).str, bool(a.weak_type)


def _work(pending):
    """The detached process of :func:`_keep_later`: compile the job's program, keep it."""
    pending = Path(pending)
    try:
        job = pickle.loads(pending.read_bytes())
        jax.config.update("jax_enable_x64", job["x64"])
        fn = importlib.import_module(job["module"])
        for part in job["name"].split("."):
            fn = getattr(fn, part)
        if not hasattr(fn, "lower"):
            fn = jax.jit(fn)
        structs = [jax.ShapeDtypeStruct(shape, np.dtype(dtype), weak_type=weak)
                   for shape, dtype, weak in job["leaves"]]
        args, _ = jax.tree_util.tree_unflatten(job["tree"], structs)
        path = Path(job["path"])
        trial = path.with_suffix(".trial")
        _store(trial, compiled_for(fn, *args))
        # loaded and run in a third process first: some executables, once serialised,
        # crash XLA:CPU when run (a segmentation fault, which no caller could catch)
        if trial.exists():
            code = subprocess.run([sys.executable, "-m", "jaxgrav.executables", "--trial",
                                   str(pending)], stdin=subprocess.DEVNULL,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  timeout=600).returncode
            ok = code == 0
            if ok:
                os.replace(trial, path)
            elif code != -signal.SIGKILL:  # not for an out-of-memory kill: tried again
                _mark_failed(path)  # e.g. the voyage loop's program (a segmentation fault)
            trial.unlink(missing_ok=True)
    finally:
        pending.unlink(missing_ok=True)


def _trial(pending):
    """Load the job's trial executable and run it on zeros: exit code 0 if it runs."""
    job = pickle.loads(Path(pending).read_bytes())
    jax.config.update("jax_enable_x64", job["x64"])
    trial = Path(job["path"]).with_suffix(".trial")
    exe, out_tree = pickle.loads(trial.read_bytes())
    compiled = serialize_executable.deserialize_and_load(exe, job["tree"], out_tree)
    zeros = [jax.numpy.zeros(shape, np.dtype(dtype)) if not weak or shape
             else np.dtype(dtype).type(0).item() for shape, dtype, weak in job["leaves"]]
    args, _ = jax.tree_util.tree_unflatten(job["tree"], zeros)
    jax.block_until_ready(compiled(*args))


def _load(path, in_tree):
    """The executable kept at ``path``, or None (absent, or unreadable: then removed)."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    try:
        exe, out_tree = pickle.loads(data)
        compiled = serialize_executable.deserialize_and_load(exe, in_tree, out_tree)
    except Exception:  # a damaged or foreign entry: removed, kept again by a later call
        path.unlink(missing_ok=True)
        return None
    os.utime(path)  # least recently used goes first
    return compiled


def _store(path, compiled):
    """Write ``compiled`` to ``path`` atomically.

    A program that cannot be kept (refused by JAX's serialiser, or larger than
    :data:`MAX_ENTRY_BYTES`) is marked failed instead (:func:`_mark_failed`): the
    callers go on with their in-memory program and start no futile keeping process for
    it again.
    """
    try:
        exe, _, out_tree = serialize_executable.serialize(compiled)
    except (ValueError, NotImplementedError):
        # what serialize_executable raises for a program it cannot write (e.g. some
        # baked-in constants): not an error of the caller's run
        _mark_failed(path)
        return
    data = pickle.dumps((exe, out_tree))
    if len(data) > MAX_ENTRY_BYTES:
        _mark_failed(path)
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(path, force=True) as tmp:
            tmp.write_bytes(data)
        _evict(path.parent)
    except OSError:  # a read-only or full cache folder: run without keeping it
        return


def _evict(where):
    """Remove the least recently used entries beyond :data:`MAX_ENTRIES`."""
    entries = []
    for p in (*where.glob("*.jaxexe"), *where.glob("*.failed")):
        try:
            entries.append((p.stat().st_mtime, p))
        except FileNotFoundError:  # removed by a concurrent command
            continue
    for _, p in sorted(entries, reverse=True)[MAX_ENTRIES:]:
        p.unlink(missing_ok=True)


def _key(fn, in_tree, leaves):
    """The entry's name: a hash of everything the executable depends on, or None.

    A module-level function in the static settings (e.g. a measurement model's map
    function) is named by its qualified name, its code being in the source hash; a
    closure, a lambda or any other object known only by its address cannot be named
    across processes, so its program is not kept (None).
    """
    name = getattr(fn, "__wrapped__", fn)
    tree = _FUNCTION_ADDRESS.sub(r"<function \1>", str(in_tree))
    if (" at 0x" in tree or "<lambda>" in tree or "<locals>" in tree
            or "<locals>" in name.__qualname__):  # a closure: what it holds is unseen
        return None
    h = hashlib.sha256()
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
        tree,
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


if __name__ == "__main__":  # python -m jaxgrav.executables [--trial] JOB (see _keep_later)
    if sys.argv[1] == "--trial":
        _trial(sys.argv[2])
    else:
        _work(sys.argv[1])
