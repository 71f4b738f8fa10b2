"""The tight point-mass filter's reading of missing map nodes: gaps (default) or land."""

import numpy as np
import pytest
import xarray as xr

from jaxgrav import datasets
from jaxgrav.cli import main
from jaxgrav.navigate import TightConfig
from jaxgrav.tracks import read_track_csv, write_track_csv


def test_tight_config_takes_gaps_or_land():
    assert TightConfig(method="pmf").pmf_missing == "gaps"
    assert TightConfig(method="pmf", pmf_missing="land").pmf_missing == "land"
    with pytest.raises(ValueError, match=r"pmf_missing must be one of .*; got 'sea'"):
        TightConfig(method="pmf", pmf_missing="sea")


@pytest.mark.parametrize("method", ["ukf", "dense", "rbpf"])
def test_missing_is_refused_for_the_other_methods(tmp_path, capsys, method):
    out = tmp_path / "n.csv"
    assert main(["navigate", "--track", str(tmp_path / "log.csv"), "--out", str(out),
                 "--method", method, "--missing", "land"]) == 2
    err = capsys.readouterr().err
    assert "--missing land is for --method pmf" in err and method in err, err
    assert not out.exists()


COAST_ROW = 164
"""Node row of the shipped 2.5' map (30.8333° N) north of which every node is land."""
ROWS = 60


@pytest.fixture(scope="module")
def coast(tmp_path_factory):
    """The shipped map with every node north of row :data:`COAST_ROW` missing (a straight
    coast, so the sea is convex), and a 10 min INS log whose truth sails north-east
    towards it at sea while the INS, 3.5 km north of the truth, ends on land.

    By the nearest-node rule a cell is land north of the midpoint between the last sea
    row and the first land row; cells south of it whose interpolation needs a land node
    are gaps."""
    d = tmp_path_factory.mktemp("coast")
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    lat_n, lon_n = np.asarray(grid.lat), np.asarray(grid.lon)
    v = np.array(grid.values)
    v[COAST_ROW + 1:] = np.nan
    xr.Dataset({"anomaly": (("lat", "lon"), v, {"units": "mGal"})},
               coords={"lat": lat_n, "lon": lon_n}).to_netcdf(d / "coast.nc")
    t = 10.0 * np.arange(ROWS)
    truth_lat = lat_n[COAST_ROW] + (-4000.0 + 5.5 * t) / 111.2e3  # 4 km -> 0.8 km south
    lon = 127.5 + 5.0 * t / (111.2e3 * np.cos(np.radians(truth_lat[0])))
    z = (np.asarray(grid.sample(truth_lat, lon, "bicubic"))
         + np.random.default_rng(0).normal(0.0, 1.0, ROWS))
    write_track_csv(d / "log.csv", {"t": t, "lat": truth_lat + 3500.0 / 111.2e3, "lon": lon,
                                    "v_east": np.full(ROWS, 5.0),
                                    "v_north": np.full(ROWS, 5.5), "gravity": z})
    return d, v, lat_n, lon_n, truth_lat


def _on_land(values, lat_n, lon_n, lat, lon):
    """Whether each position's nearest map node is missing (the documented land rule)."""
    i = np.rint((np.asarray(lat) - lat_n[0]) / (lat_n[1] - lat_n[0])).astype(int)
    j = np.rint((np.asarray(lon) - lon_n[0]) / (lon_n[1] - lon_n[0])).astype(int)
    return np.isnan(values[i, j])


@pytest.mark.long  # two compiles of the point-mass filter: 11 s on a loaded 2-core machine
def test_navigate_pmf_missing_land_keeps_the_estimate_off_land(coast, tmp_path, capsys):
    """navigate --method pmf --missing land passes the rule to the filter: the posterior
    has no mass on land cells, so on a straight coast its mean is never on land, where
    with gaps (land cells take the known cells' mean likelihood) it follows the INS onto
    land; keeping the truth's side, land ends closer to the truth."""
    d, values, lat_n, lon_n, truth_lat = coast
    ins = read_track_csv(d / "log.csv", ("t", "lat", "lon"))
    assert _on_land(values, lat_n, lon_n, ins["lat"], ins["lon"]).any()  # the INS goes ashore
    assert not _on_land(values, lat_n, lon_n, truth_lat, ins["lon"]).any()  # the truth not
    nav = {}
    for missing in ("gaps", "land"):
        out = tmp_path / f"{missing}.csv"
        assert main(["navigate", "--map", str(d / "coast.nc"), "--track", str(d / "log.csv"),
                     "--out", str(out), "--method", "pmf", "--missing", missing,
                     "--eotvos-corrected", "--sigma-pos", "3000"]) == 0
        said = capsys.readouterr().out
        assert f"missing map nodes read as {missing};" in said, said
        nav[missing] = read_track_csv(out, ("t", "lat", "lon", "sigma_north", "sigma_east"))
        for k in ("lat", "lon", "sigma_north", "sigma_east"):
            assert np.isfinite(nav[missing][k]).all(), (missing, k)
    land = {m: _on_land(values, lat_n, lon_n, nav[m]["lat"], nav[m]["lon"]) for m in nav}
    assert land["gaps"].sum() >= 5, land["gaps"].sum()
    assert not land["land"].any(), np.flatnonzero(land["land"])
    error = {m: abs(nav[m]["lat"][-1] - truth_lat[-1]) * 111.2e3 for m in nav}
    assert error["land"] < 0.75 * error["gaps"], error


def test_a_bad_missing_value_is_one_error_line(tmp_path, capsys):
    """--missing sea: exit 2, one error line naming the option, the value and the
    choices, nothing written; the same in filter and navigate."""
    out = tmp_path / "n.csv"
    for cmd in (["navigate"], ["filter", "--map", "ryukyu"]):
        with pytest.raises(SystemExit) as exc:
            main([*cmd, "--track", str(tmp_path / "log.csv"), "--out", str(out),
                  "--method", "pmf", "--missing", "sea"])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"jaxgrav {cmd[0]}: error: argument --missing: invalid choice: "
                       f"'sea' (choose from 'gaps', 'land') (see jaxgrav {cmd[0]} --help)"], err
        assert not out.exists()


@pytest.mark.parametrize("method", ["ukf", "ekf", "rbpf"])
@pytest.mark.parametrize("value", ["gaps", "land"])
def test_missing_with_another_method_is_refused_alike_by_filter_and_navigate(
        tmp_path, capsys, method, value):
    """--missing is the point-mass filter's only: filter and navigate refuse it with any
    other method in the same one line (neither ignores it), before anything runs."""
    t = 10.0 * np.arange(3)
    write_track_csv(tmp_path / "log.csv", {
        "t": t, "lat": np.full(3, 30.8), "lon": 127.5 + 5.0 * t / 95.5e3,
        "v_east": np.full(3, 5.0), "v_north": np.zeros(3), "gravity": np.zeros(3)})
    out = tmp_path / "n.csv"
    lines = []
    for cmd in (["navigate"], ["filter", "--map", "ryukyu"]):
        assert main([*cmd, "--track", str(tmp_path / "log.csv"), "--out", str(out),
                     "--method", method, "--missing", value]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and not out.exists(), err
        lines.append(err.split(": error: ", 1)[1])
    assert lines[0] == lines[1] == f"--missing {value} is for --method pmf; got --method {method}"
