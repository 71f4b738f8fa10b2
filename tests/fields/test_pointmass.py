"""Point masses against harmonica (independent kernels) and boule (independent geometry)."""

import boule
import harmonica as hm
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgrav import constants as c
from jaxgrav.fields import pointmass as pm
from jaxgrav.geodesy import meridian_radius, normal_gravity, prime_vertical_radius


def _model():
    return pm.PointMasses.create(
        lat=[24.1, 24.3, 23.8, -10.0],
        lon=[122.9, 123.2, 122.7, 40.0],
        depth=[40e3, 15e3, 5e3, 100e3],
        mass=[-2.0e16, 2.5e16, 1.0e15, 5.0e17],
    )


def _points(n=16, seed=0):
    rng = np.random.default_rng(seed)
    lat = rng.uniform(23.5, 24.8, n)
    lon = rng.uniform(122.3, 123.6, n)
    h = rng.choice([0.0, -50.0, 500.0, 12e3], n)
    return lat, lon, h


def _ecef_ref(lat, lon, h):
    """ECEF from boule's geocentric spherical coordinates (independent of jaxgrav)."""
    lon_s, lat_s, r = boule.WGS84.geodetic_to_spherical((lon, lat, h))
    ls, lo = np.radians(lat_s), np.radians(lon_s)
    return r * np.cos(ls) * np.cos(lo), r * np.cos(ls) * np.sin(lo), r * np.sin(ls)


# --- references --------------------------------------------------------------------


# Every test uses the same point count (N = 16) and the same model, so that the
# jitted kernels compile once per module.


def test_potential_matches_harmonica():
    m = _model()
    lat, lon, h = _points()
    ours = np.asarray(pm.gravitational_potential(m, lat, lon, h))
    obs = _ecef_ref(lat, lon, h)
    src = _ecef_ref(np.asarray(m.lat), np.asarray(m.lon), -np.asarray(m.depth))
    kw = {"coordinate_system": "cartesian", "parallel": False}
    ref = hm.point_gravity(obs, src, np.asarray(m.mass), field="potential", **kw)
    np.testing.assert_allclose(ours, ref, rtol=1e-10)
    assert np.all(np.abs(ref) > 1.0)  # a meaningful comparison (m²/s²)


def test_vector_matches_harmonica_in_ecef_projected_to_enu():
    # harmonica's Cartesian kernels on ECEF coordinates give ∂V/∂x, ∂V/∂y and −∂V/∂z
    # (its g_z is downward); the test projects them on ENU with its own basis.
    m = _model()
    lat, lon, h = _points(seed=1)
    obs = _ecef_ref(lat, lon, h)
    src = _ecef_ref(np.asarray(m.lat), np.asarray(m.lon), -np.asarray(m.depth))
    kw = {"coordinate_system": "cartesian", "parallel": False}
    gx = hm.point_gravity(obs, src, np.asarray(m.mass), field="g_e", **kw)
    gy = hm.point_gravity(obs, src, np.asarray(m.mass), field="g_n", **kw)
    gz = -hm.point_gravity(obs, src, np.asarray(m.mass), field="g_z", **kw)
    p, lam = np.radians(lat), np.radians(lon)
    east = -np.sin(lam) * gx + np.cos(lam) * gy
    north = -np.sin(p) * np.cos(lam) * gx - np.sin(p) * np.sin(lam) * gy + np.cos(p) * gz
    up = np.cos(p) * np.cos(lam) * gx + np.cos(p) * np.sin(lam) * gy + np.sin(p) * gz

    vec = pm.disturbance_vector(m, lat, lon, h)
    scale = np.max(np.abs(up))
    assert scale > 10.0  # mGal
    for ours, ref in zip(vec, (east, north, up), strict=True):
        np.testing.assert_allclose(np.asarray(ours), ref, rtol=0, atol=1e-9 * scale)
    anomaly = np.asarray(pm.gravity_anomaly(m, lat, lon, h))
    np.testing.assert_allclose(anomaly, -up, atol=1e-9 * scale)


def test_enu_components_are_the_hm_derivatives_of_the_potential():
    # δg_N = ∂T/((M+h)∂φ), δg_E = ∂T/((N+h)cosφ ∂λ), δg_U = ∂T/∂h, exactly, so
    # ξ = −∂T/(γ(M+h)∂φ) and η = −∂T/(γ(N+h)cosφ ∂λ) (Heiskanen–Moritz 2-22).
    m = _model()
    lat, lon, h = _points(seed=2)

    def t_rad(phi, lam, hh):
        return pm.gravitational_potential(m, jnp.rad2deg(phi), jnp.rad2deg(lam), hh)

    dphi, dlam, dh = jax.jit(jax.vmap(jax.grad(t_rad, argnums=(0, 1, 2))))(
        np.radians(lat), np.radians(lon), h
    )
    big_m, big_n = meridian_radius(lat) + h, prime_vertical_radius(lat) + h
    vec = pm.disturbance_vector(m, lat, lon, h)
    np.testing.assert_allclose(vec.north, dphi / big_m / c.MGAL, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(
        vec.east, dlam / (big_n * np.cos(np.radians(lat))) / c.MGAL, rtol=1e-10, atol=1e-10
    )
    np.testing.assert_allclose(vec.up, dh / c.MGAL, rtol=1e-10, atol=1e-10)

    gamma = normal_gravity(lat, h) * c.MGAL
    dov = pm.deflection(m, lat, lon, h)
    np.testing.assert_allclose(dov.xi, -dphi / (gamma * big_m) / c.ARCSEC, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(
        dov.eta,
        -dlam / (gamma * big_n * np.cos(np.radians(lat))) / c.ARCSEC,
        rtol=1e-10,
        atol=1e-10,
    )


# --- physics and signs -------------------------------------------------------------


def test_signs_mass_below_north_and_east():
    one = pm.PointMasses.create(lat=30.0, lon=100.0, depth=10e3, mass=1e15)
    neg = pm.PointMasses.create(lat=30.0, lon=100.0, depth=10e3, mass=-1e15)
    # points: directly above; 0.05° south (mass to the north); 0.05° west (mass to the
    # east); directly above at 10 km
    lat = np.array([30.0, 29.95, 30.0, 30.0])
    lon = np.array([100.0, 100.0, 99.95, 100.0])
    h = np.array([0.0, 0.0, 0.0, 10e3])
    vec = pm.disturbance_vector(one, lat, lon, h)
    dov = pm.deflection(one, lat, lon, h)

    # above: positive anomaly Gm/d², no horizontal pull, no deflection; 1/d² decay
    np.testing.assert_allclose(-vec.up[0], c.G_NEWTON * 1e15 / 10e3**2 / c.MGAL, rtol=1e-12)
    np.testing.assert_allclose([dov.xi[0], dov.eta[0]], 0.0, atol=1e-9)
    np.testing.assert_allclose(vec.up[3] / vec.up[0], 0.25, rtol=1e-12)
    # mass to the north: pulled north, plumb bob pulled north → zenith tilts south → ξ < 0
    assert vec.north[1] > 0 and dov.xi[1] < 0
    assert abs(dov.eta[1]) < 1e-6 * abs(dov.xi[1])
    # flat-Earth check of the magnitude: ξ ≈ −G m Δn / (ℓ³ γ), γ(30°) ≈ 979.3 Gal
    dn = np.radians(0.05) * 6.35e6  # meridian radius near 30°N, to 0.1 %
    ell = np.hypot(dn, 10e3)
    xi_flat = -c.G_NEWTON * 1e15 * dn / ell**3 / 9.793
    np.testing.assert_allclose(dov.xi[1], xi_flat / c.ARCSEC, rtol=2e-2)
    # mass to the east: pulled east, η < 0
    assert vec.east[2] > 0 and dov.eta[2] < 0
    assert abs(dov.xi[2]) < 1e-2 * abs(dov.eta[2])  # only meridian convergence

    # a mass deficit reverses every sign
    np.testing.assert_allclose(pm.gravity_anomaly(neg, lat, lon, h), vec.up, rtol=1e-12)
    np.testing.assert_allclose(pm.deflection(neg, lat, lon, h).xi, -dov.xi, rtol=1e-12)


def test_paper_d_preset_and_its_anomaly_range():
    m = pm.three_mass_model()
    assert pm.paper_d is pm.three_mass_model  # the preset under paper D's name
    assert m.size == 3
    np.testing.assert_allclose(m.lat, [24.142241, 24.275575, 24.408908])
    np.testing.assert_allclose(m.lon, 122.918751)
    np.testing.assert_allclose(m.depth, 40e3)
    np.testing.assert_allclose(m.mass, [-2.4774e16, 2.4836e16, 0.4568e16])
    lat = np.linspace(23.9, 24.6, 141)[:, None]
    lon = np.linspace(122.6, 123.3, 141)[None, :]
    g = np.asarray(pm.gravity_anomaly(m, lat, lon))
    assert g.shape == (141, 141)
    # measured with these published parameters (see the docstring of three_mass_model)
    assert -26.0 < g.min() < -25.0
    assert 50.0 < g.max() < 51.5


# --- shapes and transformations ----------------------------------------------------


def test_broadcasting_of_points():
    m = _model()
    lat = np.linspace(23.9, 24.6, 3)[:, None]
    lon = np.linspace(122.6, 123.3, 4)
    out = pm.gravity_anomaly(m, lat, lon, 100.0)
    assert out.shape == (3, 4)
    vec = pm.disturbance_vector(m, lat, lon, 100.0)
    assert all(v.shape == (3, 4) for v in vec)
    dov = pm.deflection(m, 24.0, 123.0)
    assert dov.xi.shape == () and dov.eta.shape == ()


def test_jit_does_not_retrace():
    traces = []

    @jax.jit
    def f(masses, lat, lon, h):
        traces.append(1)
        return pm.gravity_anomaly(masses, lat, lon, h)

    lat, lon, h = _points()
    a = f(_model(), lat, lon, h)
    m2 = jax.tree.map(lambda x: x * 1.01, _model())
    b = f(m2, lat + 0.1, lon, h + 1.0)
    assert len(traces) == 1
    np.testing.assert_allclose(a, pm.gravity_anomaly(_model(), lat, lon, h), rtol=1e-12)
    assert not np.allclose(a, b)


def test_vmap_over_points_and_models_equals_loop():
    m = _model()
    lat, lon, h = _points(seed=3)
    batched = jax.jit(jax.vmap(pm.deflection, in_axes=(None, 0, 0, 0)))(m, lat, lon, h)
    for i in range(3):
        one = pm.deflection(m, lat[i], lon[i], h[i])
        np.testing.assert_allclose([batched.xi[i], batched.eta[i]], [one.xi, one.eta], rtol=1e-12)

    scales = jnp.array([0.5, 1.0, 2.0])
    models = jax.vmap(lambda s: pm.PointMasses(m.lat, m.lon, m.depth * s, m.mass))(scales)
    batched = jax.jit(jax.vmap(pm.deflection, in_axes=(0, None, None, None)))(models, lat, lon, h)
    for i, s in enumerate(scales):
        ref = pm.deflection(pm.PointMasses(m.lat, m.lon, m.depth * s, m.mass), lat, lon, h)
        # batched and single rounding differ (1.7e-12 relative on one of 48 values with
        # XLA's elemental emitters)
        np.testing.assert_allclose(batched.xi[i], ref.xi, rtol=1e-11)
        np.testing.assert_allclose(batched.eta[i], ref.eta, rtol=1e-11)


def test_grad_in_positions_and_masses_matches_finite_differences():
    m = _model()
    x0 = jnp.array([24.05, 122.95, 300.0])

    @jax.jit
    def f(x, masses):
        return pm.gravity_anomaly(masses, x[0], x[1], x[2])

    g_rev, gm = jax.jit(jax.grad(f, argnums=(0, 1)))(x0, m)
    g_fwd = jax.jit(jax.jacfwd(f))(x0, m)
    np.testing.assert_allclose(g_rev, g_fwd, rtol=1e-10)
    steps = np.array([1e-5, 1e-5, 1.0])
    fd = [
        (f(x0 + e * s, m) - f(x0 - e * s, m)) / (2 * s)
        for e, s in zip(np.eye(3), steps, strict=True)
    ]
    np.testing.assert_allclose(g_rev, fd, rtol=1e-5)

    assert isinstance(gm, pm.PointMasses)
    # Δg is linear in the masses: Σ m_j ∂Δg/∂m_j = Δg, and a bumped mass checks one entry
    np.testing.assert_allclose(jnp.sum(gm.mass * m.mass), f(x0, m), rtol=1e-10)
    bumped = pm.PointMasses(m.lat, m.lon, m.depth, m.mass.at[2].add(1e14))
    np.testing.assert_allclose(gm.mass[2] * 1e14, f(x0, bumped) - f(x0, m), rtol=1e-8)
    eps = 1.0
    bumped = [pm.PointMasses(m.lat, m.lon, m.depth.at[1].add(s * eps), m.mass) for s in (1, -1)]
    fd_depth = (f(x0, bumped[0]) - f(x0, bumped[1])) / (2 * eps)
    np.testing.assert_allclose(gm.depth[1], fd_depth, rtol=1e-5)


# --- validation --------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True).filter(lambda v: not -90 <= v <= 90))
def test_latitude_out_of_range_is_rejected(bad):
    m = _model()
    with pytest.raises(ValueError, match="lat"):
        pm.gravity_anomaly(m, bad, 0.0, 0.0)
    with pytest.raises(ValueError, match="lat"):
        pm.PointMasses.create(lat=[0.0, bad], lon=0.0, depth=1e3, mass=1e10)


@settings(max_examples=20, deadline=None)
@given(
    st.sampled_from(["lon", "depth", "mass"]),
    st.sampled_from([np.nan, np.inf, -np.inf]),
)
def test_non_finite_mass_fields_are_rejected(field, bad):
    kw = {"lat": [0.0, 1.0], "lon": [0.0, 1.0], "depth": [1e3, 2e3], "mass": [1e10, 1e10]}
    kw[field] = [1.0, bad]
    with pytest.raises(ValueError, match=f"masses.{field} must be finite"):
        pm.PointMasses.create(**kw)


def test_other_bad_inputs():
    m = _model()
    with pytest.raises(ValueError, match="same length K"):
        pm.PointMasses.create(lat=[0.0, 1.0], lon=[0.0, 1.0, 2.0], depth=1e3, mass=1e10)
    with pytest.raises(ValueError, match=r"shape \(K,\)"):
        pm.PointMasses.create(lat=[[0.0]], lon=0.0, depth=1e3, mass=1e10)
    with pytest.raises(ValueError, match="at least one"):
        pm.PointMasses.create(lat=[], lon=[], depth=[], mass=[])
    with pytest.raises(TypeError, match="PointMasses"):
        pm.gravity_anomaly({"lat": 0.0}, 0.0, 0.0)
    with pytest.raises(ValueError, match="broadcastable"):
        pm.gravity_anomaly(m, np.zeros(3), np.zeros(4), 0.0)
    with pytest.raises(ValueError, match="h must be finite"):
        pm.deflection(m, 24.0, 123.0, np.nan)
    with pytest.raises(ValueError, match="1-D of the same shape"):
        pm.gravity_anomaly(pm.PointMasses(m.lat, m.lon, m.depth[:2], m.mass), 0.0, 0.0)
