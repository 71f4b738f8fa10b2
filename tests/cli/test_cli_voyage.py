"""``jaxgrav simulate-voyage``: the log and truth it writes, and its bad-input errors."""

import numpy as np
import pytest
import xarray as xr

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
    (["--preset", "loop"], "argument --preset: invalid choice: 'loop' (choose from "
                           "'patrol-12h', 'transit-24h')"),
    (["--hours", "0"], "--hours must be a positive length"),
    (["--hours", "nan"], "--hours must be a positive length"),
    (["--map-error", "-1"], "--map-error must be a finite standard deviation"),
])
def test_simulate_voyage_bad_input(tmp_path, capsys, args, message):
    out = tmp_path / "log.csv"
    try:
        code = main(["simulate-voyage", "--out", str(out), *args])
    except SystemExit as exit_:  # argparse's choices
        code = exit_.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and "\n" not in err.strip() and not out.exists()


@pytest.mark.long
def test_simulate_voyage_on_a_regional_map(tmp_path, capsys):
    """A user's map smaller than the preset's region (25-35 N, 125-135 E) was refused ("must
    cover the scenario's region"), though montecarlo --method voyage-* ran on it; now the
    voyage keeps to the map's own region and says so. A route that leaves the map (a 24 h
    transit on a 2-degree map) was reported as missing (NaN) map values; now as leaving."""
    g = load_map("ryukyu", None)
    lat, lon = np.asarray(g.lat), np.asarray(g.lon)
    m, n = (lat > 29) & (lat < 31), (lon > 129) & (lon < 131)
    path = tmp_path / "small.nc"
    xr.Dataset({"z": (("lat", "lon"), np.asarray(g.values)[m][:, n], {"units": "mGal"})},
               coords={"lat": lat[m], "lon": lon[n]}).to_netcdf(path)
    out = tmp_path / "v.csv"
    assert main(["simulate-voyage", "--map", str(path), "--out", str(out), "--hours",
                 "0.5"]) == 0
    assert "patrol-12h on the map's own region (lat 29.04..30.96, lon 129..131)" in \
        capsys.readouterr().out
    log = read_track_csv(out, required=("lat", "lon", "gravity"))
    assert np.all(np.asarray(g.contains(log["lat"], log["lon"]))) and np.isfinite(
        log["gravity"]).all()
    out2 = tmp_path / "t.csv"
    assert main(["simulate-voyage", "--map", str(path), "--out", str(out2), "--preset",
                 "transit-24h"]) == 2
    err = capsys.readouterr().err.strip()
    assert "the transit-24h route leaves --map" in err and "give a shorter --hours" in err, err
    assert "\n" not in err and not out2.exists()
