"""The tightly coupled filter's re-acquisition (navigate.tight_reacquire): the covariance
opening, checks that never reset equal to the plain filter, a forced reset taking the
fix's covariance, jit without retrace, vmap against a loop, bad settings."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.navigate import TightConfig, loose_config, navigate_tight
from jaxgrav.navigate.tight_reacquire import REACQUIRE_EVENTS, open_covariance
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import NAVIGATION_GRADE, voyage_preset, voyage_scenario


def test_open_covariance_adds_to_position_and_velocity_and_resets_the_map_error():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(15, 15))
    p = a @ a.T
    p0 = np.diag(np.arange(1.0, 16.0))
    out = np.asarray(open_covariance(jnp.asarray(p), jnp.asarray(p0), 100.0, 0.5))
    add = np.zeros(15)
    add[:2], add[2:4] = 100.0**2, 0.5**2
    np.testing.assert_allclose(out[:13, :13], p[:13, :13] + np.diag(add[:13]))
    np.testing.assert_allclose(out[13:], p0[13:])  # the map-error rows: the prior's
    np.testing.assert_allclose(out[:, 13:], p0[:, 13:])
    # no map-error state: only the opening
    np.testing.assert_allclose(open_covariance(jnp.asarray(p[:13, :13]),
                                               jnp.asarray(p0[:13, :13]), 0.0, 0.0),
                               p[:13, :13])


@pytest.mark.parametrize(("change", "message"), [
    ({"method": "gsf"}, "reacquire needs method 'ukf' or 'ekf'"),
    ({"reacquire": "dense"}, "reacquire needs method 'ukf' or 'ekf' and a LooseConfig"),
    ({"reacquire": loose_config(NAVIGATION_GRADE, fix_prior=True)}, "without fix_prior"),
])
def test_bad_reacquire_settings_get_clear_errors(change, message):
    base = {"reacquire": loose_config(NAVIGATION_GRADE, fix_prior=False)}
    with pytest.raises(ValueError, match=message):
        TightConfig(**{**base, **change})


SURE = TightConfig(ins=NAVIGATION_GRADE, sigma_pos_m=30.0, sigma_vel=0.3)
"""A filter sure of its start to 30 m; the voyages start 3 km off (it stays lost)."""


@pytest.fixture(scope="module")
def lost_voyages(smooth_grid):
    """Two 1 h voyages on the information-rich map, started 3 km off."""
    sc = voyage_preset("patrol-12h", ins=NAVIGATION_GRADE, hours=1.0,
                       region=(29.6, 30.4, 129.6, 130.4), leg_m=20000.0, margin_deg=0.1,
                       pos_error_m=3000.0, vel_error=0.3)
    keys = jax.random.split(jax.random.key(11), 2)
    return jax.vmap(lambda g, k: voyage_scenario(k, g, sc), in_axes=(None, 0))(smooth_grid, keys)


def _reacquiring(base):
    """Checks every 10 min over the last 20 min (20 fixes of 1 min): a short test."""
    return dataclasses.replace(base, reacquire=loose_config(
        NAVIGATION_GRADE, 0.0, 10000.0, fix_prior=False, n_fixes=20, stride=10, fix_every=6))


@pytest.mark.long
def test_checks_that_never_reset_leave_the_filter_as_it_was_and_a_forced_reset_takes_the_fix(
        smooth_grid, lost_voyages):
    pm = prepare_map(smooth_grid)
    v = jax.tree.map(lambda a: a[0], lost_voyages)
    plain = navigate_tight(pm, v, SURE)
    never = navigate_tight(pm, v, dataclasses.replace(_reacquiring(SURE), reacquire_gate=np.inf,
                                                      reacquire_ratio=np.inf))
    assert plain.reacquisition is None
    np.testing.assert_allclose(never.nav.lat, plain.nav.lat, rtol=0, atol=1e-12)
    np.testing.assert_allclose(never.cov_north_east, plain.cov_north_east, rtol=1e-12)
    events = np.asarray(never.reacquisition.event)
    # 1 h of 10 s steps, a check every 10 min: 7 (the last on the padded end: not matched)
    assert events.shape == (7, 1) and set(np.unique(events)) <= set(REACQUIRE_EVENTS) - {4, 5}
    assert events[0, 0] == 1 and events[-1, 0] == 2  # the first segment is not complete
    # every accepted fix resets the filter: its segment-mean position takes the fix's
    # covariance (the opened filter's own is far wider), and the check says so
    forced = navigate_tight(pm, v, dataclasses.replace(_reacquiring(SURE), reacquire_gate=0.0))
    checks = forced.reacquisition
    ev = np.asarray(checks.event[:, 0])
    assert np.any(ev == 4), (ev, np.asarray(checks.nis))
    t = np.asarray(v.ins.t)
    for c in np.flatnonzero(ev == 4):
        k = int(np.searchsorted(t, float(checks.time[c])))  # the step checked
        fix = np.trace(np.asarray(checks.fix_cov_m2[c, 0]))
        after = np.trace(np.asarray(forced.cov_north_east[k + 1]))
        before = np.trace(np.asarray(forced.cov_north_east[k]))
        assert 0.3 * fix < after < 3.0 * fix, (c, fix, after)
        assert before != after
    first = int(np.flatnonzero(ev == 4)[0])  # until the first reset: the same filter
    np.testing.assert_array_equal(np.asarray(checks.event[:first]),
                                  np.asarray(never.reacquisition.event[:first]))
    np.testing.assert_allclose(np.asarray(checks.nis[first]), np.asarray(
        never.reacquisition.nis[first]), rtol=1e-9)


@pytest.mark.long
def test_jit_without_retrace_and_vmap_equals_loop(smooth_grid, lost_voyages):
    pm = prepare_map(smooth_grid)
    cfg = _reacquiring(SURE)
    batch = jax.vmap(navigate_tight, in_axes=(None, 0, None))(pm, lost_voyages, cfg)
    for i in range(2):
        v = jax.tree.map(lambda a, i=i: a[i], lost_voyages)
        one = navigate_tight(pm, v, cfg)
        # the matcher's batched sums round differently: a reset moves the track by ~2 mm
        np.testing.assert_allclose(batch.nav.lat[i], one.nav.lat, rtol=0, atol=1e-7)
        np.testing.assert_array_equal(batch.reacquisition.event[i], one.reacquisition.event)
    before = navigate_tight._cache_size()
    navigate_tight(pm, v, dataclasses.replace(cfg, reacquire_gate=20.0, reacquire_ratio=5.0,
                                              reacquire_sigma_m=(3000.0,),
                                              reacquire_sigma_vel=0.2))
    assert navigate_tight._cache_size() == before
