"""Tests for jaxgrav.fields.harmonics against pyshtools (the independent reference).

pyshtools conventions used here: ``expand.MakeGridPoint`` evaluates a 4π-normalised
(``norm=1``), no-Condon–Shortley (``csphase=1``) expansion at (lat, lon);
``gravmag.MakeGravGridPoint`` returns ∇V as (r, θ, φ) components, θ the colatitude
(checked below by finite differences of pyshtools' own potential). Normal gravity for
the deflections comes from boule.
"""

import functools
import math

import boule
import jax
import jax.numpy as jnp
import numpy as np
import pyshtools as pysh
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgrav import constants as const
from jaxgrav.fields import harmonics as hm

GM, R = const.WGS84_GM, const.WGS84_A


def gamma_si(lat, h):
    """WGS84 normal gravity (m/s²) from boule, the independent reference."""
    lat, h = np.broadcast_arrays(np.asarray(lat, float), np.asarray(h, float))
    return boule.WGS84.normal_gravity((np.zeros_like(lat), lat, h), si_units=True)


def random_coeffs(nmax, seed=0):
    """Seeded random 4π coefficients decaying like a gravity field (Kaula-like)."""
    rng = np.random.default_rng(seed)
    n = np.arange(nmax + 1)[:, None]
    sigma = 1e-5 / np.maximum(n, 2) ** 2  # Kaula's rule for the coefficient RMS
    c = np.tril(rng.standard_normal((nmax + 1, nmax + 1)) * sigma)
    s = np.tril(rng.standard_normal((nmax + 1, nmax + 1)) * sigma)
    s[:, 0] = 0.0
    c[:2] = s[:2] = 0.0  # a disturbing potential has no degree 0/1 terms
    return c, s


def ref_potential(c, s, lat, lon, h):
    """T (m²/s²) from pyshtools, (R/r)^n applied to the coefficients."""
    nmax = c.shape[0] - 1
    out = []
    for la, lo, hh in zip(lat, lon, h, strict=True):
        r = R + hh
        cilm = np.asfortranarray(np.array([c, s]) * ((R / r) ** np.arange(nmax + 1))[:, None])
        out.append(pysh.expand.MakeGridPoint(cilm, float(la), float(lo), norm=1, csphase=1))
    return np.array(out) * GM / (R + np.asarray(h))


def ref_gradient(c, s, lat, lon, h):
    """∇T (m/s²) from pyshtools: columns (∂/∂r, (1/r)∂/∂θ, (1/(r sinθ))∂/∂λ)."""
    cilm = np.asfortranarray(np.array([c, s]))  # f2py would copy a C-ordered array per call
    return np.array(
        [
            pysh.gravmag.MakeGravGridPoint(cilm, GM, R, R + float(hh), float(la), float(lo))
            for la, lo, hh in zip(lat, lon, h, strict=True)
        ]
    )


def ref_fields(c, s, lat, lon, h):
    """(T, Δg, δg, ξ, η) in the module's units from pyshtools."""
    t = ref_potential(c, s, lat, lon, h)
    g = ref_gradient(c, s, lat, lon, h)
    r = R + np.asarray(h)
    gamma = gamma_si(lat, h)
    dist = -g[:, 0]
    return (
        t,
        (dist - 2 * t / r) / const.MGAL,
        dist / const.MGAL,
        g[:, 1] / gamma / const.ARCSEC,  # ξ = −∂T/(γ r ∂φ) = (1/(γ r)) ∂T/∂θ
        -g[:, 2] / gamma / const.ARCSEC,  # η = −∂T/(γ r cos φ ∂λ)
    )


@pytest.fixture(scope="module")
def coeffs360():
    return random_coeffs(360)


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(42)
    lat = np.concatenate([rng.uniform(-89.0, 89.0, 4), [89.95]])
    lon = rng.uniform(-180.0, 360.0, lat.size)
    heights = (0.0, 3_000.0, 250_000.0)
    lat3, lon3 = np.tile(lat, 3), np.tile(lon, 3)
    h3 = np.repeat(heights, lat.size)
    return lat3, lon3, h3


@pytest.fixture(scope="module")
def fields360(coeffs360, points):
    model = hm.SphericalHarmonics.from_arrays(*coeffs360, GM, R)
    return hm.synthesize(model, *points)


@pytest.fixture(scope="module")
def small():
    c, s = random_coeffs(24, seed=3)
    return hm.SphericalHarmonics.from_arrays(c, s, GM, R)


@pytest.mark.long
def test_potential_matches_pyshtools(coeffs360, points, fields360):
    ref = ref_potential(*coeffs360, *points)
    np.testing.assert_allclose(fields360.potential, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


def test_pyshtools_gradient_convention_by_finite_differences():
    c, s = random_coeffs(30, seed=7)
    lat, lon, h = 37.0, 211.0, 1000.0
    g = ref_gradient(c, s, [lat], [lon], [h])[0]
    r = R + h
    dh, dd = 1.0, 1e-4  # m, degrees

    def pot(la, lo, hh):
        return ref_potential(c, s, [la], [lo], [hh])[0]

    dt_dr = (pot(lat, lon, h + dh) - pot(lat, lon, h - dh)) / (2 * dh)
    dt_dphi = (pot(lat + dd, lon, h) - pot(lat - dd, lon, h)) / (2 * math.radians(dd))
    dt_dlam = (pot(lat, lon + dd, h) - pot(lat, lon - dd, h)) / (2 * math.radians(dd))
    np.testing.assert_allclose(g[0], dt_dr, rtol=1e-6)
    np.testing.assert_allclose(g[1], -dt_dphi / r, rtol=1e-6)
    np.testing.assert_allclose(g[2], dt_dlam / (r * math.cos(math.radians(lat))), rtol=1e-6)


def test_gravity_and_deflection_match_pyshtools(coeffs360, points, fields360):
    ref = ref_fields(*coeffs360, *points)
    for name, mine, want in zip(hm.FieldValues._fields[1:], fields360[1:], ref[1:], strict=True):
        np.testing.assert_allclose(
            mine, want, rtol=1e-9, atol=1e-10 * np.abs(want).max(), err_msg=name
        )


# The small-model tests share a few array shapes so that each compiled program is
# reused: points of shape (4,), scalars, and the 3-vector x = (lat, lon, h).
LAT4 = np.array([12.5, -61.0, 80.0, -5.0])
LON4 = np.array([33.0, 190.0, -20.0, 359.0])
H4 = np.array([0.0, 2_500.0, 40_000.0, 10.0])


def test_single_quantity_functions_agree(small):
    # chunk=3 on 4 points: two chunks through lax.map, the last one padded
    full = hm.synthesize(small, LAT4, LON4, H4, chunk=3)
    looped = np.array([hm.synthesize(small, *p) for p in zip(LAT4, LON4, H4, strict=True)])
    np.testing.assert_allclose(np.stack(full), looped.T, rtol=1e-13)
    kw = {"chunk": 3}
    np.testing.assert_allclose(hm.disturbing_potential(small, LAT4, LON4, H4, **kw), full[0])
    np.testing.assert_allclose(hm.gravity_anomaly(small, LAT4, LON4, H4, **kw), full.anomaly)
    np.testing.assert_allclose(hm.gravity_disturbance(small, LAT4, LON4, H4, **kw), full[2])
    xi, eta = hm.deflection(small, LAT4, LON4, H4, **kw)
    np.testing.assert_allclose(xi, full.xi)
    np.testing.assert_allclose(eta, full.eta)
    # inputs broadcast: (2, 1) x (2,) x scalar -> (2, 2)
    lat, lon = np.array([[10.0], [-20.0]]), np.array([5.0, 95.0])
    out = hm.synthesize(small, lat, lon, 300.0, **kw)
    assert all(v.shape == (2, 2) for v in out)
    flat = hm.synthesize(small, np.repeat(lat[:, 0], 2), np.tile(lon, 2), np.full(4, 300.0), **kw)
    np.testing.assert_allclose(out.anomaly.ravel(), flat.anomaly, rtol=1e-14)


def _fields_of_x(model):
    """FieldValues as a function of x = (lat deg, lon deg, h m), one point."""
    return lambda x: hm.synthesize(model, x[0], x[1], x[2])


@pytest.mark.long
def test_autodiff_in_points(small):
    """Derived fields equal autodiff of T; jacfwd = grad = finite differences."""
    f = _fields_of_x(small)
    per_rad = 180.0 / math.pi  # ∂/∂φ = (180/π) ∂/∂lat_deg

    def score(x):
        out = f(x)
        return out.anomaly + 0.3 * out.xi - 0.2 * out.eta

    # two compiled programs: the fields with their forward-mode Jacobian (jacfwd's
    # push-forward, keeping the primal), and the score with its gradient (whose values
    # also give the finite differences)
    @jax.jit
    def fields_and_jac(x):
        pushfwd = functools.partial(jax.jvp, f, (x,))
        return jax.vmap(pushfwd, out_axes=(None, -1))((jnp.eye(3, dtype=x.dtype),))

    value_and_grad = jax.jit(jax.value_and_grad(score))

    def grad(x):
        return value_and_grad(x)[1]

    steps = np.array([1e-4, 1e-4, 1.0])
    for x0 in ([12.5, 33.0, 0.0], [-61.0, 190.0, 2_500.0], [80.0, -20.0, 40_000.0]):
        x0 = jnp.array(x0)
        lat, _, h = np.array(x0)
        out, jx = fields_and_jac(x0)
        d_lat, d_lon, d_h = np.array(jx.potential)
        r = R + h
        gamma = gamma_si(lat, h)
        np.testing.assert_allclose(out.disturbance, -d_h / const.MGAL, rtol=1e-12)
        want = (-d_h - 2 * out.potential / r) / const.MGAL
        np.testing.assert_allclose(out.anomaly, want, rtol=1e-11)
        want = -d_lat * per_rad / (gamma * r) / const.ARCSEC
        np.testing.assert_allclose(out.xi, want, rtol=1e-11)
        want = -d_lon * per_rad / (gamma * r * math.cos(math.radians(lat))) / const.ARCSEC
        np.testing.assert_allclose(out.eta, want, rtol=1e-10)

        fwd = jx.anomaly + 0.3 * jx.xi - 0.2 * jx.eta
        rev = grad(x0)
        eye = np.eye(3)
        fd = [(value_and_grad(x0 + steps[i] * eye[i])[0]
               - value_and_grad(x0 - steps[i] * eye[i])[0]) / (2 * steps[i])
              for i in range(3)]  # fmt: skip
        np.testing.assert_allclose(fwd, rev, rtol=1e-10)
        np.testing.assert_allclose(rev, fd, rtol=1e-5)
    # at a pole everything, gradients included, stays finite
    assert np.all(np.isfinite(grad(jnp.array([90.0, 30.0, 0.0]))))
    assert np.all(np.isfinite(grad(jnp.array([-90.0, 30.0, 0.0]))))


def test_grid_equals_point_synthesis(small):
    lat1 = np.linspace(-80.0, 85.0, 5)
    lon1 = np.linspace(-170.0, 350.0, 6)
    grid = hm.synthesize_grid(small, lat1, lon1, 1_500.0, chunk=2)  # 5 rows: padded chunk
    assert all(g.shape == (5, 6) for g in grid)
    pts = np.array(
        [[hm.synthesize(small, la, lo, 1_500.0) for lo in lon1] for la in lat1]
    )  # (5, 6, 5): one scalar program, reused
    for k, name in enumerate(hm.FieldValues._fields):
        p = pts[..., k]
        atol = 1e-12 * np.abs(p).max()
        np.testing.assert_allclose(grid[k], p, rtol=1e-12, atol=atol, err_msg=name)


@pytest.mark.long
def test_degree_2000_at_30n_matches_pyshtools():
    c, s = random_coeffs(2000, seed=11)
    model = hm.SphericalHarmonics.from_arrays(c, s, GM, R)
    lat, lon, h = np.array([30.0, 30.01]), np.array([10.0, 243.4]), np.array([0.0, 3_000.0])
    out = hm.synthesize(model, lat, lon, h)
    assert all(np.all(np.isfinite(v)) for v in out)
    ref = ref_fields(c, s, lat, lon, h)
    for name, mine, want in zip(hm.FieldValues._fields, out, ref, strict=True):
        np.testing.assert_allclose(mine, want, rtol=1e-9, err_msg=name)


def test_poles_are_finite_and_continuous(small):
    lat = np.array([90.0, 90.0, -90.0, -90.0])
    lon = np.array([0.0, 200.0, 75.0, 300.0])
    at = hm.synthesize(small, lat, lon, 0.0, chunk=3)
    near = hm.synthesize(small, lat - np.sign(lat) * 1e-7, lon, 0.0, chunk=3)
    for name, a, b in zip(hm.FieldValues._fields, at, near, strict=True):
        assert np.all(np.isfinite(a)), name
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7 * np.abs(b).max(), err_msg=name)


def test_jit_vmap_no_retrace_equals_loop(small):
    traces = []

    def one(lat, lon, h):
        traces.append(1)
        return hm.synthesize(small, lat, lon, h)

    jf = jax.jit(jax.vmap(one))
    a = jf(jnp.asarray(LAT4), jnp.asarray(LON4), jnp.asarray(H4))
    b = jf(jnp.asarray(-LAT4), jnp.asarray(LON4 + 7.0), jnp.asarray(H4 * 2))
    assert len(traces) == 1
    assert not np.allclose(a.potential, b.potential)
    looped = [hm.synthesize(small, LAT4[i], LON4[i], H4[i]) for i in range(4)]
    for k, name in enumerate(hm.FieldValues._fields):
        assert a[k].shape == (4,)
        np.testing.assert_allclose(a[k], [lp[k] for lp in looped], rtol=1e-13, err_msg=name)
    # traced out-of-range latitudes cannot raise: they give NaN, never a clipped value
    bad = jf(jnp.asarray(LAT4).at[0].set(95.0), jnp.asarray(LON4), jnp.asarray(H4))
    assert all(np.isnan(v[0]) and np.all(np.isfinite(v[1:])) for v in bad)
    assert len(traces) == 1


def test_grad_in_coefficients(small):
    @jax.jit
    @jax.grad
    def grad_cs(cs, weights):
        """Gradient of Σ weights * fields (weights (5, 4)) with respect to (c, s)."""
        model = hm.SphericalHarmonics(c=cs[0], s=cs[1], gm=small.gm, radius=small.radius)
        return jnp.sum(weights * jnp.stack(hm.synthesize(model, LAT4, LON4, H4)))

    # ∂T(point 0)/∂C̄nm = GM/r (R/r)^n P̄nm(sin φ) cos mλ, with P̄nm from pyshtools
    gc, gs = grad_cs((small.c, small.s), jnp.zeros((5, 4)).at[0, 0].set(1.0))
    lat, lon, h = LAT4[0], LON4[0], H4[0]
    nmax = small.nmax
    plm = pysh.legendre.PlmBar(nmax, math.sin(math.radians(lat)), csphase=1, cnorm=0)
    n, m = np.tril_indices(nmax + 1)
    r = R + h
    base = GM / r * (R / r) ** n * plm[n * (n + 1) // 2 + m]
    lam = math.radians(lon)
    np.testing.assert_allclose(np.asarray(gc)[n, m], base * np.cos(m * lam), rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(np.asarray(gs)[n, m], base * np.sin(m * lam), rtol=1e-11, atol=1e-11)
    # all five fields at all points: finite
    g_all = grad_cs((small.c, small.s), jnp.ones((5, 4)))
    assert all(np.all(np.isfinite(g)) for g in g_all)


def test_truncate(small):
    trunc = small.truncate(10)
    assert trunc.nmax == 10 and trunc.c.shape == trunc.s.shape == (11, 11)
    np.testing.assert_array_equal(trunc.c, small.c[:11, :11])
    np.testing.assert_array_equal(trunc.s, small.s[:11, :11])
    assert (trunc.gm, trunc.radius) == (small.gm, small.radius)
    with pytest.raises(ValueError, match="nmax"):
        small.truncate(25)


def test_netcdf_round_trip(small, tmp_path):
    path = tmp_path / "model.nc"
    small.to_netcdf(path)
    with xr.open_dataset(path) as ds:
        assert ds["c"].dims == ("degree", "order")
        assert ds.attrs["normalization"] == "4pi" and int(ds.attrs["csphase"]) == 1
        assert ds.attrs["quantity"] == "disturbing potential"
    back = hm.SphericalHarmonics.from_netcdf(path)
    assert back.gm == small.gm and back.radius == small.radius
    np.testing.assert_array_equal(back.c, small.c)
    np.testing.assert_array_equal(back.s, small.s)
    with pytest.raises(FileExistsError, match="force"):
        small.to_netcdf(path)
    small.truncate(5).to_netcdf(path, force=True)
    assert hm.SphericalHarmonics.from_netcdf(path).nmax == 5
    assert list(tmp_path.iterdir()) == [path]  # no temp files left behind
    xr.Dataset({"c": (("degree", "order"), np.zeros((3, 3)))}).to_netcdf(tmp_path / "bad.nc")
    with pytest.raises(ValueError, match="'s'"):
        hm.SphericalHarmonics.from_netcdf(tmp_path / "bad.nc")


def test_bad_inputs(small):
    with pytest.raises(ValueError, match=r"lat.*95"):
        hm.gravity_anomaly(small, 95.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="lon"):
        hm.synthesize(small, 0.0, np.nan, 0.0)
    with pytest.raises(ValueError, match="h must be"):
        hm.synthesize(small, 0.0, 0.0, -7e6)
    with pytest.raises(ValueError, match="broadcast"):
        hm.synthesize(small, np.zeros(3), np.zeros(4), 0.0)
    with pytest.raises(ValueError, match="lat_1d"):
        hm.synthesize_grid(small, np.array([0.0, 91.0]), np.array([0.0]), 0.0)
    with pytest.raises(ValueError, match="same shape"):
        hm.SphericalHarmonics.from_arrays(np.zeros((4, 4)), np.zeros((5, 5)))
    with pytest.raises(ValueError, match="square"):
        hm.SphericalHarmonics.from_arrays(np.zeros((4, 3)), np.zeros((4, 3)))
    upper = np.zeros((4, 4))
    upper[1, 2] = 1e-9
    with pytest.raises(ValueError, match=r"c\[1, 2\]"):
        hm.SphericalHarmonics.from_arrays(upper, np.zeros((4, 4)))
    with pytest.raises(ValueError, match="finite"):
        hm.SphericalHarmonics.from_arrays(np.full((4, 4), np.nan), np.zeros((4, 4)))
    with pytest.raises(ValueError, match="radius"):
        hm.SphericalHarmonics.from_arrays(np.zeros((4, 4)), np.zeros((4, 4)), GM, -1.0)
    with pytest.raises(TypeError, match="SphericalHarmonics"):
        hm.synthesize({"c": 0}, 0.0, 0.0, 0.0)


@settings(max_examples=25, deadline=None)
@given(st.floats(min_value=90.0, max_value=1e6, exclude_min=True), st.booleans())
def test_out_of_range_latitude_always_raises(small, lat, south):
    lat = -lat if south else lat
    with pytest.raises(ValueError, match="lat"):
        hm.synthesize(small, np.array([0.0, lat]), 0.0, 0.0)
