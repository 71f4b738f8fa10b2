"""Missing (NaN) map nodes as a mask: interpolation, refinement, matchers and filters.

A missing node (land on a marine grid, a hole in a survey) masks exactly the cells it is
a corner of; it must not spread (the spline slopes and the refinement are global linear
maps, in which one NaN poisons whole rows), and the methods mask what touches it and
flag it, never returning NaN.
"""

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrav as jg
import jaxgrav.match as jm
from jaxgrav import interp
from jaxgrav.filters import STATUS_FILTER, filter_track
from jaxgrav.match import shifted_tracks
from jaxgrav.match.api import MASKED, missing_in_reach

RNG = np.random.default_rng(7)


def _field(ny=40, nx=50):
    y, x = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    return np.sin(x / 5.0) + np.cos(y / 7.0) + 0.1 * x * y / 100.0


def _holey(v):
    v = v.copy()
    v[10:14, 20:30] = np.nan  # an island
    v[0, :] = np.nan  # a missing edge row
    v[:, 45] = np.nan  # a missing column
    return v


def _touches(v, iy, ix):
    """Brute force: does the cell of each point have a missing corner?"""
    r, c = np.floor(iy).astype(int), np.floor(ix).astype(int)
    return ~(np.isfinite(v[r, c]) & np.isfinite(v[r + 1, c]) & np.isfinite(v[r, c + 1])
             & np.isfinite(v[r + 1, c + 1]))


@pytest.mark.long
def test_bicubic_masks_exactly_the_cells_touching_a_missing_node():
    full = _field()
    holey = _holey(full)
    iy, ix = RNG.uniform(0, 39, 20000), RNG.uniform(0, 49, 20000)
    # one program each, for both maps (op by op: 3.5 s)
    coefficients, bicubic = jax.jit(interp.bicubic_coefficients), jax.jit(interp.bicubic)
    coef = coefficients(jnp.asarray(holey))
    a = np.asarray(bicubic(coef, iy, ix))
    np.testing.assert_array_equal(np.isnan(a), _touches(holey, iy, ix))
    # at the present nodes (of unmasked cells), the node values exactly
    r, c = np.nonzero(np.isfinite(holey[:-1, :-1]))
    r, c = r[~_touches(holey, r, c)], c[~_touches(holey, r, c)]
    np.testing.assert_allclose(np.asarray(bicubic(coef, r, c)), holey[r, c], rtol=1e-6)
    # the missing nodes' influence decays by ~0.27 per node: far from them, the same
    # interpolant as the complete map's
    b = np.asarray(bicubic(coefficients(jnp.asarray(full)), iy, ix))
    rr, cc = np.floor(iy).astype(int), np.floor(ix).astype(int)
    far = ((np.abs(rr - 11.5) > 10) & (rr > 10) & (np.abs(cc - 45) > 10)
           & ((cc < 10) | (rr > 24)))
    assert far.sum() > 1000
    assert np.max(np.abs(a[far] - b[far])) < 2e-4


@pytest.mark.long
def test_value_and_gradient_masked_and_gradients_finite():
    holey = jnp.asarray(_holey(_field()))
    iy, ix = RNG.uniform(0, 39, 3000), RNG.uniform(0, 49, 3000)
    coef = interp.bicubic_coefficients(holey)
    v, d_y, d_x = interp.bicubic_value_and_gradient(coef, iy, ix)
    masked = _touches(np.asarray(holey), iy, ix)
    np.testing.assert_array_equal(np.isnan(np.asarray(v)), masked)
    assert np.all(np.asarray(d_y)[masked] == 0) and np.all(np.asarray(d_x)[masked] == 0)
    # reverse mode through the mask: finite in the points outside the masked cells (NaN
    # inside them: no masking of the coefficients on this hot path) and in the present values
    g_pts = jax.grad(lambda t: jnp.nansum(interp.bicubic(coef, t, ix)))(jnp.asarray(iy))
    assert np.isfinite(np.asarray(g_pts)[~masked]).all()
    g_vals = jax.grad(lambda vals: jnp.nansum(
        interp.bicubic(interp.bicubic_coefficients(vals), iy, ix)))(holey)
    assert np.isfinite(np.asarray(g_vals)[np.isfinite(np.asarray(holey))]).all()
    # and jit gives what eager gives
    np.testing.assert_allclose(np.asarray(jax.jit(interp.bicubic_coefficients)(holey)),
                               np.asarray(coef), rtol=1e-5, atol=1e-9)


def test_fill_missing_is_finite_and_linear_between_present_nodes():
    v = np.array([[1.0, np.nan, np.nan, 4.0, np.nan],
                  [np.nan] * 5,
                  [2.0, 2.0, np.nan, 2.0, 2.0]])
    fill = jax.jit(interp.fill_missing)  # one program per shape (op by op: 2.0 s)
    f = np.asarray(fill(jnp.asarray(v)))
    np.testing.assert_allclose(f[0], [1, 2, 3, 4, 4])  # between, then constant beyond
    np.testing.assert_allclose(f[1], [1.5, 2, 0, 3, 2])  # an empty row: along columns (0: none)
    np.testing.assert_allclose(f[2], 2.0)
    assert np.isfinite(np.asarray(fill(jnp.full((4, 4), jnp.nan)))).all()


def test_refined_keeps_the_mask_without_spreading_it():
    full = _field(12, 14)
    holey = full.copy()
    holey[5, 6] = np.nan
    complete = jg.Grid.from_arrays(np.arange(12.0), np.arange(14.0), full)
    ref = np.asarray(dataclasses.replace(complete, values=jnp.asarray(holey)).refine(4).values)
    ref_full = np.asarray(complete.refine(4).values)
    y, x = np.meshgrid(np.arange(ref.shape[0]) / 4, np.arange(ref.shape[1]) / 4, indexing="ij")
    touched = (np.abs(y - 5) < 1) & (np.abs(x - 6) < 1)  # bilinear: the four cells around it
    np.testing.assert_array_equal(np.isnan(ref), touched)
    np.testing.assert_allclose(ref[~touched], ref_full[~touched], rtol=1e-6)


# ---------------------------------------------------------------------------- matchers
TRUTH_OFFSET = (-1500.0, 1000.0)  # m north, east of the INS track


@pytest.fixture(scope="module")
def scene(smooth_grid):
    lat = 29.9 + 0.002 * np.arange(20)
    lon = 129.85 + 0.003 * np.arange(20)
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), *TRUTH_OFFSET, 0.0)
    z = np.asarray(smooth_grid.sample(t_lat, t_lon, "bicubic"))
    return lat, lon, z, np.asarray(t_lat), np.asarray(t_lon)


def _with_hole(grid, lat_range, lon_range):
    la, lo = np.asarray(grid.lat), np.asarray(grid.lon)
    rows = (la >= lat_range[0]) & (la <= lat_range[1])
    cols = (lo >= lon_range[0]) & (lo <= lon_range[1])
    v = np.array(grid.values)
    v[np.ix_(rows, cols)] = np.nan
    return dataclasses.replace(grid, values=jnp.asarray(v))


def _error_m(r, t_lat, t_lon):
    dn = (np.asarray(r.lat) - t_lat) * 111.2e3
    de = (np.asarray(r.lon) - t_lon) * 111.2e3 * np.cos(np.radians(30.0))
    return float(np.max(np.hypot(dn, de)))


@pytest.mark.parametrize("method", ["dense", "chains", "entropy+iccp"])
@pytest.mark.long
def test_matchers_mask_candidates_on_missing_nodes_and_flag_them(smooth_grid, scene, method):
    lat, lon, z, t_lat, t_lon = scene
    # a hole 1.5-3 km north of the INS track: inside the search region (3 km), far from
    # the truth (1.5 km south)
    holey = _with_hole(smooth_grid, (lat.max() + 0.014, lat.max() + 0.027), (129.8, 129.95))
    assert missing_in_reach(holey, lat, lon, 3000.0) > 0
    assert missing_in_reach(holey, lat, lon, 500.0) == 0
    grid = holey.refine(2) if method == "chains" else holey
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        r = jm.match_track(grid, lat, lon, z, method=method, drift_radius_m=3000.0, noise=0.5)
        ref = jm.match_track(smooth_grid.refine(2) if method == "chains" else smooth_grid,
                             lat, lon, z, method=method, drift_radius_m=3000.0, noise=0.5)
    assert int(r.status) & MASKED and not int(ref.status) & MASKED
    assert not int(r.status) & 1
    assert np.isfinite(np.asarray(r.lat)).all() and np.isfinite(float(r.score))
    assert _error_m(r, t_lat, t_lon) < max(2.0 * _error_m(ref, t_lat, t_lon), 300.0)


@pytest.mark.long
def test_dense_with_the_truth_masked_returns_a_finite_flagged_fix(smooth_grid, scene):
    lat, lon, z, t_lat, t_lon = scene
    holey = _with_hole(smooth_grid, (t_lat.min() - 0.005, t_lat.max() + 0.005),
                       (t_lon.min() - 0.005, t_lon.min() + 0.02))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        r = jm.match_track(holey, lat, lon, z, drift_radius_m=3000.0, noise=0.5,
                           missing="land")
    assert int(r.status) & MASKED
    for k in ("lat", "lon", "offset_north_m", "offset_east_m", "bias"):
        assert np.isfinite(np.asarray(getattr(r, k))).all(), k
    # the truth is not available: the best of the rest fits badly, and says so
    assert not np.isfinite(float(r.score)) or float(r.chi2_per_dof) > 3.0


# ----------------------------------------------------------------------------- filters
@pytest.mark.parametrize("method", ["ukf", "pf", "pmf"])
@pytest.mark.long
def test_filters_skip_or_mask_missing_cells_and_flag_them(smooth_grid, method):
    n = 240
    t = 10.0 * np.arange(n)
    lat = np.full(n, 30.0)
    lon = 129.7 + 0.0005 * np.arange(n)  # east at ~5 m/s
    z = np.asarray(smooth_grid.sample(lat - 0.003, lon, "bicubic"))
    holey = _with_hole(smooth_grid, (29.985, 30.02), (129.74, 129.76))
    res = filter_track(holey, t, lat, lon, z + 0.3 * RNG.standard_normal(n), method,
                       sigma_pos=500.0, sigma_gravity=0.5, n_particles=500
                       if method == "pf" else None)
    status = np.asarray(res["status"])
    off = (status & STATUS_FILTER["off_map"]) > 0
    assert off.any()  # the hole was met, and said so per row
    for k in ("lat", "lon", "sigma_north", "sigma_east"):
        assert np.isfinite(np.asarray(res[k])).all(), k
    innovation = np.asarray(res["innovation"])[off]
    if method == "ukf":  # a skipped update has no innovation
        assert np.isnan(innovation).all()
    else:  # pmf cells, pf particles without a map value take the others' mean likelihood:
        # the reading is used while some have one
        assert np.isfinite(innovation).any()


@pytest.mark.long
def test_pmf_reads_a_coast_as_land_without_dropping_the_truth(smooth_grid):
    """filter_track(..., "pmf", missing="land") end to end: every node from 30.01° N is
    land, 1.4 km north of a truth at 29.997° N whose own interpolation cell holds a land
    node (a gap: its nearest node is at sea). Land changes the posterior (the plumbing
    is used) and keeps the truth within 3 σ; counting every cell without a map value as
    land dropped such a truth (the review's 3 km case: 4 σ off, NEES 20)."""
    n = 240
    t = 10.0 * np.arange(n)
    lat = np.full(n, 30.0)
    lon = 129.7 + 0.0005 * np.arange(n)
    truth_lat = lat - 0.003
    z = np.asarray(smooth_grid.sample(truth_lat, lon, "bicubic"))
    coast = _with_hole(smooth_grid, (30.005, 31.0), (129.0, 131.0))
    noisy = z + 0.3 * RNG.standard_normal(n)
    res = {m: filter_track(coast, t, lat, lon, noisy, "pmf", sigma_pos=500.0,
                           sigma_gravity=0.5, missing=m) for m in ("gaps", "land")}
    assert not np.allclose(res["land"]["lat"], res["gaps"]["lat"])
    land = res["land"]
    dn = (land["lat"] - truth_lat) * 111.2e3
    de = (land["lon"] - lon) * 111.2e3 * np.cos(np.radians(30.0))
    assert np.all(np.abs(dn[-60:]) < 3 * land["sigma_north"][-60:]), dn[-60:]
    assert np.all(np.abs(de[-60:]) < 3 * land["sigma_east"][-60:]), de[-60:]
