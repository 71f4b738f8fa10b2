"""Inputs found by the issue-19 hunt of 2026-12-06: an output whose folder cannot be made
(a file on its path) refused before anything is written."""

import pytest

from jaxgrav.cli import main


def _refused(capsys, argv, message):
    """``argv`` exits 2 with one stderr line holding ``message``."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err, err
    assert "\n" not in err and "Traceback" not in err, err


@pytest.mark.parametrize("which", ["--out", "--truth"])
def test_an_output_under_a_file_is_refused_before_anything_is_written(tmp_path, capsys, which):
    """``simulate --out new.csv --truth TRACK.csv/t.csv`` wrote new.csv, then failed on the
    truth with "[Errno 17] File exists: 'TRACK.csv'" (exit 2, one of two files left)."""
    blocker = tmp_path / "track.csv"
    blocker.write_text("t,lat,lon\n")
    out, truth = tmp_path / "new.csv", tmp_path / "truth.csv"
    paths = {"--out": out, "--truth": truth, which: blocker / "x.csv"}
    _refused(capsys, ["simulate", "--out", paths["--out"], "--truth", paths["--truth"]],
             f"{which} '{blocker / 'x.csv'}': '{blocker}' is a file, not a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["track.csv"]


def test_an_output_in_a_new_folder_is_written(tmp_path):
    """A missing folder on the output's path is made (not refused)."""
    out = tmp_path / "new" / "deeper" / "t.csv"
    assert main(["simulate", "--out", str(out), "--n", "5"]) == 0
    assert out.read_text().startswith("t,")
