"""Inputs found by the third issue-19 hunt (2026-12-07): a particle count that cannot fit
in memory refused before compiling; navigate's map extent in words; match's --noise
that hides the map named as the noise; library parameter names kept out of match's
warnings; "exist(s)" made grammatical; and the odd files users have."""

import re

import numpy as np
import pytest
import xarray as xr

from jaxgrav.cli import filter_checks, main, match_size
from jaxgrav.cli.match_status import status_text
from jaxgrav.datasets import load_map
from jaxgrav.match import IMPLAUSIBLE_FIT, STATUS
from jaxgrav.match.api import MASKED


@pytest.fixture(scope="module")
def filter_log(tmp_path_factory):
    """A 6-row filter log over paper D's point masses (readings every 2 s)."""
    path = tmp_path_factory.mktemp("log") / "f.csv"
    t = np.arange(6) * 2.0
    path.write_text("t,lat,lon,gravity\n" + "".join(
        f"{a:g},{24.3 + 1e-5 * a:.7f},{122.74 + 1e-5 * a:.7f},{-30 + 0.1 * a:.3f}\n"
        for a in t))
    return path


@pytest.mark.parametrize("method", ["pf", "rbpf"])
def test_particles_beyond_the_machine_s_memory_are_refused(tmp_path, refused, filter_log, method):
    """``filter --method pf --particles 100000000`` compiled, then ran out of memory
    (exit 1); now the count is refused first, naming the estimate and the memory."""
    out = tmp_path / "o.csv"
    refused(["filter", "--point-masses", "paper-d", "--track", filter_log, "--out",
             out, "--method", method, "--particles", 10**12],
            "--particles 1000000000000 needs about 7e+05 GB (700 bytes a particle), more "
            "than 80 % of this machine's ")
    assert not out.exists()


def test_particles_are_checked_against_the_memory_of_the_machine(tmp_path, refused, monkeypatch):
    """On a 4 GB machine 10 million particles (7.5 GB) are refused, with the most that fit;
    navigate's rbpf too, before its log is read."""
    monkeypatch.setattr(filter_checks, "memory_bytes", lambda: 4e9)
    out = tmp_path / "n.csv"
    refused(["navigate", "--track", tmp_path / "none.csv", "--out", out, "--method",
             "rbpf", "--particles", 10_000_000],
            "--particles 10000000 needs about 7.5 GB (700 bytes a particle), more than 80 % "
            "of this machine's 4 GB of memory; expected at most 3857142 particles")
    filter_checks.check_particles(3_857_142)  # the most that fit pass
    monkeypatch.setattr(filter_checks, "memory_bytes", lambda: None)  # unknown: not checked
    filter_checks.check_particles(10**12)


def test_navigate_names_the_map_s_extent_in_words(tmp_path, refused):
    """A log off the map: "no row lies on the map (extent (124.0, 136.0, 24.0, 36.0))", a
    Python tuple in west, east, south, north order; now the map and its extent in words."""
    log = tmp_path / "v.csv"
    log.write_text("t,lat,lon,v_east,v_north,gravity\n" + "".join(
        f"{10 * i},{50 + 1e-4 * i:.4f},{130:.4f},1,1,5\n" for i in range(10)))
    out = tmp_path / "n.csv"
    refused(["navigate", "--track", log, "--out", out],
            f"track file {str(log)!r}: no row lies on the map --map 'ryukyu' (lat 24..36, "
            "lon 124..136)")
    assert not out.exists()


@pytest.fixture(scope="module")
def map_track(tmp_path_factory):
    """A 30-fix track on the shipped ryukyu map (readings: the map + 1 mGal noise)."""
    g = load_map("ryukyu")
    t = np.arange(30) * 120.0
    lat, lon = 30.2 + t * 4e-5, 130.4 + t * 4.5e-5
    z = np.asarray(g.sample(lat, lon, "bicubic")) + np.random.default_rng(0).normal(size=30)
    path = tmp_path_factory.mktemp("track") / "t.csv"
    path.write_text("t,lat,lon,gravity\n" + "".join(
        f"{a:g},{b:.6f},{c:.6f},{d:.4f}\n" for a, b, c, d in zip(t, lat, lon, z, strict=True)))
    return path


@pytest.mark.parametrize(("command", "option"), [("match", "--noise"),
                                                 ("filter", "--sigma-gravity")])
def test_a_noise_that_dwarfs_the_readings_is_named(tmp_path, refused, map_track, command, option):
    """``match --noise 1e30``: "... a factor 8.1e-30; are the readings in other units, e.g.
    m/s²?"; now the noise is named as implausibly large."""
    out = tmp_path / "o.out"
    err = refused([command, "--map", "ryukyu", "--track", map_track, "--out", out,
                   option, "1e30"],
                  f"{option} 1e+30 mGal is implausibly large: column 'gravity' of --track "
                  f"{str(map_track)!r} varies by only ")
    assert "other units" not in err and "where readings with that noise would vary by about "\
        "1.35e+30 mGal" in err
    assert not out.exists()


@pytest.mark.parametrize("bit", sorted(set(STATUS) - {MASKED, IMPLAUSIBLE_FIT}))
def test_match_status_texts_name_no_library_setting(bit):
    """match's warnings said "ICCP did not converge within max_iter iterations", "(max_sigma_m,
    or max_sigma_ratio ...)", "raise stencil_size": settings a command-line user cannot
    give. (The missing-node and implausible-fit bits have the command's own lines.)"""
    text = status_text(bit)
    assert not re.search(r"\b[a-z]+_[a-z_]+\b|=", text), text


@pytest.mark.long  # a dense match: 3-4 s with its compile
def test_a_rejected_fix_is_said_in_plain_words(tmp_path, capsys, map_track):
    """--noise 100 on 1 mGal readings: the fix is rejected as too wide, in plain words."""
    out = tmp_path / "m.json"
    assert main(["match", "--map", "ryukyu", "--track", str(map_track), "--out", str(out),
                 "--noise", "100"]) == 0
    err = capsys.readouterr().err
    assert "warning: fix rejected: the readings do not pin the position down" in err, err
    assert "max_sigma" not in err and "max_sigma" not in out.read_text()


@pytest.mark.parametrize(("argv", "message"), [
    # "A, B exist(s); pass --force to overwrite": unnamed, "(s)"
    (["simulate-filter", "--out", "{d}/a.csv", "--truth", "{d}/b.csv"],
     "--out '{d}/a.csv' and --truth '{d}/b.csv' exist; pass --force to overwrite them "
     "(nothing was written)"),
    # simulate named only the first of two
    (["simulate", "--out", "{d}/a.csv", "--truth", "{d}/b.csv"],
     "--out '{d}/a.csv' and --truth '{d}/b.csv' exist; pass --force to overwrite them"),
    (["simulate", "--out", "{d}/a.csv", "--truth", "{d}/new.csv"],
     "--out '{d}/a.csv' exists; pass --force to overwrite it (nothing was written)"),
])
def test_existing_outputs_are_named_in_one_grammatical_sentence(tmp_path, refused, argv, message):
    for name in ("a.csv", "b.csv"):
        (tmp_path / name).write_text("keep\n")
    refused([a.format(d=tmp_path) for a in argv], message.format(d=tmp_path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv"]
    assert (tmp_path / "a.csv").read_text() == "keep\n"


@pytest.mark.parametrize(("extra", "message"), [
    # the library's "runs must be at least 5; got 4"
    (["--runs", "4"], "--runs must be at least 5 Monte Carlo runs; got 4"),
    # ran (a negative seed repeats a large one), where every other command refuses it
    (["--seed", "-1"], "--seed must be an integer from 0 to 9223372036854775807"),
    # "[Errno 17] File exists: '.../t.csv'"
    (["--out", "{d}/t.csv"], "--out '{d}/t.csv' is a file; expected a folder (the demo "
                             "writes table1.md, summary.json, tracks.png into it)"),
    # "['{d}/table1.md'] exist; pass --force to overwrite them": a Python list
    (["--out", "{d}"], "'{d}/table1.md' exists; pass --force to overwrite it (nothing was "
                       "written)"),
])
def test_demo_options_are_named(tmp_path, refused, extra, message):
    (tmp_path / "t.csv").write_text("t\n")
    (tmp_path / "table1.md").write_text("keep\n")
    refused(["demo", "--smoke", "--out", tmp_path / "new",
             *[a.format(d=tmp_path) for a in extra]], message.format(d=tmp_path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv", "table1.md"]


@pytest.mark.parametrize(("argv", "message"), [
    # written with readings of noise 1e30 (exit 0), which every command then refuses
    (["simulate", "--out", "{d}/s.csv", "--noise", "1e30"],
     "--noise must be a reading noise >= 0 and at most 1000 mGal (a marine gravimeter's is "
     "about 1); got 1e+30"),
    # "at this --dt at most --minutes 0, or a longer --dt": no value that works
    (["simulate-filter", "--out", "{d}/s.csv", "--dt", "1e-9"],
     "makes 7200000000001 rows; at most 1000000 (a million take about 0.5 GB and 20 s to "
     "simulate, 70 MB of CSV): give a --dt of at least 0.00721 s"),
    (["simulate-filter", "--out", "{d}/s.csv", "--dt", "0.001"],
     "give at most --minutes 16.6 at this --dt, or a --dt of at least 0.00721 s"),
    # ran, every fix rejected (exit 0)
    (["montecarlo", "--method", "dense", "--runs", "2", "--out", "{d}/m.nc", "--noise", "1e30"],
     "--noise must be a finite standard deviation >= 0 (mGal) for --method dense, at most "
     "1000 (a marine gravimeter's is about 1); got 1e+30"),
])
def test_simulators_name_a_value_that_works(tmp_path, refused, argv, message):
    refused([a.format(d=tmp_path) for a in argv], message)
    assert list(tmp_path.iterdir()) == []


def test_match_names_a_track_too_short(tmp_path, refused):
    """One row: "the track is too short: 1 fixes, need at least 5" (no file named)."""
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon,gravity\n0,30.2,130.4,5\n")
    refused(["match", "--map", "ryukyu", "--track", track, "--out", tmp_path / "m.json"],
            f"--track {str(track)!r} has 1 row; match needs at least 5 fixes")
    assert list(tmp_path.iterdir()) == [track]


def test_an_infinite_position_is_called_so(tmp_path, capsys, refused):
    """lat 1e400 (read as inf) was reported as "1 missing or NaN value(s)"; and sample's
    summary of one point said "1 samples"."""
    track = tmp_path / "t.csv"
    track.write_text("lat,lon\n1e400,130.1\n30.2,130.2\n")
    # sample keeps a row without a position (empty cells) since hunt 8: inf is no position
    refused(["sample", "--map", "ryukyu", "--track", track, "--out", tmp_path / "o.csv"],
            f"track file {str(track)!r}, line 2, column 'lat': inf is not a value; leave the "
            "cell empty where there is none")
    track.write_text("lat,lon\n30.2,130.2\n")
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out",
                 str(tmp_path / "o.csv"), "--method", "bilinear"]) == 0
    assert ": 1 sample of " in capsys.readouterr().out


@pytest.mark.parametrize(("content", "message"), [
    # xarray's three lines: "did not find a match in any of xarray's currently installed IO
    # backends ['netcdf4', 'scipy']. Consider explicitly selecting one ..."
    ("lat,lon,xi\n35,110,1\n", "--grid '{p}' is not a NetCDF file (it is a text file "
                                "starting 'lat,lon,xi', a CSV track or table? a table of lon, "
                                "lat, value converts with GMT's xyz2grd)"),
    ("", "--grid '{p}' is not a NetCDF file (it is empty)"),
    # "'{p}' needs dimensions ...": the option unnamed
    # (hunt 7: and in Python tuples, "needs dimensions ('height', 'lat', 'lon')")
    (None, "--grid '{p}' has dimensions lat, lon; expected height, lat, lon (xi and eta in "
           "arcsec on layers at heights in m, as the shipped qinling file), missing height"),
])
def test_dov_names_a_grid_that_is_not_layers(tmp_path, refused, content, message):
    grid = tmp_path / "g.nc"
    if content is None:
        xr.Dataset({"xi": (("lat", "lon"), np.zeros((4, 4)))},
                   coords={"lat": np.arange(4.0), "lon": np.arange(4.0)}).to_netcdf(grid)
    else:
        grid.write_text(content)
    track = tmp_path / "t.csv"
    track.write_text("lat,lon,h\n35.1,110.1,100\n35.2,110.2,200\n")
    refused(["dov", "--track", track, "--out", tmp_path / "o.csv", "--grid", grid],
            message.format(p=grid))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.nc", "t.csv"]


def test_a_constant_readings_column_is_called_a_placeholder(tmp_path, refused, map_track):
    """A gravity column of zeros: "varies by 0 ... a factor 0; are the readings in other
    units, e.g. m/s²?"; now it is named as one value throughout."""
    track = tmp_path / "z.csv"
    lines = map_track.read_text().splitlines()
    track.write_text("\n".join([lines[0], *(ln.rsplit(",", 1)[0] + ",0" for ln in lines[1:])])
                     + "\n")
    err = refused(["match", "--map", "ryukyu", "--track", track, "--out",
                   tmp_path / "m.json"],
                  f"--track {str(track)!r}: column 'gravity' holds one value, 0, in all 30 "
                  "readings on the map, where the map varies by ")
    assert "a placeholder column? expected the sensor's readings" in err


@pytest.mark.parametrize("method", ["chains", "entropy+iccp"])
def test_a_track_too_long_for_a_quadratic_matcher_is_refused(tmp_path, refused, monkeypatch,
                                                             method):
    """20 000 fixes by chains or entropy+iccp: killed by the system at 13 GB (signal 9, no
    message); now refused before any work, naming the fixes, the estimate and the cure.
    Here on a 4 GB machine, 7000 fixes."""
    monkeypatch.setattr(filter_checks, "memory_bytes", lambda: 4e9)
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon,gravity\n" + "".join(
        f"{10 * i},{30 + 1e-5 * i:.6f},{130 + 1e-5 * i:.6f},{i % 7}\n" for i in range(7000)))
    refused(["match", "--map", "ryukyu", "--track", track, "--out", tmp_path / "m.json",
             "--method", method],
            f"--track {str(track)!r} has 7000 fixes: --method {method} needs about 3.54 GB "
            "for them (its memory grows with the square of the fixes), more than 80 % of this "
            "machine's 4 GB; match pieces of at most 6582 fixes, or use --method dense")
    match_size.check_fixes_memory("dense", 10**6, "t")  # linear methods pass


def test_a_map_in_radians_is_named(tmp_path, refused):
    """Coordinates declared in radians were read as degrees: "2 of 2 positions are off the
    map (lat 0.514872..0.541052, lon 2.2602..2.28638)"; now the units are named."""
    lat, lon = np.radians(np.linspace(29.5, 31.0, 7)), np.radians(np.linspace(129.5, 131, 7))
    path = tmp_path / "m.nc"
    xr.Dataset({"g": (("lat", "lon"), np.zeros((7, 7)))},
               coords={"lat": ("lat", lat, {"units": "radians"}),
                       "lon": ("lon", lon, {"units": "radians"})}).to_netcdf(path)
    track = tmp_path / "t.csv"
    track.write_text("lat,lon\n30.1,130.1\n30.2,130.2\n")
    refused(["sample", "--map", path, "--track", track, "--out", tmp_path / "o.csv"],
            f"map {str(path)!r}: coordinate 'lat' is in 'radians'; jaxgrav reads latitudes "
            "and longitudes in degrees: convert them (x 180/pi)")
    assert not (tmp_path / "o.csv").exists()
