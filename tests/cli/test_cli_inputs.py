"""The commands read the files users have: aliased and ``--columns``-mapped headers,
semicolon files with ISO times and text columns, maps with missing nodes away from the
track (``jaxgrav.cli.inputs``)."""

import json

import numpy as np
import pytest
import xarray as xr

from jaxgrav import datasets
from jaxgrav.cli import main
from jaxgrav.tracks import read_track_csv


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    assert main(["simulate", "--out", str(d / "t.csv"), "--truth", str(d / "truth.csv"),
                 "--n", "20", "--seed", "5"]) == 0
    return d, read_track_csv(d / "t.csv", required=("t", "lat", "lon", "gravity"))


def _user_log(path, track):
    """The simulated track as a user's log: semicolons, ISO times, other header names,
    a text column and the gravity as FAA (free-air anomaly)."""
    rows = ["Time;Latitude;Longitude;ship;FAA;v_east;v_north"]
    for i in range(track["t"].size):
        s = int(track["t"][i])
        rows.append(f"2024-05-01T{s // 3600:02d}:{s // 60 % 60:02d}:{s % 60:02d}Z;"
                    f"{track['lat'][i]:.9f};{track['lon'][i]:.9f};Hakuho Maru;"
                    f"{track['gravity'][i]:.6f};{track['v_east'][i]:.6f};"
                    f"{track['v_north'][i]:.6f}")
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.long
def test_match_reads_a_user_log_with_columns(sim, tmp_path):
    d, track = sim
    _user_log(tmp_path / "log.csv", track)
    ref, out = tmp_path / "ref.json", tmp_path / "r.json"
    assert main(["match", "--map", "ryukyu", "--track", str(d / "t.csv"),
                 "--out", str(ref)]) == 0
    # FAA is read as the gravity (an alias since the ninth hunt), or named by --columns
    assert main(["match", "--map", "ryukyu", "--track", str(tmp_path / "log.csv"),
                 "--out", str(tmp_path / "alias.json")]) == 0
    assert main(["match", "--map", "ryukyu", "--track", str(tmp_path / "log.csv"),
                 "--columns", "gravity=FAA", "--out", str(out)]) == 0
    assert json.loads((tmp_path / "alias.json").read_text())["lat"] == json.loads(
        out.read_text())["lat"]
    a, b = json.loads(ref.read_text()), json.loads(out.read_text())
    np.testing.assert_allclose(b["lat"], a["lat"], atol=1e-7)
    np.testing.assert_allclose(b["lon"], a["lon"], atol=1e-7)
    assert b["eotvos_applied_here"] is True


def test_columns_option_errors_are_one_line(sim, tmp_path, capsys):
    d, _ = sim
    for columns, message in (("gravity", "NAME=COLUMN pairs"),
                             ("gravity=NOPE", "has no column 'NOPE'")):
        assert main(["match", "--map", "ryukyu", "--track", str(d / "t.csv"),
                     "--columns", columns, "--out", str(tmp_path / "r.json")]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and "\n" not in err and "Traceback" not in err


def _holey_map(path, hole):
    """The shipped map with a block of NaN nodes (a land mask) at ``hole``."""
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    v = np.array(grid.values)
    v[hole] = np.nan
    xr.Dataset({"anomaly": (("lat", "lon"), v, {"units": "mGal"})},
               coords={"lat": np.asarray(grid.lat), "lon": np.asarray(grid.lon)}).to_netcdf(path)


@pytest.mark.long
def test_sample_and_match_use_a_map_with_missing_nodes_away_from_the_track(sim, tmp_path,
                                                                           capsys):
    d, track = sim
    _holey_map(tmp_path / "far.nc", (slice(0, 40), slice(0, 40)))  # far SW corner
    out = tmp_path / "s.csv"
    assert main(["sample", "--map", str(tmp_path / "far.nc"), "--track", str(d / "t.csv"),
                 "--out", str(out)]) == 0
    sampled = read_track_csv(out, required=("lat", "map"))
    full = datasets.load("ryukyu")["anomaly_2p5min"]
    np.testing.assert_allclose(sampled["map"],
                               np.asarray(full.sample(track["lat"], track["lon"], "bicubic")),
                               atol=1e-4)  # a cut map's bicubic: ~5e-5 mGal
    assert main(["match", "--map", str(tmp_path / "far.nc"), "--track", str(d / "t.csv"),
                 "--out", str(tmp_path / "r.json")]) == 0
    # a hole under the track is a mask: sample leaves those cells empty and says so,
    # match masks the candidates touching it and sets status bit 8192
    grid = full
    i = int(np.searchsorted(np.asarray(grid.lat), track["lat"][10]))
    j = int(np.searchsorted(np.asarray(grid.lon), track["lon"][10]))
    _holey_map(tmp_path / "near.nc", (slice(i - 1, i + 1), slice(j - 1, j + 1)))
    capsys.readouterr()
    assert main(["sample", "--map", str(tmp_path / "near.nc"), "--track", str(d / "t.csv"),
                 "--out", str(tmp_path / "s2.csv")]) == 0
    assert "missing (NaN) node" in capsys.readouterr().err
    holed = read_track_csv(tmp_path / "s2.csv", required=("lat",), allow_nan=("map",))["map"]
    assert 0 < np.isnan(holed).sum() < len(holed)
    np.testing.assert_allclose(holed[~np.isnan(holed)], sampled["map"][~np.isnan(holed)],
                               atol=0.5)  # next to the hole, the fill's small effect
    assert main(["match", "--map", str(tmp_path / "near.nc"), "--track", str(d / "t.csv"),
                 "--out", str(tmp_path / "r2.json")]) == 0
    r = json.loads((tmp_path / "r2.json").read_text())
    assert r["status"] & 8192 and any("missing (NaN)" in m for m in r["status_messages"])
    assert np.isfinite(r["lat"]).all() and r["missing"] == "auto"
    # the hole is under the simulated INS track: the default read it as a survey gap
    assert r["missing_read_as"] == "gaps"
    # the same hole read as land: candidates touching it dropped
    assert main(["match", "--map", str(tmp_path / "near.nc"), "--track", str(d / "t.csv"),
                 "--out", str(tmp_path / "r2g.json"), "--missing", "land"]) == 0
    r = json.loads((tmp_path / "r2g.json").read_text())
    assert r["status"] & 8192 and r["missing_read_as"] == "land" and np.isfinite(r["lat"]).all()
    # a region that is almost all hole is refused in one line naming the file
    _holey_map(tmp_path / "sea.nc", (slice(i - 30, i + 30), slice(j - 30, j + 30)))
    capsys.readouterr()
    assert main(["match", "--map", str(tmp_path / "sea.nc"), "--track", str(d / "t.csv"),
                 "--out", str(tmp_path / "r3.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "sea.nc" in err and "too little map" in err and "\n" not in err
    assert not (tmp_path / "r3.json").exists()


def test_missing_gaps_is_refused_for_methods_other_than_dense(sim, tmp_path, capsys):
    d, _ = sim
    out = tmp_path / "r.json"
    assert main(["match", "--map", "ryukyu", "--track", str(d / "t.csv"), "--out", str(out),
                 "--method", "chains", "--refine", "2", "--missing", "gaps"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--missing gaps" in err and "--method dense only" in err and "\n" not in err
    assert not out.exists()


def test_sample_passes_text_columns_through(sim, tmp_path):
    _, track = sim
    _user_log(tmp_path / "log.csv", track)
    out = tmp_path / "s.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(tmp_path / "log.csv"),
                 "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert "ship" in lines[0] and "Hakuho Maru" in lines[1] and "map" in lines[0]


def _map_with_uncertainty(path, sigma):
    """The shipped map with an uncertainty variable ``err`` (mGal) on its grid: ``sigma``
    everywhere but 4 x ``sigma`` in the south-west quarter (far from the tracks)."""
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    err = np.full(np.shape(grid.values), sigma)
    err[:100, :100] = 4 * sigma
    xr.Dataset({"anomaly": (("lat", "lon"), np.asarray(grid.values), {"units": "mGal"}),
                "err": (("lat", "lon"), err, {"units": "mGal"})},
               coords={"lat": np.asarray(grid.lat), "lon": np.asarray(grid.lon)}).to_netcdf(path)


@pytest.mark.long  # 4-8 s: the fast tier is at its 5-minute budget
def test_map_error_var_tells_the_method_the_maps_own_uncertainty(sim, tmp_path, capsys):
    d, _ = sim
    _map_with_uncertainty(tmp_path / "u.nc", 2.5)
    base = ["match", "--track", str(d / "t.csv")]
    assert main([*base, "--map", str(tmp_path / "u.nc"), "--var", "anomaly",
                 "--map-error-var", "err", "--out", str(tmp_path / "a.json")]) == 0
    assert main([*base, "--map", str(tmp_path / "u.nc"), "--var", "anomaly",
                 "--map-error", "2.5", "--out", str(tmp_path / "b.json")]) == 0
    a, b = (json.loads((tmp_path / f).read_text()) for f in ("a.json", "b.json"))
    assert a["map_error_mgal"] == pytest.approx(2.5) and a["map_error_var"] == "err"
    for k in ("lat", "lon", "covariance_m2", "score"):  # the same as --map-error 2.5
        np.testing.assert_allclose(a[k], b[k], rtol=1e-9)
    capsys.readouterr()
    for extra, message in (
            (["--map", str(tmp_path / "u.nc"), "--var", "anomaly", "--map-error-var", "err",
              "--map-error", "1"], "not both"),
            (["--map", "ryukyu", "--map-error-var", "err"], "no uncertainty variable"),
            (["--map", str(tmp_path / "u.nc"), "--var", "anomaly", "--map-error-var", "nope"],
             "nope"),
            (["--map", str(tmp_path / "u.nc"), "--var", "anomaly", "--map-error-var", "err",
              "--method", "entropy"], "--map-error-var is used by")):
        assert main([*base, *extra, "--out", str(tmp_path / "c.json")]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and "\n" not in err and not (tmp_path / "c.json").exists()
