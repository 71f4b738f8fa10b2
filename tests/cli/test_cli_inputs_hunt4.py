"""Inputs found by the fourth issue-19 hunt (2026-12-07, helper-56): a simulated map error
beyond any real map's refused by the four simulators."""

import pytest

from jaxgrav.cli import main


def _refused(capsys, argv, message):
    """``argv`` exits 2 with one stderr line holding ``message``."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err, err
    assert "\n" not in err and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("argv", [
    ["simulate", "--out", "{d}/s.csv"],
    ["simulate-filter", "--map", "ryukyu", "--out", "{d}/s.csv"],
    ["simulate-voyage", "--out", "{d}/s.csv", "--hours", "0.1"],
    ["montecarlo", "--method", "dense", "--runs", "5", "--out", "{d}/m.nc"],
])
def test_a_simulated_map_error_beyond_any_map_s_is_refused(tmp_path, capsys, argv):
    """``--map-error 1e9``: readings off by 1e9 mGal were written (exit 0; montecarlo ran
    every fix rejected), readings every command then refuses; as --noise is capped."""
    _refused(capsys, [a.format(d=tmp_path) for a in argv] + ["--map-error", "1e9"],
             "--map-error must be at most 1000 (map units; a marine gravity map's error is a "
             "few mGal, a magnetic map's tens of nT); got 1e+09")
    assert list(tmp_path.iterdir()) == []
