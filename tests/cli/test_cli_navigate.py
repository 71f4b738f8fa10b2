"""``jaxgrav navigate``: a simulated log navigated end to end, and every bad input named."""

import re

import numpy as np
import pytest
import xarray as xr

from jaxgrav import datasets
from jaxgrav.cli import main
from jaxgrav.geodesy import eotvos
from jaxgrav.tracks import read_track_csv, write_track_csv

SHORT = ["--fix-every", "6", "--n-fixes", "10", "--stride", "10"]


@pytest.fixture(scope="module")
def voyage_log(tmp_path_factory):
    d = tmp_path_factory.mktemp("voyage")
    log, truth = d / "log.csv", d / "truth.csv"
    assert main(["simulate-voyage", "--out", str(log), "--truth", str(truth), "--hours", "1.5",
                 "--seed", "4", "--map-error", "3"]) == 0
    return log, truth


@pytest.mark.long
@pytest.mark.parametrize("method", ["dense", "chains", "entropy+iccp"])
def test_navigate_writes_every_row_with_sigma_and_fix_events(voyage_log, tmp_path, capsys,
                                                             method):
    log, _ = voyage_log
    out = tmp_path / "nav.csv"
    assert main(["navigate", "--track", str(log), "--out", str(out), "--method", method,
                 *SHORT]) == 0
    said = capsys.readouterr().out
    assert "541 rows, 9 segment ends" in said and "0 missing reading(s)" in said
    nav = read_track_csv(out, ("t", "lat", "lon", "sigma_north", "sigma_east", "v_east",
                               "v_north", "fix_event"), allow_nan=("fix_event",))
    assert len(nav["t"]) == 541 and np.all(nav["sigma_north"] > 0)
    ends = np.flatnonzero(np.isfinite(nav["fix_event"]))
    np.testing.assert_array_equal(ends, np.arange(1, 10) * 60)
    assert set(nav["fix_event"][ends].astype(int)) <= {0, 1, 2, 3, 4}
    assert main(["navigate", "--track", str(log), "--out", str(out), *SHORT]) == 2
    assert "pass --force" in capsys.readouterr().err


@pytest.mark.long
@pytest.mark.parametrize("method", [["ukf"], ["rbpf", "--particles", "400", "--seed", "2"]])
def test_tight_filters_beat_the_ins_against_the_truth(voyage_log, tmp_path, capsys, method):
    """--method ukf, rbpf: every row with the filter's status, innovation and bias, and a
    solution closer to the written truth than the INS log in the last half hour."""
    log, truth_csv = voyage_log
    out = tmp_path / "tight.csv"
    assert main(["navigate", "--track", str(log), "--out", str(out), "--method", *method]) == 0
    said = capsys.readouterr().out
    assert "541 rows" in said and f"used by the {method[0]} filter" in said
    cols = ("t", "lat", "lon", "sigma_north", "sigma_east", "status", "innovation",
            "innovation_sigma", "gravimeter_bias", "sigma_gravimeter_bias")
    nav = read_track_csv(out, cols, allow_nan=("innovation", "innovation_sigma"))
    assert np.all(np.asarray(nav["status"]) == 0)  # every reading used, on the map
    assert np.all(np.isfinite(nav["innovation"][1:]))
    ins = read_track_csv(log, ("t", "lat", "lon"))
    truth = read_track_csv(truth_csv, ("t", "lat", "lon"))
    km = 111.0 * np.cos(np.deg2rad(np.asarray(truth["lat"])))

    def err(track):
        d_n = (np.asarray(track["lat"]) - truth["lat"]) * 111.0
        d_e = (np.asarray(track["lon"]) - truth["lon"]) * km
        return np.sqrt(np.mean((d_n**2 + d_e**2)[-180:]))

    assert err(nav) < 0.7 * err(ins), (err(nav), err(ins))


@pytest.mark.long
def test_missing_readings_are_counted_not_fatal(voyage_log, tmp_path, capsys):
    log, _ = voyage_log
    track = read_track_csv(log, ("t", "lat", "lon", "v_east", "v_north", "gravity"))
    g = np.asarray(track["gravity"]).copy()
    g[100:103] = np.nan
    holed = tmp_path / "holed.csv"
    write_track_csv(holed, {**{k: track[k] for k in ("t", "lat", "lon", "v_east", "v_north")},
                            "gravity": g})
    assert main(["navigate", "--track", str(holed), "--out", str(tmp_path / "n.csv"),
                 *SHORT]) == 0
    assert "3 missing reading(s) skipped" in capsys.readouterr().out


@pytest.mark.long
def test_a_log_shorter_than_the_first_segment_says_no_fix_could_be_made(voyage_log, tmp_path,
                                                                        capsys):
    """1.5 h of log, segments of 100 fixes of 6 rows (the first segment end at row 600):
    the INS is written with its growing 1-σ, and a warning says that no fix could be
    made, why, and that --first-n-fixes would make one."""
    out = tmp_path / "n.csv"
    assert main(["navigate", "--track", str(voyage_log[0]), "--out", str(out), "--method",
                 "dense", "--fix-every", "6", "--n-fixes", "100", "--stride", "100"]) == 0
    said = capsys.readouterr()
    assert "541 rows, 0 segment ends (none)" in said.out
    assert ("warning: no fix could be made: the log has 541 rows and its first segment (100 "
            "fixes of --fix-every 6 rows") in said.err and "needs more than 600" in said.err
    assert "--first-n-fixes N matches the last N fixes" in said.err
    nav = read_track_csv(out, ("t", "sigma_north", "fix_event"), allow_nan=("fix_event",))
    assert len(nav["t"]) == 541 and not np.isfinite(nav["fix_event"]).any()
    assert nav["sigma_north"][-1] > nav["sigma_north"][0]
    # the same log with the first segment end on its last 30 fixes (--stride 30 ends at
    # row 180): fixes are made
    assert main(["navigate", "--track", str(voyage_log[0]), "--out", str(out), "--force",
                 "--method", "dense", "--fix-every", "6", "--n-fixes", "60", "--stride", "30",
                 "--first-n-fixes", "30"]) == 0
    said = capsys.readouterr()
    assert "541 rows, 3 segment ends" in said.out and "no fix" not in said.err


def test_the_no_fix_warning_names_the_events():
    from jaxgrav.cli.navigate_loose import first_fix_rows, no_fix_warning
    from jaxgrav.navigate import LooseConfig
    cfg = LooseConfig(n_fixes=60, stride=30, first_n_fixes=30)
    assert first_fix_rows(cfg) == 360 and first_fix_rows(LooseConfig(n_fixes=60, stride=30)) == 720
    assert no_fix_warning(cfg, 5000, np.array([3, 0, 4])) is None
    said = no_fix_warning(cfg, 5000, np.array([3, 4, 4]))
    assert said.startswith("no fix was accepted (1 rejected by the matcher's integrity test, "
                           "2 rejected by the innovation gate")
    assert "needs more than 360" in no_fix_warning(cfg, 300, np.array([], int))


def _edited(log, tmp_path, edit):
    track = read_track_csv(log, ("t", "lat", "lon", "v_east", "v_north", "gravity"))
    cols = {k: np.asarray(track[k]).copy() for k in ("t", "lat", "lon", "v_east", "v_north",
                                                      "gravity")}
    edit(cols)
    path = tmp_path / "bad.csv"
    write_track_csv(path, cols)
    return path


def _gap(c):
    c["t"][200:] += 120.0


def _uneven(c):
    c["t"][200:] += 3.0


def _fast(c):
    c["v_east"][50] = 80.0


def _off_map(c):
    c["lat"][:] = -60.0


@pytest.mark.parametrize(("edit", "message"), [
    (_gap, "a gap of 130 s on lines 201-202 (t 1990 -> 2120 s) is longer than --max-gap 60 s"),
    (_uneven, "column t must have a regular step; a step of 13 s on lines 201-202"),
    (_fast, "is implausible for the platform"),
    (_off_map, "no row lies on the map"),
])
def test_bad_logs_are_named(voyage_log, tmp_path, capsys, edit, message):
    path = _edited(voyage_log[0], tmp_path, edit)
    out = tmp_path / "n.csv"
    assert main(["navigate", "--track", str(path), "--out", str(out), *SHORT]) == 2
    err = capsys.readouterr().err
    assert message in err and str(path) in err and not out.exists()


@pytest.mark.parametrize(("args", "message"), [
    (["--n-fixes", "4", "--stride", "4"], "--n-fixes must be at least 5"),
    (["--stride", "40"], "--stride must be at most --n-fixes"),
    (["--sigma-pos", "-1"], "--sigma-pos must be a finite value > 0"),
    (["--map-error", "nan"], "--map-error must be a finite value >= 0"),
    (["--segment-error", "markov"], "--segment-error is for --method dense; got --method ukf"),
    (["--method", "chains", "--no-fix-prior"], "--fix-prior is for --method dense"),
    (["--method", "chains", "--no-shape-update"], "--shape-update is for --method dense"),
    (["--method", "chains", "--reacquire-after", "2"], "--reacquire-after is for --method "
                                                       "dense; got --method chains"),
    (["--method", "dense", "--reacquire-inflation", "0.5"], "--reacquire-inflation must be a "
                                                           "finite factor >= 1"),
    (["--method", "dense", "--first-n-fixes", "70"], "--first-n-fixes must be from 5 to "
                                                     "--n-fixes 60; got 70"),
    (["--method", "rbpf", "--particles", "1"], "--particles must be an integer >= 100"),
])
def test_bad_options_are_named(voyage_log, tmp_path, capsys, args, message):
    out = tmp_path / "n.csv"
    assert main(["navigate", "--track", str(voyage_log[0]), "--out", str(out),
                 "--fix-every", "6", *args]) == 2
    assert message in capsys.readouterr().err and not out.exists()


@pytest.mark.long
def test_navigate_on_a_map_with_missing_nodes_by_the_track(voyage_log, tmp_path, capsys):
    """Land next to the voyage: a hole of 2 x 2 nodes beside its middle is a mask, and both
    couplings run through it without a NaN."""
    xr = pytest.importorskip("xarray")
    from jaxgrav import datasets

    log, _ = voyage_log
    track = read_track_csv(log, ("t", "lat", "lon"))
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    v = np.array(grid.values)
    mid = len(track["t"]) // 2
    i = int(np.searchsorted(np.asarray(grid.lat), track["lat"][mid]))
    j = int(np.searchsorted(np.asarray(grid.lon), track["lon"][mid]))
    v[i + 1:i + 3, j - 1:j + 1] = np.nan
    xr.Dataset({"anomaly": (("lat", "lon"), v, {"units": "mGal"})},
               coords={"lat": np.asarray(grid.lat), "lon": np.asarray(grid.lon)}).to_netcdf(
        tmp_path / "holey.nc")
    for method in ("dense", "ukf", "pmf"):
        out = tmp_path / f"{method}.csv"
        assert main(["navigate", "--map", str(tmp_path / "holey.nc"), "--track", str(log),
                     "--out", str(out), "--method", method, *SHORT]) == 0
        nav = read_track_csv(out, ("t", "lat", "lon", "sigma_north", "sigma_east"))
        for k in ("lat", "lon", "sigma_north", "sigma_east"):
            assert np.isfinite(nav[k]).all(), (method, k)
        # the point-mass filter's 1-sigma is not to be trusted on a voyage, and says so
        assert ("pmf's 1-sigma is over-confident" in capsys.readouterr().err) == (method == "pmf")
    # the point-mass filter across the hole stays with the truth (its cells over the hole
    # once took zero likelihood: the mass piled on the hole's rim, 10 km off)
    truth = read_track_csv(voyage_log[1], ("t", "lat", "lon"))
    err = [np.hypot(np.radians(a["lat"] - truth["lat"]) * 6.37e6,
                    np.radians(a["lon"] - truth["lon"]) * 6.37e6 * np.cos(np.radians(30.0)))
           for a in (nav, track)]
    assert err[0][-1] < err[1][-1], (err[0][-1], err[1][-1])


def test_a_position_jump_in_the_log_is_refused(voyage_log, tmp_path, capsys):
    """One INS row 500 m off (a reset or glitch): named by line, nothing written."""
    log = voyage_log[0]
    lines = log.read_text().splitlines()
    head = lines[0].split(",")
    row = lines[100].split(",")
    i = head.index("lat")
    row[i] = f"{float(row[i]) + 0.0045:.7f}"
    lines[100] = ",".join(row)
    bad = tmp_path / "jump.csv"
    bad.write_text("\n".join(lines) + "\n")
    out = tmp_path / "n.csv"
    for cmd in (["navigate", "--method", "ukf"], ["filter", "--method", "ukf", "--map", "ryukyu"]):
        assert main([*cmd, "--track", str(bad), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "jumps by" in err and "lines 100 and 101" in err, err
        assert not out.exists()


@pytest.mark.long
def test_a_log_mostly_in_port_then_sailing(voyage_log, tmp_path, capsys):
    """A ship at rest for longer than it then sails: the median speed was 0, and the
    tight filter's map-error state and curvature count with it gave innovation 1-sigmas of
    50 000 mGal and covariance repairs on every row (its readings ignored)."""
    pd = pytest.importorskip("pandas")
    log = pd.read_csv(voyage_log[0])
    k = 2 * len(log)
    first = log.iloc[0]
    port = pd.DataFrame({"t": np.arange(k) * 10.0, "lat": first["lat"], "lon": first["lon"],
                         "v_east": 0.0, "v_north": 0.0, "gravity": first["gravity"]
                         + np.random.default_rng(0).normal(0.0, 1.0, k)})
    log["t"] = log["t"] + k * 10.0
    path, out = tmp_path / "port.csv", tmp_path / "n.csv"
    pd.concat([port, log]).to_csv(path, index=False)
    assert main(["navigate", "--track", str(path), "--out", str(out), "--method", "ukf"]) == 0
    nav = pd.read_csv(out)
    assert not (nav["status"].to_numpy() & 4).any()  # no covariance repair
    assert nav["innovation_sigma"].max() < 20.0
    assert nav["sigma_north"].iloc[-1] < 5000.0


def test_an_implausible_fit_is_flagged_on_its_rows(voyage_log, tmp_path, capsys):
    """A +250 mGal gravimeter bias: the tight filter's CSV flags the rows of the blocks
    whose innovations fail chi-squared (bit 128), as filter's does; it said status 0."""
    pd = pytest.importorskip("pandas")
    log = pd.read_csv(voyage_log[0])
    log["gravity"] += 250.0
    path, out = tmp_path / "b.csv", tmp_path / "n.csv"
    log.to_csv(path, index=False)
    assert main(["navigate", "--track", str(path), "--out", str(out), "--method", "ukf"]) == 0
    captured = capsys.readouterr()
    assert "implausible_fit" in captured.out and "innovations are" in captured.err
    assert (pd.read_csv(out)["status"].to_numpy() & 128).mean() > 0.5
    # and named for what it is before the run (filter_checks.offset_warning)
    assert re.search(r"the readings sit \+2\d\d mGal from the map", captured.err)
    assert "a datum or an untied" in captured.err


@pytest.mark.parametrize("shift, flat_map, extra, offset, flat", [
    (0.0, False, ("--ins", "navigation"), None, False),  # the clean log, either grade
    (0.0, False, ("--ins", "strategic"), None, False),
    (15.0, False, (), None, False),  # within the 25 mGal floor
    (60.0, False, (), r"\+5\d", False),  # the clean log sits -7 mGal off (map error 3)
    (-250.0, False, ("--ins", "strategic"), r"-2\d\d", False),
    (0.0, True, ("--ins", "navigation"), None, True),  # a constant map at the readings' level
    (0.0, True, ("--ins", "strategic"), None, True),
])
def test_offset_and_information_warnings(voyage_log, tmp_path, capsys, check_filter_warnings,
                                         shift, flat_map, extra, offset, flat):
    """filter_checks' warnings in navigate (tightly coupled), with either --ins grade: the
    readings' offset from the map before the run, a map too flat to tell the position
    after it; one stderr line each, exit 0, the CSV written; none for the clean log or an
    offset within the floor. The ukf compiles once for the rows (and the module)."""
    pd = pytest.importorskip("pandas")
    log = pd.read_csv(voyage_log[0])
    log["gravity"] += shift
    path, out = tmp_path / "log.csv", tmp_path / "n.csv"
    log.to_csv(path, index=False)
    source = ()
    if flat_map:  # the map at the median Eötvös-corrected reading: no offset, no gradient
        level = float(np.median(log["gravity"] + np.asarray(
            eotvos(log["lat"].to_numpy(), log["v_east"].to_numpy(),
                   log["v_north"].to_numpy()))))
        grid = datasets.load("ryukyu")["anomaly_2p5min"]
        xr.Dataset({"anomaly": (("lat", "lon"), np.full(np.shape(grid.values), level),
                                {"units": "mGal"})},
                   coords={"lat": np.asarray(grid.lat), "lon": np.asarray(grid.lon)}).to_netcdf(
            tmp_path / "flat.nc")
        source = ("--map", str(tmp_path / "flat.nc"))
    assert main(["navigate", *source, "--track", str(path), "--out", str(out),
                 "--method", "ukf", *extra]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert out.is_file()
    check_filter_warnings(lines, offset, flat)


def test_loose_methods_refuse_a_log_with_a_reading_every_few_rows(voyage_log, tmp_path,
                                                                   capsys):
    """A reading every 5th row (simulate-filter's default): no segment was ever matched
    by dense, exit 0; now refused, and a few missing readings are warned of."""
    pd = pytest.importorskip("pandas")
    log = pd.read_csv(voyage_log[0])
    sparse = log.copy()
    sparse.loc[np.arange(len(log)) % 5 != 4, "gravity"] = np.nan
    path, out = tmp_path / "s.csv", tmp_path / "n.csv"
    sparse.to_csv(path, index=False)
    assert main(["navigate", "--track", str(path), "--out", str(out), "--method", "dense",
                 "--fix-every", "5"]) == 2
    assert "of the blocks of --fix-every 5 rows miss a reading" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.long
def test_a_jittered_log_with_dropped_records_is_navigated_on_its_rows(voyage_log, tmp_path,
                                                                      capsys):
    # a logger stamping 10 s records ±1 s late or early, and 5 records lost (two gaps):
    # the tight filter runs on the regular step, predicts through the gaps, and writes the
    # log's own rows and times, as good as on the clean log
    log = voyage_log[0]
    names = ("t", "lat", "lon", "v_east", "v_north", "gravity")
    cols = {k: np.asarray(v) for k, v in read_track_csv(log, names).items()}
    cols["t"] = cols["t"] + np.random.default_rng(3).uniform(-1.0, 1.0, cols["t"].size) * 0.45
    drop = [100, 101, 300, 301, 302]
    cols = {k: np.delete(v, drop) for k, v in cols.items()}
    path = tmp_path / "jittered.csv"
    write_track_csv(path, cols)
    clean, out = tmp_path / "clean.csv", tmp_path / "n.csv"
    assert main(["navigate", "--track", str(log), "--out", str(clean)]) == 0
    assert main(["navigate", "--track", str(path), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "536 rows" in said and "2 gap(s) bridged by prediction over 5 missing row(s)" in said
    nav, ref = read_track_csv(out, names[:3]), read_track_csv(clean, names[:3])
    np.testing.assert_array_equal(nav["t"], read_track_csv(path, ("t",))["t"])
    keep = np.delete(np.arange(541), drop)
    d_km = np.hypot(nav["lat"] - ref["lat"][keep],
                    (nav["lon"] - ref["lon"][keep]) * np.cos(np.deg2rad(nav["lat"]))) * 111.0
    assert np.max(d_km) < 0.3, np.max(d_km)


def test_the_loose_methods_refuse_a_gap(voyage_log, tmp_path, capsys):
    path = _edited(voyage_log[0], tmp_path, lambda c: c["t"].__setitem__(slice(200, None),
                                                                         c["t"][200:] + 20.0))
    for method in ("dense", "entropy+iccp"):
        out = tmp_path / "n.csv"
        assert main(["navigate", "--track", str(path), "--out", str(out), "--method",
                     method, *SHORT]) == 2
        err = capsys.readouterr().err
        assert (f"a gap of 2 missing row(s) on lines 201-202 (t 1990 -> 2020 s) (step 10 s; 1 "
                f"gap(s)), and --method {method} needs every row (a tightly coupled --method, "
                "e.g. ukf, predicts through gaps)") in err, err
        assert not out.exists()
