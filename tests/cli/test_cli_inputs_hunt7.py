"""Inputs found by the seventh issue-19 hunt (2026-12-07, helper-67).

The last hunt's leftovers: the shipped datasets' messages printed Python lists, ``demo
--out`` into an unwritable place did not name the option, Unix times in milliseconds
were read as seconds, a leap second (``23:59:60``) was refused, and ``--track -`` was
called ``'/dev/stdin'``. Then the hunt's own finds (below them)."""

import os
import warnings

import numpy as np
import pytest
import xarray as xr

from jaxgrav import datasets
from jaxgrav.cli import main
from jaxgrav.cli.main import STDIN_NAME, stdin_named
from jaxgrav.track_times import epoch_unit, iso_seconds, parse_datetime
from jaxgrav.tracks import read_track_csv

ROWS = [(29.5 + 0.0056 * i, 126.5 + 0.0068 * i) for i in range(5)]


def _track(path, header, times):
    path.write_text(header + "\n" + "".join(f"{t},{lat},{lon}\n"
                                            for t, (lat, lon) in zip(times, ROWS, strict=True)))
    return path


@pytest.mark.parametrize("call, message", [
    (lambda: datasets.path("etopo"), "unknown dataset 'etopo'; expected one of qinling, ryukyu"),
    (lambda: datasets.load_map("ryukyu:bogus"),
     "dataset 'ryukyu' has no map 'bogus'; expected one of anomaly_0p5deg, anomaly_2p5min"),
])
def test_dataset_messages_list_names_as_text(call, message):
    """Were "available: ['qinling', 'ryukyu']" and "it has ['anomaly_0p5deg', ...]"."""
    with pytest.raises(ValueError) as err:
        call()
    assert str(err.value) == message


def test_demo_into_an_unwritable_place_names_out(refused):
    """``demo --out /proc/x`` named '/proc/x/table1.md' but not the option."""
    if os.access("/proc", os.W_OK) and not os.path.isdir("/proc/self"):
        pytest.skip("needs a /proc that refuses files")
    refused(["demo", "--smoke", "--out", "/proc/x"],
            "--out '/proc/x/table1.md': a file cannot be created in the folder '/proc'")


def test_demo_existing_outputs_name_out(tmp_path, refused):
    (tmp_path / "summary.json").write_text("keep\n")
    refused(["demo", "--smoke", "--out", tmp_path],
            f"--out '{tmp_path}/summary.json' exists; pass --force to overwrite it")
    assert (tmp_path / "summary.json").read_text() == "keep\n"


@pytest.mark.parametrize("t0, factor, name", [
    (1714564800000, 1e-3, "milliseconds"), (1714564800000000, 1e-6, "microseconds"),
    (1714564800000000000, 1e-9, "nanoseconds")])
def test_unix_times_in_milliseconds_are_read_as_seconds_with_a_warning(
        tmp_path, capsys, t0, factor, name):
    """``t`` = 1714564800000 (2024 in ms, a phone's or GNSS logger's) was read as
    seconds, the year 56302, its two-minute steps 33 hours long (exit 0)."""
    step = int(120 / factor)
    path = _track(tmp_path / "t.csv", "t,lat,lon", [t0 + step * i for i in range(5)])
    out = tmp_path / "s.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(path), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"are Unix times in {name} (as seconds they would be in the year" in err, err
    assert "declare the unit in the header, e.g. 't (" in err and err.count("\n") == 1
    t = [float(line.split(",")[0]) for line in out.read_text().splitlines()[1:]]
    np.testing.assert_allclose(t, 1714564800 + 120 * np.arange(5))


def test_unix_times_in_a_declared_unit_are_converted_without_a_word(tmp_path, capsys):
    path = _track(tmp_path / "t.csv", "t (ms),lat,lon", [1714564800000 + 120000 * i
                                                          for i in range(5)])
    assert main(["sample", "--map", "ryukyu", "--track", str(path), "--out",
                 str(tmp_path / "s.csv")]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("header, times, message", [
    ("t (s)", [1714564800000 + 120000 * i for i in range(5)],
     "column 't (s)': the first time, read in the header's unit (s), is 1714564800000 s, the "
     "year 56302 as a Unix time (today's is about 1.8e9 s); check the unit in the header "
     "(e.g. 't (ms)' for milliseconds)"),
    ("t", [1714564800000, 1714564920000, 1714565040000000, 1714565160000000, 1714565280000000],
     "column 't': the times mix units: 1714564800000 on line 2 is a Unix time in "
     "milliseconds, 1714565040000000 on line 4 is not"),
])
def test_implausible_seconds_are_refused(tmp_path, refused, header, times, message):
    path = _track(tmp_path / "t.csv", header + ",lat,lon", times)
    refused(["sample", "--map", "ryukyu", "--track", path, "--out", tmp_path / "s.csv"], message)
    assert not (tmp_path / "s.csv").exists()


@pytest.mark.parametrize("t, unit", [([0, 60, 1e11], None), ([1.7e9, 1.8e9], None), ([], None),
                                     ([1.7e12, 1.8e12], "ms"), ([1.7e15], "us"),
                                     ([1.7e18], "ns")])
def test_epoch_unit_by_magnitude(t, unit):
    found = epoch_unit(t)
    assert (found and found[2]) == unit


@pytest.mark.parametrize("cell, iso", [
    ("2016-12-31T23:59:60Z", "2017-01-01T00:00:00+00:00"),
    ("2016-12-31T23:59:60.5Z", "2017-01-01T00:00:00.500000+00:00"),
    ("2016-12-31 23:59:60 UTC", "2017-01-01T00:00:00+00:00"),
    ("2017-01-01T08:59:60+09:00", "2017-01-01T09:00:00+09:00"),
    ("2016-12-31T23:59:60", "2017-01-01T00:00:00")])
def test_a_leap_second_is_the_next_midnight(cell, iso):
    """``2016-12-31T23:59:60Z`` was "neither a number nor an ISO-8601 date-time"."""
    assert parse_datetime(cell).isoformat() == iso


def test_times_around_a_leap_second_are_one_second_apart():
    cells = ["2016-12-31T23:59:59.5Z", "2016-12-31T23:59:60Z", "2016-12-31T23:59:60.5Z",
             "2017-01-01T00:00:00Z", "2017-01-01T00:00:00.5Z"]
    seconds, origin = iso_seconds(cells, range(2, 7), "x", "time")
    assert list(seconds) == [0, 0.5, 1, 1.5, 2] and origin == "2016-12-31T23:59:59.500000+00:00"
    two = ["2016-06-30T23:59:59Z", "2016-06-30T23:59:60Z", "2016-07-01T00:00:00Z",
           "2016-12-31T23:59:60Z", "2017-01-01T00:00:00Z"]
    seconds, _ = iso_seconds(two, range(2, 7), "x", "time")
    assert list(seconds - [0, 0, 0, 15897600, 15897600]) == [0, 1, 2, 2, 3]


def test_a_log_across_a_leap_second_is_read(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("time,lat,lon\n" + "".join(
        f"{c},{lat},{lon}\n" for c, (lat, lon) in zip(
            ["2016-12-31T23:59:58Z", "2016-12-31T23:59:59Z", "2016-12-31T23:59:60Z",
             "2017-01-01T00:00:00Z", "2017-01-01T00:00:01Z"], ROWS, strict=True)))
    track = read_track_csv(path, required=("t", "lat", "lon"))
    assert list(track["t"]) == [0, 1, 2, 3, 4]
    assert track.text["time"][2] == "2016-12-31T23:59:60Z"


def test_second_60_other_than_at_midnight_utc_is_refused(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("time,lat,lon\n2016-12-31T12:00:60Z,30,130\n")
    with pytest.raises(ValueError, match=r"line 2, column 'time': '2016-12-31T12:00:60Z' is "
                       r"neither .* \(second 60 is a leap second, which only 23:59:60 UTC "
                       r"can be\)"):
        read_track_csv(path, required=("t", "lat", "lon"))


def test_standard_input_is_named_so():
    """``--track -`` was named '/dev/stdin' in messages, a name the user never gave."""
    assert stdin_named("track file '/dev/stdin', line 3, column 'lat': 'x'") == (
        f"{STDIN_NAME}, line 3, column 'lat': 'x'")
    assert stdin_named("--track '/dev/stdin' has 2 rows") == f"{STDIN_NAME} has 2 rows"


@pytest.mark.skipif(not os.path.exists("/dev/stdin"), reason="needs /dev/stdin")
@pytest.mark.parametrize("argv, message", [
    (["sample", "--map", "ryukyu", "--out", "o.csv"],
     "standard input (--track -), line 3, column 'lat': 'x' is not a number"),
    (["match", "--map", "ryukyu", "--out", "o.json"],
     "standard input (--track -), line 3, column 'lat'")])
def test_a_bad_track_on_standard_input_names_it(tmp_path, capsys, argv, message):
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon\n0,29.5,126.5\n60,x,126.6\n")
    saved = os.dup(0)
    with open(track, "rb") as f:
        os.dup2(f.fileno(), 0)
        try:
            code = main([*argv[:-1], str(tmp_path / argv[-1]), "--track", "-"])
        finally:
            os.dup2(saved, 0)
            os.close(saved)
    err = capsys.readouterr().err
    assert code == 2 and message in err and "/dev/stdin" not in err, err
    assert list(tmp_path.iterdir()) == [track]


def _map(path, lat, lon, **encoding):
    """A small NetCDF map ``z`` (mGal) on ``lat`` x ``lon``."""
    values = 10 * np.sin(np.add.outer(np.asarray(lat) * 3, np.asarray(lon) * 2))
    ds = xr.Dataset({"z": (("lat", "lon"), values, {"units": "mGal"})},
                    coords={"lat": lat, "lon": lon})
    ds.to_netcdf(path, encoding={"z": encoding} if encoding else None)
    return path


@pytest.mark.parametrize("lat, lon, message", [
    ([29.5], np.linspace(126, 127, 11),
     "lat has 1 node (at 29.5); a map needs at least 2 along each axis, in one dimension (a "
     "grid, not a single row or column)"),
    (np.linspace(29, 30, 11), [126.5], "lon has 1 node (at 126.5); a map needs at least 2")])
def test_a_map_of_one_row_or_column_is_refused_in_words(tmp_path, refused, lat, lon, message):
    """Was "lat must be a 1-D array of at least 2 nodes; got shape (1,)" (a Python tuple)."""
    path = _map(tmp_path / "m.nc", lat, lon)
    (tmp_path / "t.csv").write_text("lat,lon\n29.5,126.5\n")
    err = refused(["sample", "--map", path, "--track", tmp_path / "t.csv", "--out",
                   tmp_path / "s.csv"], message)
    assert "shape" not in err and "(1,)" not in err
    assert not (tmp_path / "s.csv").exists()


def test_a_truncated_netcdf_map_is_named_damaged(tmp_path, refused, clear_message):
    """Was "cannot be read as NetCDF: [Errno -101] NetCDF: HDF error: '/full/path'"."""
    whole = _map(tmp_path / "whole.nc", np.linspace(29, 30, 11), np.linspace(126, 127, 11))
    path = tmp_path / "m.nc"
    path.write_bytes(whole.read_bytes()[:300])
    (tmp_path / "t.csv").write_text("lat,lon\n29.5,126.5\n")
    err = refused(["sample", "--map", path, "--track", tmp_path / "t.csv", "--out",
                   tmp_path / "s.csv"], f"map '{path}' cannot be read as NetCDF: ")
    clear_message(err, path, ["(the file may be truncated or damaged: copy it again)"])
    assert "Errno" not in err and err.count(str(path)) == 1


@pytest.mark.parametrize("argv, message", [
    (["simulate", "--out", "{d}/s.csv", "--n", "1e300"],
     "argument --n: expected a whole number of at most 1e+15 (a count); got '1e300'"),
    (["simulate", "--out", "{d}/s.csv", "--n", "99999999999999999999999"],
     "got '99999999999999999999999'"),
    (["montecarlo", "--method", "dense", "--out", "{d}/m.nc", "--runs", "5", "--fixes", "1e300"],
     "argument --fixes: expected a whole number of at most 1e+15"),
    (["suitability", "--map", "ryukyu:anomaly_0p5deg", "--out", "{d}/s.nc", "--fixes", "1e300"],
     "argument --fixes: expected a whole number of at most 1e+15"),
])
def test_a_huge_count_is_refused_without_its_digits(tmp_path, capsys, argv, message):
    """``--n 1e300`` was refused by a message holding the count's 301 digits."""
    with pytest.raises(SystemExit) as exit_:
        main([a.format(d=tmp_path) for a in argv])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and "\n" not in err and message in err, err
    assert "0000000000000000" not in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, message", [
    (["--noise", "1e300"], "--noise must be at most 1000 mGal (a marine gravimeter's noise is "
                           "about 1); got 1e+300"),
    (["--map-error", "2000"], "--map-error must be at most 1000 mGal (a marine map's error is a "
                              "few mGal); got 2000"),
    (["--spacing", "1e300"], "make a segment of 2.9e+298 km, 5.23e+296 nodes of the map"),
])
def test_suitability_refuses_a_noise_that_overflows(tmp_path, refused, argv, message):
    """``suitability --noise 1e300`` (squared: inf) ran; ``--spacing 1e300`` was refused
    naming a segment of 297 digits of nodes."""
    refused(["suitability", "--map", "ryukyu:anomaly_0p5deg", "--out", tmp_path / "s.nc",
             *argv], message)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("cell, iso", [
    ("2024-05-01T24:00:00Z", "2024-05-02T00:00:00+00:00"),
    ("2024-12-31 24:00", "2025-01-01T00:00:00"),
    ("2024-5-1 12:00:00", "2024-05-01T12:00:00"),
    ("2024-05-01 12:00:00.000 +0000", "2024-05-01T12:00:00+00:00"),
    ("2024-05-01 12:00:00 -05:00", "2024-05-01T12:00:00-05:00")])
def test_end_of_day_unpadded_dates_and_spaced_offsets_are_read(cell, iso):
    """ISO's ``24:00:00`` ("hour must be in 0..23"), ``2024-5-1`` (read with slashes
    only) and an offset after a space behind a fraction were refused."""
    assert parse_datetime(cell).isoformat() == iso


@pytest.mark.parametrize("cell", ["05/01/2024 12:00:00", "01.05.24 12:00", "1-5-24"])
def test_a_date_with_the_year_last_is_refused_as_ambiguous(tmp_path, cell):
    """``05/01/2024`` (May 1st or January 5th) was "neither a number nor an ISO-8601
    date-time" with no word of why; it is not guessed."""
    path = tmp_path / "t.csv"
    path.write_text(f"time,lat,lon\n{cell},30,130\n")
    with pytest.raises(ValueError, match=r"line 2, column 'time': .* \(a date with the year "
                       r"last, day/month or month/day: ambiguous; write it year first, e\.g\. "
                       r"2024-05-01\); times must be complete"):
        read_track_csv(path, required=("t", "lat", "lon"))


@pytest.mark.parametrize("layers", ["", " , "])
def test_dov_refuses_empty_layers(tmp_path, refused, layers):
    """``dov --layers ''`` ran on the default heights (0, 10000, 20000 m), exit 0."""
    track = tmp_path / "t.csv"
    track.write_text("lat,lon,h\n35.1,110.1,100\n35.2,110.2,200\n")
    refused(["dov", "--track", track, "--out", tmp_path / "o.csv", f"--layers={layers}"],
            f"--layers {layers!r} is empty; expected comma-separated heights in m, e.g. "
            "0,10000,20000 (or leave it out for the default)")
    assert not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize("name, text", [
    # "'0.0D+00' is neither a number (seconds) nor an ISO-8601 date-time"
    ("f.csv", "t,lat,lon\n0.0D+00,2.95D+01,1.265d2\n6.0D+01,29.51D0,126.51D+00\n"),
    # "lacks columns lat and lon; it has t|lat|lon"
    ("p.csv", "t|lat|lon\n0|29.5|126.5\n60|29.51|126.51\n"),
    # numpy.savetxt(header="t,lat,lon"): "lacks columns lat and lon; it has 1, 2, 3"
    ("h.csv", "# t,lat,lon\n0,29.5,126.5\n60,29.51,126.51\n"),
    ("h.xyz", "# GMT output\n# t lat lon\n0 29.5 126.5\n60 29.51 126.51\n"),
])
def test_fortran_exponents_pipes_and_a_commented_header_are_read(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    track = read_track_csv(path, required=("t", "lat", "lon"))
    assert list(track["t"]) == [0, 60] and list(track["lat"]) == [29.5, 29.51]
    assert list(track["lon"]) == [126.5, 126.51]


def test_a_comment_that_is_no_header_leaves_the_columns_numbered(tmp_path):
    path = tmp_path / "n.csv"
    path.write_text("# written by logger v2\n29.5,126.5\n29.51,126.51\n")
    track = read_track_csv(path, required=("lat", "lon"), columns={"lat": "1", "lon": "2"})
    assert list(track["lat"]) == [29.5, 29.51]


@pytest.mark.parametrize("own, rows, hint", [
    (False, [(0.5149, 2.2078), (0.5151, 2.2080)],
     "; in degrees these numbers would lie on the map: are they radians? declare the unit in "
     "the header, e.g. 'lat (rad)' and 'lon (rad)'"),
    (True, [(45.5, 15.5), (45.6, 15.6)],
     "; with latitude and longitude swapped they would lie on the map: are the columns "
     "swapped? name them with --columns lat=COLUMN,lon=COLUMN"),
    (True, [(0.0, 0.0), (15.5, 45.5)], "(lat 0, lon 0)"),  # not all off: no hint
])
def test_a_track_wholly_off_the_map_says_why_when_it_is_plain(tmp_path, refused, own, rows,
                                                               hint):
    """A track in radians, or with its columns swapped, was only "off the map"."""
    map_ = _map(tmp_path / "m.nc", np.linspace(10, 20, 11), np.linspace(40, 50, 11)) if own \
        else "ryukyu"
    track = tmp_path / "t.csv"
    track.write_text("lat,lon\n" + "".join(f"{a},{b}\n" for a, b in rows))
    err = refused(["sample", "--map", map_, "--track", track, "--out", tmp_path / "s.csv"],
                  "positions are off the map")
    assert err.endswith(hint), err
    assert not (tmp_path / "s.csv").exists()


def test_a_map_declaring_fillvalue_and_missing_value_is_read_quietly(tmp_path, capsys):
    """Both declared (CF: both missing) printed xarray's two-line SerializationWarning with
    "{np.float64(-8888.0), np.float64(-9999.0)}" on stderr."""
    lat, lon = np.linspace(29, 31, 21), np.linspace(126, 128, 21)
    values = 10 * np.sin(np.add.outer(lat * 3, lon * 2))
    values[0, 0] = -8888.0
    xr.Dataset({"z": (("lat", "lon"), values, {"units": "mGal", "missing_value": -8888.0})},
               coords={"lat": lat, "lon": lon}).to_netcdf(
        tmp_path / "m.nc", encoding={"z": {"_FillValue": -9999.0}})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        grid = datasets.load_map(tmp_path / "m.nc", allow_nan=True)
    assert grid.n_missing == 1 and [str(w.message) for w in caught] == []
    track = tmp_path / "t.csv"
    track.write_text("lat,lon\n30,127\n30.1,127.1\n")
    assert main(["sample", "--map", str(tmp_path / "m.nc"), "--track", str(track), "--out",
                 str(tmp_path / "s.csv")]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("times, hint", [
    ((86340, 86399, 59), "; seconds of the day, starting again at 0 after 86400? give times "
                         "that keep counting (add the date, e.g. ISO-8601 date-times)"),
    ((604700, 604790, 80), "; seconds of the GPS week, starting again at 0 after 604800? "
                           "give times that keep counting (add the date, e.g. ISO-8601 "
                           "date-times)"),
    ((100, 200, 90), "backward step(s))"),
])
def test_times_of_day_that_restart_at_midnight_are_named(tmp_path, times, hint):
    """A log in seconds of the day across midnight was only "time 59 is earlier than
    86399; times must increase"."""
    path = tmp_path / "t.csv"
    path.write_text("t,lat,lon\n" + "".join(f"{t},30,130\n" for t in times))
    with pytest.raises(ValueError) as err:
        read_track_csv(path, required=("t", "lat", "lon"))
    assert str(err.value).endswith(hint) and "line 4" in str(err.value), str(err.value)


@pytest.mark.parametrize("text, looks", [
    ("ncols 3\nnrows 3\nxllcorner 126\nyllcorner 29\ncellsize 0.5\n1 2 3\n4 5 6\n7 8 9\n",
     "(it is an ESRI ASCII grid: convert it, e.g. gdal_translate -of netCDF IN OUT.nc)"),
    ("126.5 29.5 1.0\n127 29.5 2.0\n", "(it is a text file starting '126.5 29.5 1.0', a CSV "
                                      "track or table? a table of lon, lat, value converts "
                                      "with GMT's xyz2grd)")])
def test_a_text_grid_given_as_map_says_how_to_convert_it(tmp_path, refused, text, looks):
    """An ESRI ASCII grid was "a text file starting 'ncols 3', a CSV track or table?"."""
    (tmp_path / "m.asc").write_text(text)
    (tmp_path / "t.csv").write_text("lat,lon\n29.5,126.5\n")
    refused(["sample", "--map", tmp_path / "m.asc", "--track", tmp_path / "t.csv", "--out",
             tmp_path / "s.csv"], f"map '{tmp_path / 'm.asc'}' is not a NetCDF file {looks}")


@pytest.mark.parametrize("header, scale", [
    ("time_s,lat_deg,lon_deg,gravity_mgal", (1, 1, 1)),
    ("t_ms,Latitude_deg,Longitude_DEG,gravity_ugal", (1e-3, 1, 1e-3)),
    ("time_min,lat_rad,lon_rad,gravity", (60, 180 / np.pi, 1))])
def test_a_unit_after_an_underscore_is_read(tmp_path, header, scale):
    """``time_s,lat_deg,lon_deg`` (a logger's snake-case headers) was "lacks columns lat and
    lon; it has time_s, lat_deg, lon_deg, ..."."""
    path = tmp_path / "t.csv"
    path.write_text(header + "\n0,0.5,2.2,10\n1,0.51,2.21,20\n")
    track = read_track_csv(path, required=("t", "lat", "lon", "gravity"))
    assert track["t"][1] == pytest.approx(scale[0])
    assert track["lat"][0] == pytest.approx(0.5 * scale[1])
    assert track["gravity"][1] == pytest.approx(20 * scale[2])


@pytest.mark.parametrize("header", ["t,lat_s,lon,x", "t,lat,lon_e,x", "t,lat,lon,v_east"])
def test_an_underscore_that_is_no_unit_stays_in_the_name(tmp_path, header):
    """``lat_s`` is not latitudes in seconds (nor south): it stays a column of its own."""
    path = tmp_path / "t.csv"
    path.write_text(header + "\n0,30,130,1\n")
    assert set(header.split(",")) <= set(read_track_csv(path, required=("t",)).order)


@pytest.mark.parametrize("encoding", ["cp1252", "utf-8"])
def test_typographic_quotes_as_minute_and_second_marks_are_read(tmp_path, encoding):
    """``35°27’42”N`` (a word processor's quotes) was "not a number"; in a Windows-1252
    file the ’ read as the control character '\\x92' (Latin-1)."""
    path = tmp_path / "t.csv"
    path.write_bytes("lat,lon\n35°27’42”N,127°30’E\n35°27.8’N,127°31’E\n".encode(encoding))
    track = read_track_csv(path, required=("lat", "lon"))
    np.testing.assert_allclose(track["lat"], [35.461667, 35.463333], atol=1e-6)
    np.testing.assert_allclose(track["lon"], [127.5, 127.516667], atol=1e-6)


def test_a_windows_1252_header_keeps_its_symbols(tmp_path):
    path = tmp_path / "t.csv"
    path.write_bytes("lat,lon,depth (m) – “raw”\n30,130,5\n".encode("cp1252"))
    assert read_track_csv(path, required=("lat", "lon")).order[-1] == "depth (m) – “raw”"


def test_unix_milliseconds_with_a_missing_time_are_still_converted(tmp_path, capsys):
    """``sample`` (times optional) kept a column of ms with one empty cell as seconds."""
    path = tmp_path / "t.csv"
    path.write_text("t,lat,lon\n,29.5,126.5\n1714564800000,29.51,126.51\n"
                    "1714564920000,29.52,126.52\n")
    out = tmp_path / "s.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(path), "--out", str(out)]) == 0
    assert "times such as 1714564800000 are Unix times in milliseconds" in capsys.readouterr().err
    assert [line.split(",")[0] for line in out.read_text().splitlines()] == [
        "t", "", "1714564800", "1714564920"]
