"""Inputs found by the fourth issue-19 hunt (2026-12-07, helper-56): a simulated map error
beyond any real map's; a no-harm guard ratio above 1; a position prior wider than any map;
an output named for another format, that is a pipe or device, or that ends in a slash; an
empty path; velocity columns in knots or swapped; a time gap in a match track; a missing
readings column in words; a --columns name no command reads; suitability's two-reading
segments; options a run would not use (simulate-filter's --geometry over a map, simulate's
--probability with a fixed drift, --seed without particles, --map-error-length or
--map-error-order without a map error)."""

import json
import os
import stat

import numpy as np
import pytest

from jaxgrav.cli import main
from jaxgrav.cli.sanity import time_gap_warning
from jaxgrav.datasets import load_map


@pytest.mark.parametrize("argv", [
    ["simulate", "--out", "{d}/s.csv"],
    ["simulate-filter", "--map", "ryukyu", "--out", "{d}/s.csv"],
    ["simulate-voyage", "--out", "{d}/s.csv", "--hours", "0.1"],
    ["montecarlo", "--method", "dense", "--runs", "5", "--out", "{d}/m.nc"],
])
def test_a_simulated_map_error_beyond_any_map_s_is_refused(tmp_path, refused, argv):
    """``--map-error 1e9``: readings off by 1e9 mGal were written (exit 0; montecarlo ran
    every fix rejected), readings every command then refuses; as --noise is capped."""
    refused([a.format(d=tmp_path) for a in argv] + ["--map-error", "1e9"],
            "--map-error must be at most 1000 (map units; a marine gravity map's error is a "
            "few mGal, a magnetic map's tens of nT); got 1e+09")
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def filter_log(tmp_path_factory):
    """A 6-row filter log over paper D's point masses (readings every 2 s)."""
    path = tmp_path_factory.mktemp("log") / "f.csv"
    path.write_text("t,lat,lon,gravity\n" + "".join(
        f"{2 * i},{24.3 + 2e-5 * i:.7f},{122.74 + 2e-5 * i:.7f},{-30 + 0.2 * i:.3f}\n"
        for i in range(6)))
    return path


@pytest.mark.parametrize("ratio", ["1.5", "1e9"])
def test_a_guard_ratio_above_one_is_refused(tmp_path, refused, filter_log, ratio):
    """``filter --guard 1e9``: the posterior/free variance ratio never exceeds 1, so the guard
    held nothing back while the summary said "no-harm guard 1e+09" (exit 0)."""
    out = tmp_path / "o.csv"
    refused(["filter", "--point-masses", "paper-d", "--track", filter_log, "--out",
             out, "--guard", ratio],
            "--guard must be a positive variance ratio of at most 1 (posterior / free INS, "
            "e.g. 0.2; at 1 the guard holds nothing back, and no ratio exceeds 1); got "
            f"{float(ratio):g}")
    assert not out.exists()


@pytest.mark.parametrize("command", ["filter", "navigate"])
def test_a_position_prior_wider_than_any_map_is_refused(tmp_path, refused, filter_log, command):
    """``--sigma-pos 1e9`` ran with every sigma point off the map: filter wrote a 1-sigma of
    1e9 m, navigate "0 reading(s) used", both exit 0."""
    out = tmp_path / "o.csv"
    source = ["--point-masses", "paper-d"] if command == "filter" else []
    refused([command, *source, "--track", filter_log, "--out", out, "--sigma-pos",
             "1e9"],
            "--sigma-pos must be at most 200000 m (200 km: a prior wider than that puts the "
            "filter's sigma points, particles or cells hundreds of km away, off any regional "
            "map; an INS unaided for days drifts tens of km); got 1e+09")
    assert not out.exists()


@pytest.mark.parametrize(("argv", "message"), [
    (["match", "--map", "ryukyu", "--track", "{d}/t.csv", "--out", "{d}/r.csv"],
     "--out '{d}/r.csv' names a CSV file, but this command writes JSON there; give a name "
     "ending .json, e.g. '{d}/r.json'"),
    (["sample", "--map", "ryukyu", "--track", "{d}/t.csv", "--out", "{d}/r.nc"],
     "--out '{d}/r.nc' names a NetCDF file, but this command writes CSV there"),
    (["filter", "--point-masses", "paper-d", "--track", "{d}/t.csv", "--out", "{d}/r.json"],
     "--out '{d}/r.json' names a JSON file, but this command writes CSV there; give a name "
     "ending .csv, e.g. '{d}/r.csv'"),
    (["navigate", "--track", "{d}/t.csv", "--out", "{d}/r.xlsx"],
     "--out '{d}/r.xlsx' names an Excel file, but this command writes CSV there"),
    (["dov", "--track", "{d}/t.csv", "--out", "{d}/r.json"], "--out '{d}/r.json' names a JSON"),
    (["simulate", "--out", "{d}/r.csv", "--truth", "{d}/truth.json"],
     "--truth '{d}/truth.json' names a JSON file, but this command writes CSV there"),
    (["simulate-filter", "--out", "{d}/r.nc"], "--out '{d}/r.nc' names a NetCDF file"),
    (["simulate-voyage", "--out", "{d}/r.json"], "--out '{d}/r.json' names a JSON file"),
    (["suitability", "--map", "ryukyu", "--out", "{d}/r.csv"],
     "--out '{d}/r.csv' names a CSV file, but this command writes NetCDF there; give a name "
     "ending .nc, e.g. '{d}/r.nc'"),
    (["montecarlo", "--method", "dense", "--runs", "5", "--out", "{d}/r.json"],
     "--out '{d}/r.json' names a JSON file, but this command writes NetCDF there"),
])
def test_an_output_named_for_another_format_is_refused(tmp_path, refused, argv, message):
    """``match --out result.csv`` wrote JSON into result.csv (exit 0), ``filter --out r.json``
    a CSV, ``montecarlo --out r.json`` NetCDF (and r.png): files other tools then misread.
    A suffix of no known format (``.out``, ``.txt``, none) is still taken."""
    (tmp_path / "t.csv").write_text("t,lat,lon,gravity,h\n0,30.2,130.4,5,0\n")
    refused([a.format(d=tmp_path) for a in argv], message.format(d=tmp_path))
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]


def test_a_track_without_readings_names_its_columns_in_words(tmp_path, refused):
    """"... column; it has ['lat', 'lon', 't']": a Python list, sorted, and no way out."""
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon,reading\n" + "".join(
        f"{60 * i},{30.2 + 1e-3 * i:.4f},130.4,{i}\n" for i in range(6)))
    out = tmp_path / "m.json"
    err = refused(["match", "--map", "ryukyu", "--track", track, "--out", out],
                  f"track file {str(track)!r} needs a 'gravity' (mGal) or 'magnetic' (nT) "
                  "column; it has t, lat, lon, reading (name the readings' column with --columns "
                  "gravity=COLUMN)")
    assert "[" not in err and not out.exists()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
@pytest.mark.parametrize("argv", [
    ["sample", "--map", "ryukyu", "--track", "{d}/t.csv", "--out", "{d}/pipe", "--force"],
    ["simulate", "--out", "{d}/s.csv", "--truth", "{d}/pipe", "--force"],
])
def test_an_output_that_is_a_pipe_or_device_is_never_replaced(tmp_path, refused, argv):
    """``--out /dev/stdout --force`` (or a named pipe) was replaced by a regular file, the
    output written whole and moved into place: as root, /dev/stdout and /dev/null
    themselves. Tried on a named pipe here, never on /dev."""
    (tmp_path / "t.csv").write_text("lat,lon\n30.2,130.4\n")
    os.mkfifo(tmp_path / "pipe")
    option = "--out" if argv[0] == "sample" else "--truth"
    refused([a.format(d=tmp_path) for a in argv],
            f"{option} '{tmp_path}/pipe' is a device, pipe or socket, not a regular file: "
            "jaxgrav writes each output whole and then moves it into place, which would "
            "replace it; give another path")
    assert stat.S_ISFIFO((tmp_path / "pipe").lstat().st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe", "t.csv"]


def _velocity_log(path, ve, vn, scale=1.0, swap=False, t_unit=1.0):
    """Ten rows 60 s apart over paper D's masses, moving at (ve, vn) m/s; the velocity
    columns times ``scale`` (and swapped with ``swap``), the times times ``t_unit``."""
    rows = []
    for i in range(10):
        lat = 24.3 + vn * 60 * i / 110_700.0
        lon = 122.74 + ve * 60 * i / (111_320.0 * np.cos(np.radians(24.3)))
        cols = (vn, ve) if swap else (ve, vn)
        rows.append(f"{60 * i * t_unit:g},{lat:.8f},{lon:.8f},{cols[0] * scale:.4f},"
                    f"{cols[1] * scale:.4f},{-30 + 0.3 * i:.2f}\n")
    path.write_text("t,lat,lon,v_east,v_north,gravity\n" + "".join(rows))
    return path


@pytest.mark.parametrize(("scale", "swap", "t_unit", "hint"), [
    (1.943844, False, 1.0, "(a factor 1.94): are they in knots (× 0.5144 gives m/s)?"),
    (3.6, False, 1.0, "(a factor 3.6): are they in km/h (÷ 3.6 gives m/s)?"),
    (1.0, True, 1.0, "but along the other axis: are v_east and v_north swapped?"),
    (1.0, False, 1000.0, "is column t in milliseconds, not seconds?"),
])
def test_velocity_columns_in_other_units_are_named(tmp_path, refused, scale, swap, t_unit, hint):
    """A log whose v_east/v_north were in knots: "the position jumps by 48.48 m between
    lines 2 and 3 ... (72 such jump(s)); a reset or glitch of the INS position: split the
    log there or remove the row" - every row blamed on a glitch of the positions."""
    log = _velocity_log(tmp_path / "v.csv", 8.0, 1.0, scale, swap, t_unit)
    out = tmp_path / "o.csv"
    err = refused(["filter", "--point-masses", "paper-d", "--track", log, "--out",
                   out],
                  f"--track {str(log)!r}: v_east/v_north disagree with the positions on 9 of "
                  "9 steps (first between lines 2 and 3): the positions move at a median "
                  f"{8.07 / t_unit:.3g} m/s, the velocity columns say ")
    assert hint in err and "glitch" not in err, err
    assert not out.exists()


def test_time_gap_warning_names_the_longest_gap():
    """The warning's rule: steps over 10 x the median step; regular tracks pass."""
    t = np.arange(30) * 120.0
    assert time_gap_warning(t, where="T") is None
    assert time_gap_warning(t[:2], where="T") is None  # one step: no median to compare
    t[10:] += 1000.0  # 1120 s: 9.3 steps, not a gap
    assert time_gap_warning(t, where="T") is None
    t[20:] += 5000.0
    assert time_gap_warning(t, where="T").startswith(
        "T has 1 gap(s) in time, the longest 5120 s between lines 21 and 22, where its fixes "
        "are 120 s apart")


@pytest.mark.long  # a dense match: 3-4 s with its compile
def test_a_time_gap_in_a_match_track_is_named(tmp_path, capsys):
    """A 10 h gap among 2-minute fixes was matched as one rigid offset, silently (exit 0):
    now named in the warnings and the JSON's status messages."""
    g = load_map("ryukyu")
    t = np.arange(30) * 120.0
    lat, lon = 30.2 + t * 4e-5, 130.4 + t * 4.5e-5
    z = np.asarray(g.sample(lat, lon, "bicubic"))
    t[15:] += 36000.0
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon,gravity\n" + "".join(
        f"{a:g},{b:.6f},{c:.6f},{d:.4f}\n" for a, b, c, d in zip(t, lat, lon, z, strict=True)))
    out = tmp_path / "m.json"
    assert main(["match", "--map", "ryukyu", "--track", str(track), "--out", str(out)]) == 0
    said = (f"--track {str(track)!r} has 1 gap(s) in time, the longest 36120 s between lines "
            "16 and 17, where its fixes are 120 s apart: the match fits one INS offset to the "
            "whole track, as if the INS error did not change across the gap; match the parts "
            "on either side separately")
    assert f"warning: {said}" in capsys.readouterr().err
    assert said in json.loads(out.read_text())["status_messages"]


def test_simulate_filter_refuses_a_geometry_it_would_not_use(tmp_path, refused):
    """``simulate-filter --map ryukyu --geometry north-east`` wrote a random straight track
    (exit 0): the geometry is paper D's, dropped over a map without a word."""
    out = tmp_path / "s.csv"
    refused(["simulate-filter", "--map", "ryukyu", "--geometry", "north-east",
             "--out", out],
            "--geometry north-east shapes the track over paper D's point masses; with --map "
            "the track is a straight line of random heading: leave --geometry out")
    assert not out.exists()


def test_simulate_refuses_a_probability_it_would_not_use(tmp_path, refused):
    """``simulate --probability 0.5`` (the default --drift-law fixed) wrote the same track as
    without it (exit 0): the quantile only sets the radius of --drift-law rayleigh."""
    out = tmp_path / "s.csv"
    refused(["simulate", "--probability", "0.5", "--out", out],
            "--probability 0.5 is the Rayleigh quantile of --drift-law rayleigh; with "
            "--drift-law fixed the search radius is 1.2 x --drift: give --drift-law rayleigh "
            "or leave it out")
    assert not out.exists()
    assert main(["simulate", "--probability", "0.5", "--drift-law", "rayleigh", "--n", "5",
                 "--out", str(out)]) == 0


@pytest.mark.parametrize(("command", "message"), [
    ("filter", "--seed is for --method pf or rbpf (their particles' draws); got --method ukf"),
    ("navigate", "--seed is for --method rbpf; got --method ukf"),
])
def test_a_seed_the_method_does_not_draw_with_is_refused(tmp_path, refused, filter_log, command,
                                                         message):
    """``filter --seed 5`` (ukf) gave the very run of seed 0, exit 0: a user trying seeds
    saw identical results and no word; --particles was already refused so."""
    out = tmp_path / "o.csv"
    source = ["--point-masses", "paper-d"] if command == "filter" else []
    refused([command, *source, "--track", filter_log, "--out", out, "--method", "ukf",
             "--seed", "5"], message)
    assert not out.exists()


@pytest.mark.parametrize(("argv", "drawn"), [
    (["match", "--map", "ryukyu", "--track", "{d}/t.csv", "--out", "{d}/m.json"], False),
    (["filter", "--point-masses", "paper-d", "--track", "{d}/t.csv", "--out", "{d}/o.csv"],
     False),
    (["suitability", "--map", "ryukyu", "--out", "{d}/s.nc"], False),
    (["simulate-filter", "--out", "{d}/o.csv"], False),
    (["simulate", "--out", "{d}/o.csv"], True),
    (["simulate-voyage", "--out", "{d}/o.csv", "--hours", "0.1"], True),
    (["montecarlo", "--method", "ukf", "--runs", "5", "--out", "{d}/m.nc"], True),
])
def test_a_map_error_length_without_a_map_error_is_refused(tmp_path, refused, argv, drawn):
    """``--map-error-length 5000`` alone ran on a perfect map (match, filter, suitability,
    the simulators; exit 0): the user believed the map's error modelled. montecarlo keeps
    it alone only beside --told-map-error SIGMA, as its length."""
    (tmp_path / "t.csv").write_text("t,lat,lon,gravity\n0,24.3,122.74,5\n2,24.3,122.7401,5.1\n"
                                    "4,24.3,122.7402,5.3\n")
    message = ("--map-error-length 5000 is the correlation length of the drawn map error, and "
               "no --map-error is given: add --map-error SIGMA, or leave it out" if drawn else
               "--map-error-length 5000 is the correlation length of the map's error, and no "
               "map error is given: add --map-error SIGMA (or --map-error-var NAME where the "
               "command takes it), or leave it out")
    refused([a.format(d=tmp_path) for a in argv] + ["--map-error-length", "5000"],
            message)
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]


def test_a_map_error_order_without_a_map_error_is_refused(tmp_path, refused, filter_log):
    """``filter --map-error-order 2`` alone ran with no map-error state at all (exit 0)."""
    out = tmp_path / "o.csv"
    refused(["filter", "--point-masses", "paper-d", "--track", filter_log, "--out", out,
             "--map-error-order", "2"],
            "--map-error-order 2 is the order of the map-error state, and no map error is "
            "given (the filter carries none): add --map-error SIGMA or --map-error-var NAME, "
            "or leave it out")
    assert not out.exists()


def test_montecarlo_refuses_a_map_error_order_with_no_map_error(tmp_path, refused):
    """``montecarlo --method ukf --map-error-order 2`` on paper D's masses (no map error
    drawn) ran, the order unused (exit 0)."""
    refused(["montecarlo", "--method", "ukf", "--runs", "5", "--out",
             tmp_path / "m.nc", "--map-error-order", "2"],
            "--map-error-order 2 is the order of the map-error state the filters are told, and "
            "the runs draw no map error: add --map-error SIGMA or --truth-map MAP, or leave it "
            "out")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("argv", "message"), [
    # "PosixPath('.') has an empty name"
    (["montecarlo", "--method", "dense", "--runs", "5", "--out="], "--out is empty; expected "
                                                                   "a path"),
    (["suitability", "--map", "ryukyu", "--out="], "--out is empty; expected a path"),
    # "--out '' is a folder; expected a file path"
    (["simulate", "--out="], "--out is empty; expected a path"),
    # the demo ran and wrote table1.md, summary.json, tracks.png into the working folder
    (["demo", "--smoke", "--out="], "--out is empty; expected a path"),
    # "map '.' is a folder; expected a NetCDF file"
    (["sample", "--map=", "--track", "t.csv", "--out", "s.csv"],
     "--map is empty; expected a NetCDF file or a shipped map's name"),
    (["filter", "--point-masses=", "--track", "t.csv", "--out", "s.csv"],
     "--point-masses is empty; expected paper-d or a MODEL.json file"),
])
def test_an_empty_path_is_named(tmp_path, refused, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    refused(argv, message)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("columns", "name"), [("foo=gravity", "foo"), ("LAT=lat", "LAT")])
def test_a_columns_name_the_commands_do_not_read_is_refused(tmp_path, refused, columns, name):
    """``sample --columns foo=gravity`` renamed the gravity column foo in the output (exit
    0); ``--columns LAT=lat`` (upper case) ended in "column 'lat' would be read as 'lat', but
    --columns LAT=lat reads it as 'LAT'"."""
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon,gravity\n0,30.2,130.4,5\n")
    out = tmp_path / "s.csv"
    refused(["sample", "--map", "ryukyu", "--track", track, "--out", out, "--columns",
             columns],
            f"--columns {columns}: {name!r} is not a name the commands read; the names are t, "
            "lat, lon, h, gravity, magnetic, v_east, v_north, drift_radius (lower case); "
            "COLUMN is the file's header or 1-based column number")
    assert not out.exists()


def test_suitability_refuses_two_readings_a_segment(tmp_path, refused):
    """``suitability --fixes 2`` wrote "0 of 83521 nodes have a bound" (every node
    no_information, exit 0): two readings cannot fix two coordinates and a bias."""
    out = tmp_path / "s.nc"
    refused(["suitability", "--map", "ryukyu", "--out", out, "--fixes", "2"],
            "--fixes 2 places no segment: two readings cannot give the position (north, east) "
            "and the free gravimeter bias; give at least 3")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("argv", "message"), [
    (["simulate", "--n", "5", "--out", "{d}/new/"],
     "--out '{d}/new/' ends in a slash, a folder, and jaxgrav simulate writes a file there: "
     "give a file name in it, e.g. '{d}/new/NAME.csv'"),
    (["montecarlo", "--method", "dense", "--runs", "5", "--out", "{d}/new/"],
     "e.g. '{d}/new/NAME.nc'"),
])
def test_an_output_ending_in_a_slash_is_not_written_as_a_file(tmp_path, refused, argv, message):
    """``simulate --out new/`` wrote a file named 'new' (montecarlo: 'new' and 'new.png'),
    exit 0, where the user meant a folder."""
    refused([a.format(d=tmp_path) for a in argv], message.format(d=tmp_path))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not os.path.exists("/dev/stdin"), reason="needs /dev/stdin")
def test_a_track_on_standard_input_is_read_with_a_dash(tmp_path, capsys):
    """``cat log.csv | jaxgrav sample --track - ...``: "track file '-' does not exist"."""
    track = tmp_path / "t.csv"
    track.write_text("lat,lon\n30.2,130.4\n30.3,130.5\n")
    out = tmp_path / "s.csv"
    saved = os.dup(0)
    with open(track, "rb") as f:
        os.dup2(f.fileno(), 0)
        try:
            code = main(["sample", "--map", "ryukyu", "--track", "-", "--out", str(out)])
        finally:
            os.dup2(saved, 0)
            os.close(saved)
    assert code == 0, capsys.readouterr().err
    assert out.read_text().splitlines()[0] == "lat,lon,map"
    assert len(out.read_text().splitlines()) == 3


def test_filter_refuses_a_map_variable_with_point_masses(tmp_path, refused, filter_log):
    """``filter --point-masses paper-d --var z`` ran on the masses, --var unused (exit 0)."""
    out = tmp_path / "o.csv"
    refused(["filter", "--point-masses", "paper-d", "--var", "z", "--track", filter_log,
             "--out", out],
            "--var z names a variable of a --map file; --point-masses paper-d has none: leave "
            "--var out")
    assert not out.exists()


def test_simulate_filter_refuses_a_map_variable_without_a_map(tmp_path, refused):
    """``simulate-filter --var z`` (no --map) simulated paper D's masses, --var unused."""
    out = tmp_path / "s.csv"
    refused(["simulate-filter", "--var", "z", "--out", out],
            "--var z names a variable of --map; without --map the readings come from paper "
            "D's point masses: give --map or leave --var out")
    assert not out.exists()
