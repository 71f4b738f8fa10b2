"""Track files of other tools: an Excel "sep=" first line, a JSON file given as a track,
a one-column header (issue 19)."""

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
