"""Monte Carlo runs on a map with land masked (missing nodes): a run's start is drawn
again until its true track reads no missing node; on a complete map the runs are those
of a single try, and the CLI takes such maps for every method (a voyage's route drawn
again, also by ``simulate-voyage``)."""

import dataclasses

import jax
import numpy as np
import pytest
import xarray as xr

from jaxgrav import datasets, montecarlo
from jaxgrav.cli import main
from jaxgrav.cli.montecarlo import summarize
from jaxgrav.grid import Grid
from jaxgrav.montecarlo import methods as montecarlo_methods
from jaxgrav.montecarlo.spec import region_of
from jaxgrav.scenarios import voyage_preset, voyage_scenario
from jaxgrav.scenarios.paper_a import MatchingScenario, matching_scenario
from jaxgrav.tracks import read_track_csv

GRID = datasets.load("ryukyu")["anomaly_2p5min"]


def _west_land(fraction=0.6):
    """The shipped map with its western ``fraction`` of columns missing (land)."""
    v = np.array(GRID.values)
    v[:, : int(fraction * v.shape[1])] = np.nan
    return Grid(v, GRID.lat0, GRID.dlat, GRID.lon0, GRID.dlon, GRID.name, GRID.units)


@pytest.mark.long
def test_a_complete_map_gives_the_runs_of_one_try():
    scen = MatchingScenario(region=region_of(GRID), n_fixes=10)
    many = dataclasses.replace(scen, start_tries=16)
    keys = jax.random.split(jax.random.key(3), 8)
    a = jax.vmap(lambda k: matching_scenario(k, GRID, scen))(keys)
    b = jax.vmap(lambda k: matching_scenario(k, GRID, many))(keys)
    np.testing.assert_array_equal(np.asarray(a.truth.lat), np.asarray(b.truth.lat))
    np.testing.assert_array_equal(np.asarray(a.readings), np.asarray(b.readings))


@pytest.mark.long
def test_starts_are_drawn_again_off_the_land():
    land = _west_land()
    scen = MatchingScenario(region=region_of(GRID), n_fixes=10)
    keys = jax.random.split(jax.random.key(0), 64)
    one = jax.vmap(lambda k: matching_scenario(k, land, scen))(keys)
    tried = jax.vmap(lambda k: matching_scenario(
        k, land, dataclasses.replace(scen, start_tries=16)))(keys)
    clear_one = np.all(np.isfinite(np.asarray(one.readings)), axis=1)
    assert 0.2 < clear_one.mean() < 0.7  # one try lands on the mask often
    assert np.all(np.isfinite(np.asarray(tried.readings)))  # sixteen: never here
    # a start that was clear is kept as it was
    np.testing.assert_array_equal(np.asarray(tried.truth.lat)[clear_one],
                                  np.asarray(one.truth.lat)[clear_one])
    with pytest.raises(ValueError, match="start_tries must be an integer >= 1"):
        MatchingScenario(start_tries=0)


@pytest.mark.long
@pytest.mark.parametrize("method, fixes", [("dense", 10), ("iccp", 20), ("ukf", 31)])
def test_runs_on_a_masked_map_read_no_missing_node(method, fixes):
    land = _west_land()
    spec = montecarlo_methods.build(method, land, n_fixes=fixes)
    assert spec.args[1].start_tries > 1
    out = montecarlo.run(spec.fn, jax.random.key(1), 8, chunk=8, args=spec.args,
                         progress=False)
    assert np.all(out["readings_on_map"])
    assert np.all(np.isfinite(out["err_m"]))
    east_edge = GRID.lon0 + 0.6 * GRID.lon.size * GRID.dlon
    assert np.all(out["start_lon"] > east_edge - 0.1)


def test_runs_without_a_clear_start_count_as_failures():
    results = dict(ins_err_m=np.full(4, 2000.0), err_m=np.full(4, 500.0),
                   status=np.zeros(4, int), readings_on_map=np.array([True, True, False, True]))
    assert summarize(results, "filter")["failure_rate"] == 0.25
    del results["readings_on_map"]
    assert summarize(results, "filter")["failure_rate"] == 0.0


@pytest.mark.long
def test_cli_takes_a_masked_map_for_dense_filters_and_voyages(tmp_path, capsys):
    v = np.array(GRID.values)
    v[:, :120] = np.nan
    xr.Dataset({"anomaly": (("lat", "lon"), v, {"units": "mGal"})},
               coords={"lat": np.asarray(GRID.lat), "lon": np.asarray(GRID.lon)}).to_netcdf(
        tmp_path / "land.nc")
    out = tmp_path / "d.nc"
    assert main(["montecarlo", "--method", "dense", "--runs", "6", "--fixes", "10",
                 "--map", str(tmp_path / "land.nc"), "--out", str(out), "--no-progress"]) == 0
    with xr.open_dataset(out) as ds:
        assert bool(ds["readings_on_map"].all()) and "units" in ds["readings_on_map"].attrs
    capsys.readouterr()
    assert main(["montecarlo", "--method", "ukf", "--runs", "4", "--fixes", "31", "--map",
                 str(tmp_path / "land.nc"), "--out", str(tmp_path / "u.nc"),
                 "--no-progress"]) == 0
    assert "clear starts: 4 of 4 runs" in capsys.readouterr().out
    with xr.open_dataset(tmp_path / "u.nc") as ds:
        assert bool(ds["readings_on_map"].all())
    assert main(["montecarlo", "--method", "voyage-ukf", "--runs", "4", "--hours", "1",
                 "--map", str(tmp_path / "land.nc"), "--out", str(tmp_path / "v.nc"),
                 "--no-progress"]) == 0
    assert "clear starts: 4 of 4 runs" in capsys.readouterr().out
    with xr.open_dataset(tmp_path / "v.nc") as ds:
        assert bool(ds["readings_on_map"].all()) and "units" in ds["readings_on_map"].attrs
        assert np.all(np.isfinite(ds["err_m"]))


@pytest.mark.long
def test_simulate_voyage_draws_its_route_again_off_the_land(tmp_path, capsys):
    v = np.array(GRID.values)
    v[:, :120] = np.nan  # west of 129 E
    land = Grid(v, GRID.lat0, GRID.dlat, GRID.lon0, GRID.dlon, GRID.name, GRID.units)
    xr.Dataset({"anomaly": (("lat", "lon"), v, {"units": "mGal"})},
               coords={"lat": np.asarray(GRID.lat), "lon": np.asarray(GRID.lon)}).to_netcdf(
        tmp_path / "land.nc")
    one = voyage_scenario(jax.random.key(10), land, voyage_preset("patrol-12h", hours=1.0))
    assert not np.all(np.isfinite(np.asarray(one.gravity)))  # seed 10's first route: land
    log, truth = tmp_path / "log.csv", tmp_path / "truth.csv"
    assert main(["simulate-voyage", "--hours", "1", "--seed", "10", "--map",
                 str(tmp_path / "land.nc"), "--out", str(log), "--truth", str(truth)]) == 0
    assert np.all(np.isfinite(read_track_csv(log)["gravity"]))
    assert np.all(read_track_csv(truth)["lon"] > 129.0)
