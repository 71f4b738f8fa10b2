"""``jaxgrav simulate-voyage``: the log and truth it writes, and its bad-input errors."""

import numpy as np
import pytest

from jaxgrav.cli import main
from jaxgrav.datasets import load_map
from jaxgrav.geodesy import eotvos, local_offsets_m
from jaxgrav.tracks import read_track_csv


@pytest.mark.long
def test_simulate_voyage_writes_a_raw_log_and_its_truth(tmp_path, capsys):
    log, truth = tmp_path / "log.csv", tmp_path / "truth.csv"
    assert main(["simulate-voyage", "--out", str(log), "--truth", str(truth),
                 "--hours", "1", "--seed", "2"]) == 0
    assert "patrol-12h, 1 h, 361 rows every 10 s" in capsys.readouterr().out
    ins = read_track_csv(log, ("t", "lat", "lon", "v_east", "v_north", "gravity"))
    tru = read_track_csv(truth, ("t", "lat", "lon", "v_east", "v_north", "d_north", "d_east"))
    assert len(ins["t"]) == 361 and np.all(np.diff(ins["t"]) == 10.0)
    d_n, d_e = local_offsets_m(ins["lat"], ins["lon"], tru["lat"], tru["lon"])
    np.testing.assert_allclose(d_n, tru["d_north"], atol=1.0)
    np.testing.assert_allclose(d_e, tru["d_east"], atol=1.0)
    # raw readings: the map at the truth minus the true Eotvos, plus noise and a bias
    grid = load_map("ryukyu", None)
    resid = (np.asarray(ins["gravity"]) - np.asarray(grid.sample(tru["lat"], tru["lon"], "bicubic"))
             + np.asarray(eotvos(tru["lat"], tru["v_east"], tru["v_north"])))
    assert np.std(resid) == pytest.approx(1.0, rel=0.15) and abs(np.mean(resid)) < 5.0
    assert main(["simulate-voyage", "--out", str(log), "--hours", "1"]) == 2  # exists
    assert "pass --force" in capsys.readouterr().err


@pytest.mark.parametrize(("args", "message"), [
    (["--preset", "loop"], "--preset 'loop': preset must be one of"),
    (["--hours", "0"], "--hours must be a positive length"),
    (["--hours", "nan"], "--hours must be a positive length"),
    (["--map-error", "-1"], "--map-error must be a finite standard deviation"),
])
def test_simulate_voyage_bad_input(tmp_path, capsys, args, message):
    out = tmp_path / "log.csv"
    assert main(["simulate-voyage", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "\n" not in err.strip() and not out.exists()
