"""Inputs found by the ninth issue-19 hunt (2026-12-07, helper-77).

The last hunt's leftovers first: a track with both ``latitude`` and ``lat`` read ``lat``
in silence, an ambiguous ``"29,512"`` was refused naming the row's first cell, and
``match --drift-radius 1e-9`` / ``suitability --spacing 1e-6`` ran. Then the hunt's own
finds (below them)."""

import math
import re

import numpy as np
import pytest
import xarray as xr

from jaxgrav.cli import main
from jaxgrav.constants import WGS84_MEAN_RADIUS
from jaxgrav.datasets import load_map
from jaxgrav.tracks import read_track_csv

ROWS = [(29.5 + 0.0056 * i, 126.5 + 0.0068 * i) for i in range(5)]


def _track(path, header="t,lat,lon,gravity", rows=None):
    rows = rows if rows is not None else [f"{120 * i},{lat},{lon},{-10 + i}"
                                          for i, (lat, lon) in enumerate(ROWS)]
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("header, names", [
    ("t,latitude,lat,lon", ("latitude", "lat")),
    ("t,lat,lon,long", ("lon", "long")),
    ("t,LAT,lon,Latitude [deg]", ("LAT", "Latitude [deg]")),
])
def test_two_names_for_one_position_column_are_refused(tmp_path, header, names):
    """``t,latitude,lat,lon`` read ``lat`` and passed ``latitude`` through, in silence."""
    track = _track(tmp_path / "t.csv", header, [f"{10 * i},29.5,29.6,126.5" for i in range(3)])
    name = "lat" if "lat" in names[0].lower() else "lon"
    with pytest.raises(ValueError, match=re.escape(
            f"columns '{names[0]}' and '{names[1]}' could both be '{name}'; choose one with "
            f"--columns {name}=COLUMN")):
        read_track_csv(track, required=("t", "lat", "lon"))


def test_one_of_two_position_columns_is_chosen_with_columns(tmp_path):
    track = _track(tmp_path / "t.csv", "t,latitude,lat,lon",
                   [f"{10 * i},29.5,29.6,126.5" for i in range(3)])
    got = read_track_csv(track, required=("t", "lat", "lon"), columns={"lat": "latitude"})
    assert got["lat"].tolist() == [29.5] * 3
    assert got["lat_col3"].tolist() == [29.6] * 3


def test_a_seconds_column_beside_iso_times_is_still_read(tmp_path):
    """The commands' own outputs write ``t`` (s from the first row) beside the log's
    ``time``: read back, ``t`` is the time (not refused as two time columns)."""
    track = _track(tmp_path / "t.csv", "t,time,lat,lon",
                   [f"{60 * i},2024-05-01T12:0{i}:00Z,29.5,126.5" for i in range(3)])
    assert read_track_csv(track, required=("t", "lat", "lon"))["t"].tolist() == [0, 60, 120]


@pytest.mark.parametrize("rows, line, cell", [
    (['"0","29,5","126,5"', '"120","29,512","126,5068"'], 3, "29,512"),
    (['0,29.5,126.5', '120,"29,512",126.5068'], 3, "29,512"),
])
def test_an_ambiguous_comma_number_is_named_where_it_is(tmp_path, rows, line, cell):
    """``"29,512"`` on line 3 was refused as line 2's ``'29,5'`` (the degrees reader
    did not take the quoted decimal comma the number reader had read)."""
    track = _track(tmp_path / "t.csv", "t,lat,lon", rows)
    with pytest.raises(ValueError) as err:
        read_track_csv(track, required=("t", "lat", "lon"))
    assert (f"line {line}, column 'lat': '{cell}' is not a number (expected degrees"
            in str(err.value))
    assert str(err.value).endswith("it could be 29512 or 29.512 (a thousands separator or a "
                                   "decimal comma): write the number meant, with a decimal "
                                   "point")


def test_a_drift_radius_the_readings_cannot_resolve_is_refused(tmp_path, refused):
    """``match --drift-radius 1e-9`` (0.1 mm) ran and reported "INS kept", exit 0."""
    track = _track(tmp_path / "t.csv")
    out = tmp_path / "r.json"
    refused(["match", "--map", "ryukyu", "--track", track, "--out", out,
             "--drift-radius", "1e-9"],
            "--drift-radius 1e-09 degrees of arc (0.000111 m) searches a region across which "
            "the map changes by at most 3.19e-06 mGal (its steepest slope is 0.0144 mGal/m), "
            "below a tenth of what 5 readings of --noise 1 mGal can tell (0.0447 mGal): every "
            "position in it would fit as the INS track does; expected a drift radius of at "
            "least 1.4e-05 degrees of arc (1.6 m)")
    assert not out.exists()


def test_a_drift_radius_column_the_readings_cannot_resolve_is_named(tmp_path, refused):
    track = _track(tmp_path / "t.csv", "t,lat,lon,gravity,drift_radius",
                   [f"{120 * i},{lat},{lon},{-10 + i},1e-8" for i, (lat, lon) in enumerate(ROWS)])
    refused(["match", "--map", "ryukyu", "--track", track, "--out", tmp_path / "r.json"],
            f"column 'drift_radius' of --track '{track}' (1e-08 degrees of arc at most) "
            "(0.00111 m) searches a region")


def test_a_spacing_the_readings_cannot_resolve_is_refused(tmp_path, refused):
    """``suitability --spacing 1e-6`` wrote "no information" at every node, exit 0."""
    out = tmp_path / "s.nc"
    refused(["suitability", "--map", "ryukyu", "--out", out, "--spacing", "1e-6"],
            "--spacing 1e-06 m makes a segment of 2.9e-05 m, along which the map changes by "
            "at most 4.16e-07 mGal (its steepest slope is 0.0144 mGal/m), below a tenth of what "
            "30 readings of --noise 1 mGal can tell (0.0183 mGal): no node could be told from "
            "its neighbours; expected a --spacing of at least 0.044 m")
    assert list(tmp_path.iterdir()) == []


# --- the hunt's own finds ---------------------------------------------------------------

@pytest.mark.parametrize("argv", [
    ["sample", "--map", "ryukyu", "--track", "t.csv", "--out", "-"],
    ["simulate", "--out", "t2.csv", "--truth", "-"],
])
def test_a_dash_output_is_refused(tmp_path, monkeypatch, refused, argv):
    """``--out -`` wrote a file named ``-`` (``--track -`` reads standard input)."""
    monkeypatch.chdir(tmp_path)
    _track(tmp_path / "t.csv")
    refused(argv, "- : jaxgrav writes its outputs to files, not to standard output; give a "
                  "file name (./- for a file named '-')")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv"]


def _ryukyu_nc(path, lat_units="degrees_north", lon_units="degrees_east", sign=(1, 1),
               shift=0.0):
    grid = load_map("ryukyu")
    lat, lon = np.asarray(grid.lat), np.asarray(grid.lon)
    xr.Dataset({"gravity": (("lat", "lon"), np.asarray(grid.values, float), {"units": "mGal"})},
               coords={"lat": ("lat", sign[0] * lat, {"units": lat_units}),
                       "lon": ("lon", sign[1] * lon + shift, {"units": lon_units})}
               ).to_netcdf(path)
    return path


@pytest.mark.parametrize("kw", [
    {"lon_units": "degrees_west", "sign": (1, -1)},
    {"lon_units": "degree_W", "sign": (1, -1)},
    {"lat_units": "degrees_south", "sign": (-1, 1)},
    {"lat_units": "degreesS", "sign": (-1, 1)},
    {"shift": -360.0},  # longitudes -236..-224: the -360..0 convention
])
def test_maps_counting_west_south_or_from_minus_360_are_read(tmp_path, kw):
    """A map declaring CF ``degrees_west`` (or ``degrees_south``) was read as east: every
    track "off the map" (lon -136..-124); one in -360..0 was refused without its name."""
    track = _track(tmp_path / "t.csv")
    want, got = tmp_path / "want.csv", tmp_path / "got.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out", str(want)]) == 0
    assert main(["sample", "--map", str(_ryukyu_nc(tmp_path / "m.nc", **kw)), "--track",
                 str(track), "--out", str(got)]) == 0
    np.testing.assert_allclose(read_track_csv(got)["map"], read_track_csv(want)["map"],
                               atol=1e-5)


@pytest.mark.parametrize("name", ["faa", "FAA (mGal)", "gravity_anomaly", "free_air_anomaly",
                                  "Free_Air"])
def test_a_survey_s_anomaly_column_is_the_gravity(tmp_path, name):
    """``t,lat,lon,faa`` was refused by ``match`` ("needs a 'gravity' (mGal) or
    'magnetic' (nT) column")."""
    track = _track(tmp_path / "t.csv", f"t,lat,lon,{name}")
    got = read_track_csv(track, required=("t", "lat", "lon"))
    assert got["gravity"].tolist() == [-10, -9, -8, -7, -6]
    assert got.renamed["gravity"] == name


def test_a_gravity_column_beside_an_anomaly_column_is_ambiguous(tmp_path):
    track = _track(tmp_path / "t.csv", "t,lat,lon,gravity,faa",
                   [f"{120 * i},{lat},{lon},979700,-10" for i, (lat, lon) in enumerate(ROWS)])
    with pytest.raises(ValueError, match="columns 'gravity' and 'faa' could both be 'gravity'"):
        read_track_csv(track, required=("t", "lat", "lon"))


def test_a_track_that_does_not_move_is_refused_by_match(tmp_path, refused):
    """A vessel at anchor (every fix at one position) ran ``match`` to "fix rejected ...
    INS track kept", exit 0: one map value tells no position."""
    track = _track(tmp_path / "t.csv", rows=[f"{120 * i},29.5,126.5,{-10 + 0.1 * i}"
                                             for i in range(6)])
    out = tmp_path / "r.json"
    refused(["match", "--map", "ryukyu", "--track", track, "--out", out],
            f"--track '{track}': its 6 fixes lie within 0 m of each other, across which the "
            "map changes by at most 0 mGal (its steepest slope is 0.0144 mGal/m), below a tenth "
            "of what 6 readings of --noise 1 mGal can tell (0.0408 mGal): a track that does "
            "not move reads one value of the map and tells no position; matching needs a "
            "track at least 2.8 m long")
    assert not out.exists()


@pytest.mark.parametrize("argv, message", [
    (["--dt", "1e-9"], "--n 30 fixes every 1e-09 s make a track of 2.11e-07 m, along which "
                       "the map changes by at most 3.03e-09 mGal (its steepest slope is 0.0144 "
                       "mGal/m), below a tenth of what 30 readings of --noise 1 mGal can tell "
                       "(0.0183 mGal): it would tell no position; expected a --dt of at "
                       "least 0.006 s"),
    (["--drift", "1e-12"], "--drift 1e-12 degrees of arc gives the track a drift radius of "
                           "1.33e-07 m, across whose search region the map changes by at most "
                           "3.83e-09 mGal"),
])
def test_simulate_refuses_a_track_or_drift_no_reading_resolves(tmp_path, refused, argv,
                                                               message):
    """``simulate --dt 1e-9`` wrote 30 fixes within 0.2 µm, ``--drift 1e-12`` a
    ``drift_radius`` of 1.2e-12 degrees (jaxgrav match now refuses it), exit 0."""
    out, truth = tmp_path / "t.csv", tmp_path / "truth.csv"
    refused(["simulate", "--out", out, "--truth", truth, *argv], message)
    assert list(tmp_path.iterdir()) == []


def test_simulate_names_the_probability_that_makes_the_radius_vanish(tmp_path, refused):
    """``--probability 1e-300 --drift-law rayleigh`` was blamed on ``--drift`` ("expected a
    --drift of at least 4e+144 degrees of arc")."""
    refused(["simulate", "--out", tmp_path / "t.csv", "--drift-law", "rayleigh",
             "--probability", "1e-300"],
            "--probability 1e-300 (the quantile of the Rayleigh drift of --drift 0.035) gives "
            "the track a drift radius of 5.5e-147 m, across whose search region the map "
            "changes by at most 1.58e-148 mGal")
    assert list(tmp_path.iterdir()) == []


def test_montecarlo_refuses_a_matcher_drift_no_reading_resolves(tmp_path, refused):
    """``montecarlo --method dense --drift 1e-12`` ran its runs (each fix the INS's)."""
    out = tmp_path / "m.nc"
    refused(["montecarlo", "--method", "dense", "--runs", "10", "--drift", "1e-12", "--out",
             out],
            "--drift 1e-12 degrees of arc (the search radius, 1.11e-07 m) searches a region "
            "across which the map changes by at most 3.19e-09 mGal (its steepest slope is "
            "0.0144 mGal/m), below a tenth of what 30 readings of --noise 1 mGal can tell "
            "(0.0183 mGal): every position in it would fit as the INS track does; expected a "
            "--drift of at least 5.7e-06 degrees of arc")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("column, header, cell, value", [
    ("v_east", "v_east (m/min)", "300", 5.0),
    ("h", "h (in)", "100", 2.54),
    ("h", "h (fathoms)", "10", 18.288),
    ("drift_radius", "drift_radius (mi)", "1", math.degrees(1609.344 / WGS84_MEAN_RADIUS)),
    ("lat", "lat (1e-7 deg)", "295000000", 29.5),
    ("lat", "lat (arcsec)", "106200", 29.5),
    ("h", "h (m MSL)", "12", 12.0),  # the unit, then a note
    ("gravity", "gravity (mGal FAA)", "-10", -10.0),
    ("gravity", "gravity (0.1 mGal)", "-100", -10.0),  # tenths: was read as mGal
])
def test_header_units_that_were_read_as_notes_are_converted(tmp_path, column, header, cell,
                                                            value):
    """``v_east (m/min)`` was read as m/s, ``h (in)`` as metres, ``drift_radius (mi)`` as
    degrees of arc, ``gravity (0.1 mGal)`` as mGal (a unit the reader did not know was
    taken for a note), exit 0."""
    rows = [f"{120 * i},{lat},{lon}" for i, (lat, lon) in enumerate(ROWS)]
    if column == "lat":
        track = _track(tmp_path / "t.csv", f"t,{header},lon",
                       [f"{120 * i},{cell},{lon}" for i, (_, lon) in enumerate(ROWS)])
    else:
        track = _track(tmp_path / "t.csv", f"t,lat,lon,{header}",
                       [f"{r},{cell}" for r in rows])
    got = read_track_csv(track, required=("t", "lat", "lon"))
    np.testing.assert_allclose(got[column], value, rtol=1e-6)


@pytest.mark.parametrize("header, unit, target", [
    ("gravity (mGal*10)", "mGal*10", "mGal"),
    ("t (ks)", "ks", "seconds"),
    ("v_north (km/s)", "km/s", "m/s"),
    ("h [yd]", "yd", "metres"),
])
def test_header_units_it_cannot_convert_are_refused(tmp_path, header, unit, target):
    """``gravity (mGal*10)`` was read as mGal, exit 0."""
    columns = f"{header},lat,lon,x" if header.startswith("t ") else f"t,lat,lon,{header}"
    track = _track(tmp_path / "t.csv", columns,
                   [f"{120 * i},{lat},{lon},5" for i, (lat, lon) in enumerate(ROWS)])
    with pytest.raises(ValueError, match=re.escape(
            f"column {header!r} declares the unit {unit!r}, which jaxgrav cannot convert to "
            f"{target}; convert the column to {target}, or declare a unit it knows (e.g. ")):
        read_track_csv(track, required=("t", "lat", "lon"))


@pytest.mark.parametrize("header", ["time (UTC)", "t (GPS)", "lat (WGS84)"])
def test_header_notes_still_pass(tmp_path, header):
    name = header.split()[0]
    cols = {"time": "time (UTC),lat,lon", "t": "t (GPS),lat,lon", "lat": "t,lat (WGS84),lon"}
    track = _track(tmp_path / "t.csv", cols[name],
                   [f"{120 * i},{lat},{lon}" for i, (lat, lon) in enumerate(ROWS)])
    assert read_track_csv(track, required=("t", "lat", "lon"))["lat"][0] == 29.5


@pytest.mark.parametrize("header", ["depth", "Depth (m)", "water_depth"])
def test_a_depth_given_as_the_height_is_refused(tmp_path, refused, header):
    """``dov --columns h=depth`` (as the "lacks column h" message suggests) read a
    submarine 50 m down as 50 m up, exit 0."""
    track = tmp_path / "d.csv"
    track.write_text(f"lat,lon,{header}\n34.0,108.5,50\n34.01,108.51,100\n")
    out = tmp_path / "o.csv"
    refused(["dov", "--track", track, "--out", out, "--columns", f"h={header}"],
            f"column {header!r} holds depths (metres down, below the sea surface) and h is "
            "the height up, in metres above the ellipsoid: give a column of heights")
    assert not out.exists()


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A simulated track (30 fixes 2 min apart, velocities in m/s)."""
    d = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "--out", str(d / "t.csv"), "--truth", str(d / "truth.csv")]) == 0
    return d / "t.csv"


@pytest.mark.parametrize("scale, cause", [
    (1.943844, "(a factor 1.94): are they in knots (× 0.5144 gives m/s)?"),
    (3.6, "(a factor 3.6): are they in km/h (÷ 3.6 gives m/s)?"),
    (-1.0, "expected the INS velocity of these rows, east and north, in m/s"),
])
def test_match_names_velocity_columns_in_other_units(simulated, tmp_path, refused, scale,
                                                     cause):
    """A track with its velocities in knots (or km/h, or negated) was matched with the
    wrong Eötvös correction: a +42 mGal (+148, -115) bias, status "implausible", exit 0;
    ``filter`` and ``navigate`` named such columns already."""
    lines = simulated.read_text().splitlines()
    rows = [line.split(",") for line in lines[1:]]
    track = tmp_path / "t.csv"
    track.write_text("\n".join([lines[0], *(",".join(
        [*r[:4], f"{float(r[4]) * scale}", f"{float(r[5]) * scale}", *r[6:]]) for r in rows)])
        + "\n")
    out = tmp_path / "r.json"
    err = refused(["match", "--map", "ryukyu", "--track", track, "--out", out],
                  f"--track '{track}': v_east/v_north disagree with the positions on 29 of 29 "
                  "steps (first between lines 2 and 3): the positions move at a median 7.27 "
                  "m/s")
    assert cause in err
    assert not out.exists()


def test_a_map_in_tenths_of_a_milligal_is_converted(tmp_path):
    """A map declaring ``units: 0.1 mGal`` (stored in tenths) was read as mGal with a
    warning: sampled 10 x too large, exit 0."""
    grid = load_map("ryukyu")
    xr.Dataset({"gravity": (("lat", "lon"), 10 * np.asarray(grid.values, float),
                            {"units": "0.1 mGal"})},
               coords={"lat": np.asarray(grid.lat), "lon": np.asarray(grid.lon)}
               ).to_netcdf(tmp_path / "m.nc")
    track = _track(tmp_path / "t.csv")
    want, got = tmp_path / "want.csv", tmp_path / "got.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out", str(want)]) == 0
    assert main(["sample", "--map", str(tmp_path / "m.nc"), "--track", str(track), "--out",
                 str(got)]) == 0
    np.testing.assert_allclose(read_track_csv(got)["map"], read_track_csv(want)["map"],
                               atol=1e-4)


@pytest.mark.parametrize("text, lat, gravity", [
    ("t,lat\u200b,lon,gravity\n0,29.5,126.5,-10\n10,29.51,126.51,-9\n", 29.5, -10.0),
    ("t,lat,lon,gravity\n0,29.5,126.5,\u221210.5\n10,29.51,126.51,\u22129.5\n", 29.5, -10.5),
    ("t,lat,lon,gravity\n0,\u221229.5,126.5,1\n10,\u221229.51,126.51,2\n", -29.5, 1.0),
    ("t,lat,lon,gravity\n0,\u221229\u00b030',126.5,1\n10,\u221229\u00b031',126.51,2\n", -29.5,
     1.0),
    ("\ufefft,lat,lon,gravity\n0,29.5,126.5,1\n\ufefft,lat,lon,gravity\n10,29.51,126.51,2\n",
     29.5, 1.0),  # two UTF-8 files joined: the second's byte-order mark mid-file
])
def test_invisible_characters_and_typeset_minus_signs_are_read(tmp_path, text, lat, gravity):
    """A zero-width space after ``lat`` (pasted from a web page) was "lacks column lat;
    it has t, lat, lon"; a typeset minus (U+2212, ``−10.5``) was "not a number"; a second
    byte-order mark where two files were joined was "'\\ufefft' is not a number"."""
    track = tmp_path / "t.csv"
    track.write_text(text, encoding="utf-8")
    got = read_track_csv(track, required=("t", "lat", "lon"))
    assert got["lat"][0] == lat and got["gravity"][0] == gravity


@pytest.mark.parametrize("key", ["Units", "UNITS", "unit"])
def test_a_map_units_attribute_in_another_spelling_is_read(tmp_path, key):
    """A map in m/s² whose attribute was spelled ``Units`` (or ``unit``) was sampled as
    mGal, 1e5 x too small, exit 0 (only ``units`` was read)."""
    grid = load_map("ryukyu")
    xr.Dataset({"gravity": (("lat", "lon"), 1e-5 * np.asarray(grid.values, float),
                            {key: "m s-2"})},
               coords={"lat": np.asarray(grid.lat), "lon": np.asarray(grid.lon)}
               ).to_netcdf(tmp_path / "m.nc")
    track = _track(tmp_path / "t.csv")
    want, got = tmp_path / "want.csv", tmp_path / "got.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out", str(want)]) == 0
    assert main(["sample", "--map", str(tmp_path / "m.nc"), "--track", str(track), "--out",
                 str(got)]) == 0
    np.testing.assert_allclose(read_track_csv(got)["map"], read_track_csv(want)["map"],
                               atol=1e-4)


@pytest.mark.parametrize("header, sign", [
    ("lat (deg. S)", -1.0), ("lat (deg.S)", -1.0), ("lat (dd S)", -1.0),
    ("lat (decimal degrees S)", -1.0), ("lat (S.)", -1.0),
    ("lat (N/S)", 1.0), ("lat (+N)", 1.0), ("lat (deg. N)", 1.0),
])
def test_a_hemisphere_among_other_words_gives_the_sign(tmp_path, header, sign):
    """``lat (deg. S)`` or ``lat (dd S)`` were read as north (the unit was not known, so
    taken for a note), exit 0; ``N/S`` and a sign (``+N``) leave the values as they are."""
    track = _track(tmp_path / "t.csv", f"t,{header},lon",
                   [f"{120 * i},{lat},{lon}" for i, (lat, lon) in enumerate(ROWS)])
    assert read_track_csv(track, required=("t", "lat", "lon"))["lat"][0] == sign * 29.5


def test_a_longitude_hemisphere_among_latitude_words_is_refused(tmp_path):
    track = _track(tmp_path / "t.csv", "t,lat (deg. W),lon",
                   [f"{120 * i},{lat},{lon}" for i, (lat, lon) in enumerate(ROWS)])
    with pytest.raises(ValueError, match=re.escape(
            "column 'lat (deg. W)' declares 'deg. w', a longitude hemisphere, for latitudes")):
        read_track_csv(track, required=("t", "lat", "lon"))


def _dov_file(path, key, xi_units, factor, h_units, h_factor):
    """A 2-layer DOV file on 0-1 N, 10-11 E, heights 0 and 1000 m, its units under ``key``."""
    lat, lon = np.linspace(0.0, 1.0, 11), np.linspace(10.0, 11.0, 11)
    values = np.stack([np.stack([np.add.outer(lat, lon) * (k + 1) * (c + 1) for c in range(2)])
                       for k in range(2)])
    xr.Dataset({name: (("height", "lat", "lon"), values[:, c] / factor, {key: xi_units})
                for c, name in enumerate(("xi", "eta"))},
               coords={"height": ("height", np.array([0.0, 1000.0]) / h_factor,
                                  {key: h_units}),
                       "lat": lat, "lon": lon}).to_netcdf(path)
    return path


@pytest.mark.parametrize("key", ["Units", "unit"])
def test_dov_grid_units_in_another_spelling_are_converted(tmp_path, key):
    """A ``--grid`` in µrad with heights in km, its attribute spelled ``Units``, was read
    as arcsec and metres, exit 0."""
    track = tmp_path / "t.csv"
    track.write_text("lat,lon,h\n0.5,10.5,500\n0.52,10.55,250\n")
    outs = []
    for name, args in (("a", ("units", "arcsec", 1.0, "m", 1.0)),
                       ("b", (key, "urad", 0.20626480624709636, "km", 1000.0))):
        grid = _dov_file(tmp_path / f"{name}.nc", *args)
        outs.append(tmp_path / f"{name}.csv")
        assert main(["dov", "--track", str(track), "--out", str(outs[-1]), "--grid", str(grid),
                     "--method", "bilinear-linear"]) == 0
    a, b = (np.loadtxt(p, delimiter=",", skiprows=1) for p in outs)
    np.testing.assert_allclose(b, a, rtol=1e-9)


def test_a_missing_height_beside_a_depth_column_says_how_they_differ(tmp_path, refused):
    """dov's "lacks column h" told a file with a depth column to give ``--columns
    h=COLUMN``, which read depths as heights."""
    track = tmp_path / "d.csv"
    track.write_text("lat,lon,depth\n34.0,108.5,50\n34.01,108.51,100\n")
    refused(["dov", "--track", track, "--out", tmp_path / "o.csv"],
            "(names in any case; aliases: time, latitude, longitude; others with --columns "
            "h=COLUMN); column 'depth' holds depths (metres down), and h is the height up, in "
            "metres above the ellipsoid: add a column of heights, the geoid height minus the "
            "depth")
