"""A compilation cache folder the command cannot use (issue 19's hunt): JAXGRAV_CACHE_DIR
naming a file, a folder under a file or a folder that cannot be made left every compile
printing JAX's multi-line "Error reading persistent compilation cache entry" warning, and
``~nosuchuser/x`` ended in a traceback (exit 1). Now one warning line, the cache off, the
command run."""

import jax
import pytest

from jaxgrav import executables
from jaxgrav.cli import main
from jaxgrav.cli.cache import cache_dir, enable_cache, unusable


def test_unusable_says_why(tmp_path):
    blocker = tmp_path / "afile"
    blocker.write_text("")
    assert unusable(blocker) == "it is a file, not a folder"
    assert unusable(blocker / "sub").startswith("it cannot be made (")
    assert unusable(tmp_path / "new" / "xla") is None and (tmp_path / "new" / "xla").is_dir()


def test_an_unknown_users_home_is_named():
    with pytest.raises(ValueError, match="JAXGRAV_CACHE_DIR='~nosuchuser1/x': its '~' names no "
                                         "home folder"):
        cache_dir({"JAXGRAV_CACHE_DIR": "~nosuchuser1/x"})


NO_SUITE_CACHE = pytest.mark.skipif(
    bool(jax.config.jax_compilation_cache_dir),
    reason="the suite's own compilation cache is on (JAXGRAV_TEST_CACHE)")


def _point_at(tmp_path, monkeypatch, name):
    (tmp_path / "afile").write_text("")
    monkeypatch.delenv("JAXGRAV_CACHE", raising=False)
    monkeypatch.setenv("JAXGRAV_CACHE_DIR", name if name.startswith("~") else
                       str(tmp_path / name))


@NO_SUITE_CACHE
@pytest.mark.parametrize("name, why", [
    ("afile", "it is a file, not a folder"),
    ("afile/sub", "it cannot be made (Not a directory)"),
    ("~nosuchuser1/x", "its '~' names no home folder"),
])
def test_an_unusable_cache_folder_is_one_warning_and_the_cache_off(
        tmp_path, capsys, monkeypatch, name, why):
    _point_at(tmp_path, monkeypatch, name)
    try:
        assert enable_cache() is None
        assert executables.folder() is None
        err = capsys.readouterr().err
        assert err.startswith("warning: the compilation cache folder") and why in err, err
        assert err.count("\n") == 1 and "JAXGRAV_CACHE=off" in err
        assert not jax.config.jax_compilation_cache_dir
    finally:
        executables.use_folder(None)


@NO_SUITE_CACHE
@pytest.mark.long
def test_the_command_runs_with_an_unusable_cache_folder(tmp_path, capsys, monkeypatch):
    """main([...]) with JAXGRAV_CACHE_DIR on a file: one warning line, exit 0, output."""
    _point_at(tmp_path, monkeypatch, "afile")
    out = tmp_path / "t.csv"
    try:
        assert main(["simulate", "--out", str(out), "--n", "5"]) == 0
    finally:
        executables.use_folder(None)
    assert out.is_file()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "it is a file, not a folder" in err, err
