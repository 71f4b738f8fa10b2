"""Monte Carlo runs on a map with land masked (missing nodes): a run's start is drawn
again until its true track reads no missing node; on a complete map the runs are those
of a single try, and the CLI takes such maps for ``dense`` (and ``chains``) only."""

import dataclasses

import jax
import numpy as np
import pytest
import xarray as xr

from jaxgrav import datasets, montecarlo
from jaxgrav.cli import main
from jaxgrav.grid import Grid
from jaxgrav.montecarlo import methods as montecarlo_methods
from jaxgrav.montecarlo.spec import region_of
from jaxgrav.scenarios.paper_a import MatchingScenario, matching_scenario

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
def test_dense_runs_on_a_masked_map_read_no_missing_node():
    land = _west_land()
    spec = montecarlo_methods.build("dense", land, n_fixes=10)
    assert spec.args[1].start_tries > 1
    out = montecarlo.run(spec.fn, jax.random.key(1), 12, chunk=12, args=spec.args,
                         progress=False)
    assert np.all(out["readings_on_map"])
    assert np.all(np.isfinite(out["err_m"]))
    east_edge = GRID.lon0 + 0.6 * GRID.lon.size * GRID.dlon
    assert np.all(out["start_lon"] > east_edge - 0.1)


@pytest.mark.long
def test_cli_takes_a_masked_map_for_dense_and_refuses_it_for_the_filters(tmp_path, capsys):
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
    assert main(["montecarlo", "--method", "ukf", "--runs", "4", "--map",
                 str(tmp_path / "land.nc"), "--out", str(tmp_path / "u.nc")]) == 2
    assert "needs a complete map" in capsys.readouterr().err
