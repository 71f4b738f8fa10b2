"""Inputs found by the eighth issue-19 hunt (2026-12-07, helper-70).

The last hunt's leftovers first: ``match`` labelled a track's Unix times ``"s"`` in its
JSON (as if counted from the track's start), and ``dov --layers 0,1e12`` ran with a
warning. Then the hunt's own finds (below them)."""

import json

import numpy as np
import pytest
import xarray as xr

from jaxgrav.cli import main
from jaxgrav.cli.filter_checks import speed_course_warning
from jaxgrav.cli.inputs import read_track, track_time_units
from jaxgrav.cli.log_clock import check_time_unit
from jaxgrav.cli.main import build_parser

ROWS = [(29.5 + 0.0056 * i, 126.5 + 0.0068 * i) for i in range(5)]


def _track(path, header, times):
    path.write_text(header + "\n" + "".join(f"{t},{lat},{lon}\n"
                                            for t, (lat, lon) in zip(times, ROWS, strict=True)))
    return path


def _units(path):
    args = build_parser().parse_args(["sample", "--map", "ryukyu", "--track", str(path),
                                      "--out", "x.csv"])
    return track_time_units(read_track(args, required=("t", "lat", "lon")))


@pytest.mark.parametrize("header, times, units, first", [
    ("t", [0, 120, 240, 360, 480], "s", None),  # the track's own clock
    ("t", [1714564800 + 120 * i for i in range(5)], "s since 1970-01-01T00:00:00Z",
     "2024-05-01T12:00:00Z"),  # Unix seconds: were labelled "s"
    ("t", [1714564800000 + 120000 * i for i in range(5)], "s since 1970-01-01T00:00:00Z",
     "2024-05-01T12:00:00Z"),  # Unix milliseconds, read as seconds since 1970
    ("t (hours since 2024-05-01)", [0, 0.5, 1, 1.5, 2], "s since 2024-05-01", None),
    ("time", ["2024-05-01T12:00:00Z", "2024-05-01T12:02:00Z", "2024-05-01T12:04:00Z",
              "2024-05-01T12:06:00Z", "2024-05-01T12:08:00Z"],
     "s since 2024-05-01T12:00:00+00:00", None),
    ("t", [86000 + 60 * i for i in range(5)], "s", None),  # seconds of the day: no epoch
])
def test_track_times_are_labelled_with_their_reference(tmp_path, capsys, header, times,
                                                        units, first):
    """``match``'s JSON said ``"t": "s"`` for Unix times and for a CF header's
    ``hours since DATE`` (converted to seconds, the reference dropped)."""
    assert _units(_track(tmp_path / "t.csv", header + ",lat,lon", times)) == (units, first)


@pytest.mark.long
def test_match_json_labels_unix_times(tmp_path):
    """The match JSON keeps the track's Unix times and says so (compiles the matcher)."""
    track, truth = tmp_path / "t.csv", tmp_path / "truth.csv"
    assert main(["simulate", "--out", str(track), "--truth", str(truth)]) == 0
    lines = track.read_text().splitlines()
    rows = [line.split(",", 1) for line in lines[1:]]
    track.write_text("\n".join([lines[0], *(f"{float(t) + 1714564800:.0f},{rest}"
                                            for t, rest in rows)]) + "\n")
    out = tmp_path / "r.json"
    assert main(["match", "--map", "ryukyu", "--track", str(track), "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["units"]["t"] == "s since 1970-01-01T00:00:00Z"
    assert r["time_start"] == "2024-05-01T12:00:00Z"
    np.testing.assert_allclose(r["t"][:2], [1714564800, 1714564920])


@pytest.fixture
def dov_track(tmp_path):
    path = tmp_path / "d.csv"
    path.write_text("lat,lon,h\n34.0,108.5,0\n34.01,108.51,100\n")
    return path


@pytest.mark.parametrize("layers, got", [("0,1e12", "1e+12"), ("0,10000,100001", "100001")])
def test_dov_layers_above_the_edge_of_space_are_refused(dov_track, tmp_path, refused, layers,
                                                         got):
    """``--layers 0,1e12`` synthesised a layer a million km up and wrote xi = -736964
    arcsec with a gap warning, exit 0."""
    out = tmp_path / "o.csv"
    refused(["dov", "--track", dov_track, "--out", out, "--layers", layers],
            f"--layers {layers}: heights must be between -11000 m (the deepest ocean floor) "
            f"and 100000 m (the edge of space), in m above the ellipsoid; got {got}")
    assert not out.exists()


@pytest.mark.parametrize("h, far", [(200000.0, "200000"), (-20000.0, "-20000")])
def test_dov_heights_beyond_any_layer_ask_for_their_unit(tmp_path, refused, h, far):
    """A point 200 km up (a height in feet or cm?) was told to give
    ``--layers=0,10000,20000,200000``, and -20 km ``--layers=-20000,...``: both refused."""
    track = tmp_path / "d.csv"
    track.write_text(f"lat,lon,h\n34.0,108.5,0\n34.01,108.51,{h}\n")
    err = refused(["dov", "--track", track, "--out", tmp_path / "o.csv"],
                  f"; a height of {far} m is beyond any layer (-11000 to 100000 m above the "
                  "ellipsoid, the deepest ocean floor to the edge of space): check the h "
                  "column's unit (declare it in the header, e.g. 'h (ft)')")
    assert "--layers=" not in err


@pytest.mark.parametrize("command", ["filter", "navigate"])
def test_an_initial_velocity_error_above_any_vessel_s_speed_is_refused(tmp_path, refused,
                                                                       command):
    """``filter --sigma-vel 1e9`` ran, exit 0: the covariance failed on 596 of 601 rows
    and the 1-sigma was 17 600 km."""
    track = _track(tmp_path / "t.csv", "t,lat,lon", [0, 10, 20, 30, 40])
    out = tmp_path / "o.csv"
    source = ["--point-masses", "paper-d"] if command == "filter" else ["--map", "ryukyu"]
    refused([command, *source, "--track", track, "--out", out, "--sigma-vel", "1e9"],
            "--sigma-vel must be at most 50 m/s (97 knots, above the speed of the vessels the "
            "filters follow; an INS starts within about 0.01-1 m/s); got 1e+09")
    assert not out.exists()


def test_navigate_without_a_single_reading_is_refused(tmp_path, refused):
    """A log whose gravity column is empty throughout ran ``navigate`` for 19 s and wrote
    the INS back, "0 reading(s) used", exit 0 (``filter`` refused it)."""
    track = tmp_path / "v.csv"
    track.write_text("t,lat,lon,v_east,v_north,gravity\n" + "".join(
        f"{10 * i},{29.3 + 2.5e-5 * i},{126.05 + 4.5e-5 * i},4.34,2.74,\n" for i in range(20)))
    out = tmp_path / "o.csv"
    refused(["navigate", "--map", "ryukyu", "--track", track, "--out", out],
            f"--track '{track}': column 'gravity' has no readings (all 20 cells empty or NaN); "
            "navigate needs at least one (mGal)")
    assert not out.exists()


@pytest.mark.parametrize("argv", [
    ["simulate", "--out", "t.csv", "--truth", "truth.csv"],
    ["simulate-voyage", "--hours", "1", "--out", "t.csv", "--truth", "truth.csv"],
    ["montecarlo", "--method", "dense", "--runs", "10", "--out", "m.nc"],
])
def test_a_truth_map_that_is_the_map_is_refused(tmp_path, monkeypatch, refused, argv):
    """``--truth-map ryukyu`` on the default ``--map ryukyu`` ran as "truth map ryukyu"
    (montecarlo: "told the map error (GLS)") while the readings saw no map error."""
    monkeypatch.chdir(tmp_path)
    refused([*argv, "--truth-map", "ryukyu"],
            "--truth-map ryukyu holds the --map's own values: the readings would see no map "
            "error; give another map (e.g. a newer survey), or leave --truth-map out for a "
            "perfect map")
    assert list(tmp_path.iterdir()) == []


def _log(path, t_unit, lat0, lon0):
    """A 20-row INS log 10 s apart at 8 m/s east, 1 m/s north from ``lat0``, ``lon0``, its
    times divided by ``t_unit`` (s), from 45413.5 days (an Excel serial date)."""
    rows = []
    for i in range(20):
        lat = lat0 + 1.0 * 10 * i / 110_700.0
        lon = lon0 + 8.0 * 10 * i / (111_320.0 * np.cos(np.radians(lat0)))
        rows.append(f"{45413.5 * 86400 / t_unit + 10 * i / t_unit:.9f},{lat:.8f},{lon:.8f},8.0,"
                    f"1.0,{-30 + 0.3 * i:.2f}\n")
    path.write_text("t,lat,lon,v_east,v_north,gravity\n" + "".join(rows))
    return path


@pytest.mark.parametrize("command, source, lat0, lon0", [
    ("filter", ["--point-masses", "paper-d"], 24.3, 122.74),
    ("navigate", ["--map", "ryukyu"], 29.3, 126.05)])
@pytest.mark.parametrize("t_unit, name, symbol", [(86400.0, "days", "d"), (3600.0, "hours", "h"),
                                                  (60.0, "minutes", "min")])
def test_log_times_in_days_or_hours_are_named(tmp_path, refused, command, source, lat0, lon0,
                                              t_unit, name, symbol):
    """Excel serial days (45413.5...), MATLAB datenums or Julian days in ``t`` ran
    ``filter`` on a 2.3e-5 s step, exit 0 (moves of 10 m a row stayed below the 25 m
    least jump): the distance the velocities explain is 86 400 times too short."""
    log = _log(tmp_path / "v.csv", t_unit, lat0, lon0)
    out = tmp_path / "o.csv"
    err = refused([command, *source, "--track", log, "--out", out],
                  f"column 't' looks like {name}, not seconds: the positions move 153")
    ratio = float(err.split(" m over the log, ")[1].split(" times what")[0])
    assert abs(ratio / t_unit - 1) < 0.01, err
    assert err.endswith(f"declare the unit in the header, e.g. 't ({symbol})'"), err
    assert not out.exists()


@pytest.mark.parametrize("rows, message", [
    ("3527.71642,12742.78991", "column 'lat': latitude 3527.72 is outside [-90, 90] degrees; "
     "it looks like NMEA ddmm.mmmm (degrees x 100 + minutes): 3527.71642 is 35 deg 27.71642' "
     "= 35.4619 degrees; convert the column to decimal degrees"),
    ("35.4619,12742.78991", "column 'lon': longitude 12742.8 is outside [-180, 360] degrees; it "
     "looks like NMEA ddmm.mmmm (degrees x 100 + minutes): 12742.78991 is 127 deg 42.78991' = "
     "127.713 degrees"),
    ("3575.5,127.7", "latitude 3575.5 is outside [-90, 90] degrees"),  # 75 minutes: no hint
])
def test_nmea_positions_are_named(tmp_path, refused, rows, message):
    """A GPS receiver's ddmm.mmmm latitudes (GGA sentences exported as numbers) were refused
    as "latitude 3527.72 is outside [-90, 90] degrees", with no word of what they are."""
    track = tmp_path / "t.csv"
    track.write_text(f"lat,lon\n{rows}\n")
    err = refused(["sample", "--map", "ryukyu", "--track", track, "--out", tmp_path / "o.csv"],
                  message)
    assert ("NMEA" in err) == ("NMEA" in message)


@pytest.mark.parametrize("header", ["t lat lon", "t\tlat\tlon", "t;lat;lon", "t  lat  lon  "])
def test_a_header_typed_with_another_delimiter_is_read(tmp_path, capsys, header):
    """``t lat lon`` over comma-separated rows was taken for a title line, and the file
    refused as "lacks columns lat and lon; it has 1, 2, 3"."""
    track = tmp_path / "t.csv"
    track.write_text(f"{header}\n0,29.5,126.5\n120,29.5056,126.5068\n")
    out = tmp_path / "o.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out", str(out)]) == 0
    assert out.read_text().splitlines()[:2] == ["t,lat,lon,map", "0,29.5,126.5,24.8326377869"]


def test_a_file_without_a_header_says_so(tmp_path, refused):
    track = tmp_path / "t.csv"
    track.write_text("0,29.5,126.5\n120,29.5056,126.5068\n")
    refused(["sample", "--map", "ryukyu", "--track", track, "--out", tmp_path / "o.csv"],
            f"track file '{track}' has no header row (line 1 holds only numbers); add one "
            "naming its 3 columns (e.g. t,lat,lon,gravity) or name them by number (e.g. "
            "--columns lat=2,lon=3)")
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out",
                 str(tmp_path / "o.csv"), "--columns", "lat=2,lon=3"]) == 0


@pytest.mark.parametrize("cell", ["120x", "2024-05-01T12:02:00"])
def test_one_bad_time_among_numbers_is_named_on_its_own_line(tmp_path, refused, cell):
    """A typo in line 3's time was reported as "line 2, column 't': '0' is neither a
    number (seconds) nor an ISO-8601 date-time": the first cell, which is fine."""
    track = tmp_path / "t.csv"
    track.write_text(f"t,lat,lon\n0,29.5,126.5\n{cell},29.5056,126.5068\n")
    refused(["sample", "--map", "ryukyu", "--track", track, "--out", tmp_path / "o.csv"],
            f"line 3, column 't': {cell!r} is not a number, as the column's other times are "
            "(seconds); give every time as a number, or every one as a date-time")


def test_a_dos_end_of_file_mark_is_ignored(tmp_path):
    """A ^Z (0x1a) after the last line, as old DOS programs end files, was a row whose time
    was not a number (and the message named line 2's '0')."""
    track = tmp_path / "t.csv"
    track.write_bytes(b"t,lat,lon\r\n0,29.5,126.5\r\n120,29.5056,126.5068\r\n\x1a")
    out = tmp_path / "o.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out", str(out)]) == 0
    assert len(out.read_text().splitlines()) == 3


def _layers_file(path, xi_units, factor, h_units, h_factor):
    """A 2-layer DOV file on 0-1 N, 10-11 E, heights 0 and 1000 m, written in other units."""
    lat, lon = np.linspace(0.0, 1.0, 11), np.linspace(10.0, 11.0, 11)
    values = np.stack([np.stack([np.add.outer(lat, lon) * (k + 1) * (c + 1) for c in range(2)])
                       for k in range(2)])
    xr.Dataset({name: (("height", "lat", "lon"), values[:, c] / factor, {"units": xi_units})
                for c, name in enumerate(("xi", "eta"))},
               coords={"height": ("height", np.array([0.0, 1000.0]) / h_factor,
                                  {"units": h_units}),
                       "lat": lat, "lon": lon}).to_netcdf(path)
    return path


@pytest.mark.parametrize("xi_units, factor, h_units, h_factor", [
    ("radians", 206264.80624709636, "km", 1000.0), ("urad", 0.20626480624709636, "m", 1.0),
    ("degrees", 3600.0, "ft", 0.3048)])
def test_dov_grid_units_are_converted(tmp_path, xi_units, factor, h_units, h_factor):
    """A --grid in radians (or µrad, degrees) was written under xi/eta as if in arcsec,
    and heights in km were read as metres."""
    track = tmp_path / "t.csv"
    track.write_text("lat,lon,h\n0.5,10.5,500\n0.52,10.55,250\n")
    outs = []
    for name, args in (("a", ("arcsec", 1.0, "m", 1.0)),
                       ("b", (xi_units, factor, h_units, h_factor))):
        grid = _layers_file(tmp_path / f"{name}.nc", *args)
        outs.append(tmp_path / f"{name}.csv")
        assert main(["dov", "--track", str(track), "--out", str(outs[-1]), "--grid", str(grid),
                     "--method", "bilinear-linear"]) == 0
    a, b = (np.loadtxt(p, delimiter=",", skiprows=1) for p in outs)
    np.testing.assert_allclose(b, a, rtol=1e-9)


@pytest.mark.parametrize("attr, units, message", [
    ("xi", "mGal", "xi declares units 'mGal', not an angle; expected deflections of the "
                   "vertical in arcsec (or rad, urad, mrad, deg, mas)"),
    ("height", "s", "height declares units 's'; expected layer heights in m (or km, ft) above "
                    "the ellipsoid")])
def test_dov_grid_units_of_no_kind_are_refused(tmp_path, refused, attr, units, message):
    grid = _layers_file(tmp_path / "g.nc", units if attr == "xi" else "arcsec", 1.0,
                        units if attr == "height" else "m", 1.0)
    track = tmp_path / "t.csv"
    track.write_text("lat,lon,h\n0.5,10.5,500\n")
    refused(["dov", "--track", track, "--out", tmp_path / "o.csv", "--grid", grid],
            f"--grid '{grid}': {message}")


@pytest.mark.parametrize("name, fmt", [("b.csv", "a CSV"), ("b.json", "a JSON"),
                                       ("b.md.gz", "a compressed")])
def test_bench_out_of_another_format_is_refused_before_running(tmp_path, refused, name, fmt):
    """``bench --out b.csv`` ran every benchmark script (minutes), then wrote its Markdown
    table into b.csv."""
    bdir = tmp_path / "bench"
    bdir.mkdir()
    (bdir / "x.py").write_text("raise SystemExit('must not run')\n")
    refused(["bench", "--dir", bdir, "--out", tmp_path / name], f"names {fmt} file")
    assert not (tmp_path / name).exists()


def test_an_output_that_is_a_broken_link_needs_force(tmp_path, refused):
    """``--out LINK`` whose target is gone (a link to last run's file on an unmounted disk)
    was replaced by a file without ``--force``: ``exists()`` follows the link."""
    track = _track(tmp_path / "t.csv", "t,lat,lon", [0, 120, 240, 360, 480])
    link = tmp_path / "latest.csv"
    link.symlink_to(tmp_path / "gone" / "run.csv")
    argv = ["sample", "--map", "ryukyu", "--track", track, "--out", link]
    refused(argv, f"--out '{link}' exists; pass --force to overwrite it (nothing was written)")
    assert link.is_symlink()
    assert main([str(a) for a in argv] + ["--force"]) == 0
    assert not link.is_symlink() and link.read_text().startswith("t,lat,lon,map")


def _rows_match(out, expected):
    """The output's rows are ``expected``: the same cells, the sampled map value (the last
    column, bicubic on a float32 map) to 1e-5 mGal — its last digits move with the CPU
    and library versions (4e-7 mGal between two machines of 2026-12)."""
    rows = [r.split(",") for r in out.read_text().splitlines()[1:]]
    want = [r.split(",") for r in expected]
    assert [r[:-1] for r in rows] == [r[:-1] for r in want]
    for got, exp in zip(rows, want, strict=True):
        assert (got[-1] == exp[-1] == "") or float(got[-1]) == pytest.approx(
            float(exp[-1]), abs=1e-5)


def test_sample_keeps_rows_without_a_position(tmp_path, capsys):
    """A GPS dropout (empty lat/lon cells on one row) refused the whole file in ``sample``
    ("column 'lat' has 1 missing or NaN value(s) ... must be complete")."""
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon,depth\n0,29.5,126.5,10\n120,,,11\n240,29.5112,126.5136,12\n")
    out = tmp_path / "o.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out", str(out)]) == 0
    _rows_match(out, ["0,29.5,126.5,10,24.8326377869", "120,,,11,",
                      "240,29.5112,126.5136,12,26.0607606636"])
    err = capsys.readouterr().err
    assert err == ("warning: 1 of 3 rows have no position (first on line 3); their 'map' cells "
                   "are left empty\n")


@pytest.mark.parametrize("argv", [
    ["simulate", "--out", "t.csv", "--truth", "truth.csv"],
    ["simulate-filter", "--out", "t.csv", "--truth", "truth.csv"],
    ["simulate-voyage", "--hours", "1", "--out", "t.csv", "--truth", "truth.csv"],
    ["montecarlo", "--method", "ukf", "--runs", "5", "--out", "m.nc"],
    ["montecarlo", "--method", "voyage-ukf", "--runs", "5", "--out", "m.nc"]])
def test_simulators_refuse_a_magnetic_map(tmp_path, monkeypatch, refused, argv):
    """A map in nT gave ``simulate`` a 'gravity' column of nT values, exit 0, and
    ``montecarlo``'s filters a gravimeter and Eötvös model over it (``match`` and the
    filters refuse a magnetic map for gravity readings)."""
    monkeypatch.chdir(tmp_path)
    lat, lon = np.linspace(28.0, 31.0, 73), np.linspace(125.0, 128.0, 73)
    xr.Dataset({"z": (("lat", "lon"), 100 * np.sin(lat[:, None] * 5) * np.cos(lon * 4),
                      {"units": "nT"})}, coords={"lat": lat, "lon": lon}).to_netcdf("mag.nc")
    refused([*argv, "--map", "mag.nc"], "--map 'mag.nc' is a magnetic map (units 'nT') and the "
            "readings are gravity (mGal); give a gravity map")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mag.nc"]


def _gravity_log(path, header, rows):
    path.write_text(header + "\n" + "".join(
        f"{10 * i},{24.3 + 1e-4 * i},{122.74 + 8e-4 * i},{row}\n" for i, row in enumerate(rows)))
    return path


@pytest.mark.parametrize("command, source", [
    ("filter", ["--point-masses", "paper-d"]), ("match", ["--map", "ryukyu"])])
def test_a_lone_velocity_column_is_refused(tmp_path, refused, command, source):
    """A log with v_east but no v_north ran as if without velocities: raw readings taken
    as Eötvös-corrected (a 62 mGal first innovation), the v_east column dropped, exit 0."""
    log = _gravity_log(tmp_path / "v.csv", "t,lat,lon,v_east,gravity",
                       [f"8.0,{-30 + 0.3 * i:.1f}" for i in range(6)])
    out = tmp_path / ("o.json" if command == "match" else "o.csv")
    refused([command, *source, "--track", log, "--out", out],
            f"--track '{log}' has a v_east column but no v_north; give both INS velocity "
            "columns (m/s; name them with --columns v_north=COLUMN) or neither (readings then "
            "taken as Eötvös-corrected)")
    assert not out.exists()


def test_filter_refuses_an_empty_velocity_cell(tmp_path, refused):
    """``filter`` skipped the reading of a row whose v_east was empty, without a word (its
    output row had an empty v_east and status 'no reading')."""
    log = _gravity_log(tmp_path / "v.csv", "t,lat,lon,v_east,v_north,gravity",
                       ["8.0,1.0,-30", "8.0,1.0,-29", ",1.0,-28", "8.0,1.0,-27"])
    refused(["filter", "--point-masses", "paper-d", "--track", log, "--out", tmp_path / "o.csv"],
            f"--track '{log}', line 4, column 'v_east': no velocity (1 such row(s)); the INS "
            "velocity columns must be complete")


@pytest.mark.parametrize("header", ["sog,cog", "speed (kn),course (deg)", "Speed,Heading",
                                    "sog,cog,v_east,v_north", "speed,depth"])
def test_speed_and_course_without_velocities_are_warned_of(tmp_path, header):
    """A ship's log with speed over ground and course but no v_east/v_north was filtered
    with its readings taken as Eötvös-corrected, without a word (raw readings 75 mGal off at
    10 kn east on the equator)."""
    names = header.split(",")
    log = _gravity_log(tmp_path / "v.csv", f"t,lat,lon,{header},gravity",
                       [",".join(["1"] * len(names) + [f"{-30 + 0.3 * i:.1f}"]) for i in range(4)])
    args = build_parser().parse_args(["filter", "--point-masses", "paper-d", "--track", str(log),
                                      "--out", "o.csv"])
    warning = speed_course_warning(read_track(args, required=("t", "lat", "lon", "gravity")), "T")
    if len(names) != 2 or names[1] == "depth":  # velocities given, or no course
        assert warning is None
    else:
        assert warning == (f"T has speed ({names[0]!r}) and course ({names[1]!r}) columns but no "
                           "v_east, v_north: its readings are taken as Eötvös-corrected; if they "
                           "are raw, add v_east = speed x sin(course) and v_north = speed x "
                           "cos(course) in m/s")


@pytest.mark.long  # compiles the filter
def test_filter_warns_of_speed_and_course(tmp_path, capsys):
    log = _gravity_log(tmp_path / "v.csv", "t,lat,lon,sog,cog,gravity",
                       [f"10,90,{-30 + 0.3 * i:.1f}" for i in range(4)])
    assert main(["filter", "--point-masses", "paper-d", "--track", str(log), "--out",
                 str(tmp_path / "o.csv")]) == 0
    assert f"warning: --track '{log}' has speed ('sog') and course ('cog')" in \
        capsys.readouterr().err


def test_a_drift_radius_column_too_wide_is_named_not_the_option(tmp_path, refused):
    """A ``drift_radius`` column in metres (4000) was refused as "--drift-radius 4000
    degrees searches a region 8000 degrees across", an option the user never gave."""
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon,gravity,drift_radius\n" + "".join(
        f"{120 * i},{30.2 + 0.005 * i},{130.4 + 0.005 * i},{i % 3},4000\n" for i in range(6)))
    refused(["match", "--map", "ryukyu", "--track", track, "--out", tmp_path / "m.json"],
            f"column 'drift_radius' of --track '{track}' holds up to 4000 degrees, searching a "
            "region 8000 degrees across, larger than the map around the track (")


@pytest.mark.parametrize("header", ["alt_ft", "altitude_ft", "ELEV_FT", "elevation_km"])
def test_an_altitude_in_feet_named_with_columns_is_converted(tmp_path, header):
    """``dov --columns h=alt_ft``: the aircraft's altitude in feet was read as metres
    (``height_ft`` and ``h (ft)`` were converted, ``alt_ft`` not)."""
    track = tmp_path / "ft.csv"
    track.write_text(f"lat,lon,{header}\n34.0,108.5,10000\n34.01,108.51,20000\n")
    args = build_parser().parse_args(["dov", "--track", str(track), "--out", "o.csv",
                                      "--columns", f"h={header}"])
    factor = 1000.0 if header.endswith("km") else 0.3048
    np.testing.assert_allclose(read_track(args, required=("lat", "lon", "h"))["h"],
                               [10000 * factor, 20000 * factor])


def test_a_log_at_rest_is_not_taken_for_minutes():
    """A moored ship's INS drifting 3 m a minute at a logged 1 mm/s: the ratio (50) is near
    a minute's 60, but a log at rest tells no time unit."""
    n = 61
    track = {"t": 60.0 * np.arange(n), "lat": 24.3 + 3.0 * np.arange(n) / 110_700.0,
             "lon": np.full(n, 122.74), "v_east": np.zeros(n), "v_north": np.full(n, 1e-3)}
    assert check_time_unit(track, where="T") is None


def test_quoted_decimal_commas_in_a_comma_separated_file_are_read(tmp_path, refused):
    """``"29,5"`` quoted in a comma-separated file (a spreadsheet in a decimal-comma locale
    saving CSV) was "not a number"; ``"1,234"`` stays refused (1234 or 1.234?)."""
    track = tmp_path / "t.csv"
    track.write_text('t,lat,lon\n"0","29,5","126,5"\n"120","29,5056","126,5068"\n')
    out = tmp_path / "o.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out", str(out)]) == 0
    _rows_match(out, ["0,29.5,126.5,24.8326377869", "120,29.5056,126.5068,25.4254756736"])
    track.write_text('t,lat,lon,gravity\n0,29.5,126.5,"1,234"\n')
    refused(["sample", "--map", "ryukyu", "--track", track, "--out", tmp_path / "p.csv"],
            "line 2, column 'gravity': '1,234' is not a number")
