"""The track and log reader (jaxgrav.tracks.read_track_csv): one case per input variant of
issue 19, and hypothesis-generated valid and malformed files."""

import codecs
import datetime as dt

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxgrav.cli import main
from jaxgrav.tracks import parse_columns, read_track_csv, write_track_csv

BASE = {"t": [0.0, 10.0, 20.0], "lat": [30.0, 30.1, 30.2], "lon": [130.0, 130.1, 130.2],
        "gravity": [1.5, -2.25, 3.0]}

# (id, file name, bytes, read_track_csv kwargs, expected columns, expected text columns)
VALID = [
    ("comma", "a.csv", b"t,lat,lon,gravity\n0,30,130,1.5\n10,30.1,130.1,-2.25\n"
     b"20,30.2,130.2,3\n", {}, BASE, {}),
    ("semicolon-decimal-comma", "a.csv", b"t;lat;lon;gravity\n0;30;130;1,5\n10;30,1;130,1;"
     b"-2,25\n20;30,2;130,2;3\n", {}, BASE, {}),
    ("tab", "a.tsv", b"t\tlat\tlon\tgravity\n0\t30\t130\t1.5\n10\t30.1\t130.1\t-2.25\n"
     b"20\t30.2\t130.2\t3\n", {}, BASE, {}),
    ("whitespace-xyz", "a.xyz", b"t   lat  lon    gravity\n 0 30 130 1.5\n10  30.1 130.1 -2.25"
     b"\n20 30.2  130.2 3\n", {}, BASE, {}),
    ("headerless-xyz", "a.xyz", b"130 30 1.5\n130.1 30.1 -2.25\n130.2 30.2 3\n",
     {"columns": {"gravity": "z"}},
     {k: BASE[k] for k in ("lat", "lon", "gravity")}, {}),
    ("headerless-by-number", "a.txt", b"0,130,30,1.5\n10,130.1,30.1,-2.25\n20,130.2,30.2,3\n",
     {"columns": {"t": "1", "lon": "2", "lat": "3", "gravity": "4"}}, BASE, {}),
    ("bom-crlf", "a.csv", codecs.BOM_UTF8 + b"t,lat,lon,gravity\r\n0,30,130,1.5\r\n10,30.1,"
     b"130.1,-2.25\r\n20,30.2,130.2,3\r\n", {}, BASE, {}),
    ("utf16-tab", "a.txt", "t\tlat\tlon\tgravity\n0\t30\t130\t1.5\n10\t30.1\t130.1\t-2.25\n"
     "20\t30.2\t130.2\t3\n".encode("utf-16"), {}, BASE, {}),
    ("aliases-case-units", "a.csv", b" Time ,LATITUDE, Longitude ,Gravity [mGal]\n0,30,130,1.5\n"
     b"10,30.1,130.1,-2.25\n20,30.2,130.2,3\n", {}, BASE, {}),
    ("long-alias", "a.csv", b"time,lat,long,gravity\n0,30,130,1.5\n10,30.1,130.1,-2.25\n"
     b"20,30.2,130.2,3\n", {}, BASE, {}),
    ("columns-mapping", "a.csv", b"SEC,Y,X,FAA\n0,30,130,1.5\n10,30.1,130.1,-2.25\n"
     b"20,30.2,130.2,3\n", {"columns": {"t": "sec", "lat": "Y", "lon": "X", "gravity": "FAA"}},
     BASE, {}),
    ("iso-z", "a.csv", b"time,lat,lon,gravity\n2024-05-01T12:00:00Z,30,130,1.5\n"
     b"2024-05-01T12:00:10Z,30.1,130.1,-2.25\n2024-05-01T12:00:20Z,30.2,130.2,3\n", {}, BASE,
     {"time": ["2024-05-01T12:00:00Z", "2024-05-01T12:00:10Z", "2024-05-01T12:00:20Z"]}),
    ("iso-offset-space-fraction", "a.csv", b"t,lat,lon,gravity\n2024-05-01 21:00:00.5+09:00,30,"
     b"130,1.5\n2024-05-01 21:00:10.5+09:00,30.1,130.1,-2.25\n2024-05-01 12:00:20.5+00:00,30.2,"
     b"130.2,3\n", {}, BASE, {"time": ["2024-05-01 21:00:00.5+09:00",
                                        "2024-05-01 21:00:10.5+09:00",
                                        "2024-05-01 12:00:20.5+00:00"]}),
    ("quoted-text-and-extra", "a.csv", b't,lat,lon,gravity,ship,depth\n0,30,130,1.5,"Maru, No. 1"'
     b',100\n10,30.1,130.1,-2.25,"Maru, No. 1",110\n20,30.2,130.2,3,Kai,120\n', {},
     {**BASE, "depth": [100.0, 110.0, 120.0]}, {"ship": ["Maru, No. 1", "Maru, No. 1", "Kai"]}),
    ("comments-blank-lines", "a.csv", b"# GMT header\n# more\nt,lat,lon,gravity\n\n0,30,130,1.5"
     b"\n# a note\n10,30.1,130.1,-2.25\n\n20,30.2,130.2,3\n", {}, BASE, {}),
    ("trailing-delimiter", "a.csv", b"t,lat,lon,gravity,\n0,30,130,1.5,\n10,30.1,130.1,-2.25,\n"
     b"20,30.2,130.2,3,\n", {}, BASE, {}),
    ("na-tokens", "a.csv", b"t,lat,lon,gravity\n0,30,130,NA\n10,30.1,130.1,\n20,30.2,130.2,nan\n",
     {"required": ("t", "gravity"), "allow_nan": ("gravity",)},
     {**BASE, "gravity": [np.nan] * 3}, {}),
    ("lon-0-360-across-greenwich", "a.csv", b"t,lat,lon\n0,30,359.5\n10,30.1,359.9\n20,30.2,0.4\n",
     {}, {"t": BASE["t"], "lat": BASE["lat"], "lon": [-0.5, -0.1, 0.4]}, {}),
    ("lon-pm180-across-dateline", "a.csv", b"t,lat,lon\n0,30,179.5\n10,30.1,-179.9\n20,30.2,"
     b"-179.4\n", {}, {"t": BASE["t"], "lat": BASE["lat"], "lon": [179.5, 180.1, 180.6]}, {}),
    ("lon-0-360-plain", "a.csv", b"t,lat,lon\n0,30,200\n10,30.1,200.1\n20,30.2,200.2\n", {},
     {"t": BASE["t"], "lat": BASE["lat"], "lon": [200.0, 200.1, 200.2]}, {}),
    ("exact-name-wins", "a.csv", b"time,t,lat,lon\n2024-05-01T00:00:00,0,30,130\n"
     b"2024-05-01T00:00:10,10,30.1,130.1\n2024-05-01T00:00:20,20,30.2,130.2\n", {},
     {k: BASE[k] for k in ("t", "lat", "lon")},
     {"time": ["2024-05-01T00:00:00", "2024-05-01T00:00:10", "2024-05-01T00:00:20"]}),
]


@pytest.mark.parametrize(("name", "fname", "data", "kw", "numbers", "text"), VALID,
                         ids=[c[0] for c in VALID])
def test_valid_track_variants(tmp_path, name, fname, data, kw, numbers, text):
    path = tmp_path / fname
    path.write_bytes(data)
    kw = {"required": tuple(numbers), **kw}
    track = read_track_csv(path, **kw)
    assert set(numbers) <= set(track)
    for k, v in numbers.items():
        np.testing.assert_allclose(track[k], v, rtol=0, atol=1e-9, err_msg=f"{name}: {k}")
    for k, v in text.items():
        assert list(track.text[k]) == v
    # pass-through: every column comes back in the file's order, text untouched
    out = tmp_path / "out.csv"
    write_track_csv(out, {**track.columns(), "extra": np.arange(len(track["lat"]))})
    back = read_track_csv(out, required=tuple(numbers), allow_nan=kw.get("allow_nan", ()))
    for k in numbers:
        np.testing.assert_allclose(back[k], track[k], rtol=1e-9, atol=1e-9)
    for k, v in track.text.items():
        assert list(back.text[k]) == list(v)


def test_line_numbers_count_comments_and_blank_lines(tmp_path):
    path = tmp_path / "a.csv"
    path.write_bytes(VALID[14][2])
    assert list(read_track_csv(path).lines) == [5, 7, 9]


# (id, file name, bytes, kwargs, error class, phrases the message must hold)
INVALID = [
    ("missing-column", "a.csv", b"lat,lon\n30,130\n", {"required": ("t", "lat")}, ValueError,
     ["lacks column t; it has lat, lon; required: t, lat", "--columns t=COLUMN"]),
    ("not-a-number", "a.csv", b"t,lat,lon\n0,30,130\n10,abc,130\n", {"required": ("lat",)},
     ValueError, ["line 3", "column 'lat'", "'abc' is not a number", "degrees"]),
    ("repeated-time", "a.csv", b"t,lat\n0,30\n10,30\n10,30\n", {}, ValueError,
     ["line 4", "time 10 repeats 10 on line 3", "times must increase"]),
    ("backward-time", "a.csv", b"t,lat\n0,30\n10,30\n5,30\n", {}, ValueError,
     ["line 4", "time 5 is earlier than 10 on line 3"]),
    ("backward-iso-time", "a.csv", b"time,lat\n2024-05-01T00:00:10,30\n2024-05-01T00:00:05,30\n",
     {}, ValueError, ["line 3", "2024-05-01T00:00:05 is earlier than 2024-05-01T00:00:10"]),
    ("bad-iso-time", "a.csv", b"time,lat\n2024-05-01T00:00:10,30\n2024-13-01T00:00:05,30\n", {},
     ValueError, ["line 3", "'2024-13-01T00:00:05' is neither a number", "ISO-8601"]),
    ("mixed-time-zones", "a.csv", b"time,lat\n2024-05-01T00:00:10Z,30\n2024-05-01T00:00:15,30\n",
     {}, ValueError, ["line 3", "lacks a time zone"]),
    ("missing-time", "a.csv", b"t,lat\n0,30\n,30\n", {"required": ("t",)}, ValueError,
     ["column 't' has 1 missing or NaN value(s), first on line 3"]),
    ("latitude-range", "a.csv", b"t,lat,lon\n0,30,130\n10,95,130\n", {}, ValueError,
     ["line 3", "latitude 95 is outside [-90, 90]"]),
    # issue 19 (hunt 7): the likely cause named
    ("latitude-and-longitude-swapped", "a.csv", b"t,lat,lon\n0,130,30\n10,130.1,30.1\n", {},
     ValueError, ["line 2", "latitude 130 is outside [-90, 90]", "look swapped",
                  "--columns lat=NAME lon=NAME"]),
    ("column-number-zero", "a.csv", b"t,lat,lon\n0,30,130\n", {"columns": {"lat": "0"}},
     ValueError, ["has no column '0'", "columns are counted from 1 to 3"]),
    ("longitude-range", "a.csv", b"t,lat,lon\n0,30,130\n10,30,400\n", {}, ValueError,
     ["line 3", "longitude 400 is outside [-180, 360]"]),
    ("nan-in-required", "a.csv", b"t,lat,gravity\n0,30,1\n10,30,\n", {"required": ("gravity",)},
     ValueError, ["column 'gravity' has 1 missing", "line 3", "must be complete"]),
    # issue 19: an inf reading was skipped as "no reading" (filter, navigate), with NumPy's
    # "RuntimeWarning: invalid value encountered in subtract" on stderr
    ("inf-where-empty-is-allowed", "a.csv", b"t,lat,FAA\n0,30,1\n10,30,\n20,30,-inf\n",
     {"required": ("gravity",), "allow_nan": ("gravity",), "columns": {"gravity": "FAA"}},
     ValueError, ["line 4, column 'FAA': -inf is not a value", "leave the cell empty"]),
    # issue 19: "lacks column(s) ['lon']; it has ['t', 'lat', 'lon']"
    ("columns-take-a-required-column", "a.csv", b"t,lat,lon\n0,30,130\n",
     {"required": ("lat", "lon"), "columns": {"lat": "lon"}}, ValueError,
     ["column 'lon' would be read as 'lon', but --columns lat=lon reads it as 'lat'",
      "--columns lon=COLUMN"]),
    ("row-too-long", "a.csv", b"t,lat,lon\n0,30,130\n10,30,130,5\n", {}, ValueError,
     ["line 3 has 4 cells but the header has 3", "comma"]),
    ("duplicate-header", "a.csv", b"t,lat,lat\n0,30,31\n", {}, ValueError,
     ["column 'lat' appears twice"]),
    ("ambiguous-alias", "a.csv", b"t,LAT,Lat\n0,30,31\n", {}, ValueError,
     ["columns LAT and Lat could all be 'lat'", "--columns lat=COLUMN"]),
    ("netcdf-as-track", "a.nc", b"CDF\x01\x00\x00\x00\x00", {}, ValueError,
     ["NetCDF-3 file, not a text table"]),
    ("binary", "a.bin", b"\x00\x01\x02\x03", {}, ValueError, ["binary file"]),
    ("empty", "a.csv", b"\n\n", {}, ValueError, ["is empty; expected a header row"]),
    ("header-only", "a.csv", b"t,lat,lon\n", {}, ValueError, ["has a header but no rows"]),
    ("columns-missing", "a.csv", b"t,lat,lon\n0,30,130\n", {"columns": {"gravity": "FAA"}},
     ValueError, ["has no column 'FAA'", "it has t, lat, lon", "--columns gravity=FAA"]),
    ("columns-same-column", "a.csv", b"t,lat,lon\n0,30,130\n",
     {"columns": {"lat": "lat", "lon": "lat"}}, ValueError, ["cannot be both 'lat' and 'lon'"]),
    ("unbalanced-quote-whitespace", "a.xyz", b"t lat name\n0 30 \"Maru\n", {}, ValueError,
     ["line 2", "quotation"]),
]


@pytest.mark.parametrize(("name", "fname", "data", "kw", "error", "phrases"), INVALID,
                         ids=[c[0] for c in INVALID])
def test_invalid_track_variants(tmp_path, clear_message, name, fname, data, kw, error, phrases):
    path = tmp_path / fname
    path.write_bytes(data)
    with pytest.raises(error) as info:
        read_track_csv(path, **kw)
    clear_message(str(info.value), path, phrases)


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        read_track_csv(tmp_path / "none.csv")
    with pytest.raises(ValueError, match="is a folder"):
        read_track_csv(tmp_path)


def test_parse_columns():
    assert parse_columns(" lat = LAT , lon=Long (deg),gravity=4 ") == {
        "lat": "LAT", "lon": "Long (deg)", "gravity": "4"}
    assert parse_columns(None) == {} == parse_columns("")
    for text, phrase in [("lat", "NAME=COLUMN pairs"), ("lat=", "NAME=COLUMN"),
                         ("=LAT", "NAME=COLUMN"), ("lat=A,lat=B", "names 'lat' twice"),
                         ("lat=A,lon=a", "gives column 'a' two names")]:
        with pytest.raises(ValueError, match=phrase):
            parse_columns(text)


# ---------------------------------------------------------------------- hypothesis
ALIAS_CHOICES = {"t": ["t", "time", "Time", "TIME", "timestamp"],
                 "lat": ["lat", "latitude", "Latitude", "LAT", "lat (deg)"],
                 "lon": ["lon", "longitude", "long", "Longitude", "LON [deg]"]}


@st.composite
def tracks(draw):
    """A track (values) and how it is written (delimiter, names, BOM, line ends, ISO)."""
    n = draw(st.integers(2, 7))
    t = np.cumsum(draw(st.lists(st.integers(1, 600), min_size=n, max_size=n))).astype(float)
    lat = draw(st.lists(st.floats(-89, 89, allow_nan=False).map(lambda v: round(v, 5)),
                        min_size=n, max_size=n))
    lon0 = draw(st.floats(-180, 359).map(lambda v: round(v, 3)))
    dlon = draw(st.lists(st.floats(-0.4, 0.4).map(lambda v: round(v, 3)), min_size=n,
                         max_size=n))
    lon = np.round(lon0 + np.cumsum(dlon), 6)
    lon = np.where(lon >= 360, lon - 360, np.where(lon < -180, lon + 360, lon))
    gravity = [draw(st.one_of(st.none(), st.floats(-300, 300).map(lambda v: round(v, 4))))
               for _ in range(n)]
    ship = draw(st.lists(st.sampled_from(["Kai", "Maru 1", "Hakuho, M", "x;y"]), min_size=n,
                         max_size=n))
    return dict(
        t=t, lat=np.asarray(lat), lon=lon, gravity=gravity, ship=ship,
        delimiter=draw(st.sampled_from([",", ";", "\t", " "])),
        names={k: draw(st.sampled_from(v)) for k, v in ALIAS_CHOICES.items()},
        bom=draw(st.booleans()), crlf=draw(st.booleans()), iso=draw(st.booleans()),
        decimal_comma=draw(st.booleans()))


def render(tr):
    """The bytes of a track file as a user's tool might write it."""
    d = tr["delimiter"]
    comma = tr["decimal_comma"] and d in ";\t"

    def num(v):
        s = "nan" if v is None else repr(float(v))
        return s.replace(".", ",") if comma else s

    def quote(s):
        return f'"{s}"' if (d in s or (d == " " and " " in s) or "," in s) else s

    start = dt.datetime(2024, 5, 1, tzinfo=dt.UTC)
    times = ([(start + dt.timedelta(seconds=float(s))).isoformat() for s in tr["t"]]
             if tr["iso"] else [num(s) for s in tr["t"]])
    names = tr["names"]
    extra = tr.get("extra", {})  # more numeric columns, after the text column
    header = [names["t"], names["lat"], names["lon"], "gravity", "ship", *extra]
    if d == " ":
        header = [h.replace(" ", "") for h in header]
    lines = [d.join(quote(h) for h in header)]
    for i in range(len(tr["t"])):
        lines.append(d.join([times[i], num(tr["lat"][i]), num(tr["lon"][i]),
                             num(tr["gravity"][i]), quote(tr["ship"][i]),
                             *(num(v[i]) for v in extra.values())]))
    eol = "\r\n" if tr["crlf"] else "\n"
    data = (eol.join(lines) + eol).encode()
    return (codecs.BOM_UTF8 if tr["bom"] else b"") + data


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(tracks())
def test_generated_valid_tracks_parse_to_their_values(tmp_path, tr):
    path = tmp_path / "g.csv"
    path.write_bytes(render(tr))
    got = read_track_csv(path, required=("t", "lat", "lon", "gravity"), allow_nan=("gravity",))
    np.testing.assert_allclose(got["t"], tr["t"] - tr["t"][0] if tr["iso"] else tr["t"])
    np.testing.assert_allclose(got["lat"], tr["lat"])
    # the same places: equal modulo 360, and no jump between neighbours
    np.testing.assert_allclose(np.mod(got["lon"] - tr["lon"] + 180, 360) - 180, 0, atol=1e-9)
    assert np.all(np.abs(np.diff(got["lon"])) < 180)
    g = np.array([np.nan if v is None else v for v in tr["gravity"]])
    np.testing.assert_array_equal(np.isnan(got["gravity"]), np.isnan(g))
    np.testing.assert_allclose(got["gravity"][~np.isnan(g)], g[~np.isnan(g)])
    assert list(got.text["ship"]) == tr["ship"]
    assert list(got.lines) == list(range(2, len(tr["t"]) + 2))


def malformed(tr, fault, k):
    """The bytes of ``tr`` with one fault at data row ``k`` (≥ 1), and the phrases its
    error message must hold."""
    t, lat = tr["t"].copy(), tr["lat"].astype(object)
    phrases = [f"line {k + 2}"]
    if fault == "repeat":
        t[k] = t[k - 1]
        phrases.append("repeats")
    elif fault == "backward":
        t[k] = t[k - 1] - 1 - (0 if tr["iso"] else 0.5)
        phrases.append("is earlier than")
    elif fault == "latitude":
        lat[k] = 91.5
        phrases.append("latitude 91.5 is outside [-90, 90]")
    tr = {**tr, "t": t, "lat": lat}
    raw = render(tr)
    if fault == "text":
        lines = raw.split(b"\n")
        cells = lines[k + 1].split(tr["delimiter"].encode())
        cells[1] = b"north"
        lines[k + 1] = tr["delimiter"].encode().join(cells)
        raw = b"\n".join(lines)
        phrases.append("'north' is not a number")
    if fault == "drop":
        raw = raw.replace(tr["names"]["lat"].replace(" ", "" if tr["delimiter"] == " " else " ")
                          .encode(), b"northing", 1)
        phrases = ["lacks column lat; it has "]
    return raw, phrases


FAULTS = ["repeat", "backward", "text", "latitude", "drop"]


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(tracks(), st.sampled_from(FAULTS), st.data())
def test_generated_malformed_tracks_name_the_line(tmp_path, tr, fault, data):
    raw, phrases = malformed(tr, fault, data.draw(st.integers(1, len(tr["t"]) - 1)))
    path = tmp_path / "m.csv"
    path.write_bytes(raw)
    with pytest.raises(ValueError) as info:
        read_track_csv(path, required=("t", "lat", "lon", "gravity"), allow_nan=("gravity",))
    msg = str(info.value)
    assert "np." not in msg and str(path) in msg
    for p in phrases:
        assert p in msg, (p, msg)


# ------------------------------------------- the same files through a command, in-process
@pytest.fixture(scope="module")
def global_map(tmp_path_factory):
    """A global 1° map on 0–359° longitudes (NetCDF) and its nodes, for ``jaxgrav sample``."""
    lat, lon = np.arange(-90.0, 90.5, 1.0), np.arange(0.0, 360.0, 1.0)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    values = 50 * np.sin(np.radians(3 * la)) * np.cos(np.radians(2 * lo)) + 0.1 * lo
    path = tmp_path_factory.mktemp("global") / "g.nc"
    xr.Dataset({"anomaly": (("lat", "lon"), values, {"units": "mGal"})},
               coords={"lat": lat, "lon": lon}).to_netcdf(path)
    return path, lat, lon, values


def _bilinear_wrapped(lat, lon, values, plat, plon):
    """Brute-force bilinear interpolation on a global 1° grid, longitudes wrapped."""
    fy = plat - lat[0]
    fx = np.mod(plon - lon[0], 360.0)
    r, c = np.minimum(np.floor(fy).astype(int), len(lat) - 2), np.floor(fx).astype(int)
    ty, tx = fy - r, fx - c
    c1 = (c + 1) % len(lon)
    return (values[r, c] * (1 - ty) * (1 - tx) + values[r + 1, c] * ty * (1 - tx)
            + values[r + 1, c1] * ty * tx + values[r, c1] * (1 - ty) * tx)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(tracks(), st.one_of(st.none(), st.sampled_from(FAULTS)), st.data())
def test_generated_tracks_through_the_sample_command(tmp_path, capsys, global_map, tr, fault,
                                                     data):
    """``jaxgrav sample`` run in-process on generated files: a valid one gives the map's
    bilinear values at every row (across 0°/360° too) and keeps the text column; a
    malformed one exits 2 with one line naming the file and the line, writing nothing."""
    path_map, lat, lon, values = global_map
    raw = render(tr) if fault is None else malformed(
        tr, fault, data.draw(st.integers(1, len(tr["t"]) - 1)))[0]
    track, out = tmp_path / "in.csv", tmp_path / "out.csv"
    track.write_bytes(raw)
    out.unlink(missing_ok=True)
    capsys.readouterr()
    code = main(["sample", "--map", str(path_map), "--track", str(track), "--out", str(out),
                 "--method", "bilinear"])
    if fault is not None:
        err = capsys.readouterr().err.strip()
        assert code == 2 and str(track) in err and "\n" not in err and "Traceback" not in err
        assert not out.exists()
        return
    assert code == 0
    got = read_track_csv(out, required=("lat", "lon", "map"), allow_nan=("gravity",))
    want = _bilinear_wrapped(lat, lon, values, np.asarray(tr["lat"], float),
                             np.asarray(tr["lon"], float))
    np.testing.assert_allclose(got["map"], want, atol=1e-6)
    assert list(got.text["ship"]) == tr["ship"]


COMMANDS = {"match": "out.json", "filter": "out.csv", "navigate": "out.csv",
            "sample": "out.csv", "dov": "out.csv"}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(tracks(), st.sampled_from(FAULTS), st.sampled_from(sorted(COMMANDS)), st.data())
def test_generated_malformed_tracks_through_every_command(tmp_path, capsys, global_map, tr,
                                                          fault, command, data):
    """Every command that reads a track (``match``, ``filter``, ``navigate``, ``sample``,
    ``dov``) refuses a generated malformed file the same way: exit 2, one line naming the file
    and the line (the tracks carry the velocity and height columns ``navigate`` and
    ``dov`` need), no
    traceback, no output written."""
    n = len(tr["t"])
    tr = {**tr, "extra": {"v_east": np.full(n, 5.0), "v_north": np.full(n, -1.5),
                          "h": np.full(n, 100.0)}}
    raw, phrases = malformed(tr, fault, data.draw(st.integers(1, n - 1)))
    track = tmp_path / "in.csv"
    track.write_bytes(raw)
    out = tmp_path / COMMANDS[command]
    out.unlink(missing_ok=True)
    capsys.readouterr()
    the_map = [] if command == "dov" else ["--map", str(global_map[0])]
    code = main([command, *the_map, "--track", str(track), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and str(track) in err and "\n" not in err and "Traceback" not in err
    for p in phrases:
        assert p in err, (p, err)
    assert not out.exists()


def test_pass_through_keeps_the_files_text_and_epoch_seconds(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("t,lat,lon,station,count\n1714564800.125,30,130,0012,7\n"
                    "1714564801.250,30.1,130.1,0013,8\n")
    track = read_track_csv(path, required=("t", "lat", "lon"))
    np.testing.assert_allclose(np.diff(track["t"]), 1.125)
    np.testing.assert_array_equal(track["station"], [12.0, 13.0])  # numeric for the commands
    write_track_csv(tmp_path / "out.csv", track.columns())
    text = (tmp_path / "out.csv").read_text().splitlines()
    assert text[0] == "t,lat,lon,station,count"
    assert text[1] == "1714564800.125,30,130,0012,7", text


def test_pass_through_keeps_the_users_longitudes(tmp_path):
    """The reader makes longitudes contiguous for the commands; what a command passes
    through (sample, dov) is the user's column: 0, 120, -120 came out as 0, 120, 240."""
    path = tmp_path / "w.csv"
    path.write_text("lat,lon\n10,0\n10,120\n10,-120\n10,179.9\n")
    track = read_track_csv(path, required=("lat", "lon"))
    assert track["lon"][2] == 240.0  # contiguous for the commands
    write_track_csv(tmp_path / "out.csv", track.columns())
    assert (tmp_path / "out.csv").read_text().splitlines()[1:] == [
        "10,0", "10,120", "10,-120", "10,179.9"]


def test_pass_through_keeps_twelve_significant_digits(tmp_path):
    """A log's coordinates to 1e-9° (0.1 mm) came out rounded to 9 significant digits
    (36.1234568: 1e-7°, about a centimetre lost per value; 1e-6° in a longitude of 120°)."""
    path = tmp_path / "p.csv"
    path.write_text("lat,lon\n36.123456789,120.123456789\n")
    write_track_csv(tmp_path / "out.csv", read_track_csv(path, required=("lat", "lon")).columns())
    assert (tmp_path / "out.csv").read_text().splitlines()[1] == "36.123456789,120.123456789"
