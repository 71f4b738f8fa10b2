"""Track files of other tools: an Excel "sep=" first line, a JSON file given as a track,
a one-column header, a unit in a header (issue 19)."""

import pytest

from jaxgrav.tracks import read_track_csv


@pytest.mark.parametrize(("text", "lines"), [
    ("sep=,\nt,lat,lon\n0,30,130\n60,30.01,130\n", [3, 4]),
    ("sep=;\r\nt;lat;lon\r\n0;30,5;130\r\n", [3]),
    ('"sep=\t"\nt\tlat\tlon\n0\t30\t130\n', [3]),
])
def test_an_excel_sep_line_declares_the_delimiter(tmp_path, text, lines):
    path = tmp_path / "x.csv"
    path.write_text(text)
    track = read_track_csv(path, required=("t", "lat", "lon"))
    assert list(track.lines) == lines and track["lat"][0] in (30.0, 30.5)


@pytest.mark.parametrize("text", ['{"t": [0, 60], "lat": [30, 30.1]}', '[\n {"t": 0}\n]\n'])
def test_a_json_file_is_named_as_json(tmp_path, text):
    path = tmp_path / "t.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=r"looks like JSON .*, not a track; a track is a CSV"):
        read_track_csv(path)


def test_one_column_header_in_the_singular(tmp_path):
    path = tmp_path / "one.txt"
    path.write_text("a\n1 2\n")
    with pytest.raises(ValueError, match=r"the header has 1 column \(whitespace-separated\)"):
        read_track_csv(path)


@pytest.mark.parametrize(("header", "cell", "name", "value"), [
    ("t (min)", "2", "t", 120.0), ("t [ms]", "1500", "t", 1.5), ("time (h)", "1", "t", 3600.0),
    ("lat (rad)", "0.5", "lat", 28.64788975654116), ("Latitude [deg]", "30", "lat", 30.0),
    ("gravity [m/s^2]", "2e-4", "gravity", 20.0), ("gravity (uGal)", "3000", "gravity", 3.0),
    ("gravity (10^-5 m/s^2)", "7", "gravity", 7.0), ("magnetic (uT)", "0.5", "magnetic", 500.0),
    ("v_east (kn)", "10", "v_east", 5.144444444444445), ("h (ft)", "100", "h", 30.48),
    ("time (UTC)", "60", "t", 60.0), ("gravity (free-air)", "7", "gravity", 7.0),
])
def test_a_unit_in_a_header_converts_the_column(tmp_path, header, cell, name, value):
    """``gravity [m/s^2]`` was refused for its spread ("are the readings in other units?")
    though the header said so; ``t (min)`` was read as seconds and ``lat (rad)`` as
    degrees ("the track leaves the map"): a known unit is now converted, a note such as
    ``(UTC)`` or ``(free-air)`` left alone."""
    path = tmp_path / "u.csv"
    cols = {"t": "0", "lat": "0.1", "lon": "130", name: cell}
    heads = {k: k for k in cols} | {name: header}
    path.write_text(",".join(heads.values()) + "\n" + ",".join(cols.values()) + "\n")
    track = read_track_csv(path, required=("t", "lat", "lon", name))
    assert track[name][0] == pytest.approx(value)


def test_a_field_column_in_the_other_field_s_unit_is_refused(tmp_path):
    """``gravity (nT)``: the header says a magnetic field; not read as mGal."""
    path = tmp_path / "u.csv"
    path.write_text("t,lat,lon,gravity (nT)\n0,30,130,5\n")
    with pytest.raises(ValueError, match=r"^track file '.*u.csv': column 'gravity \(nT\)' "
                       r"declares 'nT', a unit of magnetic fields; column 'gravity' holds mGal: "
                       r"rename it or name the right column with --columns$"):
        read_track_csv(path, required=("t", "lat", "lon", "gravity"))


def test_a_year_first_date_with_slashes_is_a_date_time(tmp_path):
    """``2024/05/01 12:00:00`` (a spreadsheet's export) was "neither a number nor an
    ISO-8601 date-time"; the text is kept as written."""
    path = tmp_path / "s.csv"
    path.write_text("time,lat,lon\n2024/05/01 12:00:00,30,130\n2024/05/01 12:01:30,30,130\n")
    track = read_track_csv(path, required=("t", "lat", "lon"))
    assert list(track["t"]) == [0.0, 90.0] and track.time_origin == "2024-05-01T12:00:00"
    assert list(track.text["time"]) == ["2024/05/01 12:00:00", "2024/05/01 12:01:30"]


def test_a_time_of_day_without_a_date_says_so(tmp_path):
    """``12:00:00`` with no date anywhere is refused with the reason (a ``date`` column
    is joined to it: ``tests/cli/test_cli_inputs_hunt6.py``)."""
    path = tmp_path / "c.csv"
    path.write_text("day,time,lat,lon\n2024-05-01,12:00:00,30,130\n")
    with pytest.raises(ValueError, match=r"line 2, column 'time': '12:00:00' is neither a "
                       r"number \(seconds\) nor an ISO-8601 date-time \(e.g. "
                       r"2024-05-01T12:00:00Z\) \(a time of day without a date: join the date "
                       r"to it, or give it a column named 'date'\); times must be complete$"):
        read_track_csv(path, required=("t", "lat", "lon"))


def test_a_units_row_under_the_header_is_read_as_the_units(tmp_path):
    """``t,lat,lon,gravity`` then ``s,deg,deg,m/s^2`` (a survey export): was "line 2, column
    'lat': 'deg' is not a number"; now the units convert the columns, and the data keep
    their line numbers."""
    path = tmp_path / "u.csv"
    path.write_text("t,lat,lon,gravity,ship\nmin,deg,deg,m/s^2,\n1,30,130,2e-4,A\n2,30,130,,A\n")
    track = read_track_csv(path, required=("t", "lat", "lon", "gravity"),
                           allow_nan=("gravity",))
    assert list(track["t"]) == [60.0, 120.0] and track["gravity"][0] == pytest.approx(20.0)
    assert list(track.lines) == [3, 4] and list(track.text["ship"]) == ["A", "A"]


def test_a_repeated_header_of_joined_files_is_skipped(tmp_path):
    """``cat a.csv b.csv``: b's header mid-file was "'t' is not a number"."""
    path = tmp_path / "j.csv"
    path.write_text("t,lat,lon\n0,30,130\nt,lat,lon\n60,30.1,130\n")
    track = read_track_csv(path, required=("t", "lat", "lon"))
    assert list(track["t"]) == [0.0, 60.0] and list(track.lines) == [2, 4]
