"""Monte Carlo runner: equal to a vmapped loop, independent of chunking, devices and hosts.

A toy function is checked exactly; two real methods of
:data:`jaxgrav.montecarlo.methods.BUILDERS` (the dense-offset matcher and the UKF,
short runs) are checked across chunk sizes and on 8 devices too.

The multi-device checks run in subprocesses with
``XLA_FLAGS=--xla_force_host_platform_device_count=N`` (the flag must be set before
JAX starts); the multi-host check starts two processes on loopback that join through
``jax.distributed.initialize`` (CPU collectives over gloo).
"""

import functools
import json
import os
import socket
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

from jaxgrav import Grid, montecarlo
from jaxgrav.montecarlo import matcher_runs
from jaxgrav.montecarlo import methods as montecarlo_methods
from jaxgrav.sim import DEG_ARC_M

N_RUNS = 11
_LAT = np.linspace(29.0, 30.0, 21)
_LON = np.linspace(129.0, 130.0, 21)
_MAP = np.sin(8 * _LAT)[:, None] * np.cos(6 * _LON)[None, :] * 30.0


def toy(key, scale, grid):
    """One run: a random walk, its cumulative statistics and a bicubic map sample."""
    k1, k2 = jax.random.split(key)
    steps = scale * jax.random.normal(k1, (6,))
    walk = jnp.cumsum(steps)
    lat = 29.5 + 0.4 * jax.random.uniform(k2, (3,), minval=-1.0)
    return {
        "walk": walk,
        "norm": jnp.sqrt(jnp.sum(walk**2)),
        "sample": grid.sample(lat, jnp.full_like(lat, 129.5), "bicubic"),
        "status": (walk[-1] > 0).astype(jnp.int32),
    }


def toy_args(scale=1.5):
    return (scale, Grid.from_arrays(_LAT, _LON, _MAP, units="mGal"))


@functools.cache
def reference():
    """The runs of ``toy`` by a plain vmap over ``jax.random.split(key(0), N_RUNS)``."""
    keys = jax.random.split(jax.random.key(0), N_RUNS)
    out = jax.vmap(toy, in_axes=(0, None, None))(keys, *toy_args())
    return {k: np.asarray(v) for k, v in out.items()}


def assert_same(a, b, label=""):
    assert a.keys() == b.keys(), label
    for k in a:
        assert a[k].shape == b[k].shape and a[k].dtype == b[k].dtype, (label, k)
        np.testing.assert_allclose(a[k], b[k], rtol=1e-12, atol=1e-12, err_msg=f"{label} {k}")


@pytest.mark.long
def test_equals_vmapped_loop_with_shapes():
    out = montecarlo.run(toy, jax.random.key(0), N_RUNS, args=toy_args(), progress=False)
    assert {k: v.shape for k, v in out.items()} == {
        "walk": (N_RUNS, 6), "norm": (N_RUNS,), "sample": (N_RUNS, 3), "status": (N_RUNS,)}
    assert all(isinstance(v, np.ndarray) for v in out.values())
    assert out["status"].dtype == np.int32 and out["walk"].dtype == np.float64
    assert_same(out, reference())


@pytest.mark.parametrize("chunk", [1, 3, 100])
@pytest.mark.long
def test_chunking_does_not_change_numbers(chunk):
    out = montecarlo.run(toy, jax.random.key(0), N_RUNS, chunk=chunk, args=toy_args(),
                         progress=False)
    assert_same(out, reference())


class Pair(NamedTuple):
    x: jax.Array
    y: jax.Array


def test_raw_uint32_key_and_namedtuple_results():
    out = montecarlo.run(_pair, jax.random.PRNGKey(3), 5, chunk=2, progress=False)
    assert isinstance(out, tuple) and out.x.shape == (5, 2) and out.y.shape == (5,)
    keys = jax.random.split(jax.random.PRNGKey(3), 5)
    np.testing.assert_array_equal(out.x, np.asarray(jax.vmap(jax.random.uniform,
                                                             in_axes=(0, None))(keys, (2,))))


def _pair(key):
    x = jax.random.uniform(key, (2,))
    return Pair(x, x.sum())


_TRACES = []


def counted(key, scale):
    _TRACES.append(1)  # runs only while tracing
    return scale * jax.random.normal(key, (2,))


def test_one_compilation_across_chunks_and_new_parameter_values():
    _TRACES.clear()
    a = montecarlo.run(counted, jax.random.key(1), 10, chunk=4, args=(jnp.float64(1.0),),
                       progress=False)
    assert len(_TRACES) == 1  # three chunks (4, 4, 2 padded to 4): one trace
    b = montecarlo.run(counted, jax.random.key(1), 10, chunk=4, args=(jnp.float64(2.5),),
                       progress=False)
    assert len(_TRACES) == 1  # a new value of an argument: no retrace
    np.testing.assert_allclose(b, 2.5 * a, rtol=1e-14)


def test_progress_bar_on_and_off(capsys):
    one = (jnp.float64(1.0),)
    montecarlo.run(counted, jax.random.key(1), 10, chunk=4, args=one, progress=False)
    assert capsys.readouterr().err == ""
    montecarlo.run(counted, jax.random.key(1), 10, chunk=4, args=one, progress=True)
    err = capsys.readouterr().err
    assert "10/10" in err and "runs/s" in err


@pytest.mark.parametrize("kw, match", [
    (dict(n_runs=0), r"n_runs must be a positive integer \(>= 1\); got 0"),
    (dict(n_runs=-3), r"n_runs .* got -3"),
    (dict(n_runs=2.5), r"n_runs must be a positive integer; got 2.5 \(float\)"),
    (dict(n_runs=True), r"n_runs must be a positive integer; got True"),
    (dict(chunk=0), r"chunk must be a positive integer \(>= 1\); got 0"),
    (dict(chunk="8"), r"chunk must be a positive integer; got '8' \(str\)"),
    (dict(devices=99), r"devices=99 but JAX sees 1 device.*xla_force_host_platform"),
    (dict(devices=[]), r"devices must be None, a positive int or a non-empty sequence"),
    (dict(key=jax.random.split(jax.random.key(0), 2)), r"key must be a single PRNG key"),
    (dict(key=np.zeros(3, np.float32)), r"key must be a PRNG key .* got dtype float32"),
    (dict(args=[1.0]), r"args must be a tuple"),
    (dict(args=(1.0, "x")), r"args must hold arrays .*args\[1\] is str: 'x'"),
])
def test_bad_input_is_named(kw, match):
    call = dict(fn=counted, key=jax.random.key(0), n_runs=4, args=(1.0,), progress=False) | kw
    with pytest.raises(ValueError, match=match):
        montecarlo.run(**call)


@pytest.mark.parametrize("fn, match", [
    (lambda key: "text", r"fn must return a pytree of arrays .*leaf <root> is str: 'text'"),
    (lambda key: {"a": key, "b": object()}, r"leaf \['b'\] is object"),
    (lambda key: None, r"fn must return a pytree of arrays .*got None with no array leaves"),
    (42, r"fn must be callable"),
])
def test_fn_returning_non_arrays(fn, match):
    with pytest.raises(ValueError, match=match):
        montecarlo.run(fn, jax.random.key(0), 3, progress=False)


def test_dataset_and_netcdf_round_trip(tmp_path):
    out = reference()
    ds = montecarlo.to_dataset(out, {"method": "toy", "seed": 0, "flag": True, "opt": None})
    assert ds["walk"].dims == ("run", "walk_dim1") and ds.sizes["run"] == N_RUNS
    assert ds.attrs == {"method": "toy", "seed": 0, "flag": 1, "opt": "None"}
    path = tmp_path / "mc.nc"
    montecarlo.write_netcdf(out, path, attrs={"method": "toy"})
    with xr.open_dataset(path) as back:
        np.testing.assert_array_equal(back["walk"].values, out["walk"])
        assert back.attrs["method"] == "toy"
    with pytest.raises(FileExistsError, match=r"mc\.nc' exists; pass force=True"):
        montecarlo.write_netcdf(out, path)
    montecarlo.write_netcdf(ds, path, force=True)
    with pytest.raises(ValueError, match="same leading run axis"):
        montecarlo.to_dataset({"a": np.zeros(3), "b": np.zeros(4)})


# ------------------------------------------------------------- real methods
# (options, n_runs, chunk): the chunk does not divide n_runs (the last chunk is padded)
# and is the one the CLI and filter tests compile (same shapes: one compilation a suite)
REAL = {"dense": (dict(drift_deg=0.03, n_fixes=20), 5, 4),
        "ukf": (dict(n_fixes=31), 3, 2),
        # the resampling of a batch runs on the runs that resample (rare_cond): its
        # rounding may depend on the others, within the tolerance (1e-14 measured)
        "pf": (dict(n_fixes=121), 4, 4)}  # ~3 resamplings a run (2.7 % of steps)


@functools.cache
def real_runs(method, chunk):
    """``method``'s runs (key 0) on one device in chunks of ``chunk``."""
    opts, n, _ = REAL[method]
    spec = montecarlo_methods.build(method, **opts)
    return montecarlo.run(spec.fn, jax.random.key(0), n, chunk=chunk, args=spec.args,
                          progress=False)


def assert_same_runs(a, b, label=""):
    """Integers equal, floats to 1e-6 relative (a millimetre in a km error), not bitwise.

    A batch of one run (chunk 1, or one run a device) is another XLA program whose fused
    arithmetic rounds differently: 1e-14 relative for the UKF; the dense matcher's
    Levenberg-Marquardt keeps a step only if it lowers the cost, and a near tie can go
    either way (seen: 7e-8 relative, 0.13 mm, on 8 devices)."""
    assert a.keys() == b.keys(), label
    for k in a:
        assert a[k].shape == b[k].shape and a[k].dtype == b[k].dtype, (label, k)
        if np.issubdtype(a[k].dtype, np.integer):
            np.testing.assert_array_equal(a[k], b[k], err_msg=f"{label} {k}")
        else:
            np.testing.assert_allclose(a[k], b[k], rtol=1e-6, atol=1e-6, err_msg=f"{label} {k}")


@pytest.mark.parametrize("method", REAL)
@pytest.mark.long
def test_real_method_gives_the_same_runs_for_any_chunk(method):
    opts, n, chunk = REAL[method]
    alone, chunked = real_runs(method, 1), real_runs(method, chunk)
    assert_same_runs(alone, chunked, f"{method} chunk 1 vs {chunk}")
    # different runs, not one repeated (a rejected dense fix keeps the INS error, equal
    # in every run of a fixed drift)
    fixed = ~np.isclose(chunked["err_m"], chunked["ins_err_m"], rtol=1e-9)
    assert fixed.sum() >= n - 2
    assert len(set(np.round(chunked["err_m"][fixed], 6))) == fixed.sum()
    if method == "dense":  # fixed INS drift: every INS track is off by exactly it
        np.testing.assert_allclose(chunked["ins_err_m"], opts["drift_deg"] * DEG_ARC_M,
                                   rtol=1e-6)
    else:  # 2 km initial error, 0.2 m/s: still about 2 km after 5 min
        assert np.all((chunked["ins_err_m"] > 1500) & (chunked["ins_err_m"] < 2500))


def test_correlation_is_a_deprecated_name_of_dense(monkeypatch):
    """``correlation`` builds ``dense`` and warns once a process; the old function names
    warn on every access and are the new functions."""
    monkeypatch.setattr(montecarlo_methods, "WARNED_ALIASES", set())
    assert "correlation" not in montecarlo_methods.BUILDERS
    opts = REAL["dense"][0]
    new = montecarlo_methods.build("dense", **opts)
    with pytest.warns(DeprecationWarning, match="'correlation' is deprecated; use 'dense'"):
        old = montecarlo_methods.build("correlation", **opts)
    assert old.fn is new.fn is matcher_runs.dense_run and old.settings == new.settings
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the second time: no warning
        assert montecarlo_methods.build("correlation", **opts).fn is matcher_runs.dense_run
    for module, name, value in ((montecarlo_methods, "correlation_run", matcher_runs.dense_run),
                                (matcher_runs, "correlation_run", matcher_runs.dense_run),
                                (matcher_runs, "correlation_builder", matcher_runs.dense_builder)):
        with pytest.warns(DeprecationWarning, match=f"{name} is deprecated"):
            assert getattr(module, name) is value
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        montecarlo_methods.nope  # noqa: B018
    with pytest.raises(ValueError, match=r"method must be one of \['chains', 'dense'"):
        montecarlo_methods.build("corr")


# ------------------------------------------------------------- other processes
_SCRIPT = """
import os, sys, json
import numpy as np
import jax
jax.config.update("jax_enable_x64", True)
if len(sys.argv) > 2:  # multi-host: process id, port; before anything starts JAX
    pid, port = int(sys.argv[2]), sys.argv[3]
    jax.distributed.initialize(coordinator_address="127.0.0.1:" + port, num_processes=2,
                               process_id=pid, initialization_timeout=60)
sys.path.insert(0, {tests!r})
from test_montecarlo import toy, toy_args, N_RUNS, REAL
from jaxgrav import montecarlo
from jaxgrav.montecarlo import methods as montecarlo_methods
cases = json.loads(sys.argv[1])
out = {{}}
for name, devices, chunk, *method in cases:  # [name, devices, chunk(, method of REAL)]
    if method:
        spec = montecarlo_methods.build(method[0], **REAL[method[0]][0])
        fn, n_runs, args = spec.fn, REAL[method[0]][1], spec.args
    else:
        fn, n_runs, args = toy, N_RUNS, toy_args()
    r = montecarlo.run(fn, jax.random.key(0), n_runs, chunk=chunk, devices=devices,
                       args=args, progress=False)
    out.update({{name + "/" + k: v for k, v in r.items()}})
if jax.process_index() == 0:
    np.savez(os.environ["MC_OUT"], n_devices=len(jax.devices()), **out)
"""


def _script(tmp_path):
    path = tmp_path / "mc_child.py"
    path.write_text(textwrap.dedent(_SCRIPT.format(tests=str(Path(__file__).parent))))
    return path


def _env(n_dev, out):
    env = dict(os.environ, MC_OUT=str(out), JAX_PLATFORMS="cpu",
               XLA_FLAGS=f"--xla_force_host_platform_device_count={n_dev}")
    env.pop("JAX_NUM_CPU_DEVICES", None)
    return env


def _split(npz, names):
    return {n: {k.split("/", 1)[1]: npz[k] for k in npz.files if k.startswith(n + "/")}
            for n in names}


@pytest.mark.long
def test_eight_devices_give_the_numbers_of_one(tmp_path):
    """The toy, and the real dense matcher and UKF (all runs in one chunk of 8,
    one run a device, padded), on 8 devices against one device in chunks."""
    cases = [["all8_chunk3", None, 3], ["two_chunk5", 2, 5],  # 2 chunks of 8; 2 of 6
             *([f"{m}8", None, None, m] for m in REAL)]
    out = tmp_path / "eight.npz"
    proc = subprocess.run([sys.executable, _script(tmp_path), json.dumps(cases)],
                          env=_env(8, out), capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    npz = np.load(out)
    assert int(npz["n_devices"]) == 8
    got = _split(npz, [c[0] for c in cases])
    for name in ("all8_chunk3", "two_chunk5"):
        assert_same(got[name], reference(), name)
    for m, (_, _, chunk) in REAL.items():
        assert_same_runs(got[f"{m}8"], real_runs(m, chunk), f"{m}: 8 devices vs 1")


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return str(s.getsockname()[1])


@pytest.mark.long
def test_two_processes_on_loopback_give_the_numbers_of_one(tmp_path):
    """jax.distributed over two local processes × 2 CPU devices (gloo collectives)."""
    out = tmp_path / "hosts.npz"
    cases = json.dumps([["hosts_chunk4", None, 4]])  # 3 chunks over 4 devices, last padded
    script, port = _script(tmp_path), _free_port()
    procs = [subprocess.Popen([sys.executable, script, cases, str(i), port], env=_env(2, out),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(2)]
    try:
        logs = [p.communicate(timeout=300) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    for p, (_, err) in zip(procs, logs, strict=True):
        assert p.returncode == 0, err[-3000:]
    npz = np.load(out)
    assert int(npz["n_devices"]) == 4  # 2 processes × 2 local devices in one mesh
    for name, res in _split(npz, ["hosts_chunk4"]).items():
        assert_same(res, reference(), name)


# ------------------------------------------------------ map error (issue 15, item 1)
def _me_grid():
    lat, lon = np.linspace(29.0, 31.0, 49), np.linspace(129.0, 131.0, 49)
    values = 30 * np.sin(9 * lat)[:, None] * np.cos(7 * lon)[None, :] + 5 * np.add.outer(
        np.cos(23 * lat), np.sin(19 * lon))
    return Grid.from_arrays(lat, lon, values, name="me", units="mGal")


@pytest.mark.parametrize("method", ["dense", "entropy"])
@pytest.mark.long
def test_matcher_builders_take_a_map_error(method):
    from jaxgrav.fields.map_error import map_error

    grid = _me_grid()
    opts = dict(drift_deg=0.02, n_fixes=12)
    plain = montecarlo_methods.build(method, grid, **opts)
    zero = montecarlo_methods.build(method, grid, map_error=map_error(0.0, 1e4), **opts)
    noisy = montecarlo_methods.build(method, grid, map_error=map_error(3.0, 1e4), **opts)
    assert plain.settings["map_error_sigma"] == zero.settings["map_error_sigma"] == 0.0
    assert (noisy.settings["map_error_sigma"], noisy.settings["map_error_length_m"]) == (3.0,
                                                                                        1e4)
    key = jax.random.key(4)
    runs = {name: montecarlo.run(s.fn, key, 4, chunk=2, args=s.args, progress=False)
            for name, s in (("plain", plain), ("zero", zero), ("noisy", noisy))}
    np.testing.assert_array_equal(runs["plain"]["err_m"], runs["zero"]["err_m"])
    np.testing.assert_array_equal(runs["plain"]["ins_err_m"], runs["noisy"]["ins_err_m"])
    assert not np.array_equal(runs["plain"]["score"], runs["noisy"]["score"])
    # the runner's run i is fn(split(key)[i], *args)
    one = noisy.fn(jax.random.split(key, 4)[3], *noisy.args)
    np.testing.assert_allclose(runs["noisy"]["err_m"][3], np.asarray(one["err_m"]), rtol=1e-5)


def test_builder_truth_grid_and_its_coverage():
    from jaxgrav.fields.map_error import truth_grid

    grid = _me_grid()
    spec = montecarlo_methods.build("dense", grid, drift_deg=0.02, n_fixes=12,
                                    map_error=truth_grid(grid))
    assert spec.settings["truth_map"] == "me"
    small = Grid.from_arrays(np.linspace(29.0, 30.0, 11), np.linspace(129.0, 130.0, 11),
                             np.zeros((11, 11)), name="small")
    with pytest.raises(ValueError, match=r"the truth map \(map_error.grid\) must cover"):
        montecarlo_methods.build("chains", grid, map_error=truth_grid(small))
    with pytest.raises(TypeError, match="map_error must be"):
        montecarlo_methods.build("dense", grid, map_error=3.0)
    # None is not passed on: a builder without the keyword still builds
    assert montecarlo_methods.build("ukf", None, map_error=None, n_fixes=20).fn is not None


@pytest.mark.long
def test_paper_a_table1_run_batch_takes_a_map_error():
    from jaxgrav.fields.map_error import map_error
    from jaxgrav.match.sizing import config_for
    from jaxgrav.montecarlo.paper_a_table1 import run_batch
    from jaxgrav.montecarlo.spec import region_of
    from jaxgrav.scenarios import MatchingScenario

    grid = _me_grid()
    scen = MatchingScenario(region=region_of(grid), drift_deg=0.02, n_fixes=12)
    cfg = config_for("dense", grid, 0.02 * DEG_ARC_M)
    key = jax.random.key(1)
    a = run_batch(key, 2, grid, grid, scen, "dense", cfg)
    b = run_batch(key, 2, grid, grid, scen, "dense", cfg, map_error=map_error(4.0, 1e4))
    np.testing.assert_array_equal(a["true_lat"], b["true_lat"])
    assert np.all(np.isfinite(b["err_m"])) and not np.array_equal(a["score"], b["score"])
