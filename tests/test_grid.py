"""Grid: sampling against paper A's formula and SciPy, transformations, windows, I/O."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import RegularGridInterpolator
from scipy.sparse.linalg import spsolve

import jaxgrav as jg
from jaxgrav.fields import pointmass
from jaxgrav.fields.spectral import upward_continue_grid

LAT = np.linspace(24.0, 36.0, 25)
LON = np.linspace(124.0, 136.0, 25)


@pytest.fixture(scope="module")
def field():
    rng = np.random.default_rng(0)
    return rng.normal(size=(25, 25)) * 30.0


@pytest.fixture(scope="module")
def grid(field):
    return jg.Grid.from_arrays(LAT, LON, field, name="gravity_anomaly", units="mGal")


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(1)
    return rng.uniform(24, 36, 500), rng.uniform(124, 136, 500)


def test_bilinear_is_paper_a_formula(grid, field, points):
    lat, lon = points
    L = 0.5
    i = np.minimum(np.floor((lat - 24) / L).astype(int), 23)
    j = np.minimum(np.floor((lon - 124) / L).astype(int), 23)
    hx, hy = lon - LON[j], lat - LAT[i]  # offsets east and north within the cell
    g_a, g_b = field[i, j], field[i + 1, j]  # A (0,0), B (0,L): north of A
    g_c, g_d = field[i + 1, j + 1], field[i, j + 1]  # C (L,L), D (L,0): east of A
    paper = (
        g_a * (L - hx) * (L - hy) + g_b * (L - hx) * hy + g_c * hx * hy + g_d * hx * (L - hy)
    ) / L**2
    np.testing.assert_allclose(grid.sample(lat, lon), paper, rtol=1e-12, atol=1e-10)


@pytest.mark.parametrize(("method", "scipy_method"), [("bilinear", "linear"), ("bicubic", "cubic")])
def test_sample_matches_scipy(grid, field, points, method, scipy_method):
    lat, lon = points
    ref = (
        RegularGridInterpolator((LAT, LON), field, method=scipy_method, solver=spsolve)
        if scipy_method == "cubic"
        else RegularGridInterpolator((LAT, LON), field)
    )
    np.testing.assert_allclose(
        grid.sample(lat, lon, method), ref(np.c_[lat, lon]), rtol=1e-10, atol=1e-9
    )


def test_exact_on_polynomials():
    yy, xx = np.meshgrid(LAT - 30, LON - 130, indexing="ij")
    lin = jg.Grid.from_arrays(LAT, LON, 2 + 3 * yy - xx + 0.5 * xx * yy)
    cub = jg.Grid.from_arrays(LAT, LON, yy**3 - 2 * xx**3 + xx**2 * yy + 0.3 * xx**3 * yy**3)
    rng = np.random.default_rng(3)
    la, lo = rng.uniform(24, 36, 200), rng.uniform(124, 136, 200)
    y, x = la - 30, lo - 130
    np.testing.assert_allclose(lin.sample(la, lo), 2 + 3 * y - x + 0.5 * x * y, atol=1e-10)
    np.testing.assert_allclose(
        cub.sample(la, lo, "bicubic"), y**3 - 2 * x**3 + x**2 * y + 0.3 * x**3 * y**3, atol=1e-8
    )


def test_descending_and_longitude_conventions(field, points):
    lat, lon = points
    asc = jg.Grid.from_arrays(LAT, LON, field)
    desc = jg.Grid.from_arrays(LAT[::-1], LON[::-1], field[::-1, ::-1])
    assert desc.lat0 == 24.0 and desc.dlat > 0
    np.testing.assert_allclose(desc.sample(lat, lon), asc.sample(lat, lon), atol=1e-12)
    # points in the ±180 convention on a 0-360 grid, and the reverse
    np.testing.assert_allclose(asc.sample(lat, lon - 360.0), asc.sample(lat, lon), atol=1e-12)
    with pytest.raises(ValueError, match="lon must lie within"):
        jg.Grid.from_arrays(LAT, LON - 360.0, field)  # -236..-224 is in neither convention
    g180 = jg.Grid.from_arrays(LAT, np.linspace(-10, 10, 25), field)
    np.testing.assert_allclose(g180.sample(30.0, 355.0), g180.sample(30.0, -5.0), atol=1e-12)


def test_off_grid_nan_mask_and_strict(grid):
    lat = np.array([30.0, 23.9, 36.0, 30.0])
    lon = np.array([130.0, 130.0, 136.0, 137.0])
    v = np.asarray(grid.sample(lat, lon, "bicubic"))
    np.testing.assert_array_equal(np.isnan(v), [False, True, False, True])
    np.testing.assert_array_equal(grid.contains(lat, lon), [True, False, True, False])
    with pytest.raises(ValueError, match=r"lat=23.9.*outside the grid"):
        grid.sample(lat, lon, strict=True)
    with pytest.raises(ValueError, match="strict=True needs concrete"):
        jax.jit(lambda a, b: grid.sample(a, b, strict=True))(lat, lon)
    with pytest.raises(ValueError, match="method"):
        grid.sample(30.0, 130.0, "nearest")


def test_channels_are_interpolated_together(field, points):
    lat, lon = points
    stack = jg.Grid.from_arrays(LAT, LON, np.stack([field, 2 * field + 1]))
    one = jg.Grid.from_arrays(LAT, LON, field)
    for m in ("bilinear", "bicubic"):
        out = stack.sample(lat, lon, m)
        assert out.shape == (2, 500)
        np.testing.assert_allclose(out[1], 2 * one.sample(lat, lon, m) + 1, atol=1e-9)


@pytest.mark.parametrize("method", ["bilinear", "bicubic"])
@pytest.mark.long
def test_jit_no_retrace_vmap_equals_loop(grid, points, method):
    traces = []

    @jax.jit
    def f(g, la, lo):
        traces.append(1)
        return g.sample(la, lo, method)

    lat, lon = (jnp.asarray(a[:50]) for a in points)
    f(grid, lat, lon)
    new_values = jg.Grid.from_arrays(
        LAT, LON, np.asarray(grid.values) + 1.0, name=grid.name, units=grid.units
    )
    f(new_values, lat + 0.01, lon - 0.01)
    assert len(traces) == 1
    batched = jax.vmap(lambda la, lo: grid.sample(la, lo, method))(lat, lon)
    looped = np.array([grid.sample(a, b, method) for a, b in zip(lat, lon, strict=True)])
    np.testing.assert_allclose(batched, looped, atol=1e-12)
    # vmap over a batch of maps
    maps = jnp.stack([grid.values, 2 * grid.values])
    per_map = jax.vmap(
        lambda v: jg.Grid(v, grid.lat0, grid.dlat, grid.lon0, grid.dlon).sample(lat, lon, method)
    )(maps)
    np.testing.assert_allclose(per_map[1], 2 * per_map[0], atol=1e-9)


@pytest.mark.parametrize("method", ["bilinear", "bicubic"])
@pytest.mark.long
def test_grad_in_points_and_values(grid, method):
    lat0, lon0 = 30.123, 131.377  # inside a cell, away from nodes
    f = lambda la, lo: grid.sample(la, lo, method)  # noqa: E731
    # one reverse-mode program for the points and the values (the grid is an argument)
    grad = jax.grad(lambda g, la, lo: g.sample(la, lo, method), argnums=(0, 1, 2))
    g_grid, *g_rev = grad(grid, lat0, lon0)
    g_fwd = jax.jacfwd(f, argnums=(0, 1))(lat0, lon0)
    eps = 1e-6
    fd = (
        (f(lat0 + eps, lon0) - f(lat0 - eps, lon0)) / (2 * eps),
        (f(lat0, lon0 + eps) - f(lat0, lon0 - eps)) / (2 * eps),
    )
    for r, fw, d in zip(g_rev, g_fwd, fd, strict=True):
        np.testing.assert_allclose(r, fw, rtol=1e-10)
        np.testing.assert_allclose(r, d, rtol=1e-5)
    # in the values: sampling is linear in them, so the gradient is the weight vector
    assert (grid.lat0, grid.dlat, grid.lon0, grid.dlon) == (24.0, 0.5, 124.0, 0.5)
    np.testing.assert_allclose(jnp.sum(g_grid.values), 1.0, atol=1e-10)  # weights sum to one
    # finite gradient even for an off-grid point (NaN value, zero gradient)
    assert np.all(np.isfinite(grad(grid, 40.0, 130.0)[1]))


def test_refine_paper_a_factor_100():
    coarse = jg.Grid.from_arrays(LAT, LON, np.random.default_rng(5).normal(size=(25, 25)))
    fine = coarse.refine(100)
    assert fine.values.shape == (2401, 2401)
    np.testing.assert_allclose(fine.dlat, 0.005)
    np.testing.assert_allclose(fine.values[::100, ::100], coarse.values, atol=1e-12)
    rng = np.random.default_rng(6)
    r, c = rng.integers(0, 2401, 50), rng.integers(0, 2401, 50)
    np.testing.assert_allclose(
        fine.values[r, c], coarse.sample(fine.lat[r], fine.lon[c]), atol=1e-10
    )
    fine3 = coarse.refine(7, "bicubic")
    r, c = rng.integers(0, fine3.ny, 50), rng.integers(0, fine3.nx, 50)
    np.testing.assert_allclose(
        fine3.values[r, c], coarse.sample(fine3.lat[r], fine3.lon[c], "bicubic"), atol=1e-10
    )


@pytest.mark.parametrize("bad", [0, -2, 1.5, "2", True])
def test_refine_rejects_bad_factor(grid, bad):
    with pytest.raises(ValueError, match="factor"):
        grid.refine(bad)


def test_window(grid, field):
    w = grid.window(np.array([30.0, 24.2, 35.9]), np.array([130.2, 130.0, 135.9]), 3)
    assert w.values.shape == (3, 7, 7)
    np.testing.assert_array_equal(w.complete, [True, False, False])
    np.testing.assert_array_equal(w.row0, [9, 0, 18])
    np.testing.assert_array_equal(w.col0, [9, 9, 18])
    np.testing.assert_allclose(w.values[0], field[9:16, 9:16])
    np.testing.assert_allclose(w.values[1], field[0:7, 9:16])
    with pytest.raises(ValueError, match="half_size"):
        grid.window(30.0, 130.0, 13)
    wj = jax.jit(lambda la, lo: grid.window(la, lo, 2))(jnp.array([30.0]), jnp.array([130.0]))
    np.testing.assert_allclose(wj.values[0], field[10:15, 10:15])


def test_gradient_on_linear_field():
    vals = np.broadcast_to(3.0 * (LAT[:, None] - 30.0) + 0.0 * LON, (25, 25))
    dn, de = jg.Grid.from_arrays(LAT, LON, vals, units="mGal").gradient()
    expected = 3.0 / (np.asarray(jg.meridian_radius(LAT)) * np.deg2rad(1.0))
    np.testing.assert_allclose(dn.values, np.broadcast_to(expected[:, None], (25, 25)), rtol=1e-12)
    np.testing.assert_allclose(de.values, 0.0, atol=1e-15)
    assert dn.units == "mGal/m"


def test_netcdf_roundtrip_and_overwrite(tmp_path, grid):
    path = tmp_path / "map.nc"
    grid.to_netcdf(path, attrs={"source": "test"})
    back = jg.Grid.from_netcdf(path)
    np.testing.assert_allclose(back.values, grid.values)
    assert (back.lat0, back.dlat, back.name, back.units) == (24.0, 0.5, "gravity_anomaly", "mGal")
    with xr.open_dataset(path) as ds:
        assert ds.attrs["source"] == "test" and ds["lat"].attrs["units"] == "degrees_north"
    with pytest.raises(FileExistsError, match="force=True"):
        grid.to_netcdf(path)
    grid.to_netcdf(path, force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.nc"]  # no temp file left


def test_reads_gmt_style_file(tmp_path, field):
    # GMT writes x/y coordinates, a variable called z, latitudes often descending
    ds = xr.Dataset({"z": (("y", "x"), field[::-1])}, coords={"y": LAT[::-1], "x": LON})
    ds.to_netcdf(tmp_path / "gmt.nc")
    g = jg.Grid.from_netcdf(tmp_path / "gmt.nc")
    np.testing.assert_allclose(g.values, field)
    ds2 = xr.Dataset(
        {"a": (("lat", "lon"), field), "b": (("lat", "lon"), field)},
        coords={"lat": LAT, "lon": LON},
    )
    ds2.to_netcdf(tmp_path / "two.nc")
    with pytest.raises(ValueError, match="choose one with --var NAME"):
        jg.Grid.from_netcdf(tmp_path / "two.nc")
    np.testing.assert_allclose(jg.Grid.from_netcdf(tmp_path / "two.nc", var="b").values, field)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        jg.Grid.from_netcdf(tmp_path / "missing.nc")


def test_from_arrays_rejects_bad_maps(field):
    with pytest.raises(ValueError, match="values must be finite"):
        jg.Grid.from_arrays(LAT, LON, np.where(field > 40, np.nan, field))
    with pytest.raises(ValueError, match="values must have shape"):
        jg.Grid.from_arrays(LAT, LON, field[:, :-1])
    with pytest.raises(ValueError, match="lat must be strictly monotonic and regularly"):
        jg.Grid.from_arrays(np.r_[LAT[:-1], 36.7], LON, field)
    with pytest.raises(ValueError, match="lat must be a latitude"):
        jg.Grid.from_arrays(LAT + 60, LON, field)
    with pytest.raises(ValueError, match="lon must lie within"):
        jg.Grid.from_arrays(LAT, np.linspace(-400, -300, 25), field)


@settings(max_examples=30, deadline=None)
@given(
    st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=8).filter(
        lambda v: np.ptp(np.diff(v)) > 1e-3 if len(v) > 2 else False
    )
)
def test_irregular_coordinates_rejected(coords):
    with pytest.raises(ValueError, match="lon"):
        jg.Grid.from_arrays(np.linspace(0, 1, 3), np.asarray(coords), np.zeros((3, len(coords))))


@settings(max_examples=15, deadline=None)
@given(st.integers(1, 4), st.integers(1, 4))
def test_sample_rejects_mismatched_lengths(n, m):
    g = jg.Grid.from_arrays(LAT, LON, np.zeros((25, 25)))
    if n != m and 1 not in (n, m):
        with pytest.raises(ValueError, match="matching"):
            g.sample(np.full(n, 30.0), np.full(m, 130.0))
    else:
        assert np.shape(g.sample(np.full(n, 30.0), np.full(m, 130.0))) == (max(n, m),)


def test_upward_continue_wrapper_matches_point_mass_field():
    masses = pointmass.PointMasses.create(30.0, 130.0, 3000.0, 5e12)
    lat = np.linspace(29.7, 30.3, 61)
    lon = np.linspace(129.65, 130.35, 61)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    g0 = jg.Grid.from_arrays(lat, lon, pointmass.gravity_anomaly(masses, la, lo, 0.0))
    up = upward_continue_grid(g0, 1000.0)
    with pytest.warns(DeprecationWarning, match="upward_continue_grid"):
        old = g0.upward_continue(1000.0)
    np.testing.assert_array_equal(np.asarray(old.values), np.asarray(up.values))
    exact = np.asarray(pointmass.gravity_anomaly(masses, la, lo, 1000.0))
    inner = (slice(15, 46), slice(15, 46))
    peak = np.abs(exact).max()
    assert np.max(np.abs(np.asarray(up.values)[inner] - exact[inner])) < 0.02 * peak
    assert up.dlat == g0.dlat and float(up.values.max()) < float(g0.values.max())
