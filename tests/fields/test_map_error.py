"""Map-error models: drawn error statistics, explicit truth grids, transformations, covariance.

Statistical bounds come from the Monte Carlo spread: each estimate is averaged over
independent draws and compared with the model within 5 standard errors of that
average (the standard error estimated from the draws' spread).
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

# names imported from the module itself: a package-level export of the function map_error
# would shadow the module attribute jaxgrav.fields.map_error
from jaxgrav.fields.map_error import (
    FAMILIES,
    CorrelatedMapError,
    along_track_covariance,
    check_covers,
    map_error,
    map_error_key,
    truth_field,
    truth_grid,
)
from jaxgrav.grid import Grid

SIGMA = 2.0  # mGal
LENGTH = 3000.0  # m


def _grid(n, step, lat0=30.0, lon0=130.0, values=None):
    lat = lat0 + step * np.arange(n)
    lon = lon0 + step * np.arange(n)
    if values is None:
        y, x = np.meshgrid(lat - lat0, lon - lon0, indexing="ij")
        values = 30.0 * np.sin(7.0 * x + 1.0) * np.cos(5.0 * y) + 10.0 * x
    return Grid.from_arrays(lat, lon, values, units="mGal")


STATS_MAP = _grid(128, 0.01)  # 128 × 128 nodes, about 1.1 km × 0.95 km
SMALL_MAP = _grid(32, 0.02)  # transformations: cheap to compile


@pytest.fixture(scope="module")
def errors():
    """32 error draws per family on STATS_MAP: truth − map, shape (32, 128, 128)."""
    keys = jax.random.split(jax.random.key(0), 32)
    out = {}
    for family in FAMILIES:
        model = map_error(SIGMA, LENGTH, family=family)
        truth = jax.vmap(lambda k, m=model: truth_field(k, STATS_MAP, m).values)(keys)
        out[family] = np.asarray(truth) - np.asarray(STATS_MAP.values)
    return out


def _within_5_se(per_draw, expected):
    per_draw = np.asarray(per_draw)
    se = per_draw.std(ddof=1) / np.sqrt(per_draw.size)
    assert abs(per_draw.mean() - expected) < 5.0 * se, (per_draw.mean(), expected, se)


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_error_level_is_sigma(errors, family):
    err = errors[family]
    _within_5_se((err**2).mean(axis=(1, 2)), SIGMA**2)  # E[mean(f²)] = σ² exactly
    # the mean over the map is not removed: its variance is Σ_r C(r) / N over wrapped lags
    ny, nx = STATS_MAP.values.shape
    dy, dx = STATS_MAP.spacing_m()
    iy = np.minimum(np.arange(ny), ny - np.arange(ny)) * dy
    ix = np.minimum(np.arange(nx), nx - np.arange(nx)) * dx
    x = np.hypot(iy[:, None], ix[None, :]) / LENGTH
    rho = (1.0 + x if family == "markov2" else 1.0) * np.exp(-x)
    _within_5_se(err.mean(axis=(1, 2)) ** 2, SIGMA**2 * rho.sum() / (ny * nx))


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_covariance_at_lags_matches_model(errors, family):
    err = errors[family]
    model = map_error(SIGMA, LENGTH, family=family)
    dy, dx = STATS_MAP.spacing_m()
    var = (err**2).mean(axis=(1, 2))
    for axis, step in ((1, dy), (2, dx)):
        for lag in range(1, 5):
            corr = (err * np.roll(err, lag, axis=axis)).mean(axis=(1, 2)) / var
            _within_5_se(corr, float(model.covariance(lag * step)) / SIGMA**2)
            # covariance itself (noisier: the variance of each draw fluctuates)
            cov = (err * np.roll(err, lag, axis=axis)).mean(axis=(1, 2))
            _within_5_se(cov, float(model.covariance(lag * step)))


def test_families_differ_at_the_measured_lags(errors):
    m1 = map_error(SIGMA, LENGTH, family="markov1")
    m2 = map_error(SIGMA, LENGTH, family="markov2")
    dy, _ = STATS_MAP.spacing_m()
    for family, other in (("markov1", m2), ("markov2", m1)):
        err = errors[family]
        corr = (err * np.roll(err, 4, axis=1)).mean() / (err**2).mean()
        assert abs(corr - float(other.covariance(4 * dy)) / SIGMA**2) > 0.2


def test_truth_has_the_maps_geometry():
    truth = truth_field(jax.random.key(1), SMALL_MAP, map_error(SIGMA, 5000.0))
    assert isinstance(truth, Grid)
    for name in ("lat0", "dlat", "lon0", "dlon", "name", "units"):
        assert getattr(truth, name) == getattr(SMALL_MAP, name)
    assert truth.values.shape == SMALL_MAP.values.shape
    assert truth.values.dtype == SMALL_MAP.values.dtype
    assert not np.allclose(truth.values, SMALL_MAP.values)
    single = dataclasses.replace(SMALL_MAP, values=SMALL_MAP.values.astype(np.float32))
    truth32 = truth_field(jax.random.key(1), single, map_error(SIGMA, 5000.0))
    assert truth32.values.dtype == np.float32
    np.testing.assert_allclose(truth32.values, truth.values, rtol=1e-6, atol=1e-4)


TRACES = []


@jax.jit
def _draw_jit(key, model):
    TRACES.append(1)
    return truth_field(key, SMALL_MAP, model).values


def test_perfect_map_is_the_map():
    key = jax.random.key(2)
    assert truth_field(key, SMALL_MAP, None) is SMALL_MAP
    assert truth_field(key, SMALL_MAP, map_error(0.0, 5000.0)) is SMALL_MAP
    traced = _draw_jit(key, map_error(0.0, 5000.0))  # σ traced: added error is exactly 0
    np.testing.assert_array_equal(traced, SMALL_MAP.values)


def test_truth_grid_is_returned_when_it_covers_the_map():
    finer = _grid(161, 0.005, lat0=29.9, lon0=129.9)  # covers SMALL_MAP (30..30.62)
    truth = truth_field(jax.random.key(3), SMALL_MAP, truth_grid(finer, map_grid=SMALL_MAP))
    assert truth is finer
    same = truth_field(None, SMALL_MAP, truth_grid(SMALL_MAP))  # edges exactly equal
    assert same is SMALL_MAP
    # another longitude convention: map in ±180, truth in 0–360
    west = _grid(8, 0.1, lat0=10.0, lon0=-170.0)
    wide = _grid(20, 0.1, lat0=9.5, lon0=189.5)
    assert truth_field(None, west, truth_grid(wide)) is wide


def test_truth_grid_that_does_not_cover_the_map_is_refused():
    small = _grid(10, 0.02, lat0=30.1, lon0=130.1)
    with pytest.raises(ValueError, match=r"model\.grid .*must cover the map's area.*lat 30\.1"):
        truth_field(None, SMALL_MAP, truth_grid(small))
    with pytest.raises(ValueError, match=r"^grid must cover the map's area \(lat 30\.\.30\.62"):
        truth_grid(small, map_grid=SMALL_MAP)
    shifted = _grid(32, 0.02, lat0=30.0, lon0=130.05)  # same size, 0.05° east
    with pytest.raises(ValueError, match="must cover"):
        check_covers(shifted, SMALL_MAP)
    with pytest.raises(TypeError, match="grid must be a jaxgrav Grid"):
        truth_grid(np.zeros((3, 3)))
    with pytest.raises(TypeError, match="error must be a CorrelatedMapError"):
        truth_grid(SMALL_MAP, error=(1.0, 2.0))


def test_vmap_over_keys_equals_the_loop():
    model = map_error(SIGMA, 5000.0)
    keys = jax.random.split(jax.random.key(4), 3)
    batched = jax.vmap(lambda k: truth_field(k, SMALL_MAP, model).values)(keys)
    loop = np.stack([truth_field(k, SMALL_MAP, model).values for k in keys])
    np.testing.assert_allclose(batched, loop, rtol=0, atol=1e-12)
    assert not np.allclose(batched[0], batched[1])  # one field per run
    # a batch-level draw: the same key gives the same field
    again = truth_field(keys[0], SMALL_MAP, model).values
    np.testing.assert_array_equal(again, loop[0])


def test_jit_does_not_retrace_when_sigma_or_length_change():
    key = jax.random.key(5)
    a = _draw_jit(key, map_error(1.0, 5000.0))
    n_traces = len(TRACES)  # 1, or 0 new if test_perfect_map_is_the_map traced it already
    b = _draw_jit(key, map_error(2.5, 5000.0))
    c = _draw_jit(key, map_error(1.0, 9000.0))
    assert len(TRACES) == n_traces == 1
    np.testing.assert_allclose(b - SMALL_MAP.values, 2.5 * (a - SMALL_MAP.values), atol=1e-10)
    assert not np.allclose(c, a)
    eager = truth_field(key, SMALL_MAP, map_error(1.0, 9000.0)).values
    np.testing.assert_allclose(c, eager, atol=1e-10)


def test_grad_of_a_sampled_truth_value_matches_finite_differences():
    key = jax.random.key(6)
    lat, lon = 30.313, 130.271

    def value(sigma, length):
        model = CorrelatedMapError(sigma=sigma, length_m=length)
        return truth_field(key, SMALL_MAP, model).sample(lat, lon)

    both = jax.jit(jax.value_and_grad(value, argnums=(0, 1)))  # one compilation for all
    s, ell = 1.7, 6000.0
    g_s, g_l = both(s, ell)[1]
    assert np.isfinite(g_s) and np.isfinite(g_l) and g_s != 0 and g_l != 0
    h = 1e-3
    fd_s = (both(s + h, ell)[0] - both(s - h, ell)[0]) / (2 * h)
    fd_l = (both(s, ell + ell * h)[0] - both(s, ell - ell * h)[0]) / (2 * ell * h)
    np.testing.assert_allclose(g_s, fd_s, rtol=1e-8)
    np.testing.assert_allclose(g_l, fd_l, rtol=1e-5)


def _numpy_covariance(sigma, length, family, north, east):
    n = len(north)
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            x = np.hypot(north[i] - north[j], east[i] - east[j]) / length
            poly = 1.0 + x if family == "markov2" else 1.0
            out[i, j] = sigma**2 * poly * np.exp(-x)
    return out


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_along_track_covariance_equals_brute_force(family):
    t = np.arange(30) * 120.0  # 30 fixes 2 min apart, 10 kn N + 10 kn E
    north, east = 5.144 * t, 5.144 * t + 300.0 * np.sin(t / 900.0)
    model = map_error(3.0, 10_000.0, family=family)
    cov = np.asarray(along_track_covariance(model, north, east))
    assert cov.shape == (30, 30)
    np.testing.assert_allclose(cov, _numpy_covariance(3.0, 10_000.0, family, north, east),
                               rtol=1e-12, atol=0)
    np.testing.assert_array_equal(cov, cov.T)
    assert np.linalg.eigvalsh(cov).min() > -1e-9 * 9.0
    # batched tracks, perfect map, explicit truth with a stated error
    both = along_track_covariance(model, np.stack([north, north + 50.0]), east)
    assert both.shape == (2, 30, 30)
    np.testing.assert_allclose(both[1], cov, rtol=1e-12)
    np.testing.assert_array_equal(along_track_covariance(None, north, east), 0.0)
    stated = truth_grid(SMALL_MAP, error=model)
    np.testing.assert_array_equal(along_track_covariance(stated, north, east), cov)


def test_along_track_covariance_has_finite_gradients_at_zero_distance():
    model = map_error(3.0, 10_000.0, family="markov1")
    g = jax.grad(lambda n: along_track_covariance(model, n, jnp.zeros(3)).sum())(
        jnp.array([0.0, 0.0, 500.0]))
    assert np.all(np.isfinite(g))


def test_along_track_covariance_of_an_unknown_truth_is_refused():
    with pytest.raises(ValueError, match="TruthGrid without an error description"):
        along_track_covariance(truth_grid(SMALL_MAP), [0.0, 1.0], [0.0, 0.0])
    with pytest.raises(TypeError, match="model must be"):
        along_track_covariance("3 mGal", [0.0, 1.0], [0.0, 0.0])
    with pytest.raises(ValueError, match=r"north_m must be finite; found .*nan"):
        along_track_covariance(map_error(1.0, 1.0), [0.0, np.nan], [0.0, 0.0])
    with pytest.raises(ValueError, match=r"shape \(\.\.\., N\)"):
        along_track_covariance(map_error(1.0, 1.0), 0.0, 0.0)


@pytest.mark.parametrize("sigma", [-1.0, np.nan, np.inf, -np.inf])
def test_bad_sigma_is_refused(sigma):
    expected = rf"sigma must be finite and >= 0 \(map units\); got {sigma}"
    with pytest.raises(ValueError, match=expected):
        map_error(sigma, LENGTH)


@pytest.mark.parametrize("length", [0.0, -5.0, np.nan, np.inf])
def test_bad_length_is_refused(length):
    with pytest.raises(ValueError, match=rf"length_m must be finite and > 0 \(m\); got {length}"):
        map_error(SIGMA, length)


@pytest.mark.parametrize("bad", ["3", None, True, 1 + 2j, [1.0, "a"]])
def test_wrong_types_are_refused(bad):
    with pytest.raises(TypeError, match="sigma must be a real number"):
        map_error(bad, LENGTH)
    with pytest.raises(TypeError, match="length_m must be a real number"):
        map_error(SIGMA, bad)


def test_bad_family_model_and_grid_are_refused():
    expected = r"family must be one of \['markov1', 'markov2'\]; got 'gauss'"
    with pytest.raises(ValueError, match=expected):
        map_error(SIGMA, LENGTH, family="gauss")
    key = jax.random.key(7)
    with pytest.raises(TypeError, match="model must be a CorrelatedMapError"):
        truth_field(key, SMALL_MAP, 3.0)
    with pytest.raises(TypeError, match="grid must be a jaxgrav Grid"):
        truth_field(key, SMALL_MAP.values, map_error(SIGMA, LENGTH))
    with pytest.raises(ValueError, match="must be scalars"):
        truth_field(key, SMALL_MAP, map_error([1.0, 2.0], LENGTH))
    layered = dataclasses.replace(SMALL_MAP, values=jnp.stack([SMALL_MAP.values] * 2))
    expected = r"grid.values must be 2-D \(ny, nx\); got shape \(2, 32, 32\)"
    with pytest.raises(ValueError, match=expected):
        truth_field(key, layered, map_error(SIGMA, LENGTH))


def test_map_error_key_is_a_separate_stream():
    key = jax.random.key(8)
    k = map_error_key(key)
    assert not np.array_equal(jax.random.key_data(k), jax.random.key_data(key))
    again = map_error_key(key)
    np.testing.assert_array_equal(jax.random.key_data(again), jax.random.key_data(k))
    for sub in jax.random.split(key, 3):  # not one of the run's usual subkeys
        assert not np.array_equal(jax.random.key_data(k), jax.random.key_data(sub))
