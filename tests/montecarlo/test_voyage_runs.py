"""Voyage methods of the Monte Carlo runner (montecarlo.voyage_runs): a run equals the
navigator called directly on the same voyage, the metrics are what they say, bad options
are named; and ``jaxgrav montecarlo --method voyage-*`` end to end."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

from jaxgrav import montecarlo
from jaxgrav.cli import main
from jaxgrav.fields.map_error import map_error
from jaxgrav.montecarlo.voyage_runs import voyage_builder, voyage_tracks
from jaxgrav.navigate import (
    DENSE_LOOP,
    hourly_rms,
    implausible_block_count,
    navigate_tight,
    voyage_errors,
)
from jaxgrav.scenarios import voyage_scenario

MODEL = map_error(3.0, 10000.0)


@pytest.fixture(scope="module", params=["voyage-ukf", "voyage-rbpf"])
def tight(request):
    spec = montecarlo.build(request.param, None, map_error=MODEL, hours=1.0)
    return spec, montecarlo.run(spec.fn, jax.random.key(3), 2, args=spec.args, progress=False)


@pytest.mark.long
def test_a_run_is_the_navigator_on_the_same_voyage(tight):
    spec, res = tight
    pm, grid, scenario, model, config = spec.args
    assert config.map_error is not None and config.map_error.order == 2  # matched, told
    key = jax.random.split(jax.random.key(3), 2)[1]
    voyage = voyage_scenario(key, grid, scenario, model)
    nav = navigate_tight(pm, voyage, config, jax.random.fold_in(key, 1))  # particles' key
    err = voyage_errors(voyage, nav.nav, nav.cov_north_east)
    last = round(3600.0 / scenario.dt)
    # batched and single-run rounding differ from the first step (1e-12 relative); the
    # particle filter's resampling carries that to 2.4e-6 relative over the hour (4e-7
    # before its batched resampling ran only on the runs that resample, rare_cond)
    rel = 1e-5 if config.method == "rbpf" else 1e-6
    assert float(res["err_m"][1]) == pytest.approx(
        float(jnp.sqrt(jnp.mean(err.nav_m[-last:] ** 2))), rel=rel)
    assert float(res["ins_err_m"][1]) == pytest.approx(
        float(jnp.sqrt(jnp.mean(err.free_m[-last:] ** 2))), rel=1e-6)
    np.testing.assert_allclose(res["hourly_err_m"][1], hourly_rms(err.nav_m, scenario.dt),
                               rtol=rel)
    # the NEES divides by the stated covariance, whose batched and single-run rounding
    # differ (the RBPF's mixture of 500 particles, its resampling carrying them on): 1e-6
    # relative apart here until the map's coefficients became one compiled program
    # (2026-12-07, other last bits), 1.8e-5 since
    assert float(res["nees"][1]) == pytest.approx(float(jnp.mean(err.nees)),
                                                  rel=1e-4 if config.method == "rbpf" else 1e-5)
    assert res["err_series_m"].shape == (2, 7)  # every 10 min over 1 h, start included
    assert np.all(res["status"] == 0)
    # the block test of the innovations, as navigate flags a log's rows with it
    assert int(res["implausible_blocks"][1]) == int(implausible_block_count(
        nav.innovation, jnp.sqrt(nav.innovation_var)))
    # the tracks of the figure are that run's: truth, free INS and the navigation solution
    tracks = voyage_tracks(key, *spec.args)
    np.testing.assert_allclose(tracks["navigation"][0], nav.nav.lat, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tracks["truth"][1], voyage.truth.lon, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tracks["free INS"][0], voyage.ins.lat, rtol=0, atol=1e-12)


@pytest.mark.long
def test_the_last_hour_is_the_last_whole_hour_of_the_hourly_figures():
    # 1.5 h: the hourly figures keep one whole hour (the partial one left out); the
    # per-run last-hour errors were the last 3600 s (0.5-1.5 h) and disagreed with them
    spec = montecarlo.build("voyage-ukf", None, map_error=MODEL, hours=1.5)
    res = montecarlo.run(spec.fn, jax.random.key(3), 2, args=spec.args, progress=False)
    assert res["hourly_err_m"].shape == (2, 1)
    np.testing.assert_array_equal(res["err_m"], res["hourly_err_m"][:, -1])
    np.testing.assert_array_equal(res["ins_err_m"], res["hourly_ins_err_m"][:, -1])


@pytest.mark.long
@pytest.mark.parametrize("kind", ["voyage-dense", "voyage-chains", "voyage-entropy+iccp"])
def test_loose_runs_record_their_fix_events(kind):
    spec = montecarlo.build(kind, None, map_error=MODEL, hours=1.0)
    res = montecarlo.run(spec.fn, jax.random.key(0), 1, args=spec.args, progress=False)
    events = res["fix_event"][0]
    assert events.shape == (1,)
    assert int(res["status"][0]) == 1 << int(events[0])  # bit k: event k happened
    assert float(res["fix_time_s"][0][0]) == pytest.approx(3600.0)  # the hour's segment end
    matcher = spec.args[-1].matcher
    assert (matcher[1] if isinstance(matcher, tuple) else matcher).map_error_mgal == 3.0  # told
    if kind == "voyage-chains":  # the 2.5′ map refined x8 (~0.005°), the stencil for 10 kn
        assert spec.args[0].dlat == pytest.approx(2.5 / 60 / 8) and matcher.stencil_size > 0


@pytest.mark.parametrize(("options", "error", "message"), [
    ({"n_fixes": 30}, ValueError, "fixes per track is not a voyage setting"),
    ({"map_error_told": "white"}, ValueError, "map_error_told must be one of state, none"),
    ({"map_error_order": 3}, ValueError, "map_error_order must be 1 or 2"),
    ({"noise": -1.0}, ValueError, "noise must be a positive reading"),
    ({"kind": "voyage-pf"}, ValueError, "kind must be one of voyage-dense"),
    ({"segment_error": "markov"}, ValueError, "segment_error are settings of voyage-dense"),
    ({"kind": "voyage-chains", "fix_prior": True}, ValueError, "fix_prior are settings of"),
    ({"kind": "voyage-dense", "segment_error": "exact"}, ValueError,
     "segment_error must be one of markov, linear, conditional"),
])
def test_bad_builder_options_are_named(options, error, message):
    kw = {"kind": "voyage-ukf", **options}
    with pytest.raises(error, match=message):
        voyage_builder(None, **kw)


def test_voyage_dense_runs_the_dense_loop_by_default_and_markov_on_request():
    config = voyage_builder(None, kind="voyage-dense").args[-1]
    assert {k: getattr(config, k) for k in DENSE_LOOP} == DENSE_LOOP
    spec = voyage_builder(None, kind="voyage-dense", segment_error="markov")
    old = spec.args[-1]
    assert (old.segment_error, old.fix_prior, old.n_fixes, old.stride, old.cell_error,
            old.first_n_fixes) == ("markov", False, 30, 30, False, None)
    assert spec.settings["segment_error"] == "markov" and spec.settings["fix_prior"] == 0
    no_prior = voyage_builder(None, kind="voyage-dense", fix_prior=False).args[-1]
    assert not no_prior.fix_prior and no_prior.segment_error == "conditional"
    assert voyage_builder(None, kind="voyage-dense").settings["shape_update"] == 1
    no_shape = voyage_builder(None, kind="voyage-dense", shape_update=False)
    assert not no_shape.args[-1].shape_update and no_shape.settings["shape_update"] == 0
    # re-acquisition: on by default (after one failed fix, x 16), 0 turns it off
    default = voyage_builder(None, kind="voyage-dense")
    assert default.args[-1].reacquire_after == 1 and default.settings["reacquire_after"] == 1
    never = voyage_builder(None, kind="voyage-dense", reacquire_after=0, reacquire_inflation=4.0)
    assert never.args[-1].reacquire_after is None and never.settings["reacquire_after"] == 0
    assert never.settings["reacquire_inflation"] == 4.0 and "re-acquiring" not in (
        never.settings["description"])


@pytest.mark.parametrize(("args", "message"), [
    (["--method", "voyage-ukf", "--segment-error", "markov"],
     "--segment-error, --fix-prior, --first-n-fixes, --shape-update and --reacquire-after / "
     "--reacquire-inflation are options of --method voyage-dense"),
    (["--method", "voyage-ukf", "--no-shape-update"],
     "--reacquire-inflation are options of --method voyage-dense"),
    (["--method", "voyage-ukf", "--reacquire-after", "2"],
     "--reacquire-inflation are options of --method voyage-dense"),
    (["--method", "voyage-dense", "--reacquire-inflation", "nan"],
     "--reacquire-inflation must be a finite factor >= 1 (the filter's covariance is "
     "multiplied by it); got nan"),
    (["--method", "voyage-dense", "--reacquire-after", "-2"],
     "--reacquire-after must be a number of failed fixes in a row, 1 or more (0: never); "
     "got -2"),
    (["--method", "dense", "--fix-prior"], "--fix-prior is an option of the voyage methods"),
])
def test_cli_loop_options_are_voyage_dense_only(tmp_path, capsys, args, message):
    out = tmp_path / "v.nc"
    assert main(["montecarlo", *args, "--runs", "2", "--no-progress", "--out", str(out)]) == 2
    assert message in capsys.readouterr().err and not out.exists()


@pytest.mark.long
@pytest.mark.parametrize("loop", [[], ["--first-n-fixes", "30"], ["--segment-error", "markov"]])
def test_cli_voyage_dense_runs_its_loop(tmp_path, capsys, loop):
    """montecarlo --method voyage-dense end to end: by default 2 h segments every hour (on
    a 2 h patrol the 1 h end is not matched, event 1), the settings stored;
    --first-n-fixes 30: the 1 h end matched on its 30 fixes; --segment-error markov: the
    old loop (1 h segments, both ends matched)."""
    out = tmp_path / "v.nc"
    assert main(["montecarlo", "--method", "voyage-dense", "--runs", "2", "--hours", "2",
                 "--map-error", "3", "--no-progress", "--out", str(out), *loop]) == 0
    said = capsys.readouterr().out
    assert "last hour / free INS" in said and "NEES mean" in said
    assert "innovations implausible" not in said  # a loose voyage has fixes, no innovations
    ds = xr.open_dataset(out)
    assert "implausible_blocks" not in ds and "summary_implausible_rate" not in ds.attrs
    events = ds["fix_event"].values
    assert events.shape == (2, 2) and np.all(events[:, 1] != 1)
    assert np.all((events[:, 0] == 1) == (loop == []))
    markov = "markov" in loop
    assert ds.attrs["setting_segment_error"] == ("markov" if markov else "conditional")
    assert ds.attrs["setting_fixes_per_segment"] == (30 if markov else 60)
    assert ds.attrs["setting_fix_prior"] == (0 if markov else 1)
    assert ds.attrs["setting_first_segment_fixes"] == (30 if "30" in loop else 0)
    assert ds.attrs["setting_shape_update"] == (0 if markov else 1)
    assert ds.attrs["setting_reacquire_after"] == (0 if markov else 1)
    ds.close()


@pytest.mark.long
def test_cli_voyage_method_writes_results_and_figure(tmp_path, capsys):
    out = tmp_path / "v.nc"
    assert main(["montecarlo", "--method", "voyage-ukf", "--runs", "2", "--hours", "1",
                 "--map-error", "3", "--no-progress", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "last hour / free INS" in said and "NEES mean" in said
    assert "innovations implausible" in said
    ds = xr.open_dataset(out)
    assert ds.attrs["summary_implausible_rate"] == float(
        np.mean(ds["implausible_blocks"].values > 0))
    assert ds["hourly_err_m"].shape == (2, 1) and ds.attrs["method"] == "voyage-ukf"
    assert "--hours 1" in ds.attrs["command"]
    assert ds["start_lat"].attrs["units"] == "degrees_north"
    assert "last whole hour" in ds["err_m"].attrs["long_name"]
    # the printed voyage figures are stored too
    assert ds.attrs["summary_voyage_last_hour_ratio"] == pytest.approx(
        float(np.sqrt(np.mean(ds["hourly_err_m"][:, -1] ** 2))
              / np.sqrt(np.mean(ds["hourly_ins_err_m"][:, -1] ** 2))))
    assert ds.attrs["summary_voyage_nonfinite_voyages"] == 0
    bare = [v for v in ds.data_vars if not {"units", "long_name"} <= set(ds[v].attrs)]
    assert not bare
    ds.close()
    assert out.with_suffix(".png").stat().st_size > 10_000
    tracks_png = tmp_path / "v_tracks.png"  # run 1 on the map
    assert tracks_png.stat().st_size > 10_000 and "v_tracks.png" in said
    # all or nothing: an existing tracks figure stops the run before anything is written
    out.unlink()
    out.with_suffix(".png").unlink()
    assert main(["montecarlo", "--method", "voyage-ukf", "--runs", "2", "--hours", "1",
                 "--no-progress", "--out", str(out)]) == 2
    assert "v_tracks.png" in capsys.readouterr().err and not out.exists()
    assert not out.with_suffix(".png").exists()


@pytest.mark.parametrize(("args", "message"), [
    (["--method", "voyage-ukf", "--fixes", "30"], "--fixes is not an option of voyage-ukf"),
    (["--method", "voyage-ukf", "--hours", "-2"], "--hours must be a patrol length from 1 h"),
    # shorter than the hour the errors are reported over: refused, not an IndexError
    (["--method", "voyage-dense", "--hours", "0.5"], "--hours must be a patrol length from 1 h"),
    (["--method", "ukf", "--hours", "2"], "--hours is an option of the voyage methods"),
    (["--method", "voyage-ekf", "--told-map-error", "white"],
     "--told-map-error must be one of state, none"),
])
def test_cli_bad_voyage_options_are_named(tmp_path, capsys, args, message):
    out = tmp_path / "v.nc"
    assert main(["montecarlo", *args, "--runs", "2", "--out", str(out)]) == 2
    assert message in capsys.readouterr().err and not out.exists()
