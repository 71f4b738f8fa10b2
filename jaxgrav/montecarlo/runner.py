"""Monte Carlo runner: one function of a PRNG key, run over many keys on every device.

:func:`run` splits the key once into ``n_runs`` keys, vmaps the per-run function,
shards the run axis over a :class:`jax.sharding.Mesh` of the devices and streams
fixed-size chunks through one compiled executable, so that device memory is bounded
by the chunk and the numbers do not depend on the chunk size or the device count
(run ``i`` always gets key ``i``). Results come back as NumPy arrays with a leading
run axis; :func:`to_dataset` and :func:`write_netcdf` turn them into an xarray
Dataset / NetCDF file.

Devices
-------
On a CPU, JAX sees one device by default. Split the host into ``D`` devices *before*
JAX starts with ``XLA_FLAGS=--xla_force_host_platform_device_count=D`` or
``jax.config.update("jax_num_cpu_devices", D)`` right after ``import jax``.

Multi-host
----------
Start every process with the same script and the same ``key``, after::

    jax.distributed.initialize(coordinator_address="host0:1234",
                               num_processes=P, process_id=i)

(on CPU the collectives go through gloo; on SLURM/TPU/cloud clusters the arguments
are detected). ``jax.devices()`` then lists the devices of all processes and the
mesh spans them. Every process computes the same ``n_runs`` keys (cheap: 8 bytes a
run) and each feeds only its own devices' slice of every chunk
(``jax.make_array_from_callback``, equivalent to slicing the keys by
``jax.process_index()`` for ``jax.make_array_from_process_local_data``). Each chunk's
results are gathered to every process (``multihost_utils.process_allgather``), so
every process returns the full arrays; write files from ``jax.process_index() == 0``
only. Tested with two local processes on loopback (``tests/montecarlo/test_montecarlo.py``).

Memory
------
The keys (8 bytes a run) and the returned arrays live on the host; on the devices
at most two chunks are alive at a time (one computing, one being copied back).
"""

import functools
import math

import jax
import numpy as np
import xarray as xr
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from tqdm.auto import tqdm

from jaxgrav._io import atomic_output
from jaxgrav.xla_options import CPU_OPTIONS, check_cpu_options, compiler_options, gc_paused

__all__ = ["DEFAULT_CHUNK", "RUN_AXIS", "run", "to_dataset", "write_netcdf"]

DEFAULT_CHUNK = 256
"""Runs per chunk when ``chunk`` is not given (rounded up to a multiple of the devices)."""

RUN_AXIS = "run"
"""Name of the mesh axis and of the Dataset dimension along runs."""


def _positive_int(name, value):
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"{name} must be a positive integer; got {value!r} "
                         f"({type(value).__name__})")
    if value < 1:
        raise ValueError(f"{name} must be a positive integer (>= 1); got {value}")
    return int(value)


def _resolve_devices(devices):
    available = jax.devices()
    if devices is None:
        return list(available)
    if isinstance(devices, int | np.integer) and not isinstance(devices, bool):
        n = _positive_int("devices", devices)
        if n > len(available):
            raise ValueError(
                f"devices={n} but JAX sees {len(available)} device(s) ({available[0].platform}); "
                "on a CPU set XLA_FLAGS=--xla_force_host_platform_device_count="
                f"{n} (or jax_num_cpu_devices) before JAX starts")
        return list(available[:n])
    devices = list(devices)
    if not devices or not all(isinstance(d, jax.Device) for d in devices):
        raise ValueError(f"devices must be None, a positive int or a non-empty sequence of "
                         f"jax.Device; got {devices!r}")
    return devices


def _split_keys(key, n_runs):
    """All run keys as host data ``(n_runs, *key_shape)`` and the key impl (None: raw)."""
    key = jax.numpy.asarray(key) if not isinstance(key, jax.Array) else key
    if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        if key.shape != ():
            raise ValueError(f"key must be a single PRNG key; got a key array of shape {key.shape}")
        impl = jax.random.key_impl(key)
        return np.asarray(jax.random.key_data(jax.random.split(key, n_runs))), impl
    if key.dtype != np.uint32 or key.ndim != 1:
        raise ValueError("key must be a PRNG key (jax.random.key) or a raw uint32 key "
                         f"(jax.random.PRNGKey); got dtype {key.dtype}, shape {key.shape}")
    return np.asarray(jax.random.split(key, n_runs)), None


_ARRAY_TYPES = jax.Array | np.ndarray | np.generic | int | float | complex


def _check_leaves(out):
    leaves = jax.tree_util.tree_leaves_with_path(out)
    if not leaves:
        raise ValueError(f"fn must return a pytree of arrays (one run); got {out!r} "
                         "with no array leaves")
    for path, leaf in leaves:
        if not isinstance(leaf, _ARRAY_TYPES):
            raise ValueError(
                f"fn must return a pytree of arrays (one run); leaf "
                f"{jax.tree_util.keystr(path) or '<root>'} is {type(leaf).__name__}: {leaf!r}")


@functools.lru_cache(maxsize=32)
def _batched(fn, impl, mesh, cpu_options):
    """The jitted, vmapped, sharded chunk function; cached so repeated runs reuse it."""
    run_sharding = NamedSharding(mesh, PartitionSpec(RUN_AXIS))

    def one(key_data, *args):
        key = key_data if impl is None else jax.random.wrap_key_data(key_data, impl=impl)
        out = fn(key, *args)
        _check_leaves(out)
        return out

    def chunk_fn(key_data, *args):
        return jax.vmap(one, in_axes=(0, *([None] * len(args))))(key_data, *args)

    return jax.jit(chunk_fn, out_shardings=run_sharding,
                   compiler_options=compiler_options(mesh.devices.flat[0], cpu_options))


def _to_host(out):
    if jax.process_count() > 1:
        return multihost_utils.process_allgather(out, tiled=True)
    return jax.tree.map(np.asarray, out)


def _store(results, host, start, count, n_runs):
    if results is None:
        results = jax.tree.map(lambda a: np.empty((n_runs, *a.shape[1:]), a.dtype), host)
    for r, a in zip(jax.tree.leaves(results), jax.tree.leaves(host), strict=True):
        r[start:start + count] = a[:count]
    return results


def run(fn, key, n_runs, *, chunk=None, devices=None, progress=True, args=(),
        cpu_options=CPU_OPTIONS):
    """Run ``fn`` over ``n_runs`` PRNG keys, vmapped, sharded over devices, in chunks.

    Parameters
    ----------
    fn : callable
        ``fn(key, *args) -> pytree of arrays`` for one run (traceable; no Python
        side effects on values). Pass a module-level function, not a fresh lambda,
        to reuse the compiled code across calls of :func:`run`.
    key : PRNG key
        ``jax.random.key(seed)`` (or a raw ``PRNGKey``); split once into ``n_runs``
        keys, run ``i`` gets ``jax.random.split(key, n_runs)[i]`` whatever the
        chunking and devices.
    n_runs : int
        Number of runs, >= 1.
    chunk : int, optional
        Runs per compiled call (default :data:`DEFAULT_CHUNK`, capped at ``n_runs``),
        rounded up to a multiple of the device count. Bounds device memory; the last
        chunk is padded to the same size (one compilation) and the padding dropped.
    devices : int or sequence of jax.Device, optional
        The first ``devices`` of ``jax.devices()``, or these devices; all by default.
    progress : bool
        Show a tqdm bar with runs/s on stderr (process 0 only).
    args : tuple
        Extra arguments of ``fn``, the same for every run (maps, configurations);
        replicated on the devices. Array leaves are traced, so new values do not
        recompile.
    cpu_options : tuple of (str, value)
        XLA options the runs are compiled with on CPU
        (:data:`jaxgrav.xla_options.CPU_OPTIONS`: LLVM ``-O2``; a method's own in
        :attr:`~jaxgrav.montecarlo.MethodSpec.cpu_options`); other platforms use XLA's
        defaults.

    Returns
    -------
    pytree of numpy.ndarray
        ``fn``'s structure, each leaf with shape ``(n_runs, *leaf_shape)``.

    Raises
    ------
    ValueError
        ``n_runs`` or ``chunk`` not a positive int, bad ``key``, ``devices`` or
        ``cpu_options``, or ``fn`` returning something other than arrays.
    """
    n_runs = _positive_int("n_runs", n_runs)
    chunk = DEFAULT_CHUNK if chunk is None else _positive_int("chunk", chunk)
    cpu_options = check_cpu_options(cpu_options)
    if not callable(fn):
        raise ValueError(f"fn must be callable as fn(key, *args); got {fn!r}")
    if not isinstance(args, tuple):
        raise ValueError(f"args must be a tuple of extra arguments of fn; got "
                         f"{type(args).__name__}")
    for path, leaf in jax.tree_util.tree_leaves_with_path(args):
        if not isinstance(leaf, _ARRAY_TYPES):
            raise ValueError(f"args must hold arrays (static settings belong in pytree meta "
                             f"fields); args{jax.tree_util.keystr(path)} is "
                             f"{type(leaf).__name__}: {leaf!r}")
    devs = _resolve_devices(devices)
    n_dev = len(devs)
    size = math.ceil(min(chunk, n_runs) / n_dev) * n_dev
    mesh = Mesh(np.array(devs), (RUN_AXIS,))
    key_sharding = NamedSharding(mesh, PartitionSpec(RUN_AXIS))
    keys, impl = _split_keys(key, n_runs)
    args = jax.device_put(args, NamedSharding(mesh, PartitionSpec()))
    batched = _batched(fn, impl, mesh, cpu_options)

    def launch(start):
        part = keys[start:start + size]
        if part.shape[0] < size:  # pad with copies of the first key; results dropped
            part = np.concatenate([part, np.repeat(part[:1], size - part.shape[0], 0)])
        data = jax.make_array_from_callback(part.shape, key_sharding, lambda idx: part[idx])
        with gc_paused():  # the first call traces and compiles (jaxgrav.xla_options)
            return batched(data, *args)

    results = None
    bar = None
    if progress and jax.process_index() == 0:
        bar = tqdm(total=n_runs, unit="runs", desc="montecarlo", dynamic_ncols=True,
                   smoothing=0.1)
    try:
        pending = None
        for start in [*range(0, n_runs, size), None]:
            out = None if start is None else launch(start)  # dispatch, then collect the last
            if pending is not None:
                count = min(size, n_runs - pending[0])
                results = _store(results, _to_host(pending[1]), pending[0], count, n_runs)
                if bar is not None:
                    bar.update(count)
            pending = None if start is None else (start, out)
    finally:
        if bar is not None:
            bar.close()
    return results


def _flat_names(results):
    names = {}
    for path, leaf in jax.tree_util.tree_leaves_with_path(results):
        parts = []
        for p in path:
            for attr in ("key", "name", "idx"):
                if hasattr(p, attr):
                    parts.append(str(getattr(p, attr)))
                    break
        names["_".join(parts) or "value"] = np.asarray(leaf)
    return names


def _attr_value(v):
    if isinstance(v, bool | np.bool_):
        return int(v)
    if isinstance(v, str | int | float | np.integer | np.floating):
        return v
    if isinstance(v, list | tuple) and v and all(isinstance(x, int | float) for x in v):
        return np.asarray(v)
    return str(v)


def to_dataset(results, attrs=None):
    """An xarray Dataset of Monte Carlo results.

    Parameters
    ----------
    results : pytree of array_like
        As returned by :func:`run`: leaves of shape ``(n_runs, ...)``. Names are the
        leaves' paths (dict keys, NamedTuple fields) joined by ``_``.
    attrs : dict, optional
        Global attributes (provenance: method, seed, settings). Values that NetCDF
        cannot hold (None, dicts) are stored as strings, booleans as 0/1.

    Returns
    -------
    xarray.Dataset
        One variable per leaf with dimensions ``("run", "<name>_dim1", ...)`` and a
        ``run`` coordinate ``0 … n_runs-1``.
    """
    flat = _flat_names(results)
    if not flat:
        raise ValueError("results must hold at least one array; got an empty pytree")
    lengths = {k: v.shape[0] if v.ndim else None for k, v in flat.items()}
    if None in lengths.values() or len(set(lengths.values())) != 1:
        raise ValueError(f"every result needs the same leading run axis; got lengths {lengths}")
    data = {k: ((RUN_AXIS, *[f"{k}_dim{i}" for i in range(1, v.ndim)]), v)
            for k, v in flat.items()}
    n = next(iter(lengths.values()))
    ds = xr.Dataset(data, coords={RUN_AXIS: np.arange(n)})
    ds.attrs.update({str(k): _attr_value(v) for k, v in (attrs or {}).items()})
    return ds


def write_netcdf(results, path, *, attrs=None, force=False):
    """Write Monte Carlo results to NetCDF, atomically.

    Parameters
    ----------
    results : pytree of array_like or xarray.Dataset
        :func:`run`'s output (converted with :func:`to_dataset`) or a Dataset.
    path : str or Path
        Output file; an existing file is replaced only with ``force=True``.
    attrs : dict, optional
        Global attributes added to the Dataset.
    force : bool
        Overwrite an existing file.

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``force`` is false.
    """
    ds = results if isinstance(results, xr.Dataset) else to_dataset(results)
    if attrs:
        ds = ds.assign_attrs({str(k): _attr_value(v) for k, v in attrs.items()})
    with atomic_output(path, force=force) as tmp:
        ds.to_netcdf(tmp)

