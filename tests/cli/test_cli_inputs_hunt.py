"""Inputs found by the issue-19 hunt of 2026-12-06: an output whose folder cannot be made
(a file on its path) refused before anything is written; a map whose gaps hold an
undeclared -9999 read as missing nodes by sample and match; readings Eötvös-corrected
twice named by match; ISO times kept by match (JSON) and navigate (CSV, with the text
columns)."""

import json
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr

from jaxgrav.cli import main
from jaxgrav.cli.inputs import check_map_field
from jaxgrav.datasets import load_map
from jaxgrav.geodesy import eotvos
from jaxgrav.grid_files import UndeclaredFillWarning


@pytest.mark.parametrize("which", ["--out", "--truth"])
def test_an_output_under_a_file_is_refused_before_anything_is_written(tmp_path, refused, which):
    """``simulate --out new.csv --truth TRACK.csv/t.csv`` wrote new.csv, then failed on the
    truth with "[Errno 17] File exists: 'TRACK.csv'" (exit 2, one of two files left)."""
    blocker = tmp_path / "track.csv"
    blocker.write_text("t,lat,lon\n")
    out, truth = tmp_path / "new.csv", tmp_path / "truth.csv"
    paths = {"--out": out, "--truth": truth, which: blocker / "x.csv"}
    refused(["simulate", "--out", paths["--out"], "--truth", paths["--truth"]],
            f"{which} '{blocker / 'x.csv'}': '{blocker}' is a file, not a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["track.csv"]


def test_an_output_in_a_folder_that_is_not_writable_is_refused(tmp_path, refused, monkeypatch):
    """A folder the user may not write: refused before any work, naming the option and the
    folder. The permission is denied through os.access (these machines run the tests as
    root, for whom a 0o555 folder is writable)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if Path(p) == ro else real(p, mode))
    out = ro / "sub" / "t.csv"
    refused(["simulate", "--out", str(out), "--n", "5"],
            f"--out '{out}': the folder '{ro}' is not writable")
    assert list(ro.iterdir()) == []


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_a_folder_that_refuses_files_is_refused_before_the_first_output(tmp_path, refused):
    """Issue 19: os.access lets root (and /proc) pass: simulate wrote --out, then failed on
    --truth with "[Errno 2] No such file or directory: '/proc/nope'"."""
    out = tmp_path / "t.csv"
    refused(["simulate", "--out", out, "--truth", "/proc/nope/truth.csv", "--n", "5"],
            "--truth '/proc/nope/truth.csv': a file cannot be created in the folder '/proc' (")
    assert list(tmp_path.iterdir()) == []


def test_an_output_in_a_new_folder_is_written(tmp_path):
    """A missing folder on the output's path is made (not refused)."""
    out = tmp_path / "new" / "deeper" / "t.csv"
    assert main(["simulate", "--out", str(out), "--n", "5"]) == 0
    assert out.read_text().startswith("t,")


@pytest.mark.long  # 4-8 s: the fast tier is at its 5-minute budget
def test_undeclared_fill_values_in_a_map_are_not_sampled_or_matched(tmp_path, capsys):
    """A 3 x 3 block of -9999 (no _FillValue attribute) on the track: sample wrote values
    down to -5194 mGal beside it (exit 0, no warning) and match refused the readings as
    in other units ("a factor 0.00044"); now the block is a missing region: sample leaves
    those cells empty (warned) and match masks it (exit 0, status bit 8192)."""
    g = load_map("ryukyu")
    lat, lon = np.asarray(g.lat), np.asarray(g.lon)
    values = np.asarray(g.values).copy()
    i, j = np.searchsorted(lat, 30.3), np.searchsorted(lon, 130.5)
    values[i:i + 3, j:j + 3] = -9999.0
    path = tmp_path / "m.nc"
    xr.Dataset({"z": (("lat", "lon"), values, {"units": "mGal"})},
               coords={"lat": lat, "lon": lon}).to_netcdf(path)
    t = np.arange(30) * 120.0
    tlat, tlon = 30.2 + t * 4e-5, 130.4 + t * 4.5e-5
    truth = np.asarray(g.sample(tlat, tlon, "bicubic"))
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon,gravity\n" + "".join(
        f"{a:g},{b:.6f},{c:.6f},{d:.4f}\n" for a, b, c, d in zip(t, tlat, tlon, truth,
                                                                 strict=True)))
    out = tmp_path / "s.csv"
    with pytest.warns(UndeclaredFillWarning, match="9 node"):
        assert main(["sample", "--map", str(path), "--track", str(track), "--out",
                     str(out)]) == 0
    sampled = np.genfromtxt(out, delimiter=",", names=True)["map"]
    assert np.isnan(sampled).any()
    assert np.nanmin(sampled) > -300.0, np.nanmin(sampled)
    assert "left empty" in capsys.readouterr().err
    res = tmp_path / "m.json"
    with pytest.warns(UndeclaredFillWarning):
        assert main(["match", "--map", str(path), "--track", str(track), "--out",
                     str(res)]) == 0
    assert json.loads(res.read_text())["status"] & 8192


def test_sample_takes_a_magnetic_map_and_names_the_file_s_own_lines(tmp_path, capsys, refused):
    """Issue 19: sample refused any map in nT ("is a magnetic map (units 'nT') and the
    readings are gravity"), even for a track with no readings; and its warning of a point
    beside a missing node named the row + 2, not the file's line (a comment line above)."""
    lat, lon = np.linspace(30.0, 30.9, 10), np.linspace(130.0, 130.9, 10)
    values = np.add.outer(lat, lon) * 100.0
    values[5, 5] = np.nan
    path = tmp_path / "mag.nc"
    xr.Dataset({"f": (("lat", "lon"), values, {"units": "uT"})},
               coords={"lat": lat, "lon": lon}).to_netcdf(path)
    track = tmp_path / "t.csv"
    track.write_text("# ship log\nlat,lon\n30.12,130.12\n30.52,130.52\n")
    out = tmp_path / "s.csv"
    assert main(["sample", "--map", str(path), "--track", str(track), "--out", str(out)]) == 0
    assert "(first on line 4)" in capsys.readouterr().err
    sampled = np.genfromtxt(out, delimiter=",", names=True)["map"]
    assert sampled[0] == pytest.approx(16.024e6) and np.isnan(sampled[1])  # uT -> nT
    # a point off the map: "point (lat=31.5, lon=130.5) is outside the grid", no file or line
    track.write_text("# ship log\nlat,lon\n30.12,130.12\n31.5,130.5\n")
    refused(["sample", "--map", path, "--track", track, "--out", tmp_path / "o.csv"],
            f"--track {str(track)!r}: 1 of 2 positions are off the map --map {path} (lat "
            "30..30.9, lon 130..130.9), first on line 4 (lat 31.5, lon 130.5)")


def test_a_map_too_small_for_bicubic_is_named(tmp_path, refused):
    """Issue 19: a 3 x 3 map ended in "bicubic interpolation needs at least 4 nodes per
    axis; got 3" (no option, no file); sample's bilinear still takes it."""
    lat, lon = np.array([30.0, 30.1, 30.2]), np.array([130.0, 130.1, 130.2])
    path = tmp_path / "m.nc"
    xr.Dataset({"g": (("lat", "lon"), np.arange(9.0).reshape(3, 3), {"units": "mGal"})},
               coords={"lat": lat, "lon": lon}).to_netcdf(path)
    track = tmp_path / "t.csv"
    track.write_text("lat,lon\n30.05,130.05\n30.15,130.12\n")
    out = tmp_path / "s.csv"
    refused(["sample", "--map", path, "--track", track, "--out", out],
            f"--map {str(path)!r} has 3 x 3 nodes (lat x lon) where the track needs it; "
            "bicubic interpolation needs at least 4 along each axis: give a larger map")
    assert not out.exists()
    assert main(["sample", "--map", str(path), "--track", str(track), "--out", str(out),
                 "--method", "bilinear"]) == 0
    assert np.genfromtxt(out, delimiter=",", names=True)["map"][0] == pytest.approx(2.0)


@pytest.mark.parametrize(("units", "field", "warned"), [
    ("m", "gravity", "declares units 'm', not a gravity unit (mGal, Gal, uGal, m s-2, gu): "
                     "its values are read as mGal"),
    ("arcsec", "magnetic", "declares units 'arcsec', not a magnetic unit (nT, uT, T): its "
                           "values are read as nT"),
    ("mGal", "gravity", None), ("", "gravity", None), ("nT", "magnetic", None),
])
def test_a_map_in_units_of_neither_field_is_warned_of(capsys, units, field, warned):
    """Issue 19: a geoid (m) or DOV (arcsec) map given to match, filter or navigate was
    read as mGal with no word (match: exit 0, a χ² warning at most)."""
    check_map_field(SimpleNamespace(units=units), field, "g.nc")
    err = capsys.readouterr().err
    assert (warned in err and err.startswith("warning: --map 'g.nc' ")) if warned else not err


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A simulated 30-fix track (raw readings, v_east = v_north = 10 kn) and its header."""
    d = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "--out", str(d / "t.csv"), "--seed", "1"]) == 0
    return np.genfromtxt(d / "t.csv", delimiter=",", names=True)


def _write(path, data, t=None):
    names = data.dtype.names
    rows = [",".join([t[i] if t is not None else f"{row['t']:g}",
                      *(f"{row[n]:.10g}" for n in names[1:])]) for i, row in enumerate(data)]
    path.write_text(",".join(names) + "\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.long  # 4-8 s: the fast tier is at its 5-minute budget
def test_readings_corrected_twice_for_eotvos_are_named(tmp_path, capsys, simulated):
    """Readings already Eötvös-corrected, with velocity columns and no --eotvos-corrected:
    match blamed the noise or a gravimeter offset ('give --bias-sigma inf', after which it
    ran silently with a +63.7 mGal bias); now the bias is named as the correction."""
    data = simulated.copy()
    data["gravity"] += np.asarray(eotvos(data["lat"], data["v_east"], data["v_north"]))
    track = _write(tmp_path / "c.csv", data)
    for extra in ([], ["--bias-sigma", "inf"]):
        out = tmp_path / f"m{len(extra)}.json"
        assert main(["match", "--map", "ryukyu", "--track", str(track), "--out", str(out),
                     *extra]) == 0
        assert "give --eotvos-corrected" in capsys.readouterr().err
        assert any("--eotvos-corrected" in m
                   for m in json.loads(out.read_text())["status_messages"])
    out = tmp_path / "ok.json"
    raw = _write(tmp_path / "raw.csv", simulated)
    assert main(["match", "--map", "ryukyu", "--track", str(raw), "--out", str(out),
                 "--bias-sigma", "inf"]) == 0
    assert "eotvos" not in capsys.readouterr().err.lower()


def test_iso_times_are_kept_in_the_match_json(tmp_path, simulated):
    """ISO-8601 times: the JSON's t counted seconds from an unstated first time (units
    's'); now the times as given and their origin are kept."""
    stamps = [f"2026-03-29T{1 + int(s) // 3600:02d}:{int(s) % 3600 // 60:02d}:00Z"
              for s in simulated["t"]]
    track = _write(tmp_path / "iso.csv", simulated, t=stamps)
    out = tmp_path / "m.json"
    assert main(["match", "--map", "ryukyu", "--track", str(track), "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["time"] == stamps and r["t"][:2] == [0.0, 120.0]
    assert r["time_origin"] == "2026-03-29T01:00:00+00:00"
    assert r["units"]["t"] == "s since 2026-03-29T01:00:00+00:00"


@pytest.mark.long
def test_navigate_keeps_iso_times_and_text_columns(tmp_path):
    """A log with ISO-8601 times and a ship column: navigate's and filter's CSVs had t from
    0 and neither the times nor the ship; now both follow t (and a 'status' text column, which the
    output uses, comes out as 'status_track')."""
    log = tmp_path / "v.csv"
    assert main(["simulate-voyage", "--out", str(log), "--hours", "0.25", "--seed", "1"]) == 0
    data = np.genfromtxt(log, delimiter=",", names=True)
    stamps = [f"2026-03-29T00:{int(s) // 60:02d}:{int(s) % 60:02d}Z" for s in data["t"]]
    names = data.dtype.names
    rows = [",".join([stamps[i], *(f"{row[n]:.10g}" for n in names[1:]), "Kaiyo", "ok"])
            for i, row in enumerate(data)]
    iso = tmp_path / "iso.csv"
    iso.write_text(",".join([*names, "ship", "status"]) + "\n" + "\n".join(rows) + "\n")
    out = tmp_path / "n.csv"
    assert main(["navigate", "--map", "ryukyu", "--track", str(iso), "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0].startswith("t,time,ship,status_track,lat,lon,"), lines[0]
    assert lines[1].startswith("0,2026-03-29T00:00:00Z,Kaiyo,ok,"), lines[1]
    assert len(lines) == len(stamps) + 1
    # filter on the same log: the same columns follow t (it dropped them too)
    out = tmp_path / "f.csv"
    assert main(["filter", "--map", "ryukyu", "--track", str(iso), "--out", str(out),
                 "--ins", "navigation"]) == 0
    lines = out.read_text().splitlines()
    assert lines[0].startswith("t,time,ship,status_track,lat,lon,"), lines[0]
    assert lines[1].startswith("0,2026-03-29T00:00:00Z,Kaiyo,ok,"), lines[1]
    assert len(lines) == len(stamps) + 1


@pytest.fixture(scope="module")
def holed(tmp_path_factory):
    """A 30-fix track 1.5 km north of its truth (readings: ryukyu + 1 mGal noise) and two
    maps with 2 x 2 missing nodes: 'near', 2 of the INS track's fixes in their cells (the
    truth's none), 'under', 19 of them (the truth's too)."""
    d = tmp_path_factory.mktemp("holed")
    g = load_map("ryukyu")
    lat, lon = np.asarray(g.lat), np.asarray(g.lon)
    t = np.arange(30) * 120.0
    tlat, tlon = 30.2 + t * 4e-5, 130.4 + t * 4.5e-5
    readings = np.asarray(g.sample(tlat, tlon, "bicubic"))
    readings = readings + np.random.default_rng(0).normal(size=t.size)
    for name, (a, b) in {"near": (30.35, 130.45), "under": (30.26, 130.47)}.items():
        values = np.asarray(g.values).copy()
        i, j = np.searchsorted(lat, a), np.searchsorted(lon, b)
        values[i:i + 2, j:j + 2] = np.nan
        xr.Dataset({"z": (("lat", "lon"), values, {"units": "mGal"})},
                   coords={"lat": lat, "lon": lon}).to_netcdf(d / f"{name}.nc")
    (d / "t.csv").write_text("t,lat,lon,gravity\n" + "".join(
        f"{a:g},{b + 0.0135:.6f},{c:.6f},{r:.4f}\n"
        for a, b, c, r in zip(t, tlat, tlon, readings, strict=True)))
    return d


@pytest.mark.long
@pytest.mark.parametrize("where, extra, said, counts", [
    ("near", [], "fixes in a cell with one: 2 of 30 on the INS track, 0 on the matched track; "
                 "read as survey gaps (--missing auto: the INS track crosses them): each "
                 "candidate was scored on its fixes over present cells", (4, 2, 0)),
    ("near", ["--missing", "land"],
     "2 of 30 on the INS track, 0 on the matched track; read as land (--missing land): "
     "candidates touching them were dropped, the fix is the best of the rest (if they are "
     "survey gaps, not land, the truth may lie in the dropped part: --missing gaps)", (4, 2, 0)),
    ("near", ["--method", "entropy+iccp"],
     "read as land (--method entropy+iccp reads them so): candidates touching them were "
     "dropped, the fix is the best of the rest", (4, 2, 0)),
    ("under", ["--missing", "gaps"],
     "19 of 30 on the INS track (the fix was rejected: the INS track is returned); read as "
     "survey gaps (--missing gaps)", (4, 19, 19)),
    ("under", ["--missing", "land"],
     "19 of 30 on the INS track (the fix was rejected: the INS track is returned); read as "
     "land (--missing land): candidates touching them were dropped (if they are", (4, 19, 19)),
])
def test_missing_map_nodes_are_reported_as_they_were_read(holed, tmp_path, capsys, where,
                                                          extra, said, counts):
    """match on a map with missing nodes in reach printed, whatever ran, one line naming
    both readings (land: dropped; gaps: scored on present cells); now the line says which
    reading ran and why, what it did, and how many fixes of the INS track and of the fix
    lie in a cell with a missing node (counts in the JSON too)."""
    out = tmp_path / "m.json"
    assert main(["match", "--map", str(holed / f"{where}.nc"), "--track",
                 str(holed / "t.csv"), "--out", str(out), *extra]) == 0
    err = capsys.readouterr().err
    line = [m for m in err.splitlines() if "missing (NaN) map nodes" in m]
    assert len(line) == 1 and said in line[0], err
    assert line[0].startswith("warning: missing (NaN) map nodes: 4 in the search region; "), err
    r = json.loads(out.read_text())
    assert r["status"] & 8192 and line[0].removeprefix("warning: ") in r["status_messages"]
    assert (r["missing_nodes_in_reach"], r["ins_fixes_over_missing"],
            r["fixes_over_missing"]) == counts


# refused before any work: (argv, the message; {d} is the test's folder). What each did:
REFUSED = [
    # named --preset for a --hours below two readings ("--preset 'patrol-12h': hours must
    # cover at least two steps of dt = 10.0 s; got hours=0.001")
    (["simulate-voyage", "--out", "{d}/v.csv", "--hours", "0.001"],
     "--hours must cover at least two readings 10 s apart (>= 0.00556 h); got 0.001"),
    # an unknown preset: "preset must be one of ['patrol-12h', 'transit-24h']" (a list)
    (["simulate-voyage", "--out", "{d}/v.csv", "--preset", "nope"],
     "argument --preset: invalid choice: 'nope' (choose from 'patrol-12h', 'transit-24h')"),
    # a segment longer than the map: "window_cells=25981 is larger than the map (289 x 289
    # nodes)", naming no option
    (["suitability", "--map", "ryukyu", "--out", "{d}/s.nc", "--fixes", "100000"],
     "--fixes 100000 readings --spacing 1200 m apart make a segment of 1.2e+05 km, 25980 "
     "nodes of the map, longer than its shorter side (289 nodes): every segment would leave "
     "the map; give fewer --fixes or a shorter --spacing"),
    (["suitability", "--map", "ryukyu", "--out", "{d}/s.nc", "--spacing", "1e7"],
     "--spacing 1e+07 m apart make a segment of 2.9e+05 km"),
    # 1e300 degrees was accepted (its remainder by 360 is noise)
    (["suitability", "--map", "ryukyu", "--out", "{d}/s.nc", "--heading", "1e300"],
     "--heading must be an angle from -360 to 360 (degrees clockwise from north); got 1e+300"),
    # issue 19: 400 (one turn and 40 degrees) and just below -360, refused the same way
    (["suitability", "--map", "ryukyu", "--out", "{d}/s.nc", "--heading", "400"],
     "--heading must be an angle from -360 to 360 (degrees clockwise from north); got 400.0"),
    (["suitability", "--map", "ryukyu", "--out", "{d}/s.nc", "--heading", "-360.5"],
     "--heading must be an angle from -360 to 360 (degrees clockwise from north); got -360.5"),
    # --out x.png: "its PNG 'x.png' and --out 'x.png' are the same file"
    (["suitability", "--map", "ryukyu", "--out", "{d}/s.png"],
     "--out '{d}/s.png' is the NetCDF output; the PNG is written next to it with suffix .png: "
     "give --out '{d}/s.nc'"),
    # one reading at the start in 3601 rows: written, exit 0
    (["simulate-filter", "--out", "{d}/g.csv", "--reading-every", "100000"],
     "--reading-every 100000 leaves one reading in the 3601 rows of --minutes 120 every --dt "
     "2 s; expected at most 3600 rows between readings"),
    # "['{d}/f.csv'] exist(s)": a Python list (then "{d}/f.csv exist(s)", unnamed)
    (["simulate-filter", "--out", "{d}/f.csv"],
     "error: --out '{d}/f.csv' exists; pass --force to overwrite it (nothing was written)"),
    # a voyage given --fixes 3: "--fixes must be at least 5 per track" (--fixes 10 was
    # refused as not a voyage option)
    (["montecarlo", "--method", "voyage-ukf", "--runs", "2", "--out", "{d}/m.nc", "--fixes",
      "3"], "--fixes is not an option of voyage-ukf: a voyage runs over --hours (default 12)"),
]


@pytest.mark.parametrize("argv, message", REFUSED,
                         ids=[f"{a[0]}-{i}" for i, (a, _) in enumerate(REFUSED)])
def test_hunted_inputs_are_refused_in_one_line(tmp_path, capsys, argv, message):
    """Exit 2 and one line (argparse's refusals exit through SystemExit), nothing written."""
    existing = tmp_path / "f.csv"
    if "{d}/f.csv" in argv:
        existing.write_text("t\n")
    try:
        code = main([a.format(d=tmp_path) for a in argv])
    except SystemExit as exit_:
        code = exit_.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and message.format(d=tmp_path) in err, err
    assert "\n" not in err and "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == ([existing] if existing.exists() else [])


def test_bench_names_a_script_that_failed_silently(tmp_path, capsys, quick_machine_info, refused):
    """A script that exits 3 with no output: stderr ended in 'failed (exit code 3):' and an
    empty line, the report in an empty code block; now '(no output)'. --dir naming a script:
    'is not a folder of benchmark scripts'; now its folder is named."""
    d = tmp_path / "b"
    d.mkdir()
    (d / "quiet.py").write_text("raise SystemExit(3)\n")
    out = tmp_path / "bench.md"
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--dir", str(d), "--out", str(out)])
    assert exc.value.code == 1
    assert "### quiet.py: exit code 3\n\n```\n(no output)\n```" in out.read_text()
    assert capsys.readouterr().err == "jaxgrav bench: quiet.py failed (exit code 3):\n(no output)\n"
    refused(["bench", "--dir", d / "quiet.py", "--out", tmp_path / "b2.md"],
            f"--dir '{d / 'quiet.py'}' is a file: give the folder of the scripts, e.g. '{d}'")
