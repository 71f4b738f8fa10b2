"""Inputs found by the sixth issue-19 hunt (2026-12-07, helper-62).

Tracks: units a header declares that were read as the library's own (``drift_radius
(km)``, ``v_east (ft/s)``, ``t (hours since ...)``, ``lon (W)``), a log keeping the date
and the time of day in two columns, date-times with a ``UTC`` suffix or an ordinal day,
positions with hemisphere letters or in degrees and minutes, ``#N/A`` and ``-`` cells,
title lines above the header, ``ve``/``vn`` velocity columns, bzip2/xz/zip files,
``--columns`` pairs split by semicolons. Maps: a CF valid range, GMT 4's native grid, a
grid in a NetCDF-4 group, a shipped map's name in another case, a GeoTIFF or Surfer grid
named. Outputs: ``.tsv`` written tab-separated, other table formats refused, names too
long for the file system, numeric log columns passed through. Count options alike."""

import bz2
import lzma
import re
import zipfile

import numpy as np
import pytest
import xarray as xr

from jaxgrav.cli import main
from jaxgrav.cli.inputs import kept_columns
from jaxgrav.cli.main import build_parser
from jaxgrav.datasets import load_map
from jaxgrav.grid_files import read_netcdf
from jaxgrav.track_files import parse_degrees, read_table
from jaxgrav.track_times import parse_datetime
from jaxgrav.track_units import header_scale
from jaxgrav.tracks import parse_columns, read_track_csv

ROWS = [(0, 29.5, 126.5, 1.0), (60, 29.51, 126.51, 2.0), (120, 29.52, 126.52, 3.0)]


def _csv(path, header, rows=ROWS, fmt=None):
    lines = [header] + [",".join(fmt(r) if fmt else map(str, r)) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("header, factor", [
    ("drift_radius (km)", 1 / 111.19508), ("drift_radius [nmi]", 1 / 60.04),
    ("drift_radius (m)", 1 / 111195.08), ("drift_radius (deg)", 1.0)])
def test_a_drift_radius_in_km_or_nautical_miles_is_converted_to_degrees(header, factor):
    """``drift_radius (km)`` 4.67 was read as 4.67 degrees (the match JSON recorded
    ``drift_radius_deg: 4.67``, exit 0)."""
    assert header_scale("drift_radius", header, "f") == pytest.approx(factor, rel=1e-4)


@pytest.mark.parametrize("header, factor", [
    ("v_east (ft/s)", 0.3048), ("v_north [cm/s]", 0.01), ("v_east (mph)", 0.44704),
    ("v_east (mm/s)", 1e-3), ("v_east (kn)", 1852 / 3600)])
def test_a_velocity_in_feet_or_centimetres_per_second_is_converted(header, factor):
    """``v_east (ft/s)`` was read as m/s: ``match`` corrected the readings for Eötvös with
    a velocity 3.3 times too large and fitted a 127 mGal "bias", exit 0."""
    assert header_scale(header.split()[0], header, "f") == pytest.approx(factor)


def test_velocities_in_ft_per_s_read_as_the_same_m_per_s(tmp_path):
    """A log with velocities in ft/s reads as the same log in m/s."""
    rows = [(120 * i, 29.5 + 0.0056 * i, 126.5 + 0.0068 * i, 0.0, 5.144, 5.144)
            for i in range(8)]
    base = _csv(tmp_path / "m.csv", "t,lat,lon,gravity,v_east,v_north", rows)
    feet = _csv(tmp_path / "f.csv", "t,lat,lon,gravity,v_east (ft/s),v_north (ft/s)", rows,
                fmt=lambda r: [str(r[0]), str(r[1]), str(r[2]), str(r[3]),
                               repr(r[4] / 0.3048), repr(r[5] / 0.3048)])
    a = read_track_csv(base, required=("t", "lat", "lon", "gravity"))
    b = read_track_csv(feet, required=("t", "lat", "lon", "gravity"))
    np.testing.assert_allclose(b["v_east"], a["v_east"], rtol=1e-12)
    np.testing.assert_allclose(b["v_north"], a["v_north"], rtol=1e-12)


@pytest.mark.parametrize("header, factor", [
    ("t (hours since 2024-05-01)", 3600.0), ("time (seconds since 1970-01-01T00:00:00Z)", 1.0),
    ("t [minutes since start]", 60.0), ("t (us)", 1e-6), ("h (cm)", 0.01), ("h (mm)", 1e-3)])
def test_a_cf_since_unit_and_small_units_are_read(header, factor):
    """``t (hours since 2024-05-01)`` was read as seconds (an unknown unit is a note)."""
    name = "h" if header.startswith("h") else "t"
    assert header_scale(name, header, "f") == factor


def test_a_date_column_is_joined_to_times_of_day(tmp_path, capsys):
    """``date,time,lat,lon`` (a logger's two columns) was refused: "'00:00:00' is neither
    a number (seconds) nor an ISO-8601 date-time (a time of day without a date)"."""
    path = tmp_path / "d.csv"
    path.write_text("Date,Time,lat,lon\n2024-05-01,23:59:00,30,130\n2024-05-02,00:01:00,30,130"
                    "\n2024/05/02,00:02:30,30,130\n")
    track = read_track_csv(path, required=("t", "lat", "lon"))
    assert list(track["t"]) == [0.0, 120.0, 210.0]
    assert track.time_origin == "2024-05-01T23:59:00"
    assert list(track.text["Date"]) == ["2024-05-01", "2024-05-02", "2024/05/02"]
    assert main(["sample", "--map", "ryukyu", "--track", str(path), "--out",
                 str(tmp_path / "s.csv")]) == 0
    head = (tmp_path / "s.csv").read_text().splitlines()[:2]
    assert head[0] == "Date,t,Time,lat,lon,map" and head[1].startswith("2024-05-01,0,23:59:00,")


def test_a_date_column_with_a_missing_date_names_the_line(tmp_path):
    path = tmp_path / "d.csv"
    path.write_text("date,time,lat,lon\n2024-05-01,12:00:00,30,130\n,12:01:00,30,130\n")
    with pytest.raises(ValueError, match=r"line 3, column 'time': ' 12:01:00' is neither"):
        read_track_csv(path, required=("t", "lat", "lon"))


@pytest.mark.parametrize("cell, iso", [
    ("2024-05-01 12:00:00 UTC", "2024-05-01T12:00:00+00:00"),
    ("2024-05-01T12:00:00GMT", "2024-05-01T12:00:00+00:00"),
    ("2024-05-01T12:00:00z", "2024-05-01T12:00:00+00:00"),
    ("2024-122T12:00:00", "2024-05-01T12:00:00"),
    ("2024-366 00:00", "2024-12-31T00:00:00"),
    ("2024-05-01T12:00:00+09:00", "2024-05-01T12:00:00+09:00")])
def test_a_utc_suffix_and_an_ordinal_date_are_date_times(cell, iso):
    """``2024-05-01 12:00:00 UTC`` (databases) and ``2024-122T12:00:00`` (the day of the
    year of survey logs, ISO 8601's ordinal date) were "neither a number nor an ISO-8601
    date-time"."""
    assert parse_datetime(cell).isoformat() == iso


@pytest.mark.parametrize("cell", ["2023-366T00:00", "2024-400T00:00", "12:00:00 UTC"])
def test_an_impossible_ordinal_date_or_a_bare_clock_is_still_refused(cell):
    with pytest.raises(ValueError):
        parse_datetime(cell)


def test_a_time_column_with_a_utc_suffix_is_read(tmp_path):
    """A track with ``... UTC`` times is read as seconds from its first, an aware time."""
    rows = [(f"2024-05-01 00:{2 * i:02d}:00 UTC", 29.5 + 0.0056 * i, 126.5 + 0.0068 * i, 0.0)
            for i in range(30)]
    path = _csv(tmp_path / "u.csv", "time,lat,lon,gravity", rows)
    track = read_track_csv(path, required=("t", "lat", "lon", "gravity"))
    assert track["t"][-1] == 58 * 60 and track.time_origin == "2024-05-01T00:00:00+00:00"


@pytest.mark.parametrize("name, cell, value", [
    ("lat", "35.5 N", 35.5), ("lat", "S35.5", -35.5), ("lat", "35.5s", -35.5),
    ("lat", "35°27.72'N", 35.462), ("lat", "35 27 43.2 S", -35.462),
    ("lon", "127°30′36″W", -127.51), ("lon", "127:30:36E", 127.51), ("lon", "-127.5", -127.5),
    ("lon", "172.5°", 172.5), ("lat", "-35°27.72'", -35.462)])
def test_hemisphere_letters_and_degrees_minutes_are_read(name, cell, value):
    """``35.4619 N`` and ``35°27.7164'N`` (ship logs, GPS exports) were "not a number
    (expected degrees)"."""
    values, bad, why = parse_degrees([cell, ""], name)
    assert bad is None and why == ""
    assert values[0] == pytest.approx(value) and np.isnan(values[1])


@pytest.mark.parametrize("name, cell, why", [
    ("lat", "35.5 E", "hemisphere E in a latitude column (expected N or S)"),
    ("lon", "N127", "hemisphere N in a longitude column (expected E or W)"),
    ("lat", "-35.5 S", "both a sign and hemisphere S"),
    ("lat", "35 75.0 N", "not degrees, minutes and seconds"),
    ("lat", "35.5 27 N", "not degrees, minutes and seconds"),
    ("lat", "N35.5S", "not a number"), ("lat", "thirty", "not a number")])
def test_a_wrong_hemisphere_or_angle_is_named(name, cell, why):
    _, bad, reason = parse_degrees(["10", cell], name)
    assert bad == 1 and reason.startswith(why)


def test_a_log_in_degrees_and_minutes_is_sampled_at_its_positions(tmp_path, refused):
    """``sample`` on a log written ``29°30.0'N,126°30.0'E`` gives the values of the same
    log in decimal degrees; a latitude with an E names the line, the cell and the reason."""
    rows = [(f"29°{30 + i}.0'N", f"126°{30 + i}.0'E") for i in range(3)]
    _csv(tmp_path / "dm.csv", "lat,lon", rows)
    _csv(tmp_path / "dd.csv", "lat,lon", [(29.5 + i / 60, 126.5 + i / 60) for i in range(3)])
    for name in ("dm", "dd"):
        assert main(["sample", "--map", "ryukyu", "--track", str(tmp_path / f"{name}.csv"),
                     "--out", str(tmp_path / f"s_{name}.csv")]) == 0
    got = [ln.split(",")[-1] for ln in (tmp_path / "s_dm.csv").read_text().splitlines()]
    want = [ln.split(",")[-1] for ln in (tmp_path / "s_dd.csv").read_text().splitlines()]
    assert got == want
    _csv(tmp_path / "bad.csv", "lat,lon", [("29.5 N", "126.5 E"), ("29.6 E", "126.6 E")])
    refused(["sample", "--map", "ryukyu", "--track", tmp_path / "bad.csv", "--out",
             tmp_path / "s.csv"],
            "bad.csv', line 3, column 'lat': '29.6 E' cannot be read as degrees: hemisphere "
            "E in a latitude column (expected N or S)")
    _csv(tmp_path / "bad.csv", "lat,lon", [("29.5 N", "126.5 E"), ("29.6 N", "east")])
    refused(["sample", "--map", "ryukyu", "--track", tmp_path / "bad.csv", "--out",
             tmp_path / "s.csv"],
            "bad.csv', line 3, column 'lon': 'east' is not a number (expected degrees (127.5, "
            "-127.5, 127.5 W or 127°30'W))")


def _ryukyu_arrays():
    grid = load_map("ryukyu")
    return np.asarray(grid.lat), np.asarray(grid.lon), np.asarray(grid.values, float)


def test_nodes_outside_a_declared_valid_range_are_missing(tmp_path):
    """CF ``valid_range``/``valid_min``/``valid_max`` (in the stored, packed type) mark the
    nodes beyond them missing; xarray does not apply them, so a -500 node in a map
    declaring ``valid_range = -400, 400`` was read as -500 mGal (``sample`` wrote it)."""
    lat, lon, v = _ryukyu_arrays()
    v = v.copy()
    v[100:103, 100:103] = -500.0
    for i, attrs in enumerate([{"valid_range": np.array([-400.0, 400.0])},
                               {"valid_min": -400.0}, {"valid_min": -400.0, "valid_max": 1e3}]):
        ds = xr.Dataset({"g": (("lat", "lon"), v, {"units": "mGal", **attrs})},
                        coords={"lat": lat, "lon": lon})
        ds.to_netcdf(tmp_path / f"m{i}.nc")
        got = read_netcdf(tmp_path / f"m{i}.nc").values
        assert np.isnan(got).sum() == 9 and np.isnan(got[100:103, 100:103]).all()
    # packed in 0.01 mGal: a range of the stored type is in packed units (-40000: -400
    # mGal), one of the unpacked (float) type in mGal, as CF says
    for i, low in enumerate([np.int32(-40000), np.float32(-400.0)]):
        packed = xr.Dataset({"g": (("lat", "lon"), v, {"units": "mGal", "valid_min": low})},
                            coords={"lat": lat, "lon": lon})
        packed["g"].encoding = {"dtype": "int32", "scale_factor": np.float32(0.01),
                                "_FillValue": np.int32(-2 ** 31)}
        packed.to_netcdf(tmp_path / f"p{i}.nc")
        got = read_netcdf(tmp_path / f"p{i}.nc").values
        assert np.isnan(got).sum() == 9 and np.nanmin(got) > -400


def _gmt4(path, lat, lon, v, pixel):
    """``v`` (south row first) written as GMT 4's native netCDF grid."""
    d = (lon[1] - lon[0]) / 2 if pixel else 0.0
    ny, nx = v.shape
    xr.Dataset({"x_range": ("side", [lon[0] - d, lon[-1] + d], {"units": "degrees"}),
                "y_range": ("side", [lat[0] - d, lat[-1] + d], {"units": "degrees"}),
                "z_range": ("side", [np.nanmin(v), np.nanmax(v)], {"units": "mGal"}),
                "spacing": ("side", [lon[1] - lon[0]] * 2),
                "dimension": ("side", np.array([nx, ny], "int32")),
                "z": ("xysize", v[::-1].ravel(), {"node_offset": int(pixel)})}).to_netcdf(path)


@pytest.mark.parametrize("pixel", [False, True])
def test_a_gmt4_native_grid_is_read(tmp_path, pixel):
    """GMT 4's native netCDF grids (``x_range``, ``y_range``, ``dimension``, ``z`` from the
    north row down; ``node_offset`` 1 for pixel registration), still what older survey
    archives hold, were refused: "has no latitude coordinate"."""
    lat, lon, v = _ryukyu_arrays()
    _gmt4(tmp_path / "g.grd", lat, lon, v, pixel)
    got = read_netcdf(tmp_path / "g.grd")
    np.testing.assert_allclose(got.lat[::-1], lat, atol=1e-9)
    np.testing.assert_allclose(got.lon, lon, atol=1e-9)
    np.testing.assert_array_equal(got.values[::-1], v)
    assert got.units == "mGal" and got.name == "z"


def test_sample_reads_a_gmt4_grid_as_the_same_map(tmp_path, refused):
    lat, lon, v = _ryukyu_arrays()
    lat, lon, v = lat[100:140], lon[50:90], v[100:140, 50:90]  # 28.2-29.8 N, 126.1-127.7 E
    _gmt4(tmp_path / "g.grd", lat, lon, v, False)
    xr.Dataset({"g": (("lat", "lon"), v, {"units": "mGal"})},
               coords={"lat": lat, "lon": lon}).to_netcdf(tmp_path / "cf.nc")
    _csv(tmp_path / "t.csv", "lat,lon", [(29.0, 126.5), (29.11, 126.73)])
    out = []
    for m in (str(tmp_path / "g.grd"), str(tmp_path / "cf.nc")):
        assert main(["sample", "--map", m, "--track", str(tmp_path / "t.csv"), "--out",
                     str(tmp_path / "s.csv"), "--force"]) == 0
        out.append(np.loadtxt(tmp_path / "s.csv", delimiter=",", skiprows=1))
    np.testing.assert_allclose(out[0], out[1], rtol=1e-7)  # nodes from x_range: 1e-14 deg
    refused(["sample", "--map", tmp_path / "g.grd", "--var", "gravity", "--track",
             tmp_path / "t.csv", "--out", tmp_path / "s2.csv"],
            "g.grd' is a GMT 4 native grid, whose one variable is 'z'; got --var 'gravity'")


def test_a_tsv_output_is_written_tab_separated(tmp_path):
    """``sample --out s.tsv`` wrote commas into a file named tab-separated (exit 0); it is
    now tab-separated and reads back as the same track."""
    _csv(tmp_path / "t.csv", "t,lat,lon,ship", [(0, 29.5, 126.5, "Maru, No. 1"),
                                                  (60, 29.51, 126.51, "Maru, No. 1")],
         fmt=lambda r: [str(r[0]), str(r[1]), str(r[2]), f'"{r[3]}"'])
    assert main(["sample", "--map", "ryukyu", "--track", str(tmp_path / "t.csv"), "--out",
                 str(tmp_path / "s.tsv")]) == 0
    lines = (tmp_path / "s.tsv").read_text().splitlines()
    assert lines[0] == "t\tlat\tlon\tship\tmap" and lines[1].count("\t") == 4
    assert "," not in lines[1].replace("Maru, No. 1", "")
    back = read_track_csv(tmp_path / "s.tsv", required=("lat", "lon"))
    assert list(back.text["ship"]) == ["Maru, No. 1"] * 2 and back["map"].shape == (2,)


@pytest.mark.parametrize("argv, message", [
    (["match", "--map", "ryukyu", "--track", "{d}/t.csv", "--out", "{d}/r.tsv"],
     "--out '{d}/r.tsv' names a TSV file, but this command writes JSON there; give a name "
     "ending .json, e.g. '{d}/r.json'"),
    (["simulate", "--out", "{d}/r.h5", "--truth", "{d}/t.csv"],
     "--out '{d}/r.h5' names an HDF5 file, but this command writes CSV there"),
    (["suitability", "--map", "ryukyu", "--out", "{d}/r.parquet"],
     "--out '{d}/r.parquet' names a Parquet file, but this command writes NetCDF there")])
def test_an_output_named_for_another_table_format_is_refused(tmp_path, refused, argv, message):
    """JSON into ``r.tsv``, CSV into ``r.h5`` were written, exit 0."""
    refused([a.format(d=tmp_path) for a in argv], message.format(d=tmp_path))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("head, looks", [
    (b"II*\0\x08\0\0\0", "it is a (Geo)TIFF raster: convert it, e.g. gdal_translate -of netCDF "
                         "IN OUT.nc"),
    (b"MM\0*\0\0\0\x08", "it is a (Geo)TIFF raster"),
    (b"DSAA\n3 3\n0 1\n0 1\n0 1\n1 2 3\n", "it is a Surfer grid: convert it, e.g. "
                                          "gdal_translate -of netCDF IN OUT.nc"),
    (b"DSRB\x04\0\0\0", "it is a Surfer grid"),
    (b"\x89PNG\r\n\x1a\n", "it is an image or a PDF, not gridded values")])
def test_a_raster_that_is_not_netcdf_says_what_it_is(tmp_path, refused, head, looks):
    """A GeoTIFF was "its format is not NetCDF-3 or NetCDF-4", and a Surfer ASCII grid
    (also named ``.grd``) "a text file starting 'DSAA', a CSV track or table?"."""
    (tmp_path / "m.grd").write_bytes(head)
    _csv(tmp_path / "t.csv", "lat,lon", [(29.5, 126.5)])
    refused(["sample", "--map", tmp_path / "m.grd", "--track", tmp_path / "t.csv", "--out",
             tmp_path / "s.csv"], f"m.grd' is not a NetCDF file ({looks}")
    assert not (tmp_path / "s.csv").exists()


@pytest.mark.parametrize("given", ["Ryukyu", "RYUKYU:anomaly_0p5deg"])
def test_a_shipped_map_name_in_another_case_is_that_map(tmp_path, given):
    """``--map Ryukyu`` was "map 'Ryukyu' does not exist"."""
    _csv(tmp_path / "t.csv", "lat,lon", [(29.5, 126.5), (29.6, 126.6)])
    out = []
    for name in (given, given.lower()):
        assert main(["sample", "--map", name, "--track", str(tmp_path / "t.csv"), "--out",
                     str(tmp_path / "s.csv"), "--force"]) == 0
        out.append((tmp_path / "s.csv").read_text())
    assert out[0] == out[1]


@pytest.mark.parametrize("argv, message", [
    (["sample", "--map", "nosuch.nc"], "--map 'nosuch.nc' is neither a file nor a shipped map "
     "(qinling, ryukyu); expected the path of a NetCDF grid or a shipped map's name"),
    (["sample", "--map", "ryukyu:bogus"], "--map 'ryukyu:bogus': the shipped dataset 'ryukyu' "
     "has no map 'bogus'; expected ryukyu:anomaly_0p5deg or ryukyu:anomaly_2p5min"),
    (["simulate", "--truth-map", "Nope.nc"], "--truth-map 'Nope.nc' is neither a file nor a "
     "shipped map")])
def test_a_map_that_is_no_file_names_the_shipped_maps(tmp_path, refused, argv, message):
    """Was "map 'nosuch.nc' does not exist" and "it has ['anomaly_0p5deg', ...]" (a Python
    list); now the option and the names that work."""
    _csv(tmp_path / "t.csv", "lat,lon", [(29.5, 126.5)])
    extra = (["--track", tmp_path / "t.csv", "--out", tmp_path / "s.csv"] if argv[0] == "sample"
             else ["--out", tmp_path / "s.csv"])
    refused([*argv, *extra], message)
    assert not (tmp_path / "s.csv").exists()


@pytest.mark.parametrize("title", ["Ryukyu survey leg 3\n", '"Ryukyu survey"\n',
                                   "Survey: Ryukyu leg 3, ship Maru\nOperator: X\n\n"])
def test_title_lines_above_the_header_are_skipped(tmp_path, title):
    """An instrument export's title lines above the header were read as the header:
    "lacks columns lat and lon; it has Ryukyu, survey, leg, 3" or "line 3 has 7 cells
    but the header has 2 columns"; the file's own line numbers stay in messages."""
    body = "t,lat,lon,gravity\n0,29.5,126.5,1\n60,29.51,126.51,x\n"
    (tmp_path / "t.csv").write_text(title + body)
    n = title.count("\n")
    with pytest.raises(ValueError, match=rf"line {n + 3}, column 'gravity': 'x' is not a number"):
        read_track_csv(tmp_path / "t.csv", required=("t", "lat", "lon"))
    (tmp_path / "t.csv").write_text(title + body.replace("x", "2"))
    track = read_track_csv(tmp_path / "t.csv", required=("t", "lat", "lon", "gravity"))
    assert list(track["gravity"]) == [1.0, 2.0] and list(track.lines) == [n + 2, n + 3]


@pytest.mark.parametrize("text", [
    "t,lat,lon,gravity\n0,29.5,126.5,1,\n60,29.51,126.51,2,\n",  # a trailing delimiter
    "t,lat,lon,gravity\ns,deg,deg,mGal\n0,29.5,126.5,1\n60,29.51,126.51,2\n",  # units row
    "lat lon\n29.5 126.5\n"])
def test_a_header_with_fewer_cells_than_its_rows_is_not_a_title(tmp_path, text):
    (tmp_path / "t.csv").write_text(text)
    track = read_track_csv(tmp_path / "t.csv", required=("lat", "lon"))
    assert track["lat"][0] == 29.5 and track.lines[0] == text.count("\n") - len(track["lat"]) + 1


@pytest.mark.parametrize("argv", [
    ["navigate", "--track", "{d}/t.csv", "--out", "{d}/n.csv", "--method", "rbpf",
     "--particles"],
    ["navigate", "--track", "{d}/t.csv", "--out", "{d}/n.csv", "--method", "dense",
     "--fix-every"],
    ["navigate", "--track", "{d}/t.csv", "--out", "{d}/n.csv", "--method", "dense", "--n-fixes"],
    ["navigate", "--track", "{d}/t.csv", "--out", "{d}/n.csv", "--method", "dense", "--stride"],
    ["simulate-filter", "--out", "{d}/s.csv", "--reading-every"],
    ["suitability", "--map", "ryukyu", "--out", "{d}/s.nc", "--window"],
    ["match", "--map", "ryukyu", "--track", "{d}/t.csv", "--out", "{d}/m.json", "--refine"],
    ["match", "--map", "ryukyu", "--track", "{d}/t.csv", "--out", "{d}/m.json",
     "--entropy-half-size"],
    ["montecarlo", "--method", "dense", "--runs", "8", "--out", "{d}/m.nc", "--devices"]])
def test_every_count_option_reads_counts_alike(tmp_path, capsys, argv):
    """``navigate --particles 1e3`` was "invalid int value: '1e3'" where ``filter
    --particles 1e3`` ran: the count options left on argparse's int now read ``1e3`` and
    name ``2.5`` as hunt 5's did."""
    with pytest.raises(SystemExit) as exit_:
        main([a.format(d=tmp_path) for a in argv] + ["2.5"])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and "\n" not in err, err
    assert f"argument {argv[-1]}: expected a whole number (e.g. 1000 or 1e6); got '2.5'" in err
    parser_args = build_parser().parse_args(
        [a.format(d=tmp_path) for a in argv] + ["1e1"])
    assert getattr(parser_args, argv[-1][2:].replace("-", "_")) == 10


def test_numeric_columns_no_command_reads_pass_through_to_per_row_outputs(tmp_path):
    """A log's ``depth`` or ``heading`` column was dropped from ``filter``'s and
    ``navigate``'s CSVs (only text columns passed through); it now follows the output's
    columns as the file wrote it, ``_track`` appended where the output has the name."""
    path = _csv(tmp_path / "l.csv", "t,lat,lon,gravity,ship,depth,status",
                [(0, 29.5, 126.5, 1.0, "Kaiyo", "0012.50", 3), (10, 29.5, 126.5, "", "Kaiyo",
                                                                  "7", 4)])
    track = read_track_csv(path, required=("t", "lat", "lon", "gravity"), allow_nan=("gravity",))
    out = kept_columns(track, {"t": track["t"], "lat": track["lat"], "status": np.zeros(2)})
    assert list(out) == ["t", "ship", "lat", "status", "depth", "status_track"]
    assert list(out["depth"]) == ["0012.50", "7"] and list(out["status_track"]) == ["3", "4"]


@pytest.mark.long
def test_filter_keeps_a_depth_column(tmp_path):
    log = tmp_path / "f.csv"
    assert main(["simulate-filter", "--out", str(log), "--minutes", "4"]) == 0
    lines = log.read_text().splitlines()
    log.write_text("\n".join([lines[0] + ",depth"] + [ln + ",12.5" for ln in lines[1:]]) + "\n")
    out = tmp_path / "o.csv"
    assert main(["filter", "--point-masses", "paper-d", "--track", str(log), "--out",
                 str(out)]) == 0
    got = out.read_text().splitlines()
    assert got[0].endswith(",status,depth") and all(ln.endswith(",12.5") for ln in got[1:])


def test_columns_pairs_may_be_separated_by_semicolons():
    """``--columns "lat=LAT;lon=LON"`` (the file's own separator) was "no column
    'LAT;lon=LON'"."""
    assert parse_columns("lat=LAT;lon=LON; gravity=FAA (mGal)") == {
        "lat": "LAT", "lon": "LON", "gravity": "FAA (mGal)"}


def test_an_output_name_that_fits_writes_though_its_temporary_name_would_not(tmp_path):
    """A 250-byte ``--out`` name ran the command, then failed writing its temporary file
    ``.NAME.XXXXXXXX.tmp`` (over 255 bytes): "failed: OSError: [Errno 36] File name too
    long", exit 1, nothing written."""
    _csv(tmp_path / "t.csv", "lat,lon", [(29.5, 126.5)])
    out = tmp_path / ("a" * 246 + ".csv")
    assert main(["sample", "--map", "ryukyu", "--track", str(tmp_path / "t.csv"), "--out",
                 str(out)]) == 0
    assert out.read_text().startswith("lat,lon,map\n")


@pytest.mark.parametrize("option", ["--out", "--track", "--map", "--truth"])
def test_a_name_too_long_for_the_file_system_is_refused_first(tmp_path, refused, option):
    """A 300-byte name was exit 1 with Python's "[Errno 36] File name too long" (for
    ``--truth``, after the track was simulated)."""
    long = tmp_path / ("b" * 296 + ".csv")
    _csv(tmp_path / "t.csv", "lat,lon", [(29.5, 126.5)])
    argv = {"--truth": ["simulate", "--out", tmp_path / "s.csv", "--truth", long]}.get(
        option, ["sample", "--map", "ryukyu", "--track", tmp_path / "t.csv", "--out",
                 tmp_path / "s.csv"])
    if option != "--truth":
        argv[argv.index(option) + 1] = long
    refused(argv, f"{option} '{long}': the name 'bbbbbbbbbbbbbbbbbbbbbbbb'... is 300 bytes "
                  "long, more than the 255 a name may have there; give a shorter name")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv"]


def test_a_grid_in_a_netcdf4_group_is_read(tmp_path, refused):
    """A NetCDF-4 file with its grid in a group (``/data``) and nothing at its root was
    "has no latitude coordinate ...; it has none"; one such group is read, two are named."""
    lat, lon, v = _ryukyu_arrays()
    ds = xr.Dataset({"g": (("lat", "lon"), v, {"units": "mGal"})},
                    coords={"lat": lat, "lon": lon})
    ds.to_netcdf(tmp_path / "one.nc", group="data")
    got = read_netcdf(tmp_path / "one.nc")
    np.testing.assert_array_equal(got.values, v)
    assert got.name == "g" and got.units == "mGal"
    ds.to_netcdf(tmp_path / "two.nc", group="a")
    ds.to_netcdf(tmp_path / "two.nc", group="b", mode="a")
    _csv(tmp_path / "t.csv", "lat,lon", [(29.5, 126.5)])
    refused(["sample", "--map", tmp_path / "two.nc", "--track", tmp_path / "t.csv", "--out",
             tmp_path / "s.csv"], "two.nc' holds no variables at its root and 2 groups with "
            "variables (/a, /b); expected one grid: extract it first (e.g. ncks -G : -g GROUP "
            "IN OUT.nc)")


@pytest.mark.parametrize("east, north", [("ve", "vn"), ("VE (kn)", "VN (kn)"),
                                         ("vel_east", "vel_north"), ("v_e", "v_n")])
def test_velocity_columns_under_common_names_are_the_velocities(tmp_path, east, north):
    """A log with ``ve, vn`` columns ran ``match`` as if it had no velocities: its raw
    readings were taken as Eötvös-corrected and a -63.7 mGal "bias" fitted (against -1.5
    with ``v_east, v_north``), exit 0 without a word."""
    scale = 1852 / 3600 if "kn" in east else 1.0
    path = _csv(tmp_path / "v.csv", f"t,lat,lon,gravity,{east},{north}",
                [(0, 29.5, 126.5, 1.0, 5 / scale, 2 / scale), (60, 29.51, 126.51, 2.0, 5 / scale,
                                                              2 / scale)])
    track = read_track_csv(path, required=("t", "lat", "lon", "gravity"),
                           optional=("v_east", "v_north"))
    np.testing.assert_allclose(track["v_east"], [5.0, 5.0])
    np.testing.assert_allclose(track["v_north"], [2.0, 2.0])
    assert track.renamed["v_east"] == east


def test_a_date_column_beside_complete_date_times_is_left_alone(tmp_path):
    path = tmp_path / "d.csv"
    path.write_text("date,time,lat,lon\n2024-05-01,2024-05-01T23:59:00Z,30,130\n"
                    "2024-05-02,2024-05-02T00:01:00Z,30,130\n")
    track = read_track_csv(path, required=("t", "lat", "lon"))
    assert list(track["t"]) == [0.0, 120.0]


@pytest.mark.parametrize("lat_h, lon_h, lat, lon", [
    ("lat", "lon (W)", 29.5, -126.5), ("Latitude (deg S)", "Longitude (degrees_west)", -29.5,
                                       -126.5),
    ("lat (°N)", "lon (deg E)", 29.5, 126.5), ("lat (N)", "lon (west)", 29.5, -126.5)])
def test_a_hemisphere_in_a_header_gives_the_sign(tmp_path, lat_h, lon_h, lat, lon):
    """``lon (W)`` (positive west, as some survey archives write) was an unknown unit, a
    note: the track was read 253 degrees of longitude away, in the east."""
    path = _csv(tmp_path / "w.csv", f"{lat_h},{lon_h}", [(29.5, 126.5)])
    track = read_track_csv(path, required=("lat", "lon"))
    assert (track["lat"][0], track["lon"][0]) == (lat, lon)


def test_a_header_hemisphere_of_the_other_axis_is_refused(tmp_path):
    path = _csv(tmp_path / "w.csv", "lat (W),lon (N)", [(29.5, 126.5)])
    with pytest.raises(ValueError, match=r"column 'lat \(W\)' declares 'W', a longitude "
                       r"hemisphere, for latitudes: name the right column with --columns "
                       r"lat=COLUMN$"):
        read_track_csv(path, required=("lat", "lon"))


@pytest.mark.parametrize("pack", ["bz2", "xz", "zip"])
def test_a_bzip2_xz_or_zipped_track_is_read(tmp_path, pack):
    """``log.csv.bz2``, ``log.csv.xz`` and ``log.zip`` (holding ``log.csv``) were "a
    binary file, not a text table" or "a zip/xlsx archive", where ``.gz`` was read."""
    text = b"lat,lon\n24.5,125.5\n24.6,125.6\n"
    path = tmp_path / f"t.{pack}"
    if pack == "zip":
        with zipfile.ZipFile(path, "w") as archive:
            archive.writestr("log/t.csv", text)
    else:
        path.write_bytes(bz2.compress(text) if pack == "bz2" else lzma.compress(text))
    assert read_table(path).rows == [["24.5", "125.5"], ["24.6", "125.6"]]
    if pack == "bz2":
        path.write_bytes(path.read_bytes()[:20])
        with pytest.raises(ValueError, match=r"is a bzip2 file that cannot be decompressed "
                           r"\(.*\); expected a whole .bz2 of a CSV text file$"):
            read_table(path)


@pytest.mark.parametrize("members, message", [
    (["a.csv", "b.csv"], "is a zip archive of 2 files (a.csv, b.csv); expected one CSV file in it"),
    (["[Content_Types].xml", "xl/workbook.xml"], "is an Excel/OpenDocument workbook, not a text "
                                                 "table; save the sheet as CSV")])
def test_a_zip_of_several_files_or_a_workbook_is_named(tmp_path, members, message):
    path = tmp_path / "t.zip"
    with zipfile.ZipFile(path, "w") as archive:
        for m in members:
            archive.writestr(m, "lat,lon\n1,2\n")
    with pytest.raises(ValueError, match=re.escape(message)):
        read_table(path)
