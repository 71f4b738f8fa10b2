"""Geodesy against boule and against identities."""

import itertools

import boule
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxgrav as jg
from jaxgrav import constants as c
from jaxgrav import geodesy


def test_constants_match_boule_wgs84():
    e = boule.WGS84
    assert c.WGS84_A == e.semimajor_axis
    assert c.WGS84_F == pytest.approx(e.flattening, rel=1e-15)
    assert c.WGS84_GM == e.geocentric_grav_const
    assert c.WGS84_OMEGA == e.angular_velocity
    # IUGG arithmetic mean radius R1 (boule's mean_radius is a different average)
    assert c.WGS84_MEAN_RADIUS == pytest.approx(6371008.7714, abs=1e-3)


def test_normal_gravity_matches_boule_on_and_above_ellipsoid():
    lat = np.linspace(-90, 90, 361)
    h = np.array([0.0, 10.0, 1e3, 1e4, 2e4, 1e5])[:, None]
    ours = np.asarray(jg.normal_gravity(lat, h))
    ref = boule.WGS84.normal_gravity((None, lat, h))
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-6)  # mGal


def test_normal_gravity_equator_and_pole_defining_values():
    # WGS84 defining normal gravity at the equator and the pole (TR8350.2), mGal
    np.testing.assert_allclose(jg.normal_gravity(0.0), 978032.53359, atol=1e-4)
    np.testing.assert_allclose(jg.normal_gravity(90.0), 983218.49378, atol=1e-4)


def test_normal_gravity_below_ellipsoid_is_second_order_continuation():
    lat = np.linspace(-80, 80, 17)
    g0 = np.asarray(jg.normal_gravity(lat, 0.0))
    # continuous at h = 0 and matching the exact field's vertical gradient there
    up = np.asarray(jg.normal_gravity(lat, 1.0))
    dn = np.asarray(jg.normal_gravity(lat, -1.0))
    np.testing.assert_allclose(dn - g0, g0 - up, rtol=1e-4)
    # free-air gradient ~ 0.3086 mGal/m
    np.testing.assert_allclose(dn - g0, 0.3086, atol=0.002)
    # the expansion reproduces the exact field above the ellipsoid to sub-µGal at 1 km
    h = 1000.0
    m = c.WGS84_OMEGA**2 * c.WGS84_A**2 * c.WGS84_B / c.WGS84_GM
    s2 = np.sin(np.deg2rad(lat)) ** 2
    taylor = g0 * (
        1 - 2 / c.WGS84_A * (1 + c.WGS84_F + m - 2 * c.WGS84_F * s2) * h + 3 * h**2 / c.WGS84_A**2
    )
    np.testing.assert_allclose(taylor, boule.WGS84.normal_gravity((None, lat, h)), atol=1e-3)


def test_normal_gravity_jit_vmap_grad():
    traces = []

    @jax.jit
    def f(lat, h):
        traces.append(1)
        return jg.normal_gravity(lat, h)

    a = f(jnp.array([10.0, 20.0]), jnp.array([0.0, -50.0]))
    b = f(jnp.array([30.0, 40.0]), jnp.array([5.0, -5.0]))
    assert len(traces) == 1 and np.all(np.isfinite(a)) and np.all(np.isfinite(b))
    lat = jnp.linspace(-60, 60, 7)
    np.testing.assert_allclose(
        jax.vmap(jg.normal_gravity)(lat, lat * 0 + 10.0), jg.normal_gravity(lat, 10.0)
    )
    gamma = jax.jit(jg.normal_gravity)
    grad = jax.jit(jax.grad(lambda h: jg.normal_gravity(45.0, h)))
    for h0 in (100.0, -100.0, 0.0):
        dg = grad(h0)
        fd = (gamma(45.0, h0 + 0.5) - gamma(45.0, h0 - 0.5)) / 1.0
        np.testing.assert_allclose(dg, fd, rtol=1e-4)
        assert np.isfinite(dg)


def test_eotvos_forms_and_sign():
    kn = c.KNOT
    simple = jg.eotvos(30.0, 10 * kn, 10 * kn, form="simple")
    expected = (
        2 * c.EARTH_RATE * 10 * kn * np.cos(np.deg2rad(30))
        + 2 * (10 * kn) ** 2 / c.WGS84_MEAN_RADIUS
    ) / c.MGAL
    np.testing.assert_allclose(simple, expected, rtol=1e-12)
    # moving east reduces the reading: E > 0; moving west: E < 0
    assert jg.eotvos(30.0, 5.0, 0.0) > 0 > jg.eotvos(30.0, -5.0, 0.0)
    # paper D: at 4 kn due east the Coriolis term is about 30 mGal at low latitude
    assert 25 < float(jg.eotvos(0.0, 4 * kn, 0.0)) < 31
    # full form = simple form to first order at h = 0, and grows with height as (1 + h/R)
    full0 = jg.eotvos(30.0, 10 * kn, 10 * kn, 0.0)
    full_h = jg.eotvos(30.0, 10 * kn, 10 * kn, 10000.0)
    np.testing.assert_allclose(full0, simple, rtol=1e-2)
    np.testing.assert_allclose(
        full_h / full0, 1 + 10000.0 / (c.WGS84_A * (1 - c.WGS84_F / 4)), rtol=1e-6
    )
    with pytest.raises(ValueError, match="form"):
        jg.eotvos(30.0, 1.0, 1.0, form="bogus")


def test_radii_of_curvature():
    np.testing.assert_allclose(jg.prime_vertical_radius(0.0), c.WGS84_A)
    np.testing.assert_allclose(jg.meridian_radius(90.0), c.WGS84_A**2 / c.WGS84_B, rtol=1e-12)
    np.testing.assert_allclose(jg.meridian_radius(0.0), c.WGS84_B**2 / c.WGS84_A, rtol=1e-12)


def test_ecef_against_boule_and_roundtrip():
    rng = np.random.default_rng(1)
    lat = rng.uniform(-89.9, 89.9, 200)
    lon = rng.uniform(-180, 180, 200)
    h = rng.uniform(-5000, 50000, 200)
    x, y, z = jg.geodetic_to_ecef(lat, lon, h)
    _lon_s, lat_s, r_s = boule.WGS84.geodetic_to_spherical((lon, lat, h))
    np.testing.assert_allclose(np.hypot(np.hypot(x, y), z), r_s, rtol=1e-12)
    np.testing.assert_allclose(np.rad2deg(np.arcsin(z / r_s)), lat_s, atol=1e-9)
    lat2, lon2, h2 = jg.ecef_to_geodetic(x, y, z)
    np.testing.assert_allclose(lat2, lat, atol=1e-10)
    np.testing.assert_allclose(lon2, lon, atol=1e-10)
    np.testing.assert_allclose(h2, h, atol=1e-5)


def test_enu_roundtrip_and_axes():
    origin = (30.0, 130.0, 0.0)
    e, n, _ = jg.geodetic_to_enu(30.0, 130.0 + 1e-3, 0.0, origin)
    assert e > 0 and abs(n) < 1.0  # east of the origin
    e, n, _u = jg.geodetic_to_enu(30.0 + 1e-3, 130.0, 0.0, origin)
    np.testing.assert_allclose(n, jg.meridian_radius(30.0) * np.deg2rad(1e-3), rtol=1e-5)
    rng = np.random.default_rng(2)
    lat, lon = rng.uniform(24, 36, 50), rng.uniform(124, 136, 50)
    h = rng.uniform(-100, 20000, 50)
    lat2, lon2, h2 = jg.enu_to_geodetic(*jg.geodetic_to_enu(lat, lon, h, origin), origin)
    np.testing.assert_allclose(lat2, lat, atol=1e-10)
    np.testing.assert_allclose(lon2, lon, atol=1e-10)
    np.testing.assert_allclose(h2, h, atol=1e-5)


@settings(max_examples=40, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True).filter(lambda v: not -90 <= v <= 90))
def test_latitude_validator_rejects_out_of_range(bad):
    with pytest.raises(ValueError, match="lat_deg"):
        jg.normal_gravity(np.array([10.0, bad]), 0.0)
    with pytest.raises(ValueError, match="lat_deg"):
        jg.eotvos(bad, 1.0, 1.0)


def test_enu_basis_is_a_right_handed_orthonormal_frame_with_up_normal_to_the_ellipsoid():
    lat = np.array([-89.0, -30.0, 0.0, 45.0, 89.9])
    lon = np.array([-179.0, 10.0, 123.0, -60.0, 0.0])
    east, north, up = (np.stack(v) for v in geodesy.enu_basis(lat, lon))
    for a, b in itertools.combinations((east, north, up), 2):
        np.testing.assert_allclose(np.sum(a * b, 0), 0.0, atol=1e-15)
    for v in (east, north, up):
        np.testing.assert_allclose(np.sum(v * v, 0), 1.0, rtol=1e-15)
    np.testing.assert_allclose(np.cross(east, north, axis=0), up, atol=1e-15)
    # up is the direction in which the height grows, at fixed latitude and longitude
    lo = np.stack(geodesy.geodetic_to_ecef(lat, lon, 0.0))
    hi = np.stack(geodesy.geodetic_to_ecef(lat, lon, 1.0))
    np.testing.assert_allclose(hi - lo, up, atol=1e-8)


def test_compiled_host_forms_equal_the_functions():
    """eotvos_jacobian_jit and local_offsets_m_jit: the functions as one program each."""
    lat, ve, vn = np.array([0.0, 30.0, -60.0]), np.array([5.0, -3.0, 0.0]), np.array([1.0, 2, -4])
    np.testing.assert_allclose(geodesy.eotvos_jacobian_jit(lat, ve, vn),
                               geodesy.eotvos_jacobian(lat, ve, vn), rtol=1e-12)
    lon = np.array([179.9, -10.0, 45.0])
    got = geodesy.local_offsets_m_jit(lat + 0.01, lon + 0.2, lat, lon)
    want = geodesy.local_offsets_m(lat + 0.01, lon + 0.2, lat, lon)
    np.testing.assert_allclose(got, want, rtol=1e-12)
