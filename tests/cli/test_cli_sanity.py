"""Readings that cannot be anomalies of the map are refused before a run, and a fit the
stated noise cannot explain is flagged after it (``jaxgrav.cli.sanity``): the functions
against SciPy's χ² distribution and synthetic columns, then ``match``, ``filter`` and
``navigate`` in-process, one case per bad input of the issue, with the exit code, the
message and no output left behind."""

import argparse
import csv
import json

import numpy as np
import pytest
from scipy.stats import chi2

from jaxgrav import datasets
from jaxgrav.cli import main
from jaxgrav.cli.match import check_search
from jaxgrav.cli.sanity import (
    check_positions,
    check_readings,
    fit_check,
    implausible_rows,
    innovation_check,
)
from jaxgrav.match import IMPLAUSIBLE_FIT, fit_p_value
from jaxgrav.tracks import read_track_csv

# ------------------------------------------------------------------ the functions


def test_fit_and_innovation_checks_against_scipy_chi2():
    for c, dof in ((0.6, 27), (1.0, 27), (2.2, 27), (3.0, 10), (900.0, 27)):
        p, warning = fit_check(c, dof, 1.0)
        assert p == pytest.approx(chi2.sf(c * dof, dof), rel=1e-9, abs=1e-300)
        assert (warning is None) == (p >= 1e-3)
    assert fit_check(float("nan"), 27, 1.0) == (pytest.approx(np.nan, nan_ok=True), None)
    rng = np.random.default_rng(0)
    s = np.full(500, 2.0)
    nis, p, warning = innovation_check(rng.normal(0, 2.0, 500), s)  # consistent
    assert nis == pytest.approx(1.0, abs=0.2) and warning is None
    nis, p, warning = innovation_check(rng.normal(0, 6.0, 500), s)  # 3 x too large
    assert nis == pytest.approx(9.0, rel=0.2) and p < 1e-3
    assert "larger than the filter predicts" in warning
    nu = rng.normal(0, 2.0, 500)
    nu[::2] = np.nan  # readings not used do not count
    assert innovation_check(nu, s)[0] == pytest.approx(
        np.mean((nu[1::2] / 2.0) ** 2))


def test_implausible_rows_against_a_loop_over_blocks():
    rng = np.random.default_rng(1)
    s = rng.uniform(1.0, 3.0, 700)
    nu = rng.normal(0.0, 1.0, 700) * s
    nu[::9] = np.nan  # no reading: not counted, but inside a flagged block's span
    nu[200:330] *= 2.5  # a stretch where the map is wrong
    flagged = implausible_rows(nu, s, block=50)
    used = np.flatnonzero(np.isfinite(nu))
    expected = np.zeros(700, bool)
    for k in range(0, used.size, 50):
        rows = used[k:k + 50]
        if chi2.sf(np.sum((nu[rows] / s[rows]) ** 2), rows.size) < 1e-3:
            expected[rows[0]:rows[-1] + 1] = True
    np.testing.assert_array_equal(flagged, expected)
    assert flagged[230:300].all() and not flagged[:150].any() and not flagged[400:].any()
    assert not implausible_rows(np.full(4, np.nan), np.ones(4)).any()
    assert fit_p_value(2.0, 27) == pytest.approx(chi2.sf(54.0, 27), rel=1e-9)
    assert np.isnan(fit_p_value(float("nan"), 27)) and np.isnan(fit_p_value(1.0, 0))


@pytest.fixture
def column():
    """A plausible anomaly column and the map along its track (mGal)."""
    rng = np.random.default_rng(1)
    expected = 20.0 * np.sin(np.linspace(0.0, 6.0, 60)) - 15.0
    return expected + rng.normal(0.0, 1.0, 60) + 2.0, expected


@pytest.mark.parametrize(("change", "phrases"), [
    (lambda z: np.where(np.arange(z.size) == 7, -9999.0, z), ["fill value", "-9999", "line 9"]),
    (lambda z: np.where(np.arange(z.size) == 3, 99999.0, z), ["fill value", "99999"]),
    (lambda z: z + 979_800.0, ["absolute gravity", "mGal"]),
    (lambda z: (z + 979_800.0) * 1e-5, ["absolute gravity", "m/s²"]),
    (lambda z: z * 1e-5, ["other units", "m/s²"]),
    (lambda z: z * 1e3, ["other units", "µGal"]),
    (lambda z: z + 5000.0, ["from the map", "datum"]),
    (lambda z: np.where(np.arange(z.size) == 11, 4000.0, z), ["far outside", "line 13"]),
])
def test_check_readings_refuses_what_cannot_be_an_anomaly(column, change, phrases):
    z, expected = column
    check_readings(z, expected, 1.0, column="gravity", where="--track 'T.csv'")  # plausible
    with pytest.raises(ValueError) as err:
        check_readings(change(z), expected, 1.0, column="gravity", where="--track 'T.csv'")
    msg = str(err.value)
    assert "--track 'T.csv'" in msg and "'gravity'" in msg and "\n" not in msg
    for phrase in phrases:
        assert phrase in msg


def test_check_readings_units_hints_and_what_passes(column):
    z, expected = column
    with pytest.raises(ValueError, match="µT"):  # a magnetic column in µT
        check_readings(z * 1e-3, expected, 1.0, column="magnetic", where="w", unit="nT")
    # a gravimeter bias of 30 mGal, missing readings and readings off the map pass
    z2 = z + 30.0
    z2[5] = np.nan
    e2 = expected.copy()
    e2[:10] = np.nan
    check_readings(z2, e2, 1.0, column="gravity", where="w")
    # raw readings with their Eötvös correction given: compared after it
    check_readings(z - 40.0, expected, 1.0, column="gravity", where="w",
                   correction=np.full(z.size, 40.0))
    with pytest.raises(ValueError, match="remove the row"):
        check_readings(np.where(np.arange(z.size) == 2, -9999.0, z), expected, 1.0,
                       column="gravity", where="w", missing_skipped=False)
    # readings that fit the map until a wild Eötvös correction (v_east 500 m/s) moves
    # them: the message names the velocity columns, not a datum
    with pytest.raises(ValueError, match="v_east and v_north"):
        check_readings(z, expected, 1.0, column="gravity", where="w",
                       correction=np.full(z.size, 3000.0))
    with pytest.raises(ValueError, match="another datum"):
        check_readings(z + 3000.0, expected, 1.0, column="gravity", where="w")
    # an anomaly of about 9.8 mGal over a quiet map is not absolute gravity in m/s²
    rng = np.random.default_rng(1)
    quiet = 9.8 + 0.5 * np.sin(np.linspace(0.0, 6.0, 40))
    check_readings(quiet + rng.standard_normal(40), quiet, 1.0, column="gravity", where="w")


def test_check_readings_names_the_file_s_own_line_for_a_gap_or_a_spike(column):
    """Issue 19: an empty reading reached the matcher ("readings has 1 NaN/inf value(s),
    first at fix 5", no file, column or line), and a spike was named by its row + 2, not
    by the file's line (two comment lines above the header: line 12 for line 14)."""
    z, expected = column
    own = lambda i: i + 4  # noqa: E731 (two comment lines and the header)
    with pytest.raises(ValueError) as err:
        check_readings(np.where(np.arange(z.size) == 5, np.nan, z), expected, 1.0,
                       column="gravity", where="--track 'T.csv'", missing_skipped=False,
                       line=own)
    assert str(err.value) == ("--track 'T.csv': column 'gravity' has 1 empty, NaN or inf "
                              "cell(s), first on line 9; remove the row (matching needs a "
                              "reading at every fix)")
    with pytest.raises(ValueError, match="4000 on line 15,"):
        check_readings(np.where(np.arange(z.size) == 11, 4000.0, z), expected, 1.0,
                       column="gravity", where="w", line=own)


# ------------------------------------------------------------------ the commands


@pytest.fixture(scope="module")
def tracks(tmp_path_factory):
    d = tmp_path_factory.mktemp("sanity")
    assert main(["simulate", "--out", str(d / "t.csv"), "--n", "30", "--seed", "3"]) == 0
    assert main(["simulate-filter", "--out", str(d / "f.csv"), "--minutes", "30"]) == 0
    return d


def _edited(src, dst, change):
    rows = list(csv.DictReader(open(src, newline="")))
    with open(dst, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for i, row in enumerate(rows):
            if row["gravity"]:
                row["gravity"] = repr(change(i, float(row["gravity"])))
            w.writerow(row)
    return dst


_MATCH_BAD = {
    "fill": (lambda i, g: -9999.0 if i == 5 else g, [], ["fill value", "-9999", "remove the row"]),
    "absolute": (lambda i, g: g + 979_741.0, [], ["absolute gravity"]),
    "empty reading": (lambda i, g: float("nan") if i == 5 else g, [],
                      ["column 'gravity' has 1 empty, NaN or inf cell(s), first on line 7"]),
    "m/s2": (lambda i, g: g * 1e-5, [], ["other units", "m/s²"]),
    "dense refined": (lambda i, g: g, ["--refine", "8"], ["--refine 8 is for --method chains",
                                                          "worse"]),
    "refine out of memory": (lambda i, g: g, ["--method", "chains", "--refine", "10000"],
                             ["--refine 10000", "GB", "smaller factor"]),
    "search wider than the map": (lambda i, g: g, ["--drift-radius", "20"],
                                  ["--drift-radius 20", "larger than the map"]),
}


@pytest.mark.parametrize("case", sorted(_MATCH_BAD))
def test_match_refuses_bad_readings_and_options(tracks, tmp_path, capsys, case):
    change, options, phrases = _MATCH_BAD[case]
    track = _edited(tracks / "t.csv", tmp_path / "bad.csv", change)
    out = tmp_path / "r.json"
    assert main(["match", "--map", "ryukyu", "--track", str(track), "--out", str(out),
                 *options]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "np." not in err
    for phrase in phrases:
        assert phrase in err
    assert not out.exists()


def test_match_flags_an_implausible_fit_and_writes_time_and_units(tracks, tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["match", "--map", "ryukyu", "--track", str(tracks / "t.csv"), "--out",
                 str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["fit_plausible"] is True and r["fit_p_value"] > 1e-3
    assert len(r["t"]) == 30 and r["t"][1] - r["t"][0] == pytest.approx(120.0)
    assert r["units"]["bias"] == "mGal" and r["units"]["t"] == "s"
    assert "mGal^2" in r["units"]["score"]
    capsys.readouterr()
    # ±30 mGal of noise stated as 1 mGal: the fix is flagged, not silently trusted
    noisy = _edited(tracks / "t.csv", tmp_path / "noisy.csv",
                    lambda i, g: g + (30.0 if i % 2 else -30.0))
    assert main(["match", "--map", "ryukyu", "--track", str(noisy), "--out", str(out),
                 "--force"]) == 0
    r = json.loads(out.read_text())
    assert r["fit_plausible"] is False and r["fit_p_value"] < 1e-3
    assert r["status"] & IMPLAUSIBLE_FIT and r["accepted"] is True  # flagged, not rejected
    assert sum("far worse than the stated noise" in m for m in r["status_messages"]) == 1
    assert "far worse than the stated noise" in capsys.readouterr().err


@pytest.mark.long  # a whole chains match on the unrefined map (a program of its own) for a
# warning: the fast tier keeps the warning by test_chains_warning_is_decided_before_the_run,
# and match's call of check_search by the "search wider than the map" case above
def test_chains_without_refine_on_a_coarse_map_warns(tracks, tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["match", "--map", "ryukyu", "--track", str(tracks / "t.csv"), "--out",
                 str(out), "--method", "chains"]) == 0
    assert "without --refine" in capsys.readouterr().err


@pytest.mark.parametrize(("method", "refine", "fine", "warned"), [
    ("chains", 1, False, True),  # the shipped 2.5' map: 4.0 km cells (east, the finer)
    ("chains", 1, True, False),  # the same map refined x8: 0.5 km cells
    ("chains", 4, False, False),  # --refine asked for
    ("dense", 1, False, False),  # continuous sampling: no node lattice
])
def test_chains_warning_is_decided_before_the_run(capsys, method, refine, fine, warned):
    """match's check of the search region (run before any matching) warns of chains on
    cells coarser than 1 km without --refine, and only then."""
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    if fine:
        grid = grid.refine(8)
    args = argparse.Namespace(method=method, refine=refine)
    check_search(args, grid, 0.05, np.array([26.0, 26.1]))
    err = capsys.readouterr().err
    assert ("without --refine" in err) is warned, err
    if warned:
        assert "--method chains on a map of 4.0 km cells" in err and "--refine 8" in err


@pytest.mark.parametrize(("change", "phrases"), [
    (lambda i, g: -9999.0 if i == 40 else g, ["fill value", "leave the cell empty"]),
    (lambda i, g: g + 979_741.0, ["absolute gravity"]),
    (lambda i, g: g * 1e-5, ["other units"]),
])
def test_filter_refuses_bad_readings(tracks, tmp_path, capsys, change, phrases):
    track = _edited(tracks / "f.csv", tmp_path / "bad.csv", change)
    out = tmp_path / "o.csv"
    assert main(["filter", "--track", str(track), "--point-masses", "paper-d", "--out",
                 str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and all(p in err for p in phrases) and not out.exists()


def test_filter_warns_when_the_innovations_are_implausible(tracks, tmp_path, capsys):
    noisy = _edited(tracks / "f.csv", tmp_path / "noisy.csv",
                    lambda i, g: g + (8.0 if i % 2 else -8.0))
    out = tmp_path / "o.csv"
    assert main(["filter", "--track", str(noisy), "--point-masses", "paper-d", "--out",
                 str(out)]) == 0
    err = capsys.readouterr().err
    assert "innovations are" in err and "not trustworthy" in err
    assert "implausible_fit on" in err
    with open(out, newline="") as f:
        status = np.array([int(row["status"]) for row in csv.DictReader(f)])
    assert np.count_nonzero(status & 128) > 0.9 * status.size  # every block of readings
    assert main(["filter", "--track", str(tracks / "f.csv"), "--point-masses", "paper-d",
                 "--out", str(out), "--force"]) == 0  # the readings as simulated: no flag
    with open(out, newline="") as f:
        assert not any(int(row["status"]) & 128 for row in csv.DictReader(f))
    assert "implausible_fit" not in capsys.readouterr().err


def _arc_log(speed, rate_deg_s, dt, n, lat0=30.0, lon0=130.0):
    """A log of a constant-rate turn: positions on the arc itself, velocities tangent."""
    t = np.arange(n) * dt
    heading = np.radians(rate_deg_s) * t
    r = speed / np.radians(rate_deg_s)
    north, east = r * np.sin(heading), r * (1.0 - np.cos(heading))
    mr, nr = 6.35e6, 6.38e6 * np.cos(np.radians(lat0))
    return {"t": t, "lat": lat0 + np.degrees(north / mr), "lon": lon0 + np.degrees(east / nr),
            "v_east": speed * np.sin(heading), "v_north": speed * np.cos(heading)}


@pytest.mark.parametrize(("speed", "rate", "dt"), [
    (5.0, 0.5, 10.0),     # a ship's gentle turn, a row every 10 s
    (10.0, 1.5, 60.0),    # a tight turn at navigate's largest default gap (90° between rows)
    (10.0, 0.5, 180.0),   # a matcher track's sparse rows
    (100.0, 3.0, 30.0),   # an aircraft's standard-rate turn
])
def test_check_positions_passes_turns_and_refuses_a_jump(speed, rate, dt):
    """Turns pass at any row spacing up to a 90° heading change, also with coordinates
    rounded to 1e-5°; a glitch in one row (60 m, or 80 % of a step; 60 % in the
    90°-a-row turn, whose allowance is wide) is named with its line."""
    log = _arc_log(speed, rate, dt, 40)
    check_positions(log, where="--track 'L.csv'")
    rounded = {**log, "lat": np.round(log["lat"], 5), "lon": np.round(log["lon"], 5)}
    check_positions(rounded, where="--track 'L.csv'")  # 1e-5 degree rounding: not a jump
    jump = max(60.0, 0.8 * speed * dt) if rate * dt < 30 else 0.6 * speed * dt
    log["lat"] = log["lat"].copy()
    log["lat"][20] += np.degrees(jump / 6.35e6)
    with pytest.raises(ValueError, match=r"jumps by .* m between lines 21 and 22.*such"):
        check_positions(log, where="--track 'L.csv'")


def test_check_positions_refuses_a_jump_in_the_ins_log():
    """A 300 m glitch in one row of a 10 s log at 5 m/s is named with its line; a
    smooth log (the simulator's) and a turn pass."""
    t = np.arange(0.0, 600.0, 10.0)
    ve = 5.0 * np.cos(t / 300.0)
    vn = 5.0 * np.sin(t / 300.0)  # turning
    lat0, lon0 = 30.0, 130.0
    mr, nr = 6.35e6, 6.38e6 * np.cos(np.radians(lat0))
    east = np.concatenate([[0.0], np.cumsum(0.5 * (ve[1:] + ve[:-1]) * 10.0)])
    north = np.concatenate([[0.0], np.cumsum(0.5 * (vn[1:] + vn[:-1]) * 10.0)])
    track = {"t": t, "lat": lat0 + np.degrees(north / mr), "lon": lon0 + np.degrees(east / nr),
             "v_east": ve, "v_north": vn}
    check_positions(track, where="--track 'L.csv'")
    track["lat"] = track["lat"].copy()
    track["lat"][20] += np.degrees(300.0 / mr)
    with pytest.raises(ValueError,
                       match=r"jumps by 3\d\d(\.\d)? m between lines 21 and 22.*2 such"):
        check_positions(track, where="--track 'L.csv'")


def test_a_jump_is_named_by_the_file_s_own_lines(tmp_path):
    # two comment lines above the header: the rows' file lines are 4, 5, ... (csv_line's
    # count from a bare header said 41-42 for what the file has on lines 43-44)
    path = tmp_path / "log.csv"
    ve = 1e-4 * np.radians(1.0) * 6378137.0 / np.sqrt(1 - 0.00669438 * 0.25) * np.cos(
        np.radians(30.0)) / 10.0  # 1e-4 degrees of longitude per 10 s at 30° N (m/s)
    rows = "\n".join(f"{10 * i},30.0,{130.0 + 1e-4 * i + (0.01 if i >= 40 else 0.0)},{ve},0.0"
                     for i in range(60))
    path.write_text("# a logger's header\n# another\nt,lat,lon,v_east,v_north\n" + rows + "\n")
    track = read_track_csv(path, ("t", "lat", "lon", "v_east", "v_north"))
    with pytest.raises(ValueError, match=r"jumps by 96\d\.\d m between lines 43 and 44 "):
        check_positions(track, where="log")
