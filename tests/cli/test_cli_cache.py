"""The command line's persistent compilation cache (``jaxgrav.cli.cache``)."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from jaxgrav.cli import main
from jaxgrav.cli.cache import cache_dir, prune_large_entries


def test_cache_dir_from_the_environment(tmp_path):
    assert cache_dir({"XDG_CACHE_HOME": str(tmp_path)}) == tmp_path / "jaxgrav" / "xla"
    assert cache_dir({"JAXGRAV_CACHE_DIR": str(tmp_path / "c")}) == tmp_path / "c"
    assert cache_dir({}) == Path.home() / ".cache" / "jaxgrav" / "xla"
    for off in ("off", "OFF", "0", "no", "false"):
        assert cache_dir({"JAXGRAV_CACHE": off, "JAXGRAV_CACHE_DIR": str(tmp_path)}) is None


def _kept(folder, count, timeout=300.0):
    """The kept executables' names once ``count`` are written and none is pending."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        names = sorted(p.name for p in folder.glob("*.jaxexe")) if folder.is_dir() else []
        if len(names) >= count and not list(folder.glob("*.pending")):
            return names
        time.sleep(1.0)
    pytest.fail(f"fewer than {count} kept executables in {folder} after {timeout} s")


def _jaxgrav(args, env):
    return subprocess.run([sys.executable, "-m", "jaxgrav.cli", *args], env=env,
                          capture_output=True, text=True, timeout=600)


@pytest.mark.long
def test_a_second_call_loads_the_compiled_programs(tmp_path):
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("JAX_") and k != "JAXGRAV_CACHE"}  # conftest turns it off
    env["JAXGRAV_CACHE_DIR"] = str(tmp_path / "xla")
    track = tmp_path / "t.csv"
    assert main(["simulate", "--out", str(track), "--n", "8", "--seed", "1"]) == 0
    args = ["sample", "--map", "ryukyu", "--track", str(track), "--force",
            "--out", str(tmp_path / "s.csv")]
    first = _jaxgrav(args, env)
    assert first.returncode == 0, first.stderr
    entries = sorted(p.name for p in (tmp_path / "xla").iterdir())
    assert entries, "the first call cached nothing"
    second = _jaxgrav(args, env)
    assert second.returncode == 0, second.stderr
    assert second.stdout == first.stdout  # same result from the loaded programs
    assert sorted(p.name for p in (tmp_path / "xla").iterdir()) == entries  # nothing new
    # match and filter keep their compiled programs: a detached process compiles and
    # keeps each after the first call; the second call loads them, same result
    flt = tmp_path / "f.csv"
    assert main(["simulate-filter", "--out", str(flt), "--minutes", "20"]) == 0
    calls = [["match", "--map", "ryukyu", "--track", str(track), "--force",
              "--out", str(tmp_path / "m.json")],
             ["filter", "--track", str(flt), "--point-masses", "paper-d", "--method", "pmf",
              "--force", "--out", str(tmp_path / "p.csv")]]
    for call in calls:
        assert _jaxgrav(call, env).returncode == 0
    kept = _kept(tmp_path / "xla" / "executables", 3)  # the matcher, pmf and its prior
    results = [(tmp_path / n).read_text() for n in ("m.json", "p.csv")]
    for call in calls:
        again = _jaxgrav(call, env)
        assert again.returncode == 0, again.stderr
    assert [(tmp_path / n).read_text() for n in ("m.json", "p.csv")] == results
    assert _kept(tmp_path / "xla" / "executables", 3) == kept  # loaded, none added
    # turned off: no folder
    env["JAXGRAV_CACHE_DIR"] = str(tmp_path / "none")
    off = _jaxgrav(["--no-cache", *args], env)
    assert off.returncode == 0, off.stderr
    assert not (tmp_path / "none").exists()


def test_prune_large_entries_removes_only_oversized_entries(tmp_path):
    """Entries above the bound go with their access-time file; the rest stay."""
    (tmp_path / "big-cache").write_bytes(b"x" * 2048)
    (tmp_path / "big-atime").write_bytes(b"1")
    (tmp_path / "small-cache").write_bytes(b"x" * 16)
    (tmp_path / "small-atime").write_bytes(b"1")
    assert prune_large_entries(tmp_path, max_entry_bytes=1024) == ["big-cache"]
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != ".lockfile") == [
        "small-atime", "small-cache"]
    assert prune_large_entries(tmp_path / "missing") == []
