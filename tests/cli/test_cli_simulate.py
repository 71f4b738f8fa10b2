"""``jaxgrav simulate`` with --map-error, --map-error-length and --truth-map."""

import numpy as np
import pytest

from jaxgrav.cli import main
from jaxgrav.datasets import load_map
from jaxgrav.match import MIN_FIXES
from jaxgrav.tracks import read_track_csv


def simulate(tmp_path, name, *extra):
    out, truth = tmp_path / f"{name}.csv", tmp_path / f"{name}_truth.csv"
    code = main(["simulate", "--out", str(out), "--truth", str(truth), "--n", "20", "--seed",
                 "3", "--noise", "0", *extra])
    return code, out, truth


def test_simulate_map_error_changes_only_the_readings(tmp_path, capsys):
    code, plain, _ = simulate(tmp_path, "plain")
    assert code == 0 and "perfect map (no map error)" in capsys.readouterr().out
    code, zero, _ = simulate(tmp_path, "zero", "--map-error", "0")
    assert code == 0
    code, noisy, _ = simulate(tmp_path, "noisy", "--map-error", "3", "--map-error-length",
                                  "8000")
    assert code == 0 and "map error 3 (map units), L = 8 km" in capsys.readouterr().out
    a, z, b = (read_track_csv(p) for p in (plain, zero, noisy))
    np.testing.assert_array_equal(a["gravity"], z["gravity"])
    np.testing.assert_array_equal(a["lat"], b["lat"])
    d = b["gravity"] - a["gravity"]  # the map error along the true track (noise 0)
    assert 0.3 < np.std(d) + abs(np.mean(d)) < 15 and np.all(np.isfinite(d))


def test_simulate_truth_map(tmp_path, capsys):
    code, out, truth = simulate(tmp_path, "t", "--map", "ryukyu:anomaly_0p5deg", "--truth-map",
                                "ryukyu")
    assert code == 0 and "truth map ryukyu" in capsys.readouterr().out
    fine = load_map("ryukyu", None)
    t = read_track_csv(truth)
    r = read_track_csv(out)
    # readings (noise 0) are the 2.5' field at the true fixes, minus the Eötvös effect
    assert np.corrcoef(r["gravity"], np.asarray(fine.sample(t["lat"], t["lon"], "bicubic")))[
        0, 1] > 0.9


@pytest.mark.parametrize("args, match", [
    (["--map-error", "-1"], "--map-error must be a finite standard deviation >= 0"),
    (["--map-error", "nan"], "got nan"),
    (["--map-error", "inf"], "got inf"),
    (["--map-error", "2", "--map-error-length", "0"],
     "--map-error-length must be a finite correlation length > 0 (m); got 0.0"),
    (["--map-error", "2", "--map-error-length", "-5"], "got -5.0"),
    (["--map-error", "2", "--truth-map", "ryukyu"], "exclude each other"),
])
def test_simulate_bad_map_error(tmp_path, capsys, args, match):
    code, out, _ = simulate(tmp_path, "bad", *args)
    assert code == 2
    assert match in capsys.readouterr().err
    assert not out.exists()


def test_simulate_truth_map_must_cover(tmp_path, capsys):
    from jaxgrav import Grid

    lat, lon = np.linspace(30.0, 31.0, 11), np.linspace(130.0, 131.0, 11)
    Grid.from_arrays(lat, lon, np.zeros((11, 11)), name="g", units="mGal").to_netcdf(
        tmp_path / "small.nc")
    code, _, _ = simulate(tmp_path, "x", "--truth-map", str(tmp_path / "small.nc"))
    assert code == 2
    err = capsys.readouterr().err
    assert f"--truth-map {tmp_path / 'small.nc'} must cover the scenario's region" in err


@pytest.mark.parametrize("n", [2, 3, MIN_FIXES - 1])
def test_simulate_refuses_n_match_cannot_use(tmp_path, capsys, n):
    """Issue 19: ``--n 2`` .. ``4`` wrote a track ``jaxgrav match`` then refused; now
    simulate refuses it first, naming --n, the value and match's minimum."""
    out, truth = tmp_path / "t.csv", tmp_path / "truth.csv"
    assert main(["simulate", "--out", str(out), "--truth", str(truth), "--n", str(n)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"--n must be at least {MIN_FIXES} fixes" in err and f"got {n}" in err, err
    assert err.count("\n") == 0 and not out.exists() and not truth.exists()
