"""Outputs all-or-nothing and with the user's permissions; numeric options range-checked
before anything runs; exit codes (2 bad input, 1 run-time failure) and ``--version``."""

import os
import stat

import pytest

from jaxgrav._io import atomic_output, check_outputs
from jaxgrav.cli import main
from jaxgrav.fields import egm2008


def test_simulate_refuses_before_writing_any_output(tmp_path, capsys):
    out, truth = tmp_path / "track.csv", tmp_path / "truth.csv"
    truth.write_text("keep me\n")
    assert main(["simulate", "--out", str(out), "--truth", str(truth), "--n", "5"]) == 2
    err = capsys.readouterr().err
    assert "--truth" in err and "exists" in err and "nothing was written" in err
    assert not out.exists(), "the first output must not be written when the second is refused"
    assert truth.read_text() == "keep me\n"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "no temp file left"


def test_simulate_same_file_twice(tmp_path, capsys):
    out = tmp_path / "a.csv"
    assert main(["simulate", "--out", str(out), "--truth", str(out), "--n", "5"]) == 2
    assert "same file" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("args, match", [
    (["--dt", "-5"], "--dt must be a positive interval"),
    (["--dt", "nan"], "--dt must be"),
    (["--drift", "-0.01"], "--drift must be a positive INS drift"),
    (["--drift", "20"], "--drift must be a positive INS drift of at most 5"),
    (["--probability", "1.5"], "--probability must be a probability strictly between 0 and 1"),
    (["--probability", "0"], "--probability"),
    (["--noise", "-1"], "--noise must be a reading noise >= 0"),
    (["--bias", "inf"], "--bias must be a finite"),
    (["--v-east", "0", "--v-north", "0"], "must move"),
    (["--v-east", "500"], "--v-east must be a speed within"),
    (["--n", "1"], "--n must be at least 5"),
])
def test_simulate_numeric_options_checked(tmp_path, capsys, args, match):
    out = tmp_path / "t.csv"
    assert main(["simulate", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert match in err and err.count("\n") == 0, err
    assert not out.exists()


def test_outputs_get_the_users_permissions(tmp_path):
    old = os.umask(0o027)
    try:
        with atomic_output(tmp_path / "x.txt") as tmp:
            tmp.write_text("x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "x.txt").stat().st_mode) == 0o640


def test_simulated_track_is_readable_by_others_under_umask_022(tmp_path):
    old = os.umask(0o022)
    try:
        assert main(["simulate", "--out", str(tmp_path / "t.csv"), "--n", "5"]) == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "t.csv").stat().st_mode) == 0o644


def test_check_outputs(tmp_path):
    (tmp_path / "a").write_text("")
    check_outputs([tmp_path / "a", None, tmp_path / "b"], force=True)
    with pytest.raises(FileExistsError, match=r"--x .*exists"):
        check_outputs([tmp_path / "b", tmp_path / "a"], names=["--y", "--x"])
    with pytest.raises(ValueError, match="is a folder"):
        check_outputs([tmp_path], names=["--out"])


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.startswith("jaxgrav ")


def test_runtime_failure_is_one_line_exit_1(monkeypatch, tmp_path, capsys):
    def boom(*args, **kwargs):
        raise RuntimeError("disk on fire")
    monkeypatch.setattr(egm2008, "build", boom)
    assert main(["data", "egm2008", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err.strip().count("\n") == 0 and "RuntimeError: disk on fire" in err
    assert "--debug" in err
    assert main(["--debug", "data", "egm2008", "--out", str(tmp_path)]) == 1
    assert "Traceback" in capsys.readouterr().err
