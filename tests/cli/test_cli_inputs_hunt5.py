"""Inputs found by the fifth issue-19 hunt (2026-12-07, helper-60): a Monte Carlo run
count that cannot be a whole number, or whose results would not fit in memory or on the
disk (and the size of a large one announced first); ``--track -`` in the commands'
help; ``filter --missing`` over point masses; a map whose latitude/longitude axes are
known only by CF attributes while a 2-D node-latitude variable is listed first."""

import argparse
import gzip
import sys

import numpy as np
import pytest
import xarray as xr

from jaxgrav import montecarlo as mc_package
from jaxgrav.cli import main, montecarlo_options
from jaxgrav.cli.inputs import whole_number
from jaxgrav.grid_files import map_units, read_netcdf
from jaxgrav.track_files import read_table


@pytest.mark.parametrize("runs", ["2.5", "nan", "1e400", "ten"])
def test_a_run_count_that_is_no_whole_number_is_refused(tmp_path, capsys, runs):
    """``--runs 2.5`` was argparse's "invalid int value" and ``--runs 1e6`` refused alike."""
    with pytest.raises(SystemExit) as exit_:
        main(["montecarlo", "--method", "ukf", "--runs", runs, "--out", f"{tmp_path}/m.nc"])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and "\n" not in err, err
    assert f"argument --runs: expected a whole number (e.g. 1000 or 1e6); got {runs!r}" in err
    assert list(tmp_path.iterdir()) == []


def test_count_options_read_exponent_forms():
    """``1e6`` is a million; digits stay exact (count options: montecarlo --runs, --chunk,
    --fixes, demo --runs, filter --particles, simulate --n, suitability --fixes)."""
    assert whole_number("1e6") == 1_000_000
    assert whole_number("123456789012345") == 123456789012345
    with pytest.raises(argparse.ArgumentTypeError, match="at most 1e"):  # hunt 7: no count
        whole_number("12345678901234567890")  # that large; its digits filled messages


@pytest.mark.parametrize("argv", [
    ["simulate", "--out", "{d}/s.csv", "--n", "2.5"],
    ["suitability", "--map", "ryukyu", "--out", "{d}/s.nc", "--fixes", "2.5"],
    ["filter", "--point-masses", "paper-d", "--method", "pf", "--track", "{d}/t.csv", "--out",
     "{d}/f.csv", "--particles", "2.5"],
    ["montecarlo", "--method", "dense", "--runs", "5", "--out", "{d}/m.nc", "--fixes", "2.5"],
])
def test_count_options_name_a_count_that_is_no_whole_number(tmp_path, capsys, argv):
    """The other count options read ``1e4`` too and refuse ``2.5`` in the same words."""
    with pytest.raises(SystemExit) as exit_:
        main([a.format(d=tmp_path) for a in argv])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and "\n" not in err, err
    assert f"argument {argv[-2]}: expected a whole number (e.g. 1000 or 1e6); got '2.5'" in err


@pytest.fixture
def machine_25gb(monkeypatch):
    """A machine of 25 GB (20 GB usable), whatever the test machine has."""
    monkeypatch.setattr(montecarlo_options, "memory_budget", lambda: (20e9, 25e9))


def test_a_run_count_beyond_the_memory_is_refused(tmp_path, refused, machine_25gb):
    """``--runs 1e9`` started splitting 16 GB of keys with no estimate (then out of memory
    or hours later a 69 GB file)."""
    refused(["montecarlo", "--method", "ukf", "--runs", "1e9", "--out", tmp_path / "m.nc"],
            "--runs 1e+09 needs about 163 GB of memory (73 bytes of results and 16 of key a "
            "run, kept until the file is written), more than 80 % of this machine's 25 GB; "
            "expected at most 117283950 runs (run more batches with other --seed values)")
    assert list(tmp_path.iterdir()) == []


def test_a_run_count_beyond_the_disk_is_refused(tmp_path, refused, machine_25gb,
                                                monkeypatch):
    """Results that fit in memory but not in --out's folder are refused before the runs."""
    monkeypatch.setattr(montecarlo_options.shutil, "disk_usage",
                        lambda path: type("Usage", (), {"free": 1e6})())
    refused(["montecarlo", "--method", "ukf", "--runs", "1e5", "--out", tmp_path / "m.nc"],
            f"--runs 100000 writes about 0.0073 GB to --out {tmp_path / 'm.nc'} (73 bytes a "
            "run), more than the 0.001 GB free in its folder")
    assert list(tmp_path.iterdir()) == []


def test_a_large_run_count_is_announced_with_its_sizes(tmp_path, capsys, machine_25gb,
                                                      monkeypatch):
    """From 10000 runs the memory and file size are printed before the runs start."""
    def stop(*args, **kwargs):
        raise ValueError("stopped before the runs")

    monkeypatch.setattr(mc_package, "run", stop)
    out = tmp_path / "m.nc"
    assert main(["montecarlo", "--method", "ukf", "--runs", "2e4", "--out", str(out),
                 "--no-progress"]) == 2
    printed = capsys.readouterr().out
    assert (f"jaxgrav montecarlo: 20000 runs hold about 1 GB in memory and write about 1.46 MB "
            f"to {out} (73 bytes a run); no time estimate with --no-progress") in printed
    assert not out.exists()


@pytest.mark.parametrize("command", ["match", "sample", "filter", "navigate", "dov"])
def test_help_says_track_reads_standard_input(capsys, command):
    """``--track -`` read the standard input, and no help said so."""
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "'-' reads it from standard input (e.g. a pipe)" in text


@pytest.mark.parametrize("missing", ["gaps", "land"])
def test_filter_missing_over_point_masses_is_refused(tmp_path, refused, missing):
    """``filter --point-masses paper-d --method pmf --missing land`` ran and the option did
    nothing: point masses have no map nodes."""
    track = tmp_path / "f.csv"
    track.write_text("t,lat,lon,gravity\n0,24.3,122.74,-30\n2,24.30002,122.74002,-29.8\n")
    refused(["filter", "--point-masses", "paper-d", "--method", "pmf", "--missing", missing,
             "--track", track, "--out", tmp_path / "o.csv"],
            f"--missing {missing} says how pmf reads a --map's missing (NaN) nodes; "
            "--point-masses paper-d is a field with no nodes: leave --missing out")
    assert not (tmp_path / "o.csv").exists()


def test_cf_axes_beat_a_node_latitude_variable_listed_first(tmp_path):
    """Axes ``j``, ``i`` known by CF standard_name, and a 2-D ``node_lat`` (degrees_north)
    listed first: was "coordinate 'node_lat' is 2-D ... not curvilinear or projected
    ones"; now the axes are j, i and the map is the one variable that is not a latitude."""
    lat, lon = np.linspace(24, 25, 11), np.linspace(122, 123, 11)
    nodes, _ = np.meshgrid(lat, lon, indexing="ij")
    xr.Dataset({"node_lat": (("j", "i"), nodes, {"units": "degrees_north"}),
                "gravity": (("j", "i"), np.full((11, 11), 5.0), {"units": "mGal"})},
               coords={"j": ("j", lat, {"standard_name": "latitude"}),
                       "i": ("i", lon, {"standard_name": "longitude"})}
               ).to_netcdf(tmp_path / "m.nc")
    got = read_netcdf(tmp_path / "m.nc")
    assert (got.name, got.values.shape, float(got.values[5, 5])) == ("gravity", (11, 11), 5.0)
    assert got.lat == pytest.approx(lat) and got.lon == pytest.approx(lon)


@pytest.mark.parametrize("runs, message", [
    ("1e9", "--runs must be at most 100000 for the demo (its realistic table runs them three "
            "times; the default 200 take about a minute); got 1e+09; for larger studies use "
            "jaxgrav montecarlo, which checks their memory and disk space first"),
    ("4", "--runs must be at least 5 Monte Carlo runs; got 4"),
])
def test_demo_run_counts_out_of_range_are_refused(tmp_path, refused, runs, message):
    """``demo --runs 1000000000`` started, silently, for years (and ``--runs 1e4`` was "invalid
    int value")."""
    refused(["demo", "--out", tmp_path / "d", "--runs", runs], message)
    assert list(tmp_path.iterdir()) == []


def test_data_region_is_named_with_its_choices(tmp_path, capsys):
    """``data egm2008 --region mars`` said "region must be one of ['ryukyu', 'qinling',
    'all']" (a Python list, no option name)."""
    with pytest.raises(SystemExit) as exit_:
        main(["data", "egm2008", "--region", "mars", "--out", str(tmp_path / "e")])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and "\n" not in err
    assert ("argument --region: invalid choice: 'mars' (choose from 'ryukyu', 'qinling', "
            "'all')") in err


def test_a_two_column_xyz_file_gains_no_empty_column(tmp_path):
    """A headerless ``lon lat`` ``.xyz`` file was read with an empty third column ``z``,
    written into ``sample``'s output (``lon,lat,z,map``)."""
    track = tmp_path / "t.xyz"
    track.write_text("125.5 24.5\n125.51 24.51\n")
    table = read_table(track)
    assert table.header == ["lon", "lat"]
    assert table.rows == [["125.5", "24.5"], ["125.51", "24.51"]]


@pytest.mark.parametrize("units, factor", [
    ("10^-5 m/s^2", 1.0), ("1e-6 m s-2", 0.1), ("mGals", 1.0), ("mGal (free-air)", 1.0),
    ("gammas", 1.0), ("1E-9 T", 1.0),
])
def test_map_units_with_a_power_of_ten_or_a_note_are_read(units, factor):
    """``10^-5 m/s^2`` (mGal, common in gravity surveys), ``1e-6 m s-2`` (0.1 mGal), a
    plural or a parenthesised note were not recognised, and the values read as they are
    (1e-6 m s-2 taken for mGal: 10 x too large)."""
    values, canonical = map_units(np.array([2.0]), units)
    assert canonical in ("mGal", "nT") and values[0] == pytest.approx(2.0 * factor)


def test_a_gzip_compressed_track_is_read(tmp_path):
    """``track.csv.gz`` was "a binary file, not a text table"; a cut one is named."""
    path = tmp_path / "t.csv.gz"
    path.write_bytes(gzip.compress(b"lat,lon\n24.5,125.5\n24.6,125.6\n"))
    assert read_table(path).rows == [["24.5", "125.5"], ["24.6", "125.6"]]
    path.write_bytes(path.read_bytes()[:20])
    with pytest.raises(ValueError, match=r"^track file '.*t.csv.gz' is a gzip file that cannot "
                       r"be decompressed \(.*\); expected a whole .gz of a CSV text file$"):
        read_table(path)


@pytest.mark.parametrize(("command", "out", "writes"), [
    (["sample", "--map", "ryukyu", "--track", "{d}/t.csv"], "s.csv.gz", "CSV"),
    (["match", "--map", "ryukyu", "--track", "{d}/t.csv"], "m.json.bz2", "JSON"),
    (["montecarlo", "--method", "dense", "--runs", "5"], "m.nc.zip", "NetCDF"),
])
def test_a_compressed_output_name_is_refused(tmp_path, refused, command, out, writes):
    """``--out s.csv.gz`` wrote plain text under a gzip name (gunzip: "not in gzip format")."""
    (tmp_path / "t.csv").write_text("t,lat,lon,gravity\n0,24.5,125.5,1\n")
    stem = out.rsplit(".", 1)[0]
    refused([a.format(d=tmp_path) for a in command] + ["--out", tmp_path / out],
            f"--out '{tmp_path / out}' names a compressed file, but this command writes plain "
            f"{writes} there; give a name ending .{stem.rsplit('.', 1)[1]} (e.g. "
            f"'{tmp_path / stem}') and compress it afterwards")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv"]


def test_a_compressed_map_says_decompress_it(tmp_path):
    """A gzipped NetCDF map was "its format is not NetCDF-3 or NetCDF-4"."""
    path = tmp_path / "m.nc.gz"
    path.write_bytes(gzip.compress(b"CDF\x01" + bytes(64)))
    with pytest.raises(ValueError, match=r"is not a NetCDF file \(it is compressed \(gzip, "
                       r"bzip2, xz or zip\): decompress it first\)"):
        read_netcdf(path)


def test_a_dash_track_on_a_terminal_is_refused(tmp_path, refused, monkeypatch):
    """``jaxgrav sample --track -`` typed at a terminal waited, silently, for a track."""
    monkeypatch.setattr(sys, "stdin", type("Tty", (), {"isatty": lambda self: True})())
    refused(["sample", "--map", "ryukyu", "--track", "-", "--out", tmp_path / "s.csv"],
            "--track - reads the track from standard input, which is a terminal here; pipe or "
            "redirect a file into it (e.g. jaxgrav sample --track - ... < track.csv), or give "
            "its path")
    assert list(tmp_path.iterdir()) == []
