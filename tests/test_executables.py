"""Compiled programs kept on disk between processes (``jaxgrav.executables``)."""

import os
import subprocess
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import executables
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.geodesy import eotvos_jit
from jaxgrav.grid import Grid


@pytree_dataclass
class _Settings:
    scale: float = 2.0
    power: int = static_field(2)
    fn: object = static_field(np.sin)


@jax.jit
def _program(x, y, settings):
    return {"sum": jnp.sum(x**settings.power) * settings.scale + y, "x": x[::-1]}


@pytest.fixture
def kept(tmp_path):
    """Executables kept in a fresh folder for the test, off again afterwards."""
    before = executables.use_folder(tmp_path / "exe")
    yield tmp_path / "exe"
    executables.use_folder(before)


def _key(fn, *args):
    leaves, tree = jax.tree_util.tree_flatten((args, {}))
    return executables._key(fn, tree, leaves)


def _args(n=5, **kw):
    return (jnp.arange(n, dtype=float), 0.5, _Settings(**kw))


def _kept_entries(folder, count, timeout=240.0):
    """The folder's entries once ``count`` are there (a detached process writes them)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        entries = sorted(folder.glob("*.jaxexe")) if folder.is_dir() else []
        pending = list(folder.glob("*.pending")) if folder.is_dir() else []
        if len(entries) >= count and not pending:
            return entries
        time.sleep(0.5)
    pytest.fail(f"no {count} kept executable(s) in {folder} after {timeout} s")


def test_off_by_default_is_the_jitted_call():
    assert executables.folder() is None  # conftest turns the command line's cache off
    out = executables.call(_program, *_args())
    assert out["sum"] == _program(*_args())["sum"]


def test_the_key_tells_programs_apart():
    base = _key(_program, *_args())
    assert base == _key(_program, *_args(scale=5.0))  # a traced field: the same program
    assert base != _key(_program, *_args(power=3))  # a static field: another program
    assert base != _key(_program, *_args(n=7))  # another shape
    assert base == _key(_program, *_args(fn=np.sin))  # a function by its name, not address
    assert base != _key(_program, *_args(fn=np.cos))


def test_only_programs_named_across_processes_are_kept(kept):
    """A lambda in the settings, or a closure as the program, cannot be named in another
    process: it runs, and nothing is kept for it."""
    assert _key(_program, *_args(fn=lambda v: 2 * v)) is None

    def make(scale):
        return jax.jit(lambda v: scale * v)

    assert _key(make(3.0), jnp.ones(2)) is None
    np.testing.assert_allclose(executables.call(make(3.0), jnp.ones(2)), 3.0)
    assert not kept.exists() or not list(kept.glob("*"))


def test_a_program_is_kept_by_a_process_of_its_own_then_loaded(kept, monkeypatch):
    """The first call runs the program the usual way and leaves a detached process to
    compile and keep it; a later call loads it (no compile: the keeping step is not
    reached) and gives the same numbers."""
    lat, ve, vn = jnp.linspace(10.0, 40.0, 7), jnp.full(7, 5.0), jnp.full(7, -2.0)
    first = executables.call(eotvos_jit, lat, ve, vn)
    np.testing.assert_array_equal(first, eotvos_jit(lat, ve, vn))
    (entry,) = _kept_entries(kept, 1)
    monkeypatch.setattr(executables, "_keep_later", lambda *a: pytest.fail("not loaded"))
    np.testing.assert_array_equal(executables.call(eotvos_jit, lat, ve, vn), first)
    # a damaged entry is removed, and the call still gives the result
    entry.write_bytes(b"not an executable")
    monkeypatch.setattr(executables, "_keep_later", lambda *a: None)
    np.testing.assert_array_equal(executables.call(eotvos_jit, lat, ve, vn), first)
    assert not entry.exists()


def test_an_entry_that_fails_to_run_is_removed(kept, monkeypatch):
    """One that loads but fails when run (XLA:CPU: "Function ... not found") is removed,
    marked as failed, and the program runs the usual way."""
    kept.mkdir(parents=True)
    leaves, tree = jax.tree_util.tree_flatten((_args(), {}))
    entry = kept / f"{executables._key(_program, tree, leaves)}.jaxexe"
    entry.write_bytes(b"x")

    class Broken:
        def __call__(self, *args):
            raise jax.errors.JaxRuntimeError("INTERNAL: Function fusion.2 not found")

    monkeypatch.setattr(executables, "_load", lambda path, tree: Broken())
    monkeypatch.setattr(executables, "_keep_later", lambda *a: None)
    assert float(executables.call(_program, *_args())["sum"]) == pytest.approx(60.5)
    assert not entry.exists()
    # remembered: later calls run it the usual way and start no futile keeping process
    assert entry.with_suffix(".failed").exists()
    monkeypatch.setattr(executables, "_load", lambda path, tree: None)
    monkeypatch.setattr(executables, "_keep_later", lambda *a: pytest.fail("kept again"))
    assert float(executables.call(_program, *_args())["sum"]) == pytest.approx(60.5)


def test_the_folder_keeps_the_most_recently_used_entries(tmp_path, monkeypatch):
    monkeypatch.setattr(executables, "MAX_ENTRIES", 2)
    for i in range(4):
        (tmp_path / f"{i}.jaxexe").write_bytes(b"x")
        t = time.time() - 100 + i
        os.utime(tmp_path / f"{i}.jaxexe", (t, t))
    executables._evict(tmp_path)
    assert sorted(p.name for p in tmp_path.glob("*.jaxexe")) == ["2.jaxexe", "3.jaxexe"]


def test_an_unwritable_folder_still_gives_the_result(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the folder should be")
    before = executables.use_folder(blocker / "exe")
    try:
        out = executables.call(_program, *_args())
    finally:
        executables.use_folder(before)
    assert float(out["sum"]) == pytest.approx(60.5)


@pytest.mark.long  # waits for a detached process to compile match_track (the slowest fast
# test); the fast tier keeps the keep-then-load path by test_a_program_is_kept_by_a_process_of_
# its_own_then_loaded, and the key of pytree settings by test_the_key_tells_programs_apart
def test_match_track_gives_the_same_fix_through_a_kept_executable(kept):
    from jaxgrav.match import match_track

    rng = np.random.default_rng(0)
    values = rng.normal(0.0, 20.0, (40, 40))
    grid = Grid.from_arrays(30.0 + 0.05 * np.arange(40), 130.0 + 0.05 * np.arange(40), values)
    lat = 30.8 + 0.01 * np.arange(12)
    lon = 130.8 + 0.012 * np.arange(12)
    g = np.asarray(grid.sample(lat - 0.02, lon + 0.01, "bicubic"))
    first = match_track(grid, lat, lon, g, drift_radius_m=4000.0, warn=False)
    _kept_entries(kept, 1)
    loaded = match_track(grid, lat, lon, g, drift_radius_m=4000.0, warn=False)
    for a, b in zip(first, loaded, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_a_program_whose_trial_fails_is_marked_not_kept(kept, monkeypatch):
    """The keeping process's trial run fails (as the voyage loop's crashes XLA:CPU): no
    entry, a failed mark, and no keeping process for that program again."""
    started = []
    monkeypatch.setattr(executables.subprocess, "Popen", lambda cmd, **kw: started.append(cmd))
    lat, ve, vn = jnp.linspace(10.0, 40.0, 7), jnp.full(7, 5.0), jnp.full(7, -2.0)
    first = executables.call(eotvos_jit, lat, ve, vn)
    (cmd,) = started
    monkeypatch.setattr(executables.subprocess, "run",
                        lambda *a, **kw: subprocess.CompletedProcess(a, returncode=-11))
    executables._work(cmd[-1])  # the detached process's work, here
    assert not list(kept.glob("*.jaxexe")) and not list(kept.glob("*.trial"))
    assert len(list(kept.glob("*.failed"))) == 1
    np.testing.assert_array_equal(executables.call(eotvos_jit, lat, ve, vn), first)
    assert len(started) == 1


@pytest.mark.parametrize("error", [ValueError, NotImplementedError])
def test_a_program_that_cannot_be_serialised_is_not_kept(kept, monkeypatch, error):
    """serialize_executable refuses the program: no entry, a failed mark (no futile keeping
    process again), the result as usual."""
    started = []
    monkeypatch.setattr(executables.subprocess, "Popen", lambda cmd, **kw: started.append(cmd))
    first = executables.call(_program, *_args())
    (cmd,) = started

    def refuse(compiled):
        raise error("cannot serialise this executable")

    monkeypatch.setattr(executables.serialize_executable, "serialize", refuse)
    executables._work(cmd[-1])  # the detached process's work, here
    assert not list(kept.glob("*.jaxexe")) and not list(kept.glob("*.trial"))
    assert len(list(kept.glob("*.failed"))) == 1  # tried again only by a new version
    assert float(executables.call(_program, *_args())["sum"]) == float(first["sum"])
    assert len(started) == 1
