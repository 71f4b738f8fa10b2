"""Inputs kept: no output of simulate, simulate-filter, simulate-voyage, suitability, dov or
bench replaces one of the command's inputs, --force or not; --seed outside 0 .. 2**63 - 1
refused naming --seed; dov's early output check and its out-of-grid point named by line;
simulate on a global map (reaching the poles)."""

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import jaxgrav.datasets
from jaxgrav.cli import main
from jaxgrav.tracks import read_track_csv

RYUKYU = Path(jaxgrav.datasets.__file__).parent / "ryukyu_anomaly_2p5min.nc"


def _refused(capsys, argv, message, *, kept=(), absent=()):
    """``argv`` exits 2 with one stderr line holding ``message``; every file of ``kept``
    is byte-identical afterwards and none of ``absent`` exists."""
    before = {p: p.read_bytes() for p in kept}
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err, err
    assert "\n" not in err and "Traceback" not in err and "=True" not in err, err
    for p, data in before.items():
        assert p.read_bytes() == data, p
    for p in absent:
        assert not p.exists(), p


@pytest.fixture
def files(tmp_path):
    """A copy of the shipped map (also as p.png), a DOV track and a script folder."""
    m = tmp_path / "m.nc"
    m.write_bytes(RYUKYU.read_bytes())
    (tmp_path / "p.png").write_bytes(RYUKYU.read_bytes())
    (tmp_path / "d.csv").write_text("lat,lon,h\n34.0,108.5,1000\n35.0,109.0,2000\n")
    (tmp_path / "g.nc").write_bytes(b"not read: refused before\n")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "x.py").write_text("print('bench')\n")
    return tmp_path


# argv (names relative to the fixture's folder), the input kept, the expected message
SAME_FILE = [
    (["simulate", "--map", "m.nc", "--out", "m.nc"], "m.nc", "--out '{d}/m.nc' and the input "
     "--map '{d}/m.nc' are the same file"),
    (["simulate", "--map", "m.nc", "--out", "o.csv", "--truth", "m.nc"], "m.nc",
     "--truth '{d}/m.nc' and the input --map"),
    (["simulate", "--map", "ryukyu", "--truth-map", "m.nc", "--out", "m.nc"], "m.nc",
     "--out '{d}/m.nc' and the input --truth-map"),
    (["simulate-filter", "--map", "m.nc", "--out", "o.csv", "--truth", "m.nc"], "m.nc",
     "--truth '{d}/m.nc' and the input --map"),
    (["simulate-filter", "--map", "m.nc", "--out", "m.nc"], "m.nc",
     "--out '{d}/m.nc' and the input --map"),
    (["simulate-voyage", "--map", "m.nc", "--out", "m.nc"], "m.nc",
     "--out '{d}/m.nc' and the input --map"),
    (["simulate-voyage", "--map", "m.nc", "--out", "o.csv", "--truth", "m.nc"], "m.nc",
     "--truth '{d}/m.nc' and the input --map"),
    (["simulate-voyage", "--map", "ryukyu", "--truth-map", "m.nc", "--out", "o.csv",
      "--truth", "m.nc"], "m.nc", "--truth '{d}/m.nc' and the input --truth-map"),
    (["suitability", "--map", "m.nc", "--out", "m.nc"], "m.nc",
     "--out '{d}/m.nc' and the input --map"),
    (["suitability", "--map", "p.png", "--out", "p.nc"], "p.png",
     "its PNG '{d}/p.png' and the input --map '{d}/p.png'"),
    (["dov", "--track", "d.csv", "--out", "d.csv"], "d.csv",
     "--out '{d}/d.csv' and the input --track"),
    (["dov", "--track", "d.csv", "--out", "g.nc", "--grid", "g.nc"], "g.nc",
     "--out '{d}/g.nc' and the input --grid"),
    (["bench", "--dir", "b", "--out", "b/x.py"], "b/x.py",
     "--out '{d}/b/x.py' and the input script x.py of --dir"),
]


@pytest.mark.parametrize("force", [[], ["--force"]], ids=["plain", "force"])
@pytest.mark.parametrize("argv, kept, message", SAME_FILE,
                         ids=[f"{a[0]}-{i}" for i, (a, _, _) in enumerate(SAME_FILE)])
def test_an_output_never_replaces_an_input(files, capsys, argv, kept, message, force):
    paths = [a if a.startswith("--") or a in ("ryukyu",) or i == 0 else str(files / a)
             for i, a in enumerate(argv)]
    _refused(capsys, [*paths, *force], message.format(d=files), kept=[files / kept],
             absent=[files / "o.csv", files / "p.nc"])


SEEDED = [
    ["simulate", "--out", "{o}"],
    ["simulate-filter", "--out", "{o}", "--minutes", "5", "--dt", "10"],
    ["simulate-voyage", "--out", "{o}", "--hours", "1"],
    ["montecarlo", "--method", "dense", "--runs", "2", "--out", "{o}"],
]


@pytest.mark.parametrize("seed", [2**63, 2**64, -1])
@pytest.mark.parametrize("argv", SEEDED, ids=[a[0] for a in SEEDED])
def test_seed_out_of_range(tmp_path, capsys, argv, seed):
    out = tmp_path / "o.csv"
    _refused(capsys, [a.format(o=out) for a in argv] + ["--seed", str(seed)],
             f"--seed must be an integer from 0 to {2**63 - 1} (2**63 - 1); got {seed}",
             absent=[out, out.with_suffix(".png")])


def test_largest_seed_runs(tmp_path):
    out = tmp_path / "o.csv"
    assert main(["simulate", "--out", str(out), "--n", "5", "--seed", str(2**63 - 1)]) == 0
    assert np.isfinite(read_track_csv(out, required=("gravity",))["gravity"]).all()


def test_dov_existing_out_refused_before_reading(files, capsys):
    out = files / "o.csv"
    out.write_text("keep me\n")
    _refused(capsys, ["dov", "--track", files / "missing.csv", "--out", out],
             f"--out '{out}' exists; pass --force to overwrite it", kept=[out])


def test_dov_point_outside_names_track_and_line(files, capsys):
    track = files / "far.csv"
    track.write_text("lat,lon,h\n34.0,108.5,1000\n# a comment\n35.0,110.0,-500\n")
    _refused(capsys, ["dov", "--track", track, "--out", files / "o.csv"],
             f"--track '{track}', line 4: point (lat=35.0, lon=110.0, h=-500.0 m) is outside "
             "the layered grid of the shipped qinling layers", absent=[files / "o.csv"])


def test_dov_inside_still_writes(files):
    assert main(["dov", "--track", str(files / "d.csv"), "--out", str(files / "o.csv")]) == 0
    assert {"xi", "eta"} <= set(read_track_csv(files / "o.csv", required=("xi", "eta")))


def test_simulate_on_a_global_map(tmp_path):
    lat, lon = np.arange(-90.0, 91.0), np.arange(0.0, 360.0)
    values = 50 * np.sin(np.radians(lat))[:, None] + 30 * np.cos(np.radians(3 * lon))[None, :]
    xr.Dataset({"gravity": (("lat", "lon"), values)},
               coords={"lat": lat, "lon": lon}).to_netcdf(tmp_path / "g.nc")
    for seed in range(3):
        out = tmp_path / f"t{seed}.csv"
        assert main(["simulate", "--map", str(tmp_path / "g.nc"), "--out", str(out),
                     "--seed", str(seed)]) == 0
        track = read_track_csv(out, required=("lat", "lon", "gravity"))
        assert np.isfinite(track["gravity"]).all()
        assert (np.abs(track["lat"]) < 89.5).all()
        assert ((track["lon"] >= 0) & (track["lon"] <= 359)).all()
