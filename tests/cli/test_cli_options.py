"""Bad options of match, sample, filter, navigate, montecarlo and bench: one line on stderr
naming the option, the value and what was expected, exit code 2, in CLI syntax, before
anything is computed and with no output left behind."""

import json
import re

import numpy as np
import pytest

from jaxgrav._io import atomic_output, check_outputs
from jaxgrav.cli import main
from jaxgrav.cli.montecarlo_options import BYTES_PER_FIX
from jaxgrav.cli.navigate import nis_warning
from jaxgrav.tracks import read_track_csv, write_track_csv


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """A 20-fix simulated track on the shipped map, and one copy of it with an edited
    drift_radius column per bad value."""
    d = tmp_path_factory.mktemp("options")
    assert main(["simulate", "--out", str(d / "t.csv"), "--n", "20", "--seed", "5"]) == 0
    track = read_track_csv(d / "t.csv", required=("t", "lat", "lon", "gravity"))
    for name, value in (("neg", -1.0), ("zero", 0.0)):
        write_track_csv(d / f"dr_{name}.csv",
                        {**track.columns(), "drift_radius": np.full(20, value)})
    (d / "bare.csv").write_text("t,lat,lon\n0,28,130\n10,28,130.01\n")  # no readings
    return d


def _refused(capsys, argv, message, leftovers=()):
    """``argv`` exits 2 with one line holding ``message``, in CLI syntax, no traceback,
    and none of ``leftovers`` (nor a temporary file next to them) is written."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err, err
    assert "\n" not in err and "Traceback" not in err, err
    for library in ("=True", "np.", "_m ", "window_cells", "margin_m"):
        assert library not in err, err
    for path in leftovers:
        assert not path.is_file(), path
        assert not [p for p in path.parent.iterdir() if p.name.startswith(f".{path.name}.")]
    return err


# ------------------------------------------------------------------- match and sample
@pytest.mark.parametrize("args, message", [
    # 1. the added column: not one of the track's (any case), not empty
    (["sample", "--column", "lat"], "--column 'lat' is the name of a column of --track"),
    (["sample", "--column", "GRAVITY"], "--column 'GRAVITY' is the name of a column"),
    (["sample", "--column", ""], "--column must be a non-empty column name; got ''"),
    (["sample", "--column", "  "], "--column must be a non-empty column name; got '  '"),
    # 2. the bias prior: > 0 (0 left no candidate), of dense and chains only
    (["match", "--bias-sigma", "0"], "--bias-sigma must be a standard deviation > 0"),
    (["match", "--bias-sigma", "-1"], "--bias-sigma must be a standard deviation > 0"),
    (["match", "--bias-sigma", "nan"], "got nan"),
    (["match", "--bias-sigma", "2", "--method", "entropy"],
     "--bias-sigma is the bias prior of --method dense and chains; --method entropy"),
    # 6. no reading noise: infinite weights, a chi-squared of 1e306
    (["match", "--noise", "0"], "--noise must be a finite standard deviation > 0"),
])
def test_match_and_sample_options(sim, tmp_path, capsys, args, message):
    out = tmp_path / ("r.json" if args[0] == "match" else "s.csv")
    _refused(capsys, [args[0], "--map", "ryukyu", "--track", str(sim / "t.csv"),
                      "--out", str(out), *args[1:]], message, [out])


@pytest.mark.parametrize("track, message", [
    ("dr_neg.csv", "line 2, column 'drift_radius': drift radius -1 is not a positive angle"),
    ("dr_zero.csv", "drift radius 0 is not a positive angle in degrees of arc (20 such row"),
])
def test_match_drift_radius_column(sim, tmp_path, capsys, track, message):
    """5. the track's drift_radius column is checked as the option is (it said margin_m)."""
    out = tmp_path / "r.json"
    err = _refused(capsys, ["match", "--map", "ryukyu", "--track", str(sim / track),
                            "--out", str(out)], message, [out])
    assert "--drift-radius" in err


def test_match_bias_sigma_small_and_inf_run(sim, tmp_path):
    """A bias known to be near zero (0.01 mGal) and a free one (inf) still match."""
    for value in ("0.01", "inf"):
        out = tmp_path / f"r{value}.json"
        assert main(["match", "--map", "ryukyu", "--track", str(sim / "t.csv"),
                     "--out", str(out), "--bias-sigma", value]) == 0
        assert out.is_file()


# ----------------------------------------------------- 3. output targets, checked first
def _montecarlo(out):
    return ["montecarlo", "--method", "dense", "--runs", "2", "--out", str(out),
            "--no-progress", "--force"]


@pytest.mark.parametrize("command, message", [
    (lambda d, o: ["match", "--map", "ryukyu", "--track", str(d / "t.csv"), "--out", str(o)],
     "--out '{o}' is a folder; expected a file path"),
    (lambda d, o: ["sample", "--map", "ryukyu", "--track", str(d / "t.csv"), "--out", str(o),
                   "--force"], "--out '{o}' is a folder"),
    (lambda d, o: ["filter", "--point-masses", "paper-d", "--track", str(d / "t.csv"),
                   "--out", str(o), "--force"], "--out '{o}' is a folder"),
    (lambda d, o: ["navigate", "--track", str(d / "t.csv"), "--out", str(o), "--force"],
     "--out '{o}' is a folder"),
    (lambda d, o: _montecarlo(o), "--out '{o}' is a folder"),
    (lambda d, o: ["bench", "--dir", str(o.parent / "benchmarks"), "--out", str(o),
                   "--force"], "--out '{o}' is a folder"),
])
def test_out_is_a_folder(sim, tmp_path, capsys, command, message):
    out = tmp_path / "out.x"
    out.mkdir()
    (tmp_path / "benchmarks").mkdir()  # for bench: one script, refused before it runs
    (tmp_path / "benchmarks" / "b.py").write_text("raise SystemExit(3)\n")
    _refused(capsys, command(sim, out), message.format(o=out))
    assert out.is_dir() and not list(out.iterdir())


def test_montecarlo_png_folder_refused_before_the_runs(tmp_path, capsys):
    """The PNG next to --out was written last and failed after the runs, leaving the
    NetCDF behind."""
    (tmp_path / "mc.png").mkdir()
    _refused(capsys, _montecarlo(tmp_path / "mc.nc"),
             f"the PNG next to --out '{tmp_path / 'mc.png'}' is a folder", [tmp_path / "mc.nc"])


@pytest.mark.parametrize("command", ["match", "sample", "filter"])
def test_out_may_not_be_the_input(sim, tmp_path, capsys, command):
    """--out naming the --track file would replace the input, --force or not."""
    track = tmp_path / "t.csv"
    track.write_bytes((sim / "t.csv").read_bytes())
    source = ["--point-masses", "paper-d"] if command == "filter" else ["--map", "ryukyu"]
    _refused(capsys, [command, *source, "--track", str(track), "--out", str(track), "--force"],
             f"--out '{track}' and the input --track '{track}' are the same file")
    assert track.read_bytes() == (sim / "t.csv").read_bytes()


def test_existing_out_names_the_cli_option(sim, tmp_path, capsys):
    """5. no 'pass force=True': the command's own --force is named."""
    for command, out in (("match", tmp_path / "r.json"), ("sample", tmp_path / "s.csv")):
        out.write_text("keep me\n")
        _refused(capsys, [command, "--map", "ryukyu", "--track", str(sim / "t.csv"),
                          "--out", str(out)], "exists; pass --force to overwrite it")
        assert out.read_text() == "keep me\n"


# ----------------------------------------------------------------- filter, navigate
@pytest.mark.parametrize("argv, message", [
    (["filter", "--point-masses", "paper-d", "--method", "rbpf", "--particles", "2"],
     "--particles must be an integer >= 100"),
    (["filter", "--point-masses", "paper-d", "--method", "pf", "--particles", "99"],
     "--particles must be an integer >= 100 (fewer cannot represent the position's "
     "posterior); got 99"),
    (["navigate", "--method", "rbpf", "--particles", "2"], "--particles must be an integer >= 100"),
    (["navigate", "--method", "ukf", "--particles", "600"],
     "--particles is for --method rbpf; got --method ukf"),
])
def test_particle_options(sim, tmp_path, capsys, argv, message):
    out = tmp_path / "f.csv"
    _refused(capsys, [*argv, "--track", str(sim / "t.csv"), "--out", str(out)], message, [out])


@pytest.mark.parametrize("argv, message", [
    # --missing is the point-mass filter's reading of missing map nodes: refused, not
    # ignored, with any other method, in the same words by filter and navigate
    (["filter", "--point-masses", "paper-d", "--method", "ukf", "--missing", "gaps"],
     "--missing gaps is for --method pmf; got --method ukf"),
    (["filter", "--map", "ryukyu", "--method", "pf", "--missing", "land"],
     "--missing land is for --method pmf; got --method pf"),
    (["filter", "--map", "ryukyu", "--method", "rbpf", "--ins", "navigation", "--missing",
      "land"], "--missing land is for --method pmf; got --method rbpf"),
    (["navigate", "--method", "ekf", "--missing", "gaps"],
     "--missing gaps is for --method pmf; got --method ekf"),
    (["navigate", "--method", "entropy+iccp", "--missing", "land"],
     "--missing land is for --method pmf; got --method entropy+iccp"),
    (["navigate", "--method", "ukf", "--ins", "strategic", "--missing", "land"],
     "--missing land is for --method pmf; got --method ukf"),
])
def test_missing_option_with_another_method(sim, tmp_path, capsys, argv, message):
    out = tmp_path / "f.csv"
    _refused(capsys, [*argv, "--track", str(sim / "t.csv"), "--out", str(out)], message, [out])


CHOICES = {"--ins": "'navigation', 'strategic'", "--missing": "'gaps', 'land'"}


@pytest.mark.parametrize("argv, option, value", [
    (["filter", "--point-masses", "paper-d", "--ins", "tactical"], "--ins", "tactical"),
    (["filter", "--point-masses", "paper-d", "--ins", "Navigation"], "--ins", "Navigation"),
    (["filter", "--point-masses", "paper-d", "--ins", ""], "--ins", ""),
    (["navigate", "--ins", "tactical"], "--ins", "tactical"),
    (["navigate", "--ins", "STRATEGIC"], "--ins", "STRATEGIC"),
    (["filter", "--map", "ryukyu", "--method", "pmf", "--missing", "sea"], "--missing", "sea"),
    (["filter", "--map", "ryukyu", "--method", "pmf", "--missing", "Land"], "--missing",
     "Land"),
    (["filter", "--map", "ryukyu", "--method", "pmf", "--missing", "auto"], "--missing",
     "auto"),  # match's --missing auto is not the point-mass filter's
    (["navigate", "--method", "pmf", "--missing", "sea"], "--missing", "sea"),
    (["navigate", "--method", "pmf", "--missing", "auto"], "--missing", "auto"),
    (["navigate", "--method", "ukf", "--missing", "nope"], "--missing", "nope"),
])
def test_choice_options_name_the_value_and_the_choices(sim, tmp_path, capsys, argv, option,
                                                       value):
    """A value outside --ins's or --missing's choices: exit 2 and one line on stderr naming
    the option, the value and the choices (argparse's usage block left out); nothing
    written."""
    out = tmp_path / "f.csv"
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--track", str(sim / "t.csv"), "--out", str(out)])
    assert exc.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [f"jaxgrav {argv[0]}: error: argument {option}: invalid choice: "
                     f"{value!r} (choose from {CHOICES[option]}) (see jaxgrav {argv[0]} "
                     "--help)"], lines
    assert not out.exists()


def test_navigate_warns_of_loose_options_with_a_tight_method(sim, tmp_path, capsys):
    """6. --fix-every, --n-fixes, --stride set the loosely coupled fixes: named in one
    warning line with --method ukf (the run then stops at the log with no readings)."""
    out = tmp_path / "n.csv"
    assert main(["navigate", "--track", str(sim / "bare.csv"), "--out", str(out),
                 "--fix-every", "6", "--n-fixes", "10"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 2 and lines[0].startswith("warning: --fix-every, --n-fixes set the "
                                                   "fixes of the loosely coupled methods")
    assert "--method ukf uses every reading and ignores them" in lines[0]
    assert not out.exists()
    assert main(["navigate", "--track", str(sim / "bare.csv"), "--out", str(out),
                 "--method", "dense", "--fix-every", "6"]) == 2
    assert "warning" not in capsys.readouterr().err


def test_navigate_nis_warning_names_noise():
    """4. the innovation check's advice names navigate's --noise, not --sigma-gravity."""
    rng = np.random.default_rng(0)
    warning = nis_warning(3.0 * rng.standard_normal(200), np.ones(200))
    assert "a larger --noise" in warning and "--sigma-gravity" not in warning
    assert nis_warning(rng.standard_normal(200), np.ones(200)) is None


def test_filter_help_lists_the_guarded_methods(capsys):
    """7. --guard works with ukf, ekf, gsf, pf and rbpf (pmf refuses it)."""
    with pytest.raises(SystemExit):
        main(["filter", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "no-harm guard (ukf, ekf, gsf, pf, rbpf; not pmf)" in text


# ---------------------------------------------------------------- montecarlo, bench
@pytest.mark.parametrize("args, message", [
    (["--method", "dense", "--noise", "-1"],
     "--noise must be a finite standard deviation >= 0 (mGal) for --method dense"),
    (["--method", "ukf", "--noise", "0"],
     "--noise must be a finite standard deviation > 0 (mGal) for --method ukf"),
    (["--method", "dense", "--drift", "10"],
     "--drift 10 degrees of arc (1112 km, the search radius) spans 20 degrees, more than the "
     "map"),
    (["--method", "ukf", "--drift", "1"], "more than paper D's match area"),
    (["--method", "voyage-ukf", "--drift", "10"], "the initial position error"),
    (["--method", "dense", "--fixes", "100000000"], "use --fixes"),
    (["--method", "dense", "--fixes", "1000000", "--runs", "300"], "GB for --method dense"),
    (["--method", "ukf", "--runs", "100000", "--chunk", "100000", "--fixes", "100000"],
     "--fixes 100000 with 100000 runs per compiled call (--chunk) needs about"),
])
def test_montecarlo_options(tmp_path, capsys, args, message):
    out = tmp_path / "mc.nc"
    argv = ["montecarlo", "--runs", "2", "--out", str(out), "--no-progress", *args]
    _refused(capsys, argv, message, [out, tmp_path / "mc.png"])


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf"])
def test_bench_timeout(tmp_path, capsys, value):
    out = tmp_path / "b.md"
    _refused(capsys, ["bench", "--timeout", value, "--dir", str(tmp_path), "--out", str(out)],
             "--timeout must be a finite number of seconds > 0 per script; got", [out])


# ------------------------------------------------------------------------------ dov
@pytest.fixture(scope="module")
def dov_track(tmp_path_factory):
    """Two points over the shipped qinling layers: 5 km and 50 km up."""
    d = tmp_path_factory.mktemp("dov")
    write_track_csv(d / "d.csv", {"lat": [36.5, 36.6], "lon": [109.5, 109.6],
                                  "h": [5000.0, 50000.0]})
    return d / "d.csv"


@pytest.mark.parametrize("layers, message", [
    ("0", "--layers needs at least 2 heights; got '0'"),
    ("a,b", "--layers must be comma-separated heights in m; got 'a,b'"),
    ("0;10000", "--layers must be comma-separated heights in m; got '0;10000'"),
    ("10000,0", "--layers 10000,0: heights must be strictly ascending (m); got 10000, 0"),
    ("0,10000,10000", "--layers 0,10000,10000: heights must be strictly ascending"),
    ("0,nan,20000", "--layers 0,nan,20000: heights must be finite numbers (m)"),
    ("0,inf", "--layers 0,inf: heights must be finite numbers (m)"),
    # issue 19 (helper-56): a lost height was dropped and the rest used (exit 0)
    ("0,,20000", "--layers '0,,20000': item 2 is empty; expected comma-separated heights in "
                 "m, e.g. 0,10000,20000"),
    # the synthesis's "h must be > -radius = -6378136.3 m; got -1000000000.0": no option
    ("-1e9,0,20000", "--layers -1e9,0,20000: heights must be between -11000 m (the deepest "
                     "ocean floor) and 100000 m (the edge of space), in m above the "
                     "ellipsoid; got -1e+09"),
])
def test_dov_layers_values(dov_track, tmp_path, capsys, layers, message):
    out = tmp_path / "d.csv"
    _refused(capsys, ["dov", "--track", str(dov_track), "--out", str(out), "--layers", layers],
             message, [out])


@pytest.mark.parametrize("layers, method, warned", [
    # 10-100 km: k*gap 3.2 over the 50 km point, beyond the trusted 2
    ("0,10000,100000", "bicubic-harmonic", "1 between 10000 and 100000 m (k*gap = 3.2)"),
    ("0,10000,100000", "bilinear-harmonic", "1 between 10000 and 100000 m (k*gap = 3.2)"),
    ("0,10000,60000", "bicubic-harmonic", None),  # k*gap 1.75: trusted
    ("0,10000,100000", "bicubic-linear", None),  # no vertical continuation to warn of
    (None, "bicubic-harmonic", None),  # the shipped 0, 10, 20 km (50 km is refused there)
])
def test_dov_layers_gap_warning(dov_track, tmp_path, capsys, layers, method, warned):
    """dov --layers with a gap too wide for the harmonic continuation: exit 0, the output
    written, one warning naming the gap and asking for closer --layers (not a --grid)."""
    out = tmp_path / "d.csv"
    track = dov_track
    if layers is None:  # the shipped layers end at 20 km: the low point only
        track = tmp_path / "low.csv"
        write_track_csv(track, {"lat": [36.5], "lon": [109.5], "h": [5000.0]})
    argv = ["dov", "--track", str(track), "--out", str(out), "--method", method]
    assert main([*argv, *(["--layers", layers] if layers else [])]) == 0
    err = capsys.readouterr().err.strip()
    assert out.is_file()
    if warned is None:
        assert err == "", err
        return
    assert err.count("\n") == 0 and err.startswith("warning: track points lie in layer gaps "
                                                   f"too wide for {method}'s"), err
    assert warned in err and "--method bicubic-linear" in err and "--grid" not in err
    assert re.search(r"use --layers at most about 5\d{4} m apart", err), err


# -------------------------------------------------------------------- 8. line ends
def test_csv_outputs_end_lines_with_lf(sim, tmp_path):
    out = tmp_path / "s.csv"
    assert main(["sample", "--map", "ryukyu", "--track", str(sim / "t.csv"),
                 "--out", str(out), "--column", "faa"]) == 0
    data = out.read_bytes()
    assert b"\r" not in data and data.count(b"\n") == 21
    assert data.splitlines()[0].endswith(b",faa")


def test_atomic_output_and_check_outputs_refuse_folders_and_inputs(tmp_path):
    """The shared helpers: a folder is never a target, --force or not; an output that is
    an input file is refused; an input name that is no file (a shipped map) is not."""
    with pytest.raises(ValueError, match="is a folder; expected a file path"):
        with atomic_output(tmp_path, force=True):
            pass
    (tmp_path / "in.csv").write_text("t\n")
    with pytest.raises(ValueError, match=r"and the input --track .* are the same file"):
        check_outputs([tmp_path / "in.csv"], force=True, names=["--out"],
                      inputs={"--track": tmp_path / "in.csv"})
    check_outputs([tmp_path / "ryukyu"], names=["--out"], inputs={"--map": "ryukyu"})


@pytest.mark.long
def test_montecarlo_matchers_take_noiseless_readings_and_default_sizes(tmp_path, capsys):
    """Paper A's noiseless readings run (the matchers weight by at least 0.1 mGal), and
    the memory estimate of a run measured at 1.43 GB peak (dense, --fixes 500, chunks of
    114: 0.53 GB over the one-run baseline) is within 2.5 x of it, not 20 x as before."""
    out = tmp_path / "mc.nc"
    assert main(["montecarlo", "--method", "dense", "--runs", "2", "--noise", "0", "--out",
                 str(out), "--no-progress", "--fixes", "10"]) == 0, capsys.readouterr().err
    assert 0.53e9 <= BYTES_PER_FIX["dense"] * 500 * 114 <= 2.5 * 0.53e9


def test_map_units_must_match_the_readings_field(sim, tmp_path, capsys):
    """A magnetic map (nT) with gravity readings is refused by name (it ran as mGal with
    an Eötvös correction); a file with both gravity and magnetic columns is matched on
    the one the map's units name (it was matched on the magnetic column)."""
    xr = pytest.importorskip("xarray")
    from jaxgrav import datasets

    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    xr.Dataset({"f": (("lat", "lon"), np.asarray(grid.values), {"units": "nT"})},
               coords={"lat": np.asarray(grid.lat), "lon": np.asarray(grid.lon)}).to_netcdf(
        tmp_path / "mag.nc")
    for cmd in (["match"], ["filter", "--method", "ukf"]):
        out = tmp_path / "o.out"
        assert main([*cmd, "--map", str(tmp_path / "mag.nc"), "--track", str(sim / "t.csv"),
                     "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "is a magnetic map (units 'nT') and the readings are gravity" in err, err
        assert not out.exists()
    track = read_track_csv(sim / "t.csv", required=("t", "lat", "lon", "gravity"))
    both = tmp_path / "both.csv"
    write_track_csv(both, {**track.columns(), "magnetic": 40000.0 + np.arange(20.0)})
    out = tmp_path / "m.json"
    assert main(["match", "--map", "ryukyu", "--track", str(both), "--out", str(out)]) == 0
    assert json.loads(out.read_text())["field"] == "gravity"


@pytest.mark.parametrize("cmd", [["filter", "--method", "pf", "--map", "ryukyu"],
                                 ["navigate", "--method", "rbpf"]])
def test_seed_beyond_int64_is_refused(sim, tmp_path, capsys, cmd):
    """2**63 ended in an OverflowError traceback (exit 1) in jax.random.PRNGKey."""
    out = tmp_path / "o.csv"
    assert main([*cmd, "--track", str(sim / "t.csv"), "--seed", str(2**63),
                 "--out", str(out)]) == 2
    assert "--seed must be an integer from 0 to 9223372036854775807" in capsys.readouterr().err
    assert not out.exists()


def test_a_large_gravimeter_offset_is_named_in_the_fit_warning(sim, tmp_path, capsys):
    """+250 mGal on raw readings (the bias prior is 3 mGal with velocities): the warning
    blamed the noise or the map error only; it now names the fitted bias and the option."""
    track = read_track_csv(sim / "t.csv", required=("t", "lat", "lon", "gravity"))
    biased = tmp_path / "b.csv"
    write_track_csv(biased, {**track.columns(), "gravity": track["gravity"] + 250.0})
    out = tmp_path / "m.json"
    assert main(["match", "--map", "ryukyu", "--track", str(biased), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "sigma of the bias prior (3 mGal): a gravimeter offset? give --bias-sigma inf" in err
