"""Re-acquisition (navigate.loose_reacquire): a run of failed fixes widens the filter's
covariance, so the next window reaches a truth the filter had lost."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.match.dense import DenseConfig
from jaxgrav.navigate import LooseConfig
from jaxgrav.navigate.loose_reacquire import LOST_STATUS, lost_fix, reacquire, widest_reach_m
from jaxgrav.sim.drift import rayleigh_quantile

P = jnp.diag(jnp.array([300.0**2, 200.0**2, *([0.1**2] * 11)]))


def _config(**changes):
    return LooseConfig(matcher=DenseConfig(half_size=10), max_spacing_m=1500.0,
                       **{"reacquire_after": 2, "reacquire_inflation": 4.0, **changes})


def test_a_failure_is_an_edge_or_misfit_rejection_or_a_shape_rejection_not_a_gated_one():
    event = jnp.array([0, 1, 2, 3, 3, 3, 3, 4, 5])
    status = jnp.array([0, 0, 0, 4096, 2048, 4104, 512 | 1024, 0, 0])
    np.testing.assert_array_equal(
        lost_fix(event, status), [False, False, False, True, True, True, False, False, True])
    assert LOST_STATUS == 4096 | 2048


def test_the_run_widens_the_covariance_from_its_kth_failure_and_a_fix_ends_it():
    cfg = _config()
    run = jnp.zeros((), jnp.int32)
    p1, run = reacquire(cfg, P, run, jnp.asarray(5), jnp.asarray(0))  # first failure
    assert int(run) == 1 and np.array_equal(p1, P)
    p2, run = reacquire(cfg, P, run, jnp.asarray(3), jnp.asarray(4096))  # second: widened
    assert int(run) == 2
    np.testing.assert_allclose(p2, 4.0 * P)
    p3, run = reacquire(cfg, P, run, jnp.asarray(3), jnp.asarray(512))  # says nothing
    assert int(run) == 2 and np.array_equal(p3, P)
    _, run = reacquire(cfg, P, run, jnp.asarray(0), jnp.asarray(0))  # accepted: run over
    assert int(run) == 0


def test_the_covariance_is_widened_no_further_than_the_widest_window():
    cfg = _config(reacquire_after=1, reacquire_inflation=1e6)
    p, _ = reacquire(cfg, P, jnp.zeros((), jnp.int32), jnp.asarray(5), jnp.asarray(0))
    sigma = 10 * 1500.0 / rayleigh_quantile(1.0, cfg.window_p)
    assert widest_reach_m(cfg) == 15000.0
    np.testing.assert_allclose(float(jnp.sqrt(p[0, 0])), sigma, rtol=1e-9)  # the larger axis
    np.testing.assert_allclose(p, P * sigma**2 / 300.0**2, rtol=1e-9)  # correlations kept


def test_without_reacquisition_the_covariance_is_left_and_the_run_still_counted():
    cfg = _config(reacquire_after=None)
    p, run = jax.jit(reacquire, static_argnums=0)(cfg, P, jnp.asarray(3, jnp.int32),
                                                  jnp.asarray(5), jnp.asarray(0))
    assert np.array_equal(p, P) and int(run) == 4


def test_vmap_equals_loop():
    cfg = _config(reacquire_after=1)
    events, status = jnp.array([0, 3, 4, 5]), jnp.array([0, 4096, 0, 0])
    runs = jnp.array([2, 0, 1, 3], jnp.int32)
    batched = jax.vmap(lambda r, e, s: reacquire(cfg, P, r, e, s))(runs, events, status)
    for i in range(4):
        one = reacquire(cfg, P, runs[i], events[i], status[i])
        np.testing.assert_array_equal(batched[0][i], one[0])
        assert int(batched[1][i]) == int(one[1])


@pytest.mark.parametrize("change, message", [
    ({"reacquire_after": 0}, "reacquire_after must be None or an integer >= 1"),
    ({"reacquire_inflation": 0.5}, "reacquire_inflation must be a number >= 1"),
])
def test_bad_reacquisition_settings_are_named(change, message):
    with pytest.raises(ValueError, match=message):
        LooseConfig(**change)
