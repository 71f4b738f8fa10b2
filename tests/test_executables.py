"""Compiled programs kept on disk between processes (``jaxgrav.executables``)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import executables
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.grid import Grid


@pytree_dataclass
class _Settings:
    scale: float = 2.0
    power: int = static_field(2)


@jax.jit
def _program(x, y, settings):
    return {"sum": jnp.sum(x**settings.power) * settings.scale + y, "x": x[::-1]}


@pytest.fixture
def kept(tmp_path):
    """Executables kept in a fresh folder for the test, off again afterwards."""
    before = executables.use_folder(tmp_path / "exe")
    yield tmp_path / "exe"
    executables.use_folder(before)


def _args(n=5, **kw):
    return (jnp.arange(n, dtype=float), 0.5, _Settings(**kw))


def test_off_by_default_is_the_jitted_call():
    assert executables.folder() is None  # conftest turns the command line's cache off
    out = executables.call(_program, *_args())
    assert out["sum"] == _program(*_args())["sum"]


def test_a_second_call_loads_the_kept_executable(kept, monkeypatch):
    first = executables.call(_program, *_args())
    entries = sorted(kept.glob("*.jaxexe"))
    assert len(entries) == 1
    # a loaded executable is neither traced, lowered nor compiled again
    monkeypatch.setattr(type(_program), "lower", lambda *a, **k: pytest.fail("compiled again"))
    second = executables.call(_program, *_args())
    for k in ("sum", "x"):
        np.testing.assert_array_equal(second[k], first[k])
        np.testing.assert_array_equal(second[k], _program(*_args())[k])
    assert sorted(kept.glob("*.jaxexe")) == entries


def test_each_static_setting_and_shape_has_its_own_entry(kept):
    executables.call(_program, *_args())
    executables.call(_program, *_args(power=3))  # a static field: another program
    executables.call(_program, *_args(n=7))  # another shape
    executables.call(_program, *_args(scale=5.0))  # a traced field: the same program
    assert len(list(kept.glob("*.jaxexe"))) == 3
    out = executables.call(_program, *_args(power=3, scale=5.0))
    assert float(out["sum"]) == pytest.approx(5.0 * np.sum(np.arange(5.0) ** 3) + 0.5)


def test_a_damaged_entry_is_compiled_again_and_replaced(kept):
    executables.call(_program, *_args())
    (entry,) = kept.glob("*.jaxexe")
    entry.write_bytes(b"not an executable")
    out = executables.call(_program, *_args())
    assert float(out["sum"]) == pytest.approx(2.0 * 30.0 + 0.5)
    assert entry.read_bytes() != b"not an executable"


def test_the_folder_keeps_the_most_recently_used_entries(kept, monkeypatch):
    monkeypatch.setattr(executables, "MAX_ENTRIES", 2)
    for n in (3, 4, 5, 6):
        executables.call(_program, *_args(n=n))
    assert len(list(kept.glob("*.jaxexe"))) == 2


def test_an_unwritable_folder_still_gives_the_result(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the folder should be")
    before = executables.use_folder(blocker / "exe")
    try:
        out = executables.call(_program, *_args())
    finally:
        executables.use_folder(before)
    assert float(out["sum"]) == pytest.approx(60.5)


def test_match_track_gives_the_same_fix_through_a_kept_executable(kept):
    from jaxgrav.match import match_track

    rng = np.random.default_rng(0)
    values = rng.normal(0.0, 20.0, (40, 40))
    grid = Grid.from_arrays(30.0 + 0.05 * np.arange(40), 130.0 + 0.05 * np.arange(40), values)
    lat = 30.8 + 0.01 * np.arange(12)
    lon = 130.8 + 0.012 * np.arange(12)
    g = np.asarray(grid.sample(lat - 0.02, lon + 0.01, "bicubic"))
    plain_before = executables.use_folder(None)
    plain = match_track(grid, lat, lon, g, drift_radius_m=4000.0, warn=False)
    executables.use_folder(plain_before)
    first = match_track(grid, lat, lon, g, drift_radius_m=4000.0, warn=False)
    loaded = match_track(grid, lat, lon, g, drift_radius_m=4000.0, warn=False)
    assert len(list(kept.glob("*.jaxexe"))) == 1
    for a, b, c in zip(plain, first, loaded, strict=True):
        np.testing.assert_array_equal(np.asarray(b), np.asarray(c))
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-9)


def test_an_entry_that_fails_to_run_is_compiled_again(kept, monkeypatch):
    """A kept executable that loads but fails when run (as one serialised after XLA loaded
    it from its own cache did) is removed, compiled again past XLA's cache, and kept."""
    executables.call(_program, *_args())
    (entry,) = kept.glob("*.jaxexe")

    class Broken:
        def __call__(self, *args):
            raise jax.errors.JaxRuntimeError("INTERNAL: Function fusion.2 not found")

    real = executables.serialize_executable.deserialize_and_load
    monkeypatch.setattr(executables.serialize_executable, "deserialize_and_load",
                        lambda *a, **k: Broken())
    out = executables.call(_program, *_args())
    assert float(out["sum"]) == pytest.approx(60.5)
    assert entry.exists()  # written again
    monkeypatch.setattr(executables.serialize_executable, "deserialize_and_load", real)
    assert float(executables.call(_program, *_args())["sum"]) == pytest.approx(60.5)
