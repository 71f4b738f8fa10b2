"""The scenario commands refuse what they cannot simulate honestly and accept what they can:
tracks longer than the map (``simulate --n``, ``simulate-filter --minutes``) are refused
with the largest value that fits, absurd ``--bias`` and other out-of-range options in one
line (exit 2, nothing written); maps with missing (NaN) nodes away from the track are
used, a track across them is refused; a flat map's suitability says it carries no
information (missing values with ``status`` 3, never ``inf``); a short voyage Monte Carlo
reports only the hours it has."""

import re
import warnings

import numpy as np
import pytest
import xarray as xr

from jaxgrav import datasets
from jaxgrav.cli import main
from jaxgrav.cli.montecarlo_voyage import voyage_lines
from jaxgrav.navigate import voyage_summary
from jaxgrav.tracks import read_track_csv


def _write_map(path, grid, values):
    xr.Dataset({"anomaly": (("lat", "lon"), values, {"units": "mGal"})},
               coords={"lat": np.asarray(grid.lat), "lon": np.asarray(grid.lon)}).to_netcdf(path)
    return str(path)


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    """Maps over the shipped area: with NaN in a far corner, in a band across the middle,
    everywhere but a corner, everywhere, and a flat (constant) map."""
    d = tmp_path_factory.mktemp("maps")
    fine = datasets.load("ryukyu")["anomaly_2p5min"]
    coarse = datasets.load("ryukyu")["anomaly_0p5deg"]
    v, lat = np.array(fine.values), np.asarray(fine.lat)
    corner = v.copy()
    corner[:8, :8] = np.nan  # 24-24.3 N, 124-124.3 E: inside every margin
    band = v.copy()
    band[(lat > 29.5) & (lat < 30.5)] = np.nan  # every long enough track crosses it
    mostly = np.full_like(v, np.nan)
    mostly[:40, :40] = v[:40, :40]
    c = np.array(coarse.values)
    holey = c.copy()
    holey[:5, :5] = np.nan
    return dict(corner=_write_map(d / "corner.nc", fine, corner),
                band=_write_map(d / "band.nc", fine, band),
                mostly_nan=_write_map(d / "mostly_nan.nc", fine, mostly),
                all_nan=_write_map(d / "all_nan.nc", coarse, np.full_like(c, np.nan)),
                flat=_write_map(d / "flat.nc", coarse, np.full_like(c, 12.0)),
                holey_coarse=_write_map(d / "holey_coarse.nc", coarse, holey))


def _args(argv, maps, out):
    return [a.format(out=out, **maps) for a in argv]


def _one_line_error(capsys):
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    return err


REFUSED = [
    # defect 1: a track longer than the map
    ("simulate-n-too-long", ["simulate", "--n", "2000", "--out", "{out}"],
     "--n 2000 fixes every 120 s at 14.1 kn make a track of 1745 km"),
    ("simulate-n-max", ["simulate", "--n", "2000", "--out", "{out}"], "at most --n 1734 fits"),
    # defect 5: validation
    ("simulate-bias", ["simulate", "--bias=-1e9", "--out", "{out}"],
     "--bias must be a finite gravimeter bias within ±1000 mGal"),
    ("simulate-bias-positive", ["simulate", "--bias", "5000", "--out", "{out}"],
     "got 5000.0"),
    ("simulate-dt", ["simulate", "--dt=-1", "--out", "{out}"],
     "--dt must be a positive interval between fixes (s); got -1.0"),
    ("simulate-drift", ["simulate", "--drift=-1", "--out", "{out}"],
     "--drift must be a positive INS drift"),
    ("simulate-probability", ["simulate", "--probability", "1.5", "--out", "{out}"],
     "--probability must be a probability strictly between 0 and 1; got 1.5"),
    ("filter-minutes-point-masses", ["simulate-filter", "--minutes", "100000", "--out", "{out}"],
     "--minutes must be at most 14400 (240 h"),
    ("filter-minutes-map", ["simulate-filter", "--minutes", "100000", "--map", "ryukyu", "--out",
                            "{out}"], "at most --minutes 1745.8 fits"),
    ("filter-rows", ["simulate-filter", "--minutes", "1000", "--dt", "0.01", "--out", "{out}"],
     "makes 6000001 rows; at most 1000000"),
    ("filter-minutes-inf", ["simulate-filter", "--minutes", "inf", "--out", "{out}"],
     "--minutes must be a finite duration (min); got inf"),
    # defect 4: a track across missing nodes is refused (nodes elsewhere are fine, below)
    ("simulate-nan-on-track", ["simulate", "--map", "{band}", "--n", "1200", "--out", "{out}"],
     "has missing (NaN) nodes along the simulated track"),
    ("simulate-truth-map-nan-on-track", ["simulate", "--truth-map", "{band}", "--n", "1200",
                                         "--out", "{out}"],
     "--truth-map {band} has missing (NaN) nodes along the simulated track"),
    ("filter-nan-on-track", ["simulate-filter", "--map", "{mostly_nan}", "--out", "{out}"],
     "has missing (NaN) nodes along the simulated track: 721 of 721 readings"),
    ("voyage-nan-on-route", ["simulate-voyage", "--hours", "1", "--map", "{mostly_nan}",
                             "--out", "{out}"],
     "--map {mostly_nan} has missing (NaN) values along the simulated route: 361 of 361"),
    ("suitability-all-nan", ["suitability", "--map", "{all_nan}", "--out", "{out}"],
     "every node is missing (NaN)"),
    ("suitability-even-window", ["suitability", "--map", "ryukyu", "--window", "4", "--out",
                                 "{out}"], "--window must be an odd number of nodes >= 3; got 4"),
    ("suitability-huge-window", ["suitability", "--map", "ryukyu", "--window", "999", "--out",
                                 "{out}"], "at most the map's shorter side (289 nodes); got 999"),
]


SLOW_REFUSALS = {"voyage-nan-on-route"}
"""Cases that simulate a whole voyage before refusing (11 s): in the long tier."""


@pytest.mark.parametrize("argv, message", [
    pytest.param(*c[1:], id=c[0], marks=[pytest.mark.long] if c[0] in SLOW_REFUSALS else [])
    for c in REFUSED])
def test_refused_in_one_line_and_nothing_written(maps, tmp_path, capsys, argv, message):
    out = tmp_path / "out.nc" if argv[0] == "suitability" else tmp_path / "out.csv"
    assert main(_args(argv, maps, out)) == 2
    err = _one_line_error(capsys)
    assert message.format(**maps) in err, err
    assert list(tmp_path.iterdir()) == []


LARGEST = [  # the largest value an error names does fit, and its readings are all finite
    ("simulate-default", ["simulate", "--n", "5000"], "--n"),
    ("simulate-north-small-drift", ["simulate", "--n", "5000", "--v-east", "0", "--v-north",
                                    "20", "--drift", "0.001", "--seed", "3"], "--n"),
    ("filter-map", ["simulate-filter", "--map", "ryukyu", "--minutes", "5000", "--dt", "7"],
     "--minutes"),
]


@pytest.mark.parametrize("argv, option", [c[1:] for c in LARGEST], ids=[c[0] for c in LARGEST])
def test_the_largest_value_named_fits(tmp_path, capsys, argv, option):
    out = str(tmp_path / "t.csv")
    assert main([*argv, "--out", out]) == 2
    most = re.search(rf"at most {option} ([0-9.]+) fits", _one_line_error(capsys)).group(1)
    argv = list(argv)
    argv[argv.index(option) + 1] = most
    assert main([*argv, "--out", out]) == 0, capsys.readouterr().err
    track = read_track_csv(out, required=("lat", "gravity"), allow_nan=("gravity",))
    g = track["gravity"]
    assert np.isfinite(g[::5] if argv[0] == "simulate-filter" else g).all()


ACCEPTED = [  # defect 4: missing nodes away from the track are no reason to refuse
    ("simulate", ["simulate", "--map", "{corner}", "--n", "200", "--seed", "1", "--out",
                  "{out}"]),
    ("simulate-map-error", ["simulate", "--map", "{corner}", "--n", "50", "--map-error", "2",
                            "--out", "{out}"]),
    ("simulate-filter", ["simulate-filter", "--map", "{corner}", "--out", "{out}"]),
    ("simulate-voyage", ["simulate-voyage", "--hours", "1", "--map", "{corner}", "--out",
                         "{out}"]),
]


@pytest.mark.parametrize("argv", [  # a voyage simulation takes 5-7 s: long tier
    pytest.param(c[1], marks=[pytest.mark.long] if c[0] == "simulate-voyage" else [])
    for c in ACCEPTED], ids=[c[0] for c in ACCEPTED])
def test_missing_nodes_away_from_the_track_are_used(maps, tmp_path, argv):
    out = tmp_path / "t.csv"
    assert main(_args(argv, maps, out)) == 0
    track = read_track_csv(out, required=("lat", "gravity"), allow_nan=("gravity",))
    g = track["gravity"]
    assert np.isfinite(g[::5] if argv[0] == "simulate-filter" else g).all()


SUITABILITY = [  # (map, status counts that must be > 0, == 0, stdout phrase)
    ("flat", "{flat}", (1, 3), (0, 2), "the map does not place the segment"),
    ("holey", "{holey_coarse}", (0, 1, 2), (), "cross missing map nodes"),
]


@pytest.mark.parametrize("path, present, absent, phrase", [c[1:] for c in SUITABILITY],
                         ids=[c[0] for c in SUITABILITY])
def test_suitability_flat_and_holey_maps(maps, tmp_path, capsys, path, present, absent, phrase):
    out = tmp_path / "s.nc"
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # NaN nodes: no numpy warning
        assert main(["suitability", "--map", path.format(**maps), "--fixes", "5",
                     "--out", str(out)]) == 0
    printed = capsys.readouterr()
    assert phrase in printed.out and printed.err == "", printed
    with xr.open_dataset(out) as ds:
        status = ds["status"].values
        assert ds["status"].attrs["flag_meanings"] == "ok off_map missing_map no_information"
        for name in ("precision_m", "sigma_north_m", "sigma_east_m", "corr"):
            v = ds[name].values
            assert not np.isinf(v).any(), name
            assert np.isnan(v[status != 0]).all() if name in ("precision_m", "corr") else True
        assert np.isfinite(ds["precision_m"].values[status == 0]).all()
    for k in present:
        assert (status == k).any(), k
    for k in absent:
        assert not (status == k).any(), k


def _results(hours, runs=4):
    rng = np.random.default_rng(hours)
    return dict(hourly_err_m=rng.uniform(500, 1500, (runs, hours)),
                hourly_ins_err_m=rng.uniform(800, 2000, (runs, hours)),
                nees=rng.uniform(1, 3, runs))


@pytest.mark.parametrize("hours, shown, hidden", [
    (1, ["last hour / free INS", "one whole hour, no second"],
     ["last / second hour 1", "from the second:"]),
    (2, ["from the second:", "no last / second hour ratio"], ["last / second hour 1"]),
    (3, ["last / second hour", "from the second:"], ["no last", "no second"]),
])
def test_voyage_summary_reports_only_the_hours_it_has(hours, shown, hidden):
    text = voyage_lines(_results(hours))
    for phrase in shown:
        assert phrase in text, text
    for phrase in hidden:
        assert phrase not in text, text


@pytest.mark.long
def test_one_hour_voyage_montecarlo_says_there_is_no_second_hour(tmp_path, capsys):
    out = tmp_path / "v.nc"
    assert main(["montecarlo", "--method", "voyage-ukf", "--hours", "1", "--runs", "2",
                 "--no-progress", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "one whole hour, no second" in text and "last / second hour 1" not in text


@pytest.mark.parametrize("hours", [1, 2, 3])
def test_voyage_summary_leaves_out_what_the_voyage_lacks(hours):
    """The library's figures too: NaN where the voyage has no such hour, else by hand."""
    r = _results(hours)
    vs = voyage_summary(r["hourly_err_m"], r["hourly_ins_err_m"], r["nees"])
    nav = np.sqrt(np.mean(r["hourly_err_m"] ** 2, 0))
    ratio = r["hourly_err_m"] / r["hourly_ins_err_m"]
    if hours >= 3:
        assert vs["last_over_second_hour"] == pytest.approx(nav[-1] / nav[1])
    else:
        assert np.isnan(vs["last_over_second_hour"])
    if hours >= 2:
        assert vs["worst_hourly_ratio"] == pytest.approx(ratio[:, 1:].max())
        assert vs["share_worse_than_free_some_hour"] == pytest.approx(
            np.mean(np.any(ratio[:, 1:] > 1, axis=1)))
    else:
        assert np.isnan(vs["worst_hourly_ratio"])
        assert np.isnan(vs["share_worse_than_free_some_hour"])
