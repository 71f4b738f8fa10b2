"""Map-error models in paper A's and paper B's scenarios (issue 15, item 1)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import Grid
from jaxgrav.fields import map_error as map_errors
from jaxgrav.fields.map_error import map_error, truth_grid
from jaxgrav.scenarios import MatchingScenario, PaperBScenario, matching_scenario, paper_b_scenario

SIGMA, LENGTH = 3.0, 10_000.0


@pytest.fixture(scope="module")
def grid():
    """A smooth 2° x 2° map at 1' nodes (mGal)."""
    lat = np.linspace(30.0, 32.0, 121)
    lon = np.linspace(130.0, 132.0, 121)
    la, lo = np.meshgrid(np.deg2rad(lat), np.deg2rad(lon), indexing="ij")
    values = 20 * np.sin(7 * la) * np.cos(5 * lo) + 10 * np.cos(11 * la + 3 * lo)
    return Grid.from_arrays(lat, lon, values, name="test map", units="mGal")


def scen(grid, **kw):
    w, e, s, n = grid.extent
    base = dict(region=(s + 0.1, n - 0.1, w + 0.1, e - 0.1), noise_mgal=0.0, eotvos=None)
    return MatchingScenario(**{**base, **kw})


@pytest.mark.long
def test_map_error_none_is_bit_identical(grid):
    key = jax.random.key(7)
    s = MatchingScenario(region=scen(grid).region)
    a = matching_scenario(key, grid, s)
    for b in (matching_scenario(key, grid, s, None),
              matching_scenario(key, grid, s, map_error(0.0, LENGTH))):
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    sb = PaperBScenario(region=(30.2, 31.8, 130.2, 131.8))
    a, b = paper_b_scenario(key, grid, sb), paper_b_scenario(key, grid, sb, None)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def errors_along_track(grid, model, n_runs, **kw):
    s = scen(grid, **kw)
    keys = jax.random.split(jax.random.key(1), n_runs)
    runs = jax.vmap(lambda k: matching_scenario(k, grid, s, model))(keys)
    m = grid.sample(runs.truth.lat, runs.truth.lon, "bicubic")
    return np.asarray(runs.readings - m), s


@pytest.mark.long
def test_readings_minus_map_have_the_model_std_and_correlation(grid):
    err, s = errors_along_track(grid, map_error(SIGMA, LENGTH), 60, n_fixes=30)
    assert np.std(err) == pytest.approx(SIGMA, rel=0.2)
    # correlation along the track at lags of k fixes, as the model says
    model = map_error(1.0, LENGTH)
    for k in (1, 3, 6):
        a, b = err[:, :-k].ravel(), err[:, k:].ravel()
        rho = np.mean(a * b) / np.sqrt(np.mean(a * a) * np.mean(b * b))
        expected = float(model.covariance(jnp.asarray(k * s.step_m)))
        assert rho == pytest.approx(expected, abs=0.12), k


@pytest.mark.long  # 4-8 s: the fast tier is at its 5-minute budget
def test_other_draws_unchanged_by_the_map_error(grid):
    key = jax.random.key(3)
    s = scen(grid, noise_mgal=1.0)
    a = matching_scenario(key, grid, s)
    b = matching_scenario(key, grid, s, map_error(SIGMA, LENGTH))
    np.testing.assert_array_equal(np.asarray(a.truth.lat), np.asarray(b.truth.lat))
    np.testing.assert_array_equal(np.asarray(a.ins_lon), np.asarray(b.ins_lon))
    assert not np.allclose(np.asarray(a.readings), np.asarray(b.readings))


def test_no_retrace_when_sigma_or_length_change(grid):
    traces = []
    s = scen(grid)

    @jax.jit
    def f(key, model):
        traces.append(1)
        return matching_scenario(key, grid, s, model).readings

    key = jax.random.key(0)
    r1 = f(key, map_error(1.0, 5_000.0))
    r2 = f(key, map_error(4.0, 20_000.0))
    assert len(traces) == 1
    assert not np.allclose(np.asarray(r1), np.asarray(r2))


@pytest.mark.long
def test_vmap_over_keys_equals_the_loop(grid):
    s = scen(grid, noise_mgal=1.0)
    model = map_error(SIGMA, LENGTH)
    keys = jax.random.split(jax.random.key(5), 3)
    batch = jax.vmap(lambda k: matching_scenario(k, grid, s, model))(keys)
    for i in range(3):
        one = matching_scenario(keys[i], grid, s, model)
        np.testing.assert_allclose(np.asarray(batch.readings[i]), np.asarray(one.readings),
                                   rtol=1e-6, atol=1e-6)
    sb = PaperBScenario(region=(30.2, 31.8, 130.2, 131.8))
    batch = jax.vmap(lambda k: paper_b_scenario(k, grid, sb, model))(keys)
    one = paper_b_scenario(keys[1], grid, sb, model)
    np.testing.assert_allclose(np.asarray(batch.readings[1]), np.asarray(one.readings),
                               rtol=1e-6, atol=1e-6)


def test_per_batch_draw_is_a_truth_grid_passed_as_truth_field(grid):
    s = scen(grid)
    model = map_error(SIGMA, LENGTH)
    truth = map_errors.truth_field(jax.random.key(9), grid, model)
    run = matching_scenario(jax.random.key(2), truth, s)
    via_truth_grid = matching_scenario(jax.random.key(2), grid, s, truth_grid(truth))
    np.testing.assert_array_equal(np.asarray(run.readings), np.asarray(via_truth_grid.readings))


def test_truth_grid_must_cover_the_region(grid):
    small = Grid.from_arrays(np.linspace(30.0, 31.0, 61), np.linspace(130.0, 131.0, 61),
                             np.zeros((61, 61)))
    with pytest.raises(ValueError, match="must cover the scenario's region"):
        matching_scenario(jax.random.key(0), grid, scen(grid), truth_grid(small))
    with pytest.raises(ValueError, match="must cover the scenario's region"):
        paper_b_scenario(jax.random.key(0), grid, PaperBScenario(region=(30.2, 31.8, 130.2,
                                                                           131.8)),
                         truth_grid(small))


def test_bad_map_error_types(grid):
    with pytest.raises(TypeError, match="map_error must be"):
        matching_scenario(jax.random.key(0), grid, scen(grid), 3.0)
    with pytest.raises(TypeError, match="truth_field must be a Grid"):
        matching_scenario(jax.random.key(0), lambda la, lo: la * 0, scen(grid),
                          map_error(1.0, LENGTH))
    with pytest.raises(ValueError, match="sigma must be finite"):
        map_error(float("nan"), LENGTH)
