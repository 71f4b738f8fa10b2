"""Voyage routes drawn again on a map with missing (land) nodes, as the other scenarios'
starts (issue 19): ``VoyageScenario.start_tries`` routes are drawn at once and the first
whose sailed true track reads no missing node is kept; one try, or a complete map, gives
the voyages of today."""

import dataclasses

import jax
import numpy as np
import pytest

from jaxgrav import datasets
from jaxgrav.grid import Grid
from jaxgrav.montecarlo.matcher_runs import MISSING_MAP_START_TRIES
from jaxgrav.montecarlo.voyage_runs import voyage_builder
from jaxgrav.scenarios import VoyageScenario, voyage_preset, voyage_scenario

GRID = datasets.load("ryukyu")["anomaly_2p5min"]


def _west_land(lon_max=128.0):
    """The shipped map with every node west of ``lon_max`` (degrees E) missing."""
    v = np.array(GRID.values)
    v[:, np.asarray(GRID.lon) < lon_max] = np.nan
    return Grid(v, GRID.lat0, GRID.dlat, GRID.lon0, GRID.dlon, GRID.name, GRID.units)


def test_start_tries_is_checked():
    for bad in (0, 2.0, True):
        with pytest.raises(ValueError, match="start_tries must be an integer >= 1"):
            VoyageScenario(start_tries=bad)
    assert VoyageScenario().start_tries == 1


@pytest.mark.long
def test_the_builder_sets_the_tries_only_on_a_masked_map():  # prepare_map: ~1.6 s
    assert voyage_builder(GRID, kind="voyage-ukf").args[2].start_tries == 1
    tries = voyage_builder(_west_land(), kind="voyage-ukf").args[2].start_tries
    assert tries == MISSING_MAP_START_TRIES


def _voyages(grid, scenario, n=12, seed=0):
    keys = jax.random.split(jax.random.key(seed), n)
    return jax.jit(jax.vmap(lambda k: voyage_scenario(k, grid, scenario)))(keys)


@pytest.mark.long
def test_routes_are_drawn_again_off_the_land_and_complete_maps_keep_their_voyages():
    one = voyage_preset("patrol-12h", hours=2.0)
    many = dataclasses.replace(one, start_tries=16)
    a, b = _voyages(GRID, one), _voyages(GRID, many)
    for u, v in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):  # bit for bit
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))
    land = _west_land()
    first, tried = _voyages(land, one, n=24), _voyages(land, many, n=24)
    clear_one = np.all(np.isfinite(np.asarray(first.gravity)), axis=1)
    assert 0.2 < clear_one.mean() < 0.9  # one try reads the land often
    assert np.all(np.isfinite(np.asarray(tried.gravity)))  # sixteen: never here
    assert np.all(np.asarray(tried.truth.lon) > 128.0)
    # a route that was clear is kept as it was, the voyage along it too
    for u, v in zip(jax.tree.leaves(first), jax.tree.leaves(tried), strict=True):
        np.testing.assert_array_equal(np.asarray(u)[clear_one], np.asarray(v)[clear_one])
