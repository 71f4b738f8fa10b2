"""Inputs found by the eleventh issue-19 hunt (2026-12-08, helper-85).

The last hunt's leftovers first: ``filter --method pmf --point-masses`` with a tiny
``--sigma-pos`` ran ("final 1-sigma 0 m"), map coordinates packed as ``int32`` were
refused as irregular, ``01.05.2024`` was refused as ambiguous, ``match`` suggested
``--columns gravity=`` on a magnetic map, its JSON called nT ``map_error_mgal``, and
German headers (``Breite``, ``Länge``, ``Zeit``) needed ``--columns``. Then the hunt's own
finds (below them)."""

import json

import numpy as np
import pytest
import xarray as xr

from jaxgrav.cli import main
from jaxgrav.datasets import load_map
from jaxgrav.tracks import read_track_csv

ROWS = [(29.5 + 0.0056 * i, 126.5 + 0.0068 * i) for i in range(8)]


def _track(path, header="t,lat,lon,gravity", rows=None, newline="\n"):
    rows = rows if rows is not None else [f"{120 * i},{lat:.4f},{lon:.4f},{-10 + i}"
                                          for i, (lat, lon) in enumerate(ROWS)]
    path.write_text(header + newline + newline.join(rows) + newline, encoding="utf-8")
    return path


def _small_map(path, units="mGal", **encoding):
    """The shipped map's 36 x 36 nodes from 29.4 N 126.0 E, in ``units``; ``encoding`` of
    the coordinates (e.g. ``dtype="int32", scale_factor=1e-6``)."""
    grid = load_map("ryukyu")
    lat, lon, values = (np.asarray(a) for a in (grid.lat, grid.lon, grid.values))
    i, j = np.searchsorted(lat, 29.4), np.searchsorted(lon, 126.0)
    xr.Dataset({"z": (("lat", "lon"), values[i:i + 36, j:j + 36], {"units": units})},
               coords={"lat": lat[i:i + 36], "lon": lon[j:j + 36]}).to_netcdf(
        path, encoding={c: encoding for c in ("lat", "lon")} if encoding else None)
    return path


def _sampled(tmp_path, grid, track, name="s.csv"):
    out = tmp_path / name
    assert main(["sample", "--map", str(grid), "--track", str(track), "--out", str(out)]) == 0
    return np.loadtxt(out, delimiter=",", skiprows=1, usecols=-1)


# --- the last hunt's leftovers ----------------------------------------------------------

def test_pmf_on_point_masses_refuses_a_sigma_pos_they_cannot_resolve(tmp_path, refused):
    """``filter --point-masses paper-d --method pmf --sigma-pos 1e-9`` ran: "final 1-sigma
    0 m", every row at the grid's edge, exit 0 (the check needed a grid's slope; the
    model's gradient along the track stands in for it)."""
    rows = [f"{2 * i},{24.2 + 1e-4 * i:.5f},{122.9 + 1e-4 * i:.5f},{-10 + 0.1 * i:.2f}"
            for i in range(30)]
    log = _track(tmp_path / "log.csv", rows=rows)
    out = tmp_path / "o.csv"
    err = refused(["filter", "--point-masses", "paper-d", "--track", log, "--out", out,
                   "--method", "pmf", "--sigma-pos", "1e-9"],
                  "--sigma-pos 1e-09 m makes pmf's grid 8e-09 m across (±4 sigma, the region "
                  "it searches), across which the field changes by at most")
    assert "(its steepest gradient along the track is" in err
    assert "expected a --sigma-pos of at least" in err and not out.exists()


@pytest.mark.parametrize("scale", [1e-6, 1e-7])
def test_map_coordinates_packed_as_integers_are_read(tmp_path, scale):
    """``lat``/``lon`` stored as ``int32`` with ``scale_factor`` 1e-6 were refused: "the
    step from lat[0] = 29.416667 to lat[1] = 29.458333 is 0.041666, not the regular
    0.041667" (the packing's rounding, well below a metre)."""
    track = _track(tmp_path / "t.csv")
    plain = _sampled(tmp_path, _small_map(tmp_path / "f.nc"), track, "f.csv")
    packed = _sampled(tmp_path, _small_map(tmp_path / "p.nc", dtype="int32",
                                           scale_factor=scale), track, "p.csv")
    np.testing.assert_allclose(packed, plain, atol=1e-3)  # 0.5e-6 deg: 5 cm, 1e-6 mGal/cm


@pytest.mark.parametrize("header", ["t,latitudeE7,longitudeE7", "t,lat_e7,lon_e7",
                                    "t,lat (degE7),lon (degE7)"])
def test_positions_in_whole_degrees_times_1e7_are_read_when_declared(tmp_path, header):
    """Google's location history (``latitudeE7``) and MAVLink (``degE7``) write integers:
    ``latitudeE7`` was "lacks columns lat and lon"."""
    track = _track(tmp_path / "t.csv", header, ["0,295000000,1265000000",
                                                "60,295056000,1265068000"])
    got = read_track_csv(track, required=("t", "lat", "lon"))
    np.testing.assert_allclose(got["lat"], [29.5, 29.5056], rtol=1e-12)
    np.testing.assert_allclose(got["lon"], [126.5, 126.5068], rtol=1e-12)


def test_undeclared_positions_times_1e7_are_named(tmp_path, refused):
    track = _track(tmp_path / "t.csv", "t,lat,lon", ["0,295000000,1265000000",
                                                     "60,295056000,1265068000"])
    refused(["sample", "--map", "ryukyu", "--track", track, "--out", tmp_path / "s.csv"],
            f"track file {str(track)!r}, line 2, column 'lat': latitude 2.95e+08 is outside "
            "[-90, 90] degrees; whole numbers of degrees x 1e7 (degE7, as MAVLink and Google's "
            "location history write them)? 295000000 would be 29.5 degrees: declare it in the "
            "header, e.g. 'lat (1e-7 deg)' or 'lat_e7'")


def test_dates_with_dots_are_day_month_year(tmp_path):
    """``01.05.2024 12:00:00`` (German, Russian, ... software) was refused as "a date with
    the year last, day/month or month/day: ambiguous"; with dots it is day.month.year."""
    track = _track(tmp_path / "t.csv", "time,lat,lon",
                   ["30.04.2024 23:59:00,29.5,126.5", "1.5.2024 00:01:00,29.51,126.51"])
    got = read_track_csv(track, required=("t", "lat", "lon"))
    np.testing.assert_allclose(got["t"], [0.0, 120.0])
    assert got.time_origin == "2024-04-30T23:59:00"


def test_a_dotted_date_without_a_month_is_named(tmp_path):
    track = _track(tmp_path / "t.csv", "time,lat,lon", ["13.13.2024 12:00,29.5,126.5"])
    with pytest.raises(ValueError, match=r"'13.13.2024 12:00' is neither a number .* \(a date "
                                         r"with dots is day.month.year, and 13 is no month\)"):
        read_track_csv(track, required=("t", "lat", "lon"))


def test_a_german_log_is_read_without_columns(tmp_path):
    """``Datum;Zeit;Breite;Länge;Schwere [mGal]`` with decimal commas and CRLF (a German
    spreadsheet's CSV) was "lacks columns lat and lon"."""
    rows = ["01.05.2024;" + f"12:{2 * i:02d}:00;{lat:.4f};{lon:.4f};{i - 9.5:.1f}".replace(".", ",")
            for i, (lat, lon) in enumerate(ROWS)]
    track = _track(tmp_path / "de.csv", "Datum;Zeit;Breite;Länge;Schwere [mGal]", rows,
                   newline="\r\n")
    got = read_track_csv(track, required=("t", "lat", "lon", "gravity"))
    np.testing.assert_allclose(got["t"], 120.0 * np.arange(8))
    np.testing.assert_allclose(got["lat"], [round(a, 4) for a, _ in ROWS])
    np.testing.assert_allclose(got["gravity"], -9.5 + np.arange(8))
    assert got.renamed == {"t": "Zeit", "lat": "Breite", "lon": "Länge",
                           "gravity": "Schwere [mGal]"}


def _magnetic_track(path, column="reading"):
    rows = [f"{60 * i},{29.45 + 0.004 * i:.4f},{126.3 + 0.005 * i:.4f},{40 + i}"
            for i in range(12)]
    return _track(path, f"t,lat,lon,{column}", rows)


@pytest.mark.parametrize("units, column, hint", [
    ("nT", "reading", "(--map '{m}' is in nT: name the readings' column with --columns "
                      "magnetic=COLUMN)"),
    ("mGal", "RMI (nT)", "(column 'RMI (nT)' declares nT: if it holds the readings, give "
                         "--columns magnetic='RMI (nT)')")])
def test_match_names_the_readings_column_of_the_map_s_field(tmp_path, refused, units, column,
                                                              hint):
    """On a magnetic map, a track without a readings column was told "name the readings'
    column with --columns gravity=COLUMN"."""
    grid = _small_map(tmp_path / "m.nc", units)
    track = _magnetic_track(tmp_path / "t.csv", column)
    refused(["match", "--map", grid, "--track", track, "--out", tmp_path / "r.json"],
            f"track file {str(track)!r} needs a 'gravity' (mGal) or 'magnetic' (nT) column; it "
            f"has t, lat, lon, {column} " + hint.format(m=grid))


def test_the_match_json_on_a_magnetic_map_names_its_map_error_in_nt(tmp_path):
    """``map_error_mgal`` held nT (its units block said so): now ``map_error_nt``."""
    grid = _small_map(tmp_path / "m.nc", "nT")
    out = tmp_path / "r.json"
    assert main(["match", "--map", str(grid), "--track",
                 str(_magnetic_track(tmp_path / "t.csv", "magnetic")), "--out", str(out),
                 "--method", "entropy"]) == 0
    r = json.loads(out.read_text())
    assert r["map_error_nt"] == 0.0 and r["units"]["map_error_nt"] == "nT"
    assert "map_error_mgal" not in r and "map_error_mgal" not in r["units"]


@pytest.mark.long
def test_montecarlo_settings_on_a_magnetic_map_are_named_in_nt(tmp_path):
    """The Monte Carlo attribute ``setting_noise_mgal`` held nT on an nT map."""
    out = tmp_path / "mc.nc"
    assert main(["montecarlo", "--method", "entropy", "--map",
                 str(_small_map(tmp_path / "m.nc", "nT")), "--runs", "2", "--out", str(out),
                 "--no-progress"]) == 0
    with xr.open_dataset(out) as ds:
        assert ds.attrs["setting_noise_nt"] == 1.0 and "setting_noise_mgal" not in ds.attrs


# --- the hunt's own finds ---------------------------------------------------------------

def test_a_map_in_gravity_units_is_converted(tmp_path, capsys):
    """A map whose ``units`` say ``gravity units`` (1 g.u. = 1 µm/s² = 0.1 mGal, as
    exploration surveys write it) was sampled as mGal, 10 x too large, and ``sample``'s
    summary named no unit."""
    track = _track(tmp_path / "t.csv")
    plain = _sampled(tmp_path, _small_map(tmp_path / "f.nc"), track, "f.csv")
    path = _small_map(tmp_path / "g.nc")
    with xr.open_dataset(path) as ds:
        gu = ds.load()
    gu["z"] = gu["z"] * 10.0
    gu["z"].attrs["units"] = "gravity units"
    gu.to_netcdf(tmp_path / "gu.nc")
    capsys.readouterr()
    np.testing.assert_allclose(_sampled(tmp_path, tmp_path / "gu.nc", track, "gu.csv"), plain,
                               rtol=1e-6)
    assert "8 samples of z (in mGal, bicubic)" in capsys.readouterr().out


def test_map_coordinates_of_whole_degrees_times_1e7_are_named(tmp_path, refused):
    """Integer coordinates of degrees x 1e7 without a ``scale_factor`` were called
    irregular ("the step from lat[0] = 294166667 to lat[1] = 294583333 is 416666, not the
    regular 416667"), which says nothing of the unit."""
    path = _small_map(tmp_path / "m.nc")
    with xr.open_dataset(path) as ds:
        m = ds.load()
    m = m.assign_coords(lat=np.round(m.lat.values * 1e7).astype("int64"),
                        lon=np.round(m.lon.values * 1e7).astype("int64"))
    m.to_netcdf(tmp_path / "e7.nc")
    refused(["sample", "--map", tmp_path / "e7.nc", "--track", _track(tmp_path / "t.csv"),
             "--out", tmp_path / "s.csv"],
            f"map '{tmp_path / 'e7.nc'}': coordinate value 2.94167e+08 is not a latitude/"
            "longitude in degrees (projected coordinates in metres?); jaxgrav reads geographic "
            "grids: reproject it first (e.g. gmt grdproject -I); whole degrees x 1e7? declare "
            "it: e.g. ncatted -a scale_factor,lat,c,d,1e-7")


@pytest.mark.parametrize("header, cells, t", [
    ("time", ["2024-05-01 11:59:00 AM", "2024-05-01 12:01:00 PM", "2024-05-01 1:00 p.m."],
     [0.0, 120.0, 3660.0]),
    ("date,time", ["2024-05-01,12:00:00 AM", "2024-05-01,12:30 AM", "2024-05-01,01:00 AM"],
     [0.0, 1800.0, 3600.0]),
    ("Time_UTC", ["0", "60", "120"], [0.0, 60.0, 120.0]),
    ("UTC", ["2024-05-01T12:00:00Z", "2024-05-01T12:01:00Z", "2024-05-01T12:02:00Z"],
     [0.0, 60.0, 120.0])])
def test_twelve_hour_clocks_and_utc_time_headers_are_read(tmp_path, header, cells, t):
    """``2024-05-01 01:00 PM`` was "neither a number (seconds) nor an ISO-8601 date-time";
    a time column headed ``Time_UTC`` or ``UTC`` was "lacks column t"."""
    rows = [f"{c},29.{5 + i},126.5" for i, c in enumerate(cells)]
    got = read_track_csv(_track(tmp_path / "t.csv", f"{header},lat,lon", rows),
                         required=("t", "lat", "lon"))
    np.testing.assert_allclose(got["t"], t)


def test_a_thirteen_o_clock_pm_is_named(tmp_path):
    track = _track(tmp_path / "t.csv", "time,lat,lon", ["2024-05-01 13:00 PM,29.5,126.5"])
    with pytest.raises(ValueError, match=r"\(a 12-hour time \(AM/PM\) has hours 1 to 12, not "
                                         r"13\)"):
        read_track_csv(track, required=("t", "lat", "lon"))


@pytest.mark.parametrize("text, what, fmt", [
    ("$GPGGA,120000.00,2930.0000,N,12630.0000,E,1,08,0.9,10.0,M,20.0,M,,*47\n",
     "NMEA 0183 sentences", "nmea"),
    ('<?xml version="1.0"?>\n<gpx><trk><trkseg><trkpt lat="29.5" lon="126.5"/></trkseg>'
     "</trk></gpx>\n", "XML (GPX?)", "gpx")])
def test_a_gps_receiver_s_raw_log_is_named(tmp_path, refused, text, what, fmt):
    """A raw NMEA log given as --track was refused as "column 'M' appears twice (columns
    11 and 13 of line 1)", a GPX file as "line 2 has 4 cells but the header has 2"."""
    track = tmp_path / "log.txt"
    track.write_text(text)
    refused(["sample", "--map", "ryukyu", "--track", track, "--out", tmp_path / "s.csv"],
            f"track file {str(track)!r} holds {what} ({text[:16]!r}...), not a table; convert "
            f"it to a CSV first (e.g. gpsbabel -i {fmt} -f IN -o unicsv -F OUT.csv, whose Date, "
            "Time, Latitude, Longitude jaxgrav reads)")


def test_gpsbabel_s_csv_is_read(tmp_path):
    """The conversion the message above suggests: gpsbabel's ``unicsv``."""
    track = _track(tmp_path / "u.csv", "No,Latitude,Longitude,Altitude,Speed,Date,Time",
                   ["1,29.500000,126.500000,10.0,5.0,2024/05/01,12:00:00",
                    "2,29.510000,126.510000,10.0,5.0,2024/05/01,12:01:00"])
    got = read_track_csv(track, required=("t", "lat", "lon"))
    np.testing.assert_allclose(got["t"], [0.0, 60.0])
    np.testing.assert_allclose(got["h"], [10.0, 10.0])


@pytest.mark.parametrize("header, row", [("t,lat,lon,gravity", '0,29.5,126.5,"1,234.5"'),
                                         ("t;lat;lon;gravity", "0;29,5;126,5;1.234,5")])
def test_thousands_grouped_before_a_decimal_mark_are_read(tmp_path, header, row):
    """``"1,234.5"`` (a spreadsheet's number format, quoted in its CSV) was "not a
    number"; the comma before a decimal point can only group thousands (``"1,234"`` alone
    stays refused: 1234 or 1.234?). Likewise ``1.234,5`` in a decimal-comma file."""
    got = read_track_csv(_track(tmp_path / "t.csv", header, [row]),
                         required=("t", "lat", "lon", "gravity"))
    assert got["gravity"][0] == 1234.5 and got["lat"][0] == 29.5


def test_a_home_folder_after_an_equals_sign_is_the_home_folder(tmp_path, monkeypatch):
    """``--out=~/s.csv`` (the shell expands ``~`` only at a word's start) wrote into a new
    folder named ``~`` under the working folder, exit 0; ``--track=~/t.csv`` was "does not
    exist"."""
    home, work = tmp_path / "home", tmp_path / "work"
    home.mkdir()
    work.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    _track(home / "t.csv")
    assert main(["sample", "--map", "ryukyu", "--track=~/t.csv", "--out=~/s.csv"]) == 0
    assert (home / "s.csv").is_file() and list(work.iterdir()) == []


@pytest.mark.parametrize("decimals", [6, 4])
def test_map_coordinates_written_with_few_decimals_are_read(tmp_path, decimals):
    """A 2.5' map whose coordinates were written with 6 decimals (29.416667, 29.458333: an
    ASCII grid converted with ``%.6f``) was refused: "the step ... is 0.041666, not the
    regular 0.041667"."""
    path = _small_map(tmp_path / "f.nc")
    with xr.open_dataset(path) as ds:
        m = ds.load()
    m.assign_coords(lat=np.round(m.lat.values, decimals),
                    lon=np.round(m.lon.values, decimals)).to_netcdf(tmp_path / "r.nc")
    track = _track(tmp_path / "t.csv")
    # half the last decimal, 5.6 m at 4 decimals, where the map changes by 0.015 mGal/m
    np.testing.assert_allclose(_sampled(tmp_path, tmp_path / "r.nc", track, "r.csv"),
                               _sampled(tmp_path, path, track, "f.csv"), atol=0.1 ** decimals * 30)


def test_an_axis_irregular_beyond_its_decimals_is_still_refused(tmp_path, refused):
    """A step of 0.1 written with 3 decimals has no rounding to forgive: 0.301 is a node
    out of place."""
    lat, lon = np.round(np.arange(29.4, 30.01, 0.1), 3), np.round(np.arange(126.0, 126.61, 0.1), 3)
    lat[3] += 0.001
    xr.Dataset({"z": (("lat", "lon"), np.zeros((lat.size, lon.size)), {"units": "mGal"})},
               coords={"lat": lat, "lon": lon}).to_netcdf(tmp_path / "m.nc")
    refused(["sample", "--map", tmp_path / "m.nc", "--track", _track(tmp_path / "t.csv"),
             "--out", tmp_path / "s.csv"],
            "lat must be strictly monotonic and regularly spaced; the step from lat[2] = 29.6 "
            "to lat[3] = 29.701 is 0.101, not the regular 0.1")


@pytest.mark.parametrize("header", ["Time s,Latitude deg,Longitude deg,Gravity mGal",
                                    "Date Time,Lat,Lon,Free-air Anomaly",
                                    "time,lat,lon,Gravity Anomaly (mGal)"])
def test_names_in_words_and_units_after_a_space_are_columns(tmp_path, header):
    """``Latitude deg``, ``Gravity mGal`` (a unit after a space), ``Free-air Anomaly`` and
    ``Date Time`` (words for ``free_air_anomaly``, ``date_time``) were "lacks columns"."""
    t = "2024-05-01 12:0{}" if header.startswith("Date") else "{}"
    rows = [f"{t.format(i)},29.{5 + i},126.5,{i - 10}" for i in range(3)]
    got = read_track_csv(_track(tmp_path / "t.csv", header, rows),
                         required=("t", "lat", "lon", "gravity"))
    np.testing.assert_allclose(got["t"], [0.0, 1.0, 2.0] if t == "{}" else [0.0, 60.0, 120.0])
    np.testing.assert_allclose(got["lat"], [29.5, 29.6, 29.7])
    np.testing.assert_allclose(got["gravity"], [-10.0, -9.0, -8.0])


def test_a_log_cut_short_on_its_last_line_says_so(tmp_path, refused):
    """A log copied while still being written ends mid-line (``120,29.5``): the message
    named only "column 'lon' has 1 missing or NaN value(s), first on line 4"."""
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon,gravity\n0,29.5,126.5,-10\n60,29.51,126.51,-9\n120,29.5")
    refused(["match", "--map", "ryukyu", "--track", track, "--out", tmp_path / "r.json"],
            f"track file {str(track)!r}, column 'lon' has 1 missing or NaN value(s), first on "
            "line 4; this column must be complete; it is the last line, and only that one: "
            "was the file cut short while being written?")
