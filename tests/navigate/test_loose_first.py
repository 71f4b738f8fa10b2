"""The dense loop's default settings (navigate.DENSE_LOOP): the first segments shorter
(LooseConfig.first_n_fixes), the lattice's cell told (LooseConfig.cell_error), and
loose_config's defaults per matcher."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.navigate import (
    DENSE_LOOP,
    LooseConfig,
    error_kf_tables,
    first_segment_ends,
    first_tables,
    loose_config,
    navigate_loose,
)
from jaxgrav.navigate.loose_match import segment_error_covariance
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import NAVIGATION_GRADE

FIELDS = ("segment_error", "fix_prior", "n_fixes", "stride", "fix_cov_scale", "cell_error",
          "first_n_fixes", "shape_update", "reacquire_after", "reacquire_inflation")


def _loop(cfg):
    return {k: getattr(cfg, k) for k in FIELDS}


def test_the_dense_default_is_the_conditional_loop_and_markov_the_old_one():
    assert _loop(loose_config()) == DENSE_LOOP
    old = loose_config(segment_error="markov")
    assert _loop(old) == {"segment_error": "markov", "fix_prior": False, "n_fixes": 30,
                          "stride": 30, "fix_cov_scale": 3.0, "cell_error": False,
                          "first_n_fixes": None, "shape_update": False,
                          "reacquire_after": None, "reacquire_inflation": 16.0}
    assert loose_config(reacquire_after=None).reacquire_after is None
    assert loose_config(fix_prior=False).fix_prior is False  # a change overrides
    assert loose_config(segment_error="linear").cell_error  # the rest of DENSE_LOOP
    assert loose_config(segment_error="linear").shape_update
    assert not loose_config(shape_update=False).shape_update
    assert loose_config(n_fixes=20, stride=20).first_n_fixes is None
    assert loose_config(first_n_fixes=30).first_n_fixes == 30
    assert loose_config(segment_error="markov", n_fixes=60, first_n_fixes=30).first_n_fixes == 30
    # the other matchers keep LooseConfig's own settings
    grid = _flat_grid()
    for matcher in ("chains", "entropy+iccp"):
        cfg = loose_config(matcher=matcher, grid=grid)
        assert cfg.segment_error == "markov" and cfg.n_fixes == 30 and not cfg.fix_prior


@pytest.mark.parametrize(("change", "message"), [
    ({"cell_error": True}, "cell_error needs the dense matcher and segment_error"),
    ({"segment_error": "conditional", "cell_error": True, "first_n_fixes": 4},
     "first_n_fixes must be None or an integer from 5"),
    ({"n_fixes": 30, "first_n_fixes": 31}, "first_n_fixes must be None or an integer from 5"),
])
def test_bad_first_segments_and_cell_error_are_named(change, message):
    with pytest.raises(ValueError, match=message):
        LooseConfig(**change)


def test_the_first_segments_are_the_ends_before_a_full_segment():
    cfg = LooseConfig(n_fixes=60, stride=30, first_n_fixes=30)
    assert first_segment_ends(cfg, 12) == 1 and first_segment_ends(cfg, 0) == 0
    assert first_segment_ends(dataclasses.replace(cfg, n_fixes=90), 12) == 2
    assert first_segment_ends(dataclasses.replace(cfg, first_n_fixes=None), 12) == 0
    assert first_segment_ends(LooseConfig(n_fixes=30, stride=30, first_n_fixes=30), 12) == 0
    tables = error_kf_tables(NAVIGATION_GRADE, 30.0, 10.0, 4, 24)
    short = first_tables(dataclasses.replace(cfg, fix_every=2, first_n_fixes=5), tables)
    assert short.backward.shape == (10, 13, 13)
    np.testing.assert_array_equal(short.backward, tables.backward[-10:])
    np.testing.assert_allclose(short.h_mean, jnp.mean(tables.backward[-10:, :2], axis=0))


def _flat_grid():
    import jaxgrav as jg
    lat, lon = np.linspace(29, 31, 21), np.linspace(129, 131, 21)
    values = 20.0 * np.sin(lat[:, None] * 3.0) + 10.0 * np.cos(lon[None, :] * 4.0)
    return jg.Grid.from_arrays(lat, lon, values, units="mGal")


def test_the_cell_is_told_through_the_map_gradient():
    """cell_m adds the offset's place within a lattice cell, uniform (cell²/12 per axis),
    read through the map's gradient: cell²/12 ∇m ∇mᵀ."""
    pm = prepare_map(_flat_grid())
    n = 6
    lat, lon = 30.0 + 0.01 * jnp.arange(n), jnp.full(n, 130.0) + 0.005 * jnp.arange(n)
    v = jnp.full(n, 5.0)
    rng = np.random.default_rng(0)
    b = jnp.asarray(rng.normal(size=(n, 4, 13)))
    h = jnp.asarray(rng.normal(size=(2, 13)))
    a = rng.normal(size=(13, 13))
    p = jnp.asarray(a @ a.T + 13 * np.eye(13))
    c0, _ = segment_error_covariance(pm, lat, lon, v, v, b, h, p)
    c1, _ = segment_error_covariance(pm, lat, lon, v, v, b, h, p, cell_m=2000.0)
    _, d_lat, d_lon = pm.value_and_gradient(lat, lon)
    from jaxgrav.constants import DEG
    from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
    grad = np.stack([d_lat / (meridian_radius(lat) * DEG),
                     d_lon / (prime_vertical_radius(lat) * np.cos(lat * DEG) * DEG)], -1)
    want = 2000.0**2 / 12.0 * grad @ grad.T
    np.testing.assert_allclose(c1 - c0, want, rtol=1e-6, atol=1e-6 * float(np.max(want)))
    assert float(jnp.max(jnp.abs(c1 - c0))) > 0.05  # mGal²: the term is there


@pytest.mark.long  # the loop compiles twice (the first segments' span and the full one)
def test_the_first_fix_comes_after_the_first_segment_not_a_full_one(smooth_grid):
    """2 h segments every hour: without first_n_fixes the first end (1 h) is not matched
    (event 1); with it the last first_n_fixes fixes are, and the hour's fix updates the
    filter (its 1-σ falls there)."""
    from tests.navigate.test_loose import CONFIG, voyage_preset, voyage_scenario
    from tests.navigate.test_loose import INS as STRATEGIC
    sc = voyage_preset("patrol-12h", ins=STRATEGIC, hours=2.0, region=(29.6, 30.4, 129.6, 130.4),
                       leg_m=20000.0, margin_deg=0.1, pos_error_m=1500.0)
    v = voyage_scenario(jax.random.split(jax.random.key(4), 2)[0], smooth_grid, sc)
    every = CONFIG.fix_every
    n_fix = round(3600.0 / (sc.dt * every))  # one hour of fixes
    cfg = dataclasses.replace(CONFIG, matcher=dataclasses.replace(
        CONFIG.matcher, score_model="gls", map_error_mgal=1.0), segment_error="conditional",
        fix_prior=True, fix_cov_scale=1.0, cell_error=True, n_fixes=2 * n_fix, stride=n_fix)
    pm = prepare_map(smooth_grid)
    late = navigate_loose(pm, v, cfg)
    early = navigate_loose(pm, v, dataclasses.replace(cfg, first_n_fixes=n_fix))
    assert int(late.fix_event[0]) == 1 and int(early.fix_event[0]) == 0
    end = n_fix * every
    sigma = lambda r: float(jnp.sqrt(jnp.trace(r.cov_north_east[end])))  # noqa: E731
    assert sigma(early) < 0.7 * sigma(late)
    # the later ends are matched on full segments either way
    assert int(early.fix_event[1]) in (0, 3, 4)


def test_the_cell_is_not_counted_twice_nor_the_fix_narrower_than_it():
    """less_cell: λ → max(λ − q, q) per eigenvalue, the axes kept: a wide posterior loses
    the cell's variance, a posterior one lattice row wide (the narrow axis at the
    quantisation term alone) keeps it (the loop's fix was singular there: NEES 10³)."""
    from jaxgrav.navigate import less_cell
    rng = np.random.default_rng(3)
    a = rng.normal(size=(2, 2))
    wide = jnp.asarray(a @ a.T * 1e4 + 500.0 * np.eye(2))
    np.testing.assert_allclose(less_cell(wide, 100.0), wide - 100.0 * jnp.eye(2), rtol=1e-6)
    rot = np.array([[np.cos(0.4), -np.sin(0.4)], [np.sin(0.4), np.cos(0.4)]])
    thin = jnp.asarray(rot @ np.diag([9e4, 120.0]) @ rot.T)
    out = np.asarray(less_cell(thin, 100.0))
    np.testing.assert_allclose(out, rot @ np.diag([9e4 - 100.0, 100.0]) @ rot.T, rtol=1e-6,
                               atol=1e-6)
    assert np.all(np.linalg.eigvalsh(out) >= 100.0 - 1e-6)


def test_less_cell_has_a_finite_gradient_at_a_round_covariance():
    """An isotropic covariance has no axis (arctan2(0, 0)): the value is max(λ − q, q) I
    and its derivative finite, equal to central differences (the suite runs in x64)."""
    from jaxgrav.navigate import less_cell
    weights = jnp.array([[1.0, 0.3], [0.3, 2.0]])
    f = lambda s: jnp.sum(less_cell(s * jnp.eye(2), 100.0) * weights)  # noqa: E731
    np.testing.assert_allclose(less_cell(900.0 * jnp.eye(2), 100.0), 800.0 * np.eye(2))
    g = float(jax.grad(f)(900.0))
    fd = (float(f(900.0 + 1e-3)) - float(f(900.0 - 1e-3))) / 2e-3
    assert np.isfinite(g) and g == pytest.approx(fd, rel=1e-6) and g == pytest.approx(3.0)
