"""End-to-end command-line tests (in-process through ``jaxgrav.cli.main``)."""

import json
import subprocess
import sys

import jax
import numpy as np
import pytest

from jaxgrav import datasets
from jaxgrav.cli import main
from jaxgrav.fields import harmonics
from jaxgrav.match import match_track
from jaxgrav.scenarios.paper_b import PaperBScenario, paper_b_scenario
from jaxgrav.sim import DEG_ARC_M
from jaxgrav.tracks import read_track_csv, write_track_csv


@pytest.fixture(scope="module")
def track(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    assert main(["simulate", "--out", str(d / "t.csv"), "--truth", str(d / "truth.csv"),
                 "--n", "20", "--seed", "3"]) == 0
    return d


@pytest.mark.long
def test_match_eotvos_corrected_takes_the_column_as_is(track):
    """--eotvos-corrected (older name --no-eotvos): the same rule as filter and navigate."""
    for flag in ("--eotvos-corrected", "--no-eotvos"):
        out = track / f"r{flag}.json"
        assert main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"),
                     "--out", str(out), flag]) == 0
        r = json.loads(out.read_text())
        assert r["eotvos_applied_here"] is False
        assert r["eotvos"].startswith("given corrected (--eotvos-corrected)"), r["eotvos"]


@pytest.mark.long
def test_simulate_then_match_beats_ins(track):
    out = track / "r.json"
    assert main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"),
                 "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    truth = read_track_csv(track / "truth.csv", required=("lat", "lon"))
    ins = read_track_csv(track / "t.csv", required=("lat", "lon"))
    assert len(r["lat"]) == 20 and len(r["topk_score"]) == 5
    err = np.hypot(np.subtract(r["lat"], truth["lat"]), np.subtract(r["lon"], truth["lon"]))
    ins_err = np.hypot(ins["lat"] - truth["lat"], ins["lon"] - truth["lon"])
    assert np.mean(err) < np.mean(ins_err) / 3
    assert r["status"] == 0 and r["eotvos_applied_here"] is True
    assert r["eotvos"] == "corrected here with the track's v_east, v_north"
    # existing output is not overwritten without --force
    assert main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"),
                 "--out", str(out)]) == 2
    assert main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"),
                 "--out", str(out), "--force", "--method", "chains", "--refine", "4"]) == 0
    _check_chains_result(json.loads(out.read_text()), truth, ins)


def _check_chains_result(r, truth, ins):
    """RESULT.json of --method chains: one matched fix per INS fix, on the map, nearer
    the truth than the INS; the work counts of paper A's Table 1."""

    n_fix = len(truth["lat"])
    assert r["method"] == "chains" and len(r["lat"]) == len(r["lon"]) == n_fix
    assert np.shape(r["topk_lat"]) == (5, n_fix) and len(r["n_candidates"]) == n_fix
    lat, lon = np.asarray(r["lat"]), np.asarray(r["lon"])
    w, e, s, n = datasets.load("ryukyu")["anomaly_2p5min"].extent
    assert np.all(np.isfinite(lat) & (lat >= s) & (lat <= n) & (lon >= w) & (lon <= e))
    assert np.isfinite(r["score"]) and r["status"] & 1 == 0
    # work: the product of candidate counts, at least the chains left after elimination
    np.testing.assert_allclose(r["work_unconstrained"],
                               np.prod(np.asarray(r["n_candidates"], float)), rtol=1e-9)
    assert r["work_unconstrained"] >= r["work_constrained"] >= 1 and r["work_pairs"] > 0
    err = np.hypot(lat - truth["lat"], lon - truth["lon"]).mean()
    ins_err = np.hypot(ins["lat"] - truth["lat"], ins["lon"] - truth["lon"]).mean()
    assert err < ins_err, (err, ins_err)  # (0.014° against 0.035° when written)


@pytest.mark.long
def test_match_reads_a_user_netcdf_map(track, tmp_path):
    datasets.load("ryukyu")["anomaly_2p5min"].to_netcdf(tmp_path / "map.nc")
    assert main(["match", "--map", str(tmp_path / "map.nc"), "--track", str(track / "t.csv"),
                 "--out", str(tmp_path / "r.json")]) == 0


@pytest.mark.parametrize(("edit", "message"), [
    (lambda c: c.pop("gravity"), "needs a 'gravity' (mGal) or 'magnetic' (nT) column"),
    (lambda c: c.pop("t"), "lacks column t; it has "),
    (lambda c: c["gravity"].__setitem__(3, np.nan),
     "column 'gravity' has 1 empty, NaN or inf cell(s), first on line 5"),
    (lambda c: c["lon"].__setitem__(slice(None), c["lon"] + 20.0), "leaves the map"),
    (lambda c: [c.__setitem__(k, v[:3]) for k, v in list(c.items())],
     "has 3 rows; match needs at least 5 fixes"),
])
def test_match_bad_tracks_get_clear_errors(track, tmp_path, capsys, edit, message):
    cols = read_track_csv(track / "t.csv")
    edit(cols)
    write_track_csv(tmp_path / "bad.csv", cols)
    code = main(["match", "--map", "ryukyu", "--track", str(tmp_path / "bad.csv"),
                 "--out", str(tmp_path / "r.json")])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()


@pytest.mark.long
def test_sample_command(track, tmp_path):
    assert main(["sample", "--map", "ryukyu:anomaly_0p5deg", "--track", str(track / "t.csv"),
                 "--out", str(tmp_path / "s.csv")]) == 0
    s = read_track_csv(tmp_path / "s.csv", required=("map",))
    assert np.all(np.isfinite(s["map"]))


@pytest.mark.long
def test_console_script_help():
    r = subprocess.run([sys.executable, "-m", "jaxgrav.cli", "--help"], capture_output=True,
                       text=True, check=True)
    for cmd in ("demo", "match", "simulate", "sample", "data"):
        assert cmd in r.stdout


@pytest.mark.long
def test_dov_command_against_the_exact_model(tmp_path, capsys):
    lat = np.array([34.23, 35.0, 36.1, 37.3])
    lon = np.array([108.33, 109.0, 110.2, 111.0])
    h = np.array([1000.0, 5000.0, 12000.0, 19000.0])
    write_track_csv(tmp_path / "track.csv", {"lat": lat, "lon": lon, "h": h})
    assert main(["dov", "--track", str(tmp_path / "track.csv"),
                 "--out", str(tmp_path / "dov.csv")]) == 0
    out = read_track_csv(tmp_path / "dov.csv", required=("lat", "lon", "h", "xi", "eta"))
    xi, eta = harmonics.deflection(datasets.load("qinling")["coefficients"], lat, lon, h)
    np.testing.assert_allclose(out["xi"], xi, atol=0.02)
    np.testing.assert_allclose(out["eta"], eta, atol=0.02)
    write_track_csv(tmp_path / "high.csv", {"lat": lat, "lon": lon, "h": h + 10000.0})
    assert main(["dov", "--track", str(tmp_path / "high.csv"),
                 "--out", str(tmp_path / "x.csv")]) == 2
    assert "h" in capsys.readouterr().err


@pytest.mark.parametrize("method", ["entropy+iccp"])
@pytest.mark.long
def test_match_paper_b_methods(track, tmp_path, method):
    out = tmp_path / "b.json"
    assert main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"), "--out", str(out),
                 "--method", method]) == 0
    r = json.loads(out.read_text())
    assert len(r["lat"]) == 20 and r["method"] == method and r["field"] == "gravity"


@pytest.mark.long
def test_match_iccp_max_rotation_bounds_the_heading_and_matches_the_library(tmp_path):
    # paper B's experiment: INS offset 0.02-0.03 deg and rotated 1.5 deg, 1 mGal
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    w, e, s, n = grid.extent
    run = paper_b_scenario(jax.random.key(1), grid, PaperBScenario(region=(s, n, w, e)))
    cols = {"t": np.asarray(run.truth.t), "lat": np.asarray(run.ins_lat),
            "lon": np.asarray(run.ins_lon), "gravity": np.asarray(run.readings)}
    write_track_csv(tmp_path / "b.csv", cols)
    cols = read_track_csv(tmp_path / "b.csv")
    rot = {}
    for bound in ("0", "0.5", None):
        out = tmp_path / f"b{bound}.json"
        extra = [] if bound is None else ["--max-rotation", bound]
        assert main(["match", "--map", "ryukyu", "--track", str(tmp_path / "b.csv"), "--out",
                     str(out), "--method", "iccp", "--drift-radius", "0.035", *extra]) == 0
        r = json.loads(out.read_text())
        rot[bound] = r["rotation_deg"]
        assert r["max_rotation_deg"] == (90.0 if bound is None else float(bound))
        lib = match_track(grid, cols["lat"], cols["lon"], cols["gravity"], method="iccp",
                          drift_radius_m=0.035 * DEG_ARC_M,
                          max_rotation_deg=r["max_rotation_deg"], warn=False)
        np.testing.assert_allclose(r["lat"], np.asarray(lib.lat), rtol=0, atol=1e-12)
        np.testing.assert_allclose(r["rotation_deg"], float(lib.rotation_deg), atol=1e-12)
    assert rot["0"] == 0.0
    assert abs(rot["0.5"]) <= 0.5 + 1e-9
    assert abs(rot[None]) > 0.5  # the bound is what held it, not the data


@pytest.mark.parametrize(("args", "message"), [
    (["--method", "iccp", "--max-rotation", "-1"], "--max-rotation must be the INS heading"),
    (["--method", "iccp", "--max-rotation", "200"], "between 0 and 180; got 200.0"),
    (["--method", "entropy+iccp", "--max-rotation", "nan"], "--max-rotation must be"),
    (["--method", "dense", "--max-rotation", "2"], "no effect with --method dense"),
    (["--method", "entropy", "--max-rotation", "2"], "no effect with --method entropy"),
    (["--method", "iccp", "--drift-radius", "0"], "--drift-radius must be a positive"),
    (["--method", "iccp", "--drift-radius", "-0.03"], "got -0.03"),
    (["--method", "iccp", "--noise", "-1"], "--noise must be a finite standard deviation"),
    (["--method", "entropy", "--entropy-half-size", "0"], "--entropy-half-size must be"),
    (["--method", "iccp", "--entropy-half-size", "5"], "no effect with --method iccp"),
    (["--refine", "0"], "--refine must be an integer factor >= 1; got 0"),
])
def test_match_bad_options_get_clear_errors(track, tmp_path, capsys, args, message):
    code = main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"),
                 "--out", str(tmp_path / "r.json"), *args])
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and err.startswith("jaxgrav match: error: ")
    assert not (tmp_path / "r.json").exists()


def test_match_help_documents_paper_b_options(capsys):
    # in-process (test_console_script_help runs the ``python -m jaxgrav.cli`` entry point)
    with pytest.raises(SystemExit) as exit_info:
        main(["match", "--help"])
    assert exit_info.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for option in ("--max-rotation DEG", "--entropy-half-size N", "--drift-radius"):
        assert option in text
    assert "heading error" in text


@pytest.mark.long
def test_match_map_error_options_and_result_fields(track, tmp_path, capsys):
    out = tmp_path / "gls.json"
    assert main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"), "--out", str(out),
                 "--map-error", "3", "--map-error-length", "10000"]) == 0
    r = json.loads(out.read_text())
    cov = np.asarray(r["covariance_m2"])
    assert cov.shape == (2, 2) and isinstance(r["accepted"], bool)
    assert r["sigma_north_m"] == pytest.approx(np.sqrt(cov[0, 0]))
    assert r["sigma_east_m"] == pytest.approx(np.sqrt(cov[1, 1]))
    for k in ("n_effective", "second_mode_ratio", "edge_mass", "chi2_per_dof"):
        assert k in r
    white = tmp_path / "white.json"
    assert main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"),
                 "--out", str(white)]) == 0
    assert json.loads(white.read_text())["accepted"] is True
    for opt, val in (("--map-error", "-1"), ("--map-error", "nan"),
                     ("--map-error-length", "0"), ("--map-error-length", "inf")):
        code = main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"),
                     "--out", str(tmp_path / "bad.json"), opt, val])
        assert code == 2
        assert opt in capsys.readouterr().err


@pytest.mark.parametrize("method", ["chains", "entropy+iccp"])
@pytest.mark.long
def test_match_map_error_with_chains_and_entropy_iccp(track, tmp_path, method):
    out = tmp_path / "gls.json"
    assert main(["match", "--map", "ryukyu", "--track", str(track / "t.csv"), "--out", str(out),
                 "--method", method, "--map-error", "3", "--map-error-length", "10000"]) == 0
    r = json.loads(out.read_text())
    cov = np.asarray(r["covariance_m2"])
    assert cov.shape == (2, 2) and isinstance(r["accepted"], bool)
    assert np.all(np.isfinite(cov)) and cov[0, 1] == cov[1, 0] and np.linalg.det(cov) > 0
    assert r["sigma_north_m"] == pytest.approx(np.sqrt(cov[0, 0]))
    assert r["sigma_east_m"] == pytest.approx(np.sqrt(cov[1, 1]))
