"""``jaxgrav simulate-filter`` and ``jaxgrav filter`` end to end, in-process through ``main``.

Tracks are tiny (20 min at 10 s, a reading every row) and every command runs in this
process, so each filter compiles once per module: ukf, pmf on point masses, ekf on a
NetCDF map; gsf (one more compilation) runs with ``JAXGRAV_SLOW=1``.
"""

import contextlib
import os
import re

import jax
import numpy as np
import pytest
import xarray as xr

import jaxgrav as jg
from jaxgrav.cli import main
from jaxgrav.constants import DEG
from jaxgrav.fields.pointmass import gravity_anomaly, paper_d
from jaxgrav.fields.pointmass_fit import save_point_masses
from jaxgrav.filters import STATUS_FILTER, filter_track
from jaxgrav.geodesy import eotvos, meridian_radius, prime_vertical_radius
from jaxgrav.sim.ins import INSErrorModel
from jaxgrav.tracks import read_track_csv, write_track_csv

OUT_COLUMNS = ["t", "lat", "lon", "sigma_north", "sigma_east", "cov_north_east", "v_east",
               "v_north", "v_north_error", "v_east_error", "sigma_v_north", "sigma_v_east",
               "gravimeter_bias", "sigma_gravimeter_bias", "innovation", "innovation_sigma",
               "status"]
slow = pytest.mark.skipif(
    os.environ.get("JAXGRAV_SLOW") != "1", reason="slow: set JAXGRAV_SLOW=1 to run"
)


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    d = tmp_path_factory.mktemp("filter")
    assert main(["simulate-filter", "--out", str(d / "track.csv"), "--truth",
                 str(d / "truth.csv"), "--minutes", "20", "--dt", "10", "--reading-every", "1",
                 "--geometry", "east-west", "--seed", "0"]) == 0
    return d


def _rms_error_m(lat, lon, truth):
    dn = (lat - truth["lat"]) * DEG * np.asarray(meridian_radius(truth["lat"]))
    de = ((lon - truth["lon"]) * DEG * np.asarray(prime_vertical_radius(truth["lat"]))
          * np.cos(truth["lat"] * DEG))
    half = truth["lat"].size // 2
    return float(np.sqrt(np.mean(dn[half:] ** 2 + de[half:] ** 2)))


def _filter(track, out, *extra, source=("--point-masses", "paper-d")):
    return main(["filter", *source, "--track", str(track), "--out", str(out), *extra])


@pytest.mark.long
def test_simulate_filter_writes_track_and_truth(sim):
    track = read_track_csv(sim / "track.csv")
    truth = read_track_csv(sim / "truth.csv")
    assert list(track) == ["t", "lat", "lon", "v_east", "v_north", "gravity"]
    assert list(truth) == ["t", "lat", "lon", "v_east", "v_north"]
    assert track["t"].size == truth["t"].size == 121
    np.testing.assert_allclose(np.diff(track["t"]), 10.0)
    assert np.isfinite(track["gravity"]).all()
    assert np.all(np.abs(truth["v_north"]) < 1e-9) and np.allclose(np.abs(truth["v_east"]), 5)
    # the INS starts 2 km off the truth (paper D)
    dn = (track["lat"][0] - truth["lat"][0]) * DEG * float(meridian_radius(truth["lat"][0]))
    de = ((track["lon"][0] - truth["lon"][0]) * DEG * np.cos(truth["lat"][0] * DEG)
          * float(prime_vertical_radius(truth["lat"][0])))
    assert np.hypot(dn, de) == pytest.approx(2000.0, rel=1e-6)


@pytest.mark.long
def test_ukf_beats_the_ins_on_an_east_west_track(sim, tmp_path, capsys):
    out = tmp_path / "ukf.csv"
    assert _filter(sim / "track.csv", out, "--method", "ukf") == 0
    cap = capsys.readouterr()
    assert f"wrote {out}: ukf over 121 rows (121 readings)" in cap.out
    # the one Eötvös rule: raw readings with velocities, corrected here, the error modelled
    assert "readings Eötvös-corrected here with the INS velocity, its error in the filter" in (
        cap.out)
    assert cap.err == ""  # no status warnings on a clean run
    res = read_track_csv(out)
    track = read_track_csv(sim / "track.csv")
    truth = read_track_csv(sim / "truth.csv")
    assert list(res) == OUT_COLUMNS
    np.testing.assert_array_equal(res["t"], track["t"])
    ins = _rms_error_m(track["lat"], track["lon"], truth)
    err = _rms_error_m(res["lat"], res["lon"], truth)
    assert err < 0.7 * ins, (err, ins)
    # 1-σ shrinks from the prior (1414 m per axis) and is honest to a factor of 3
    assert np.all(res["sigma_north"][-10:] < 1000) and np.all(res["sigma_east"] <= 1415)
    assert err < 3 * np.hypot(res["sigma_north"][-1], res["sigma_east"][-1])
    # the rest of the state: the corrected velocity is nearer the truth than the INS's,
    # the position covariance is a valid 2 x 2, innovations are whitened to ~1, status 0
    dv_ins = np.hypot(track["v_east"] - truth["v_east"], track["v_north"] - truth["v_north"])
    dv_out = np.hypot(res["v_east"] - truth["v_east"], res["v_north"] - truth["v_north"])
    assert np.sqrt(np.mean(dv_out[-30:] ** 2)) < np.sqrt(np.mean(dv_ins[-30:] ** 2))
    np.testing.assert_allclose(res["v_east"], track["v_east"] - res["v_east_error"], atol=1e-9)
    assert np.all(res["cov_north_east"] ** 2 <= (res["sigma_north"] * res["sigma_east"]) ** 2)
    assert np.all(res["sigma_v_north"] > 0) and np.all(res["sigma_gravimeter_bias"] > 0)
    nis = (res["innovation"] / res["innovation_sigma"]) ** 2
    assert np.isfinite(nis).all() and 0.3 < nis.mean() < 3.0, nis.mean()
    assert np.all(res["status"] == 0)


@pytest.mark.long
def test_rbpf_beats_the_ins_reproducibly_and_pf_runs(sim, tmp_path, capsys):
    """The particle filters through the CLI: same columns, honest-ish 1-σ, seeds matter."""
    track, truth = read_track_csv(sim / "track.csv"), read_track_csv(sim / "truth.csv")
    ins = _rms_error_m(track["lat"], track["lon"], truth)
    a, b, c = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    assert _filter(sim / "track.csv", a, "--method", "rbpf", "--particles", "300") == 0
    assert "rbpf over 121 rows (121 readings, 300 particles, seed 0)" in capsys.readouterr().out
    assert _filter(sim / "track.csv", b, "--method", "rbpf", "--particles", "300") == 0
    assert _filter(sim / "track.csv", c, "--method", "rbpf", "--particles", "300",
                   "--seed", "1") == 0
    ra, rb, rc = read_track_csv(a), read_track_csv(b), read_track_csv(c)
    assert list(ra) == OUT_COLUMNS
    np.testing.assert_array_equal(ra["lat"], rb["lat"])  # reproducible
    assert not np.array_equal(ra["lat"], rc["lat"])  # the seed matters
    err = _rms_error_m(ra["lat"], ra["lon"], truth)
    assert err < 0.7 * ins, (err, ins)
    assert err < 3 * np.hypot(ra["sigma_north"][-1], ra["sigma_east"][-1])
    nis = (ra["innovation"] / ra["innovation_sigma"]) ** 2
    assert np.isfinite(nis).all() and 0.3 < nis.mean() < 3.0, nis.mean()
    p = tmp_path / "pf.csv"
    assert _filter(sim / "track.csv", p, "--method", "pf", "--particles", "500") == 0
    res = read_track_csv(p)
    assert np.all(np.isfinite(res["lat"])) and np.all(res["sigma_north"] > 0)
    assert _rms_error_m(res["lat"], res["lon"], truth) < ins


@pytest.mark.long
def test_guard_holds_back_weak_directions(sim, tmp_path, capsys):
    plain, guarded = tmp_path / "ukf.csv", tmp_path / "ukf_guard.csv"
    assert _filter(sim / "track.csv", plain, "--method", "ukf") == 0
    assert _filter(sim / "track.csv", guarded, "--method", "ukf", "--guard") == 0
    assert "no-harm guard 0.2" in capsys.readouterr().out
    res, ref = read_track_csv(guarded), read_track_csv(plain)
    track = read_track_csv(sim / "track.csv")
    # the guard moves the output between the filter and the INS, with a 1-σ between theirs
    for k in ("sigma_north", "sigma_east"):
        assert np.all(res[k] >= ref[k] - 1e-6) and np.all(res[k] <= 1414.2 * 1.5)
    d_filter = np.hypot(ref["lat"] - track["lat"], ref["lon"] - track["lon"])
    d_guard = np.hypot(res["lat"] - track["lat"], res["lon"] - track["lon"])
    assert np.all(d_guard <= d_filter * (1 + 1e-9) + 1e-12)
    # a ratio of 1 (any variance reduction passes) is the filter itself
    one = tmp_path / "ukf_guard1.csv"
    assert _filter(sim / "track.csv", one, "--method", "ukf", "--guard", "1") == 0
    np.testing.assert_allclose(read_track_csv(one)["lat"], ref["lat"], rtol=0, atol=1e-12)


def test_point_mass_model_file(sim, tmp_path, capsys):
    """--point-masses MODEL.json (save_point_masses): paper D's masses with a +5 mGal offset
    on readings carrying that offset give the paper-d run on the original readings."""
    model = tmp_path / "model.json"
    save_point_masses(model, paper_d(), offset=5.0)
    cols = read_track_csv(sim / "track.csv")
    cols["gravity"] = cols["gravity"] + 5.0
    write_track_csv(tmp_path / "shifted.csv", cols, precision=15)
    ref, out = tmp_path / "ref.csv", tmp_path / "model.csv"
    assert _filter(sim / "track.csv", ref) == 0
    assert _filter(tmp_path / "shifted.csv", out, source=("--point-masses", str(model))) == 0
    cap = capsys.readouterr()
    assert f"on point masses {model} (K = 3, offset +5.000 mGal)" in cap.out and cap.err == ""
    a, b = read_track_csv(out), read_track_csv(ref)
    for k in OUT_COLUMNS:
        np.testing.assert_allclose(a[k], b[k], rtol=1e-9, atol=1e-9, err_msg=k)
    # a bad model file: one clear line, no output
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "grid"}')
    for path, message in ((bad, f"model {str(bad)!r} is not a jaxgrav point-mass model (its "
                                '"format" is "grid")'),
                          (tmp_path / "none.json", "none.json': no such file")):
        code = _filter(sim / "track.csv", tmp_path / "o.csv",
                       source=("--point-masses", str(path)))
        err = capsys.readouterr().err
        assert code == 2 and err.startswith("jaxgrav filter: error: ") and err.count("\n") == 1
        assert message in err, err
        assert not (tmp_path / "o.csv").exists()


def _anomaly_map(path, lat, lon):
    """Paper D's point-mass anomaly sampled on a NetCDF grid (mGal)."""
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    values = np.asarray(gravity_anomaly(paper_d(), la, lo))
    jg.Grid.from_arrays(lat, lon, values, units="mGal").to_netcdf(path)
    return path


@pytest.mark.long
def test_ekf_on_a_netcdf_map(sim, tmp_path, capsys):
    nc = _anomaly_map(tmp_path / "pd.nc", np.linspace(23.9, 24.7, 81),
                      np.linspace(122.6, 123.3, 71))
    out = tmp_path / "ekf.csv"
    assert _filter(sim / "track.csv", out, "--method", "ekf", source=("--map", str(nc))) == 0
    assert f"on map {nc}" in capsys.readouterr().out
    res = read_track_csv(out)
    truth = read_track_csv(sim / "truth.csv")
    track = read_track_csv(sim / "track.csv")
    assert list(res) == OUT_COLUMNS and res["t"].size == 121
    assert np.all(res["sigma_north"] > 0) and np.all(res["sigma_east"] > 0)
    assert (_rms_error_m(res["lat"], res["lon"], truth)
            < 0.8 * _rms_error_m(track["lat"], track["lon"], truth))

    # --map-error-var: the map file's own uncertainty, RMS near the track, is the sigma
    with xr.open_dataset(nc) as ds:
        ds = ds.load()
    var = next(iter(ds.data_vars))
    ds["err"] = xr.full_like(ds[var], 2.0)
    ds.to_netcdf(tmp_path / "pd_err.nc")
    src = ("--map", str(tmp_path / "pd_err.nc"), "--var", var)
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert _filter(sim / "track.csv", a, "--map-error-var", "err", source=src) == 0
    assert "map-error state 2 mGal" in capsys.readouterr().out
    assert _filter(sim / "track.csv", b, "--map-error", "2", source=src) == 0
    np.testing.assert_allclose(read_track_csv(a)["lat"], read_track_csv(b)["lat"], rtol=1e-12)
    assert _filter(sim / "track.csv", tmp_path / "c.csv", "--map-error-var", "err") == 2
    assert "needs --map" in capsys.readouterr().err


@slow
def test_gsf_runs(sim, tmp_path):
    out = tmp_path / "gsf.csv"
    assert _filter(sim / "track.csv", out, "--method", "gsf") == 0
    res = read_track_csv(out)
    truth = read_track_csv(sim / "truth.csv")
    track = read_track_csv(sim / "track.csv")
    assert list(res) == OUT_COLUMNS
    assert (_rms_error_m(res["lat"], res["lon"], truth)
            < _rms_error_m(track["lat"], track["lon"], truth))


@pytest.fixture(scope="module")
def stride_track(sim):
    """A reading every 3rd row, Eötvös-corrected with the true velocity (exact), no velocity
    columns: the point-mass filter's tests see readings without an Eötvös error."""
    cols = read_track_csv(sim / "track.csv")
    truth = read_track_csv(sim / "truth.csv")
    exact = cols["gravity"] + np.asarray(eotvos(truth["lat"], truth["v_east"], truth["v_north"]))
    g = np.full_like(cols["gravity"], np.nan)
    g[2::3] = exact[2::3]  # a reading every 3rd row, from row 2
    cols = {k: cols[k] for k in ("t", "lat", "lon")}
    cols["gravity"] = g
    write_track_csv(sim / "stride.csv", cols)
    return sim / "stride.csv"


@pytest.mark.long
def test_pmf_on_a_reading_stride_is_causal(sim, stride_track, tmp_path, capsys):
    cols = read_track_csv(stride_track)
    out = tmp_path / "pmf.csv"
    assert _filter(stride_track, out, "--method", "pmf") == 0
    assert "(40 readings, updates every 3 rows)" in capsys.readouterr().out
    res = read_track_csv(out)
    no_velocity = [c for c in OUT_COLUMNS if c not in ("v_east", "v_north")]
    assert list(res) == no_velocity and res["t"].size == 121
    # rows before the first reading: the prior predicted (zero mean error, σ ≥ the prior's)
    np.testing.assert_allclose(res["lat"][:2], cols["lat"][:2], rtol=0, atol=1e-9)
    assert np.all(res["sigma_north"][:2] >= 1414.2 * (1 - 1e-3))
    # between readings only predictions: σ does not shrink until the next reading
    for a, b in ((2, 4), (5, 7), (116, 118)):
        assert np.all(np.diff(res["sigma_east"][a:b + 1]) >= -1e-3 * res["sigma_east"][a])
    # causal: a changed reading on row 50 leaves rows 0..49 untouched
    cols["gravity"][50] += 5.0
    write_track_csv(tmp_path / "changed.csv", cols)
    assert _filter(tmp_path / "changed.csv", tmp_path / "pmf2.csv", "--method", "pmf") == 0
    res2 = read_track_csv(tmp_path / "pmf2.csv")
    np.testing.assert_array_equal(res2["lat"][:50], res["lat"][:50])
    assert res2["lat"][50] != res["lat"][50]
    cols["gravity"][50] -= 5.0
    truth = read_track_csv(sim / "truth.csv")
    assert (_rms_error_m(res["lat"], res["lon"], truth)
            < _rms_error_m(cols["lat"], cols["lon"], truth))


def test_force_overwrites_and_its_absence_protects(sim, tmp_path, capsys):
    out = tmp_path / "o.csv"
    out.write_text("keep me\n")
    assert _filter(sim / "track.csv", out) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out" in err and "exists; pass --force" in err
    assert out.read_text() == "keep me\n"
    assert _filter(sim / "track.csv", out, "--force") == 0
    assert list(read_track_csv(out)) == OUT_COLUMNS
    # simulate-filter refuses to overwrite either output without --force
    assert main(["simulate-filter", "--out", str(tmp_path / "new.csv"), "--truth", str(out),
                 "--minutes", "20", "--dt", "10", "--reading-every", "1"]) == 2
    assert f"--truth {str(out)!r} exists; pass --force" in capsys.readouterr().err
    assert not (tmp_path / "new.csv").exists()


@pytest.mark.long
def test_pmf_grid_too_small_warns(stride_track, tmp_path, capsys):
    # --sigma-pos 300 m: the grid spans ±1.2 km, the INS is 2 km off
    assert _filter(stride_track, tmp_path / "o.csv", "--method", "pmf",
                   "--sigma-pos", "300") == 0
    err = capsys.readouterr().err
    assert "warning: grid_edge on" in err and "of 121 rows" in err and "--sigma-pos" in err


def _bad(kind, cols):
    if kind == "missing":
        cols.pop("gravity")
    elif kind == "nonuniform":
        cols["t"][7:] += 3.0
    elif kind == "backwards":
        cols["t"][7] = cols["t"][5]
    elif kind == "long gap":  # 100 s
        cols = {k: np.delete(v, np.arange(30, 39)) for k, v in cols.items()}
    elif kind == "no readings":
        cols["gravity"][:] = np.nan
    elif kind == "nan lat":
        cols["lat"][3] = np.nan
    return cols


@pytest.mark.parametrize(("kind", "extra", "message"), [
    ("missing", (), "lacks column gravity; it has "),
    ("nonuniform", (), "column t must have a regular step; a step of 13 s on lines 8-9 (t 60 "
                       "-> 73 s) is not within 10% of the step 10.025 s or a whole number of "
                       "steps (a gap); 1 such step(s)"),
    ("backwards", (), "line 9, column 't': time 50 is earlier than 60 on line 8; times must "
                      "increase"),
    ("long gap", (), "a gap of 100 s on lines 31-32 (t 290 -> 390 s) is longer than --max-gap "
                     "60 s (1 such gap(s)); split the log at the gap, or raise --max-gap"),
    ("ok", ("--max-gap", "0"), "--max-gap must be a finite time > 0 (s); got 0.0"),
    ("no readings", (), "column 'gravity' has no readings (all 121 cells empty or NaN)"),
    ("nan lat", (), "column 'lat' has 1 missing or NaN value(s), first on line 5"),
    ("ok", ("--map", "ryukyu"), "121 of 121 positions are off the map --map ryukyu"),
    ("ok", ("--map", "ryukyu", "--point-masses", "paper-d"),
     "give exactly one of --map MAP.nc and --point-masses paper-d|MODEL.json; got both"),
    ("ok", ("--sigma-pos", "-1"), "--sigma-pos must be a positive, finite standard deviation"),
    ("ok", ("--sigma-gravity", "nan"), "--sigma-gravity must be a positive"),
    ("ok", ("--method", "pmf", "--guard"),
     "--guard applies to ukf, ekf, gsf, pf and rbpf; got --method pmf"),
    ("ok", ("--method", "ukf", "--particles", "100"),
     "--particles is for --method pf or rbpf; got --method ukf"),
    ("ok", ("--method", "rbpf", "--particles", "1"), "--particles must be an integer >= 100"),
    ("ok", ("--guard", "-0.5"), "--guard must be a positive variance ratio"),
    ("ok", ("--method", "ukf", "--missing", "land"),
     "--missing land is for --method pmf; got --method ukf"),
    ("ok", ("--map-error", "-1"), "--map-error must be a finite map-error sigma >= 0 (mGal); "
                                  "got -1.0"),
    ("ok", ("--map-error", "nan"), "--map-error must be a finite map-error sigma >= 0"),
    ("ok", ("--map-error", "1", "--map-error-length", "0"),
     "--map-error-length must be a finite correlation length > 0 (m); got 0.0"),
])
def test_bad_input_gets_one_clear_line(sim, tmp_path, capsys, kind, extra, message):
    cols = _bad(kind, read_track_csv(sim / "track.csv"))
    write_track_csv(tmp_path / "bad.csv", cols)
    source = () if "--map" in extra else ("--point-masses", "paper-d")
    code = main(["filter", *source, "--track", str(tmp_path / "bad.csv"),
                 "--out", str(tmp_path / "o.csv"), *extra])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("jaxgrav filter: error: ") and err.count("\n") == 1
    assert message in err
    assert not (tmp_path / "o.csv").exists()


def test_neither_map_nor_point_masses(sim, tmp_path, capsys):
    code = main(["filter", "--track", str(sim / "track.csv"), "--out", str(tmp_path / "o.csv")])
    assert code == 2
    assert ("give exactly one of --map MAP.nc and --point-masses paper-d|MODEL.json; got "
            "neither") in capsys.readouterr().err


@contextlib.contextmanager
def _traces():
    """Names of the functions JAX traces to a jaxpr inside the block (jax.monitoring)."""
    names = []

    def listener(event, duration, **kwargs):
        if event == "/jax/core/compile/jaxpr_trace_duration":
            names.append(kwargs.get("fun_name"))

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield names
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def test_a_second_run_with_new_values_does_not_retrace(sim, stride_track, tmp_path):
    """filter_track's and simulate-filter's jitted runners are module functions: a second
    call with the same shapes (new values, another INS model) traces nothing."""
    with _traces() as names:
        jax.jit(lambda x: x + 1.0)(1.0)
    assert names == ["<lambda>"]  # the counter sees a trace
    sim_args = ["simulate-filter", "--minutes", "20", "--dt", "10", "--reading-every", "1",
                "--geometry", "east-west"]
    runs = [
        (_filter, (sim / "track.csv", tmp_path / "a.csv", "--method", "ukf"),
         (sim / "track.csv", tmp_path / "b.csv", "--method", "ukf", "--guard", "0.5",
          "--ins", "navigation")),
        (_filter, (stride_track, tmp_path / "c.csv", "--method", "pmf"),
         (stride_track, tmp_path / "d.csv", "--method", "pmf", "--sigma-pos", "1500")),
        (main, ([*sim_args, "--out", str(tmp_path / "e.csv"), "--seed", "3"],),
         ([*sim_args, "--out", str(tmp_path / "f.csv"), "--seed", "4"],)),
    ]
    for fn, first, second in runs:
        assert fn(*first) == 0
        with _traces() as names:
            assert fn(*second) == 0
        assert names == [], (second, names)


@pytest.mark.long
def test_map_error_on_a_map_end_to_end(tmp_path, capsys):
    """simulate-filter --map with a 3 mGal map error; filter --map-error adds the FOGM state,
    which widens the filter's 1-sigma (it no longer trusts the map to 1 mGal)."""
    d = tmp_path
    assert main(["simulate-filter", "--map", "ryukyu", "--map-error", "3",
                 "--map-error-length", "10000", "--out", str(d / "t.csv"), "--truth",
                 str(d / "truth.csv"), "--minutes", "20", "--dt", "10", "--reading-every", "1",
                 "--seed", "1"]) == 0
    assert "map error 3 mGal, L 10000 m" in capsys.readouterr().out
    base = ["filter", "--map", "ryukyu", "--track", str(d / "t.csv")]
    assert main([*base, "--out", str(d / "o0.csv")]) == 0
    assert main([*base, "--out", str(d / "o1.csv"), "--map-error", "3",
                 "--map-error-length", "20000"]) == 0
    out = capsys.readouterr().out
    assert "map-error state 3 mGal over 20000 m" in out
    o0, o1 = read_track_csv(d / "o0.csv"), read_track_csv(d / "o1.csv")
    assert np.all(np.isfinite(o1["lat"])) and np.all(o1["sigma_north"] > 0)
    assert o1["sigma_north"][-1] > o0["sigma_north"][-1]
    # the second-order state (the simulated error's own model)
    assert main([*base, "--out", str(d / "o3.csv"), "--map-error", "3",
                 "--map-error-length", "10000", "--map-error-order", "2"]) == 0
    assert "map-error state 3 mGal over 10000 m, second order" in capsys.readouterr().out
    o3 = read_track_csv(d / "o3.csv")
    assert np.all(np.isfinite(o3["lat"])) and o3["sigma_north"][-1] > o0["sigma_north"][-1]
    # 0 is today's filter, bit for bit
    assert main([*base, "--out", str(d / "o2.csv"), "--map-error", "0"]) == 0
    o2 = read_track_csv(d / "o2.csv")
    np.testing.assert_array_equal(o2["lat"], o0["lat"])


def test_simulate_filter_map_error_needs_a_map(tmp_path, capsys):
    code = main(["simulate-filter", "--out", str(tmp_path / "t.csv"), "--map-error", "2"])
    assert code == 2
    assert "--map-error needs --map" in capsys.readouterr().err


@pytest.mark.long
def test_eotvos_corrected_needs_the_velocity_columns(stride_track, tmp_path, capsys):
    out = tmp_path / "o.csv"
    assert _filter(stride_track, out, "--eotvos-corrected") == 2
    err = capsys.readouterr().err
    assert "--eotvos-corrected needs the INS velocity columns v_east, v_north" in err
    assert not out.exists()
    assert _filter(stride_track, out) == 0
    assert "no velocity columns: gravity taken as Eötvös-corrected" in capsys.readouterr().out


def test_ins_option_names_the_model(sim, tmp_path, capsys):
    """--ins: the filter's INS error model, named on the summary line; strategic (paper D's,
    the default) and navigation grade (simulate-voyage's INS, whose larger biases the filter
    must be told or its 1-sigma is over-confident)."""
    a, b = tmp_path / "s.csv", tmp_path / "n.csv"
    assert _filter(sim / "track.csv", a) == 0
    assert "strategic INS (0.001 deg/h gyro, 10 ug accelerometer biases)" in (
        capsys.readouterr().out)
    assert _filter(sim / "track.csv", b, "--ins", "navigation") == 0
    assert "navigation INS (0.01 deg/h gyro, 25 ug accelerometer biases)" in (
        capsys.readouterr().out)
    strategic, navigation = read_track_csv(a), read_track_csv(b)
    # the worse INS drifts more between readings: the filter trusts its prediction less
    assert navigation["sigma_north"][-1] > strategic["sigma_north"][-1]
    assert navigation["sigma_v_east"][-1] > strategic["sigma_v_east"][-1]


def test_a_track_far_from_the_masses_is_warned_of(sim, tmp_path, capsys):
    """600 km north of paper D's masses the model is flat: no reading can tell the position,
    and the filter said nothing (its output is the INS's). The clean track is not warned."""
    cols = read_track_csv(sim / "track.csv").columns()
    cols["lat"] = cols["lat"] + 5.4
    cols["gravity"] = np.random.default_rng(0).normal(0.0, 1.0, cols["lat"].size)
    write_track_csv(tmp_path / "far.csv", cols)
    assert _filter(tmp_path / "far.csv", tmp_path / "f.csv", "--eotvos-corrected") == 0
    err = capsys.readouterr().err
    assert "the map along the track cannot tell the position" in err
    assert "more than the filter's own 1-sigma" in err, err
    assert _filter(sim / "track.csv", tmp_path / "n.csv", "--eotvos-corrected") == 0
    assert "cannot tell the position" not in capsys.readouterr().err


def test_readings_offset_from_the_map_are_warned_of(sim, tmp_path, capsys):
    """+250 mGal (an untied gravimeter) passed the readings' checks (below their 300 mGal
    floor) and the filter moved the position to explain it, blamed on the noise."""
    cols = read_track_csv(sim / "track.csv").columns()
    cols["gravity"] = cols["gravity"] + 250.0
    write_track_csv(tmp_path / "b.csv", cols)
    assert _filter(tmp_path / "b.csv", tmp_path / "f.csv") == 0
    err = capsys.readouterr().err
    assert re.search(r"the readings sit \+2\d\d mGal from the map along the INS track", err)
    assert "subtract the offset from the gravity column" in err, err
    assert _filter(sim / "track.csv", tmp_path / "n.csv") == 0
    assert "the readings sit" not in capsys.readouterr().err


@pytest.mark.parametrize("shift, north, extra, offset, flat", [
    (0.0, 0.0, ("--ins", "navigation"), None, False),  # the clean track, either grade
    (0.0, 0.0, ("--ins", "strategic"), None, False),
    (15.0, 0.0, (), None, False),  # below the 25 mGal floor (a wrong INS position differs)
    (-15.0, 0.0, ("--ins", "navigation"), None, False),
    (40.0, 0.0, (), r"\+4\d", False),
    (-250.0, 0.0, ("--ins", "navigation"), r"-2\d\d", False),
    (250.0, 0.0, ("--ins", "strategic"), r"\+2\d\d", False),
    (None, 5.4, ("--ins", "navigation", "--eotvos-corrected"), None, True),  # 600 km north
    (None, 5.4, ("--ins", "strategic", "--eotvos-corrected"), None, True),
])
def test_offset_and_information_warnings(sim, tmp_path, capsys, check_filter_warnings, shift,
                                         north, extra, offset, flat):
    """filter_checks' warnings in filter, with either --ins grade: readings offset beyond
    what the gravimeter-bias state allows (floor 25 mGal) and a map too flat to tell the
    position, each one stderr line (the run still exits 0 and writes its track); none for
    the clean track or an offset within the floor. The ukf compiles once for all rows."""
    cols = read_track_csv(sim / "track.csv").columns()
    cols["lat"] = cols["lat"] + north
    cols["gravity"] = (np.random.default_rng(0).normal(0.0, 1.0, cols["lat"].size)
                       if shift is None else cols["gravity"] + shift)
    write_track_csv(tmp_path / "t.csv", cols)
    out = tmp_path / "f.csv"
    assert _filter(tmp_path / "t.csv", out, *extra) == 0
    lines = capsys.readouterr().err.splitlines()
    assert out.is_file()
    check_filter_warnings(lines, offset, flat)


@pytest.mark.long  # the fixture simulates a log
def test_pmf_missing_gaps_or_land_without_missing_nodes(stride_track, tmp_path, capsys):
    """filter --method pmf --missing gaps|land over paper D's point masses is refused: a
    point-mass field has no map nodes, so the option changed nothing (it was accepted, and
    both runs agreed); the refusal's text is tested in tests/cli/test_cli_inputs_hunt5.py."""
    for m in ("gaps", "land"):
        assert _filter(stride_track, tmp_path / f"{m}.csv", "--method", "pmf", "--missing",
                       m) == 2
        assert "is a field with no nodes: leave --missing out" in capsys.readouterr().err
        assert not (tmp_path / f"{m}.csv").exists()


@pytest.mark.long
def test_pmf_summary_names_how_missing_nodes_were_read(stride_track, tmp_path, capsys):
    """filter --method pmf on a map with a missing node near the track: the summary says
    how it was read (as navigate's does); the map without it says nothing of the kind."""
    lat, lon = np.linspace(23.9, 24.7, 81), np.linspace(122.6, 123.3, 71)
    nc = _anomaly_map(tmp_path / "pd.nc", lat, lon)
    with xr.open_dataset(nc) as ds:
        ds = ds.load()
    var = next(iter(ds.data_vars))
    track = read_track_csv(stride_track)
    i = int(np.searchsorted(lat, track["lat"].max() + 0.03))
    j = int(np.searchsorted(lon, np.median(track["lon"])))
    ds[var][i, j] = np.nan  # one node ~3 km north of the track
    ds.to_netcdf(tmp_path / "hole.nc")
    for path, said in ((nc, False), (tmp_path / "hole.nc", True)):
        assert _filter(stride_track, tmp_path / "o.csv", "--method", "pmf", "--missing",
                       "land", "--force", source=("--map", str(path))) == 0
        out = capsys.readouterr().out
        assert ("missing map nodes read as land" in out) == said, out


def test_filter_track_refuses_a_bad_ins_model():
    t = np.arange(3) * 10.0
    args = (paper_d(), t, np.full(3, 30.0), np.full(3, 130.0), np.zeros(3))
    with pytest.raises(TypeError, match=r"ins must be an INSErrorModel .*; got dict"):
        filter_track(*args, ins={"gyro_sigma": 1e-8})
    with pytest.raises(ValueError, match=r"ins.accel_sigma must be a finite number >= 0; "
                                         r"got -1.0"):
        filter_track(*args, ins=INSErrorModel(accel_sigma=-1.0))
    with pytest.raises(ValueError, match=r"ins.gyro_tau must be > 0 \(s; inf: a random "
                                         r"constant\); got 0.0"):
        filter_track(*args, ins=INSErrorModel(gyro_tau=0.0))


@pytest.mark.long
def test_a_track_mostly_at_rest_then_moving_with_a_map_error(sim, tmp_path, capsys):
    """At rest for twice as long as it then moves: the median speed was 0, so the map-error
    state's time constant L / speed was infinite; the second-order state's prior, diag(s^2,
    (speed / L)^2 s^2), was singular, and every row needed a covariance repair. The mean
    speed (as navigate's tight filter) keeps it regular."""
    cols = read_track_csv(sim / "track.csv")
    k = 2 * cols["t"].size
    first = {c: float(v[0]) for c, v in cols.items()}
    # at rest the raw reading is the anomaly there (no Eötvös effect), plus noise
    anomaly = first["gravity"] + float(eotvos(first["lat"], first["v_east"], first["v_north"]))
    port = {"t": np.arange(k) * 10.0, "lat": np.full(k, first["lat"]),
            "lon": np.full(k, first["lon"]), "v_east": np.zeros(k), "v_north": np.zeros(k),
            "gravity": anomaly + np.random.default_rng(0).normal(0.0, 1.0, k)}
    cols["t"] = cols["t"] + k * 10.0
    track, out = tmp_path / "port.csv", tmp_path / "o.csv"
    write_track_csv(track, {c: np.concatenate([port[c], cols[c]]) for c in port},
                    precision=15)
    assert _filter(track, out, "--map-error", "3", "--map-error-length", "10000",
                   "--map-error-order", "2") == 0
    cap = capsys.readouterr()
    assert "covariance_repaired" not in cap.err, cap.err
    res = read_track_csv(out)
    assert not (res["status"].astype(int) & STATUS_FILTER["covariance_repaired"]).any()
    assert np.all(res["innovation_sigma"] < 10.0), np.max(res["innovation_sigma"])
    nis = (res["innovation"] / res["innovation_sigma"]) ** 2
    assert 0.3 < nis.mean() < 3.0, nis.mean()


@pytest.mark.long
def test_pmf_predicts_with_the_ins_model_it_is_given(stride_track):
    """filter_track(..., "pmf", ins=...) built the point-mass filter with paper D's model
    whatever ``ins`` said (only the prior took it): before the first reading the PMF's
    Gaussian part is the Kalman prediction, the UKF's too, with the same model."""
    from jaxgrav.scenarios import INS_GRADES

    c = read_track_csv(stride_track, allow_nan=("gravity",))
    args = (paper_d(), c["t"], c["lat"], c["lon"], c["gravity"])
    for grade in ("navigation", "strategic"):
        res = {m: filter_track(*args, m, ins=INS_GRADES[grade]) for m in ("pmf", "ukf")}
        for k in ("sigma_v_north", "sigma_v_east", "sigma_gravimeter_bias"):
            np.testing.assert_allclose(res["pmf"][k][:2], res["ukf"][k][:2], rtol=1e-9,
                                       err_msg=f"{grade} {k}")


def test_clock_jitter_and_gaps_are_filtered_on_the_regular_step(sim, tmp_path, capsys):
    # a logger's jitter (±0.5 s on 10 s) and dropped records (2 rows, then 3): the filter
    # runs on the regular step, predicts through the gaps, writes the log's own rows
    cols = read_track_csv(sim / "track.csv")
    clean = tmp_path / "clean.csv"
    assert _filter(sim / "track.csv", clean) == 0
    jittered = dict(cols)
    jittered["t"] = cols["t"] + np.random.default_rng(1).uniform(-0.5, 0.5, cols["t"].size)
    write_track_csv(tmp_path / "jitter.csv", jittered)
    assert _filter(tmp_path / "jitter.csv", tmp_path / "j.csv") == 0
    assert "time step 10.0006 s (steps jitter by up to 0.878 s)" in capsys.readouterr().out
    a, b = read_track_csv(clean), read_track_csv(tmp_path / "j.csv")
    # the log's times, not the grid's
    np.testing.assert_array_equal(b["t"], read_track_csv(tmp_path / "jitter.csv")["t"])
    assert np.max(np.abs(a["lat"] - b["lat"])) * DEG * 6.4e6 < 1.0  # metres
    drop = [40, 41, 80, 81, 82]
    gapped = {k: np.delete(np.asarray(v), drop) for k, v in cols.items()}
    write_track_csv(tmp_path / "gaps.csv", gapped)
    assert _filter(tmp_path / "gaps.csv", tmp_path / "g.csv") == 0
    assert "2 gap(s) bridged by prediction over 5 missing row(s)" in capsys.readouterr().out
    g = read_track_csv(tmp_path / "g.csv")
    np.testing.assert_array_equal(g["t"], read_track_csv(tmp_path / "gaps.csv")["t"])
    keep = np.delete(np.arange(cols["t"].size), drop)
    # the same filter less 5 of 121 readings: before the first gap identical, after it close
    np.testing.assert_allclose(g["lat"][:40], a["lat"][:40], rtol=0, atol=1e-12)
    assert np.isfinite(g["sigma_north"]).all() and np.all(g["status"] == 0)
    assert np.max(np.abs(g["lat"] - a["lat"][keep])) * DEG * 6.4e6 < 200.0


@pytest.mark.long
def test_pmf_takes_missing_and_irregular_readings_and_gaps(stride_track, tmp_path, capsys):
    # the point-mass filter updates on the readings' common stride: a dropped record (rows
    # 30-32, a reading among them) and a missing reading (row 50) keep it at 3; an extra
    # reading off the stride (row 51) makes it 1, the same filter updating every row
    clean, out = tmp_path / "clean.csv", tmp_path / "o.csv"
    assert _filter(stride_track, clean, "--method", "pmf") == 0
    cols = {k: np.asarray(v).copy() for k, v in read_track_csv(stride_track).items()}
    cols["gravity"][50] = np.nan
    holed = {k: np.delete(v, [30, 31, 32]) for k, v in cols.items()}
    write_track_csv(tmp_path / "holed.csv", holed)
    capsys.readouterr()
    assert _filter(tmp_path / "holed.csv", out, "--method", "pmf") == 0
    said = capsys.readouterr().out
    assert "(38 readings, updates every 3 rows)" in said and "1 gap(s) bridged" in said
    a, b = read_track_csv(clean), read_track_csv(out)
    assert b["t"].size == 118
    np.testing.assert_allclose(b["lat"][:30], a["lat"][:30], rtol=0, atol=1e-12)
    assert np.all(np.isfinite(b["sigma_north"]))
    cols["gravity"][51] = cols["gravity"][50 - 3]  # a reading off the stride
    write_track_csv(tmp_path / "odd.csv", cols)
    assert _filter(tmp_path / "odd.csv", tmp_path / "odd_out.csv", "--method", "pmf") == 0
    assert "updates every 1 rows" in capsys.readouterr().out
    odd = read_track_csv(tmp_path / "odd_out.csv")
    # every row an update: the same filter (the pending spread settled at each step, not
    # three steps at once: within a centimetre, 1e-7 degrees)
    np.testing.assert_allclose(odd["lat"][:50], a["lat"][:50], rtol=0, atol=1e-7)
