"""``jaxgrav montecarlo`` and ``jaxgrav bench``, in-process through ``jaxgrav.cli.main``."""

import argparse
import json
import os
import textwrap
from pathlib import Path

import jax
import numpy as np
import pytest
import xarray as xr

import jaxgrav
from jaxgrav import Grid, montecarlo
from jaxgrav.cli import bench, main
from jaxgrav.cli.bench import default_bench_dir
from jaxgrav.cli.montecarlo import format_summary, summarize
from jaxgrav.cli.montecarlo_options import check_options
from jaxgrav.montecarlo import methods as montecarlo_methods
from jaxgrav.sim import DEG_ARC_M

slow = pytest.mark.skipif(
    os.environ.get("JAXGRAV_SLOW") != "1", reason="slow: set JAXGRAV_SLOW=1 to run"
)


def _every_variable_described(ds):
    """CF ``units`` and ``long_name`` on every per-run variable of a Monte Carlo file."""
    bare = [v for v in ds.data_vars if not {"units", "long_name"} <= set(ds[v].attrs)]
    assert not bare, f"variables without units/long_name: {bare}"


@pytest.fixture(scope="module")
def mc_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("mc") / "corr.nc"
    code = main(["montecarlo", "--method", "dense", "--runs", "8", "--chunk", "4",
                 "--seed", "3", "--fixes", "20", "--drift", "0.03", "--out", str(out),
                 "--no-progress"])
    return code, out


@pytest.mark.long
def test_montecarlo_writes_netcdf_png_and_summary(mc_run, capsys):
    code, out = mc_run
    assert code == 0
    assert out.with_suffix(".png").stat().st_size > 10_000
    with xr.open_dataset(out) as ds:
        assert ds.sizes["run"] == 8
        for k in montecarlo_methods.METRICS:
            assert ds[k].dims == ("run",)
        assert ds["status"].dtype == np.int32
        assert np.all(ds["ins_err_m"] > 0) and np.all(np.isfinite(ds["err_m"]))
        a = ds.attrs
        assert (a["method"], a["runs"], a["seed"], a["chunk"]) == ("dense", 8, 3, 4)
        assert a["setting_n_fixes"] == 20 and a["setting_drift_deg"] == 0.03
        assert 0 <= a["summary_failure_rate"] <= 1
        assert a["summary_err_m_p50"] == pytest.approx(float(np.median(ds["err_m"])))
        assert a["summary_worse_rate"] == pytest.approx(  # the printed "worse than the INS"
            float(np.mean(ds["err_m"] > ds["ins_err_m"] * (1 + 1e-9))))
        assert "--runs 8 --chunk 4" in a["command"]
        _every_variable_described(ds)
        # each run's draws: where its true track starts and the INS offset there
        assert np.all((ds["start_lat"] >= 24) & (ds["start_lat"] <= 36))
        assert np.all(np.hypot(ds["ins_offset_north_m"], ds["ins_offset_east_m"]) > 0)
        assert json.loads(a["status_bits"])["8"].startswith("the best candidate")
        # fix metrics with units; a perfect map: the white-noise matcher, not told
        assert ds["accepted"].dtype == bool and ds["accepted"].attrs["units"] == "1"
        assert ds["sigma_max_m"].attrs["units"] == "m" and "95 %" in ds["covered95"].attrs[
            "long_name"]
        assert a["setting_told_map_error_sigma"] == 0.0 and a["summary_accepted_rate"] == 1.0
        # the same keys through the library give the same numbers
        spec = montecarlo_methods.build("dense", drift_deg=0.03, n_fixes=20)
        lib = montecarlo.run(spec.fn, jax.random.key(3), 8, chunk=4, args=spec.args,
                             progress=False)
        np.testing.assert_array_equal(ds["err_m"].values, lib["err_m"])


@pytest.mark.long
def test_montecarlo_prints_summary_table(tmp_path, capsys):
    out = tmp_path / "again.nc"  # compiled already: same shapes as mc_run
    assert main(["montecarlo", "--method", "dense", "--runs", "8", "--chunk", "4",
                 "--seed", "3", "--fixes", "20", "--drift", "0.03", "--out", str(out)]) == 0
    cap = capsys.readouterr()
    assert "8/8" in cap.err and "runs/s" in cap.err  # the progress bar
    for text in ("INS error (m)", "error / INS", "median", "p95", "failure rate",
                 "runs/s", f"wrote {out}"):
        assert text in cap.out


def test_montecarlo_method_correlation_is_dense(mc_run, tmp_path, capsys, monkeypatch):
    """The deprecated name still runs (same shapes as mc_run: compiled already), notes
    the new name on stderr and records it."""
    monkeypatch.setattr(montecarlo_methods, "WARNED_ALIASES", set())
    out = tmp_path / "old.nc"
    with pytest.warns(DeprecationWarning, match="'correlation' is deprecated"):
        assert main(["montecarlo", "--method", "correlation", "--runs", "8", "--chunk", "4",
                     "--seed", "3", "--fixes", "20", "--drift", "0.03", "--out", str(out),
                     "--no-progress"]) == 0
    assert "--method correlation is deprecated; use --method dense" in capsys.readouterr().err
    with xr.open_dataset(out) as ds, xr.open_dataset(mc_run[1]) as ref:
        assert ds.attrs["method"] == "dense" and "--method dense" in ds.attrs["command"]
        np.testing.assert_array_equal(ds["err_m"].values, ref["err_m"].values)


def test_montecarlo_help_lists_the_methods_without_the_old_name(capsys):
    with pytest.raises(SystemExit):
        main(["montecarlo", "--help"])
    text = capsys.readouterr().out
    assert "{chains,dense,ekf," in text and "correlation," not in text
    # --drift says what it is for the voyage methods (it named matchers and filters only)
    drift = " ".join(text.split("--drift DRIFT")[-1].split("--noise")[0].split())
    assert ("voyage-*: initial position error (size; default 0.0045 = 500 m), not the INS "
            "drift over the hours (that is --ins)") in drift, drift


def test_montecarlo_refuses_to_overwrite(mc_run, capsys):
    _, out = mc_run
    args = ["montecarlo", "--method", "dense", "--runs", "8", "--out", str(out)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert (f"--out {str(out)!r} and the PNG next to --out {str(out.with_suffix('.png'))!r} "
            "exist; pass --force to overwrite them") in err, err  # not a list


@pytest.mark.parametrize("args, match", [
    (["--runs", "0"], "--runs must be a positive number of runs; got 0"),
    (["--runs", "8", "--chunk", "0"], "--chunk must be a positive number of runs; got 0"),
    (["--runs", "80", "--devices", "64"], "devices=64 but JAX sees 1 device"),
    (["--runs", "1", "--devices", "3"], "--devices 3 is more than --runs 1: each device takes "
     "whole runs, so the extra devices would only compute copies that are dropped; give "
     "--devices at most 1 (or more --runs)"),
    (["--runs", "8", "--devices", "0"], "--devices must be at least 1; got 0"),
    (["--runs", "8", "--noise", "-1"], "--noise must be a finite standard deviation >= 0"),
    (["--runs", "8", "--noise", "nan"], "--noise must be a finite standard deviation >= 0"),
    (["--runs", "8", "--drift", "0"], "--drift must be a finite positive angle"),
    (["--runs", "8", "--drift", "inf"], "--drift must be a finite positive angle"),
    (["--runs", "8", "--fixes", "2"], "--fixes must be at least 5 per track"),
])
def test_montecarlo_bad_input(tmp_path, capsys, args, match):
    jax.devices()  # JAX runs already (else --devices 64 would split the host into 64)
    code = main(["montecarlo", "--method", "dense", *args, "--out",
                 str(tmp_path / "x.nc")])
    assert code == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "x.nc").exists()


def test_montecarlo_devices_and_runs(capsys):
    """Issue 19: ``--devices 3 --runs 1`` ran silently (two devices computed dropped
    copies): refused above (test_montecarlo_bad_input). A ``--chunk`` that is not a
    multiple of ``--devices`` is rounded up by the runner: one warning line, no refusal."""
    def args(**kw):
        base = dict(method="dense", runs=7, chunk=None, seed=0, devices=None, drift=None,
                    noise=None, fixes=None)
        return argparse.Namespace(**{**base, **kw})
    check_options(args(devices=3, chunk=4))
    err = capsys.readouterr().err
    assert err == ("jaxgrav montecarlo: warning: --chunk 4 is not a multiple of --devices 3: "
                   "each compiled call holds 6 runs (and their memory), not 4; give a --chunk "
                   "that is a multiple of --devices\n"), err
    for ok in (args(devices=3, chunk=6), args(devices=3), args(devices=7, chunk=8),
               args(devices=None, chunk=4)):
        check_options(ok)
        assert capsys.readouterr().err == ""
    with pytest.raises(ValueError, match="--devices 8 is more than --runs 7"):
        check_options(args(devices=8))


@pytest.mark.long
def test_montecarlo_filter_summary_uses_no_harm_bound(tmp_path, capsys):
    out = tmp_path / "ukf.nc"
    assert main(["montecarlo", "--method", "ekf", "--runs", "4", "--chunk", "2", "--fixes",
                 "40", "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "paper D's point masses" in text and "position NEES" in text
    assert "failure rate (error > 1.05 x INS or not finite)" in text
    with xr.open_dataset(out) as ds:
        a = ds.attrs
        assert a["map"] == "paper-d" and a["summary_failure_ratio"] == 1.05
        assert a["summary_nees_mean"] == pytest.approx(float(ds["nees"].mean()))
        ratio = ds["err_m"].values / ds["ins_err_m"].values
        assert a["summary_failure_rate"] == pytest.approx(float(np.mean(ratio > 1.05)))
        _every_variable_described(ds)
        assert np.all(np.isfinite(ds["start_lat"])) and np.all(np.isfinite(ds["start_lon"]))
        # the block test of the innovations, per run and summarised
        assert a["summary_implausible_rate"] == float(np.mean(ds["implausible_blocks"] > 0))


@pytest.mark.long
def test_montecarlo_filter_on_a_map(tmp_path, capsys):
    """--map for a filter: straight tracks in random directions inside the map."""
    out = tmp_path / "ekf_map.nc"
    assert main(["montecarlo", "--method", "ekf", "--runs", "2", "--chunk", "2", "--fixes",
                 "31", "--map", "ryukyu", "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "map ryukyu" in text and "position NEES" in text
    with xr.open_dataset(out) as ds:
        a = ds.attrs
        assert a["map"] == "ryukyu" and a["setting_geometry"] == "random"
        # starts 5 m/s x 300 s + 3 x 2 km + 10 km inside the 24-36 N map (hand computed)
        s, n = (float(v) for v in a["setting_region"].split(",")[:2])
        assert s == pytest.approx(24 + 17.5e3 / DEG_ARC_M, abs=1e-4)
        assert n == pytest.approx(36 - 17.5e3 / DEG_ARC_M, abs=1e-4)
        assert np.all((ds["ins_err_m"] > 1500) & (ds["ins_err_m"] < 2500))  # 2 km, 5 min
        assert np.all(np.isfinite(ds["err_m"])) and np.all(ds["err_m"] < 2 * ds["ins_err_m"])
        assert np.all(np.isfinite(ds["nees"]))
        assert not np.any(ds["status"].values & 2)  # no reading fell off the map


def test_montecarlo_filter_map_too_small(tmp_path, capsys):
    lat, lon = np.linspace(30.0, 30.2, 11), np.linspace(130.0, 130.2, 11)
    small = Grid.from_arrays(lat, lon, np.add.outer(lat, lon), name="g", units="mGal")
    small.to_netcdf(tmp_path / "small.nc")
    code = main(["montecarlo", "--method", "ukf", "--runs", "2", "--map",
                 str(tmp_path / "small.nc"), "--out", str(tmp_path / "x.nc")])
    assert code == 2
    err = capsys.readouterr().err
    assert "(lat 30..30.2, lon 130..130.2) is too small for the filter runs" in err
    assert "52 km inside it" in err  # default 2 h: 36 km track + 3 x 2 km + 10 km


@pytest.mark.parametrize("method, fixes, drift", [("chains", 12, 0.02), ("entropy", 20, 0.03),
                                                  ("iccp", 20, 0.03)])
@pytest.mark.long
def test_montecarlo_more_matchers(tmp_path, capsys, method, fixes, drift):
    """Paper A's chains and paper B's stages alone, two runs each through the command."""
    out = tmp_path / f"{method}.nc"
    assert main(["montecarlo", "--method", method, "--runs", "2", "--chunk", "2", "--seed",
                 "1", "--fixes", str(fixes), "--drift", str(drift), "--out", str(out),
                 "--no-progress"]) == 0
    text = capsys.readouterr().out
    for t in ("INS error (m)", "error / INS", "failure rate (error > INS/3", f"wrote {out}"):
        assert t in text
    with xr.open_dataset(out) as ds:
        a = ds.attrs
        assert ds.sizes["run"] == 2 and a["method"] == method and a["setting_n_fixes"] == fixes
        assert ds["status"].dtype == np.int32 and np.all(np.isfinite(ds["err_m"]))
        ins, err = ds["ins_err_m"].values, ds["err_m"].values
        assert a["summary_err_m_p50"] == pytest.approx(float(np.median(err)))
        assert a["summary_ratio_mean"] == pytest.approx(float(np.mean(err / ins)))
        d = drift * DEG_ARC_M
        _every_variable_described(ds)
        if method == "chains":  # fixed drift; the map refined 2.5' / 0.005 deg = x8
            assert a["setting_refine_factor"] == 8 and "chains" in a["setting_description"]
            np.testing.assert_allclose(ins, d, rtol=1e-6)
            np.testing.assert_allclose(np.hypot(ds["ins_offset_north_m"],
                                                ds["ins_offset_east_m"]), d, rtol=1e-3)
            assert "work_constrained" in ds
        else:  # offset in [2/3, 1] x drift; a 1.5 deg turn about the start moves the
            # fixes of the 11.4 km track by 150 m on average
            assert np.all((ins > 2 / 3 * d - 160) & (ins < d + 160))
            assert "rotation_deg" in ds
            if method == "entropy":  # the coarse stage only shifts
                np.testing.assert_array_equal(ds["rotation_deg"], 0.0)
            else:
                assert np.all(np.abs(ds["rotation_deg"]) <= 90.0)


def test_summarize_failure_bounds():
    res = dict(ins_err_m=np.array([300.0, 300, 300]), err_m=np.array([90.0, 150, 310]),
               status=np.zeros(3, np.int32))
    assert summarize(res)["failure_rate"] == pytest.approx(2 / 3)  # > INS/3: 150 and 310
    assert summarize(res, "filter")["failure_rate"] == pytest.approx(0.0)  # none > 315
    with pytest.raises(ValueError, match="kind must be one of"):
        summarize(res, "smoother")


def test_summary_says_what_it_leaves_out_and_what_a_voyage_flags():
    res = dict(ins_err_m=np.array([300.0, 300, 300]), err_m=np.array([90.0, np.nan, 310]),
               status=np.zeros(3, np.int32), nees=np.array([2.0, np.inf, 1.5]))
    s = summarize(res, "filter")
    assert (s["nonfinite"], s["nees_nonfinite"]) == (1, 1)
    assert s["nees"]["mean"] == pytest.approx(1.75)  # finite runs only, as said below
    assert ("runs left out of the statistics above: 1 without a finite error (failures), "
            "1 without a finite NEES") in format_summary(s)
    assert "left out" not in format_summary(summarize(dict(res, err_m=np.full(3, 90.0),
                                                           nees=np.ones(3)), "filter"))
    # a loosely coupled voyage: bit 0 of its status is the "accepted" fix event
    loose = dict(res, err_m=np.full(3, 90.0), status=np.array([1, 1 | 8, 2]),
                 fix_event=np.zeros((3, 2), np.int32))
    assert summarize(loose, "voyage")["flagged_rate"] == pytest.approx(2 / 3)
    tight = {k: v for k, v in loose.items() if k != "fix_event"}  # filter flags: all count
    assert summarize(tight, "voyage")["flagged_rate"] == 1.0


def test_summary_says_how_many_failed_runs_the_innovations_announce():
    res = dict(ins_err_m=np.full(5, 300.0), err_m=np.array([90.0, 400, 500, 90, np.nan]),
               status=np.zeros(5, np.int32), nees=np.full(5, 2.0),
               implausible_blocks=np.array([0, 3, 0, 1, 2]))
    s = summarize(res, "filter")  # failed: 400, 500 and the non-finite one
    assert s["implausible_rate"] == pytest.approx(3 / 5)
    assert s["implausible_failed_rate"] == pytest.approx(2 / 3)
    assert ("innovations implausible (a block of 60 readings fails chi-square, p < 1e-3; a "
            "consistent filter fails one block in 1000): 60.0 % of runs, 67 % of the 3 "
            "failed runs") in format_summary(s)
    none_failed = summarize(dict(res, err_m=np.full(5, 90.0)), "filter")
    assert np.isnan(none_failed["implausible_failed_rate"])
    assert format_summary(none_failed).endswith("60.0 % of runs")
    assert "innovations" not in format_summary(summarize(
        {k: v for k, v in res.items() if k != "implausible_blocks"}, "filter"))


def test_summary_names_each_flag_raised_and_its_share():
    """"status flagged: 100 %" alone hid that a flag may only inform (entropy+ICCP's 128:
    the coarse fix kept) while another rejects: each bit is named with its share."""
    from jaxgrav.match.result import STATUS

    res = dict(ins_err_m=np.full(4, 300.0), err_m=np.full(4, 90.0),
               status=np.array([128, 128 | 512, 128, 128 | 131072], np.int32))
    s = summarize(res)
    assert s["flagged_rate"] == 1.0
    assert s["status_rates"] == {"128": 1.0, "512": 0.25, "131072": 0.25}
    text = format_summary(s, STATUS)
    line = next(r for r in text.splitlines() if r.startswith("  flags raised"))
    assert ("128 entropy+ICCP: the ICCP result did not fit significantly better than the "
            "coarse match 100.0 %") in line
    assert "512 fix rejected: the posterior of the offset is too wide 25.0 %" in line
    assert "131072 fix rejected: not shown better than the INS track 25.0 %" in line
    assert "flags raised" not in format_summary(summarize(dict(res, status=np.zeros(4))))
    assert "512 25.0 %" in format_summary(s)  # no meanings given: the bits alone


@slow
def test_montecarlo_entropy_iccp(tmp_path):
    out = tmp_path / "b.nc"
    assert main(["montecarlo", "--method", "entropy+iccp", "--runs", "6", "--chunk", "3",
                 "--out", str(out), "--no-progress"]) == 0
    with xr.open_dataset(out) as ds:
        assert ds.sizes["run"] == 6 and "rotation_deg" in ds
        assert np.median(ds["err_m"]) < np.median(ds["ins_err_m"])


# --------------------------------------------------------------------------- bench
_GOOD = """
import json, sys
quick = "--quick" in sys.argv
print("warming up")
for n in (10, 100):
    print(json.dumps({"bench": "fake", "case": "quick" if quick else "full", "n": n,
                      "jaxgrav_s": 0.5, "baseline": "numpy", "baseline_s": 2.0, "ratio": 4.0,
                      "machine": "x", "note": "a|b"}))
"""
_BAD = """
import sys
print('{"bench": "half", "case": "before the crash", "n": 1, "jaxgrav_s": 1, '
      '"baseline": "b", "baseline_s": 1, "ratio": 1.0}')
print("Traceback: something broke", file=sys.stderr)
sys.exit(3)
"""


@pytest.fixture
def bench_dir(tmp_path):
    d = tmp_path / "benchmarks"
    d.mkdir()
    (d / "good.py").write_text(textwrap.dedent(_GOOD))
    (d / "_common.py").write_text("raise SystemExit('helpers are not benchmarks')\n")
    return d


def test_bench_quick_writes_table(bench_dir, tmp_path, capsys):
    out = tmp_path / "bench.md"
    assert main(["bench", "--quick", "--dir", str(bench_dir), "--out", str(out)]) == 0
    md = out.read_text()
    assert "Command: `jaxgrav bench --quick`" in md
    assert "| good.py | fake | quick | 10 | 0.5 | numpy | 2 | 4 | note=a\\|b |" in md
    assert "| good.py | ok |" in md and "_common" not in md
    raw = md.split("```jsonl\n")[1].split("```")[0].splitlines()
    assert [json.loads(r)["n"] for r in raw] == [10, 100]
    # the machine the ratios were measured on, with its measured roofline
    assert "## Machine" in md and "load average (1, 5, 15 min)" in md and "jax " in md
    machine = json.loads(md.split("```json\n")[1].split("```")[0])
    assert machine["cores"] >= 1 and len(machine["load_average"]) == 3 and machine["devices"]
    assert machine["roofline"]["float64_gflops"] > 0 and machine["roofline"]["float32_gflops"] > 0
    assert "wrote" in capsys.readouterr().out
    assert main(["bench", "--dir", str(bench_dir), "--out", str(out)]) == 2  # no --force
    assert main(["bench", "--dir", str(bench_dir), "--out", str(out), "--force"]) == 0
    assert "| fake | full |" in out.read_text()


def test_bench_reports_failed_scripts(bench_dir, tmp_path, capsys):
    (bench_dir / "bad.py").write_text(textwrap.dedent(_BAD))
    out = tmp_path / "bench.md"
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--quick", "--dir", str(bench_dir), "--out", str(out)])
    assert exc.value.code == 1
    md = out.read_text()
    assert "| bad.py | FAILED (exit code 3) |" in md
    assert "### bad.py: exit code 3" in md and "Traceback: something broke" in md
    assert "| bad.py | half | before the crash |" in md  # its lines are kept
    assert "| good.py | fake | quick | 100 |" in md
    err = capsys.readouterr().err
    assert "bad.py failed (exit code 3)" in err and "something broke" in err


def test_bench_bad_dir(tmp_path, capsys):
    assert main(["bench", "--dir", str(tmp_path / "nope"), "--out", str(tmp_path / "b.md")]) == 2
    assert "is not a folder of benchmark scripts" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["bench", "--dir", str(tmp_path / "empty"), "--out",
                 str(tmp_path / "b.md")]) == 2
    assert "has no benchmark scripts" in capsys.readouterr().err


def test_bench_default_dir_is_cwd_benchmarks(bench_dir, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # holds benchmarks/ (the fake scripts)
    assert main(["bench", "--quick", "--out", "b.md"]) == 0
    assert "| good.py | ok |" in (tmp_path / "b.md").read_text()


def test_bench_default_dir_falls_back_to_the_repository(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no benchmarks/ here
    repo = Path(__file__).resolve().parents[2] / "benchmarks"  # this checkout's
    assert default_bench_dir().resolve() == repo and (repo / "montecarlo_scaling.py").exists()


def test_bench_default_dir_missing_names_both(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    site = tmp_path / "site-packages"
    monkeypatch.setattr(jaxgrav, "__file__", str(site / "jaxgrav" / "__init__.py"))
    assert main(["bench", "--quick", "--out", str(tmp_path / "b.md")]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "benchmarks") in err and str(site / "benchmarks") in err
    assert "pass --dir" in err and not (tmp_path / "b.md").exists()


@pytest.mark.long
def test_montecarlo_map_error_setting_in_summary_and_attributes(tmp_path, capsys):
    out = tmp_path / "me.nc"
    assert main(["montecarlo", "--method", "dense", "--runs", "4", "--chunk", "4", "--fixes",
                 "12", "--map-error", "3", "--map-error-length", "8000", "--out", str(out),
                 "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "readings: map error 3 (map units), L = 8 km" in text
    with xr.open_dataset(out) as ds:
        a = ds.attrs
        assert (a["map_error_sigma"], a["map_error_length_m"]) == (3.0, 8000.0)
        assert (a["setting_map_error_sigma"], a["setting_map_error_length_m"]) == (3.0, 8000.0)
        assert "--map-error 3.0 --map-error-length 8000.0" in a["command"]
        assert a["map_error_setting"] == "map error 3 (map units), L = 8 km"


@pytest.mark.long
def test_montecarlo_truth_map(tmp_path, capsys):
    out = tmp_path / "tm.nc"
    assert main(["montecarlo", "--method", "dense", "--runs", "2", "--chunk", "2", "--fixes",
                 "12", "--map", "ryukyu:anomaly_0p5deg", "--truth-map", "ryukyu", "--out",
                 str(out), "--no-progress"]) == 0
    assert "readings: truth map ryukyu" in capsys.readouterr().out
    with xr.open_dataset(out) as ds:
        assert ds.attrs["truth_map"] == "ryukyu" and ds.attrs["map"] == "ryukyu:anomaly_0p5deg"
        assert ds.attrs["setting_truth_map"]


@pytest.mark.parametrize("args, match", [
    (["--map-error", "-2"], "--map-error must be a finite standard deviation >= 0 (map units, "
                            "0 = perfect map); got -2.0"),
    (["--map-error", "1", "--map-error-length", "inf"], "--map-error-length must be a finite"),
    (["--map-error", "1", "--truth-map", "ryukyu"], "exclude each other"),
    (["--method", "ukf", "--map-error", "1"], "--map-error and --truth-map need --map MAP"),
])
def test_montecarlo_bad_map_error(tmp_path, capsys, args, match):
    argv = ["montecarlo", "--runs", "2", *args, "--out", str(tmp_path / "x.nc")]
    if "--method" not in args:
        argv[1:1] = ["--method", "dense"]
    code = main(argv)
    assert code == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "x.nc").exists()


@pytest.mark.parametrize("told, match", [
    ("-1", "--told-map-error SIGMA must be a finite standard deviation >= 0"),
    ("nan", "--told-map-error SIGMA must be a finite"),
    ("inf", "--told-map-error SIGMA must be a finite"),
    ("3,0", "--told-map-error L must be a finite correlation length > 0 (m); got 0.0"),
    ("3,-5", "--told-map-error L must be a finite correlation length > 0"),
    ("3,inf", "--told-map-error L must be a finite correlation length > 0"),
    ("abc", "--told-map-error must be SIGMA or SIGMA,L"),
    ("1,2,3", "--told-map-error must be SIGMA or SIGMA,L"),
])
def test_montecarlo_told_map_error_bad_input(tmp_path, capsys, told, match):
    code = main(["montecarlo", "--method", "dense", "--runs", "2", "--map-error", "3",
                 "--told-map-error", told, "--out", str(tmp_path / "x.nc")])
    assert code == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "x.nc").exists()


def test_montecarlo_told_map_error_parsing(tmp_path, capsys):
    import argparse

    from jaxgrav.cli.montecarlo_options import told_from_args

    def told(text, length=None):
        return told_from_args(argparse.Namespace(told_map_error=text, map_error_length=length))

    assert told(None) == "auto" and told("0") is None and told("0,0") is None
    m = told("2.5")
    assert (float(m.sigma), float(m.length_m)) == (2.5, 10000.0)
    m = told("2.5", 7000.0)
    assert float(m.length_m) == 7000.0
    m = told("4,3000")
    assert (float(m.sigma), float(m.length_m)) == (4.0, 3000.0)
    code = main(["montecarlo", "--method", "entropy", "--runs", "2", "--told-map-error", "3",
                 "--out", str(tmp_path / "c.nc")])
    assert code == 2
    assert ("--told-map-error is used by the filters and --method dense, chains, "
            "entropy+iccp only; got --method entropy") in capsys.readouterr().err
    code = main(["montecarlo", "--method", "ukf", "--map", "ryukyu", "--runs", "2",
                 "--map-error", "3", "--told-map-error", "3", "--out", str(tmp_path / "u.nc")])
    assert code == 2
    assert "--told-map-error must be one of none, white, state" in capsys.readouterr().err
    code = main(["montecarlo", "--method", "dense", "--runs", "2", "--map-error-order", "2",
                 "--out", str(tmp_path / "d.nc")])
    assert code == 2
    assert "--map-error-order is a filter option" in capsys.readouterr().err


_EMITS = f"""
import sys
sys.path.insert(0, {str(Path(__file__).resolve().parents[2] / "benchmarks")!r})
from _common import emit
emit("real", "the shipped emit", 3, 0.1, "numpy", 0.2, extra=1)
"""


def test_bench_script_without_result_line_fails(tmp_path, capsys, quick_machine_info):
    """Issue 19: a script exiting 0 with no JSON line was 'ok', and any JSON line with a
    "bench" key was a result; now only lines with emit's fields count, and a script
    with none fails, named."""
    d = tmp_path / "b"
    d.mkdir()
    (d / "emits.py").write_text(_EMITS)
    (d / "profile.py").write_text("print('{\"bench\": \"p_profile\", \"part\": \"x\"}')\n")
    (d / "silent.py").write_text("print('done')\n")
    out = tmp_path / "bench.md"
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--dir", str(d), "--out", str(out)])
    assert exc.value.code == 1
    err = capsys.readouterr().err
    for script in ("profile.py", "silent.py"):
        assert f"jaxgrav bench: {script} failed (exit code 0 but no result line: no JSON " \
               "line with bench, case, n, jaxgrav_s, baseline, baseline_s, ratio" in err, err
    assert "emits.py failed" not in err and "1 JSON line(s) without them" in err
    md = out.read_text()
    assert "| emits.py | real | the shipped emit | 3 | 0.1 | numpy | 0.2 | 2 |" in md
    assert "| emits.py | ok |" in md and "| silent.py | FAILED (exit code 0" in md
    assert "| profile.py | p_profile" not in md  # not a result row ...
    assert '{"script": "profile.py", "bench": "p_profile", "part": "x"}' in md  # ... kept aside
    assert not bench.is_result({"bench": "x", "case": "c", "n": 1, "jaxgrav_s": "fast",
                                "baseline": "b", "baseline_s": None, "ratio": None})
