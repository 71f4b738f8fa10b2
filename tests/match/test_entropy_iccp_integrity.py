"""Entropy + ICCP integrity: the no-harm test (``max_p_worse``, status 131072), the
informativeness test (``max_sigma_ratio``, status 512) and the searched disc."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import norm

from jaxgrav.fields.map_error import map_error
from jaxgrav.match import shifted_tracks
from jaxgrav.match.combined import NOT_BETTER, match_entropy_iccp, p_worse_than_ins
from jaxgrav.match.entropy import EntropyConfig
from jaxgrav.match.iccp import IccpConfig
from jaxgrav.match.integrity import region_mask
from jaxgrav.match.result import STATUS
from jaxgrav.match.sizing import ICCP_MAP_ERROR_INTEGRITY, iccp_config_for

ENT = EntropyConfig(spacing_m=200.0, half_size=4)
ICP = IccpConfig(window_m=600.0, max_step_m=300.0, contour_tol=2.0, noise=0.3,
                 map_error_mgal=1.0, map_error_length_m=5000.0, fix="posterior", region="disc")


def _track(n=20):
    return 29.85 + 0.0045 * np.arange(n), 129.85 + 0.0035 * np.arange(n)


def test_p_worse_than_ins_by_hand_and_against_sampling():
    # on the INS track: a coin flip; isotropic: Φ(−|m| / 2σ); never above 0.5
    assert float(p_worse_than_ins(jnp.zeros(2), 1e4 * jnp.eye(2))) == pytest.approx(0.5)
    got = p_worse_than_ins(jnp.array([[900.0, 0.0], [0.0, -300.0]]), 250.0**2 * jnp.eye(2))
    np.testing.assert_allclose(got, norm.sf([900.0 / 500.0, 300.0 / 500.0]), rtol=1e-6)
    # anisotropic: the share of samples of N(m, C) nearer the origin than m
    rng = np.random.default_rng(3)
    m, c = np.array([700.0, -400.0]), np.array([[4e5, 1.5e5], [1.5e5, 2e5]])
    x = rng.multivariate_normal(m, c, 400_000)
    share = np.mean(np.hypot(*(x - m).T) > np.hypot(*x.T))
    assert float(p_worse_than_ins(jnp.asarray(m), jnp.asarray(c))) == pytest.approx(share,
                                                                                   abs=3e-3)
    assert float(p_worse_than_ins(jnp.ones(2), jnp.diag(jnp.array([jnp.inf, 1.0])))) == 0.5
    assert NOT_BETTER in STATUS


def test_integrity_settings_are_validated_and_set_when_told(smooth_grid):
    for bad in (dict(region="circle"), dict(max_sigma_ratio=-1.0), dict(max_p_worse=np.nan)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            IccpConfig(**bad)
    plain = IccpConfig()
    assert (plain.region, plain.max_sigma_ratio, plain.max_p_worse) == ("square", np.inf, np.inf)
    told = iccp_config_for(smooth_grid, 3000.0, stage="fine", map_error=map_error(3.0, 1e4))
    white = iccp_config_for(smooth_grid, 3000.0, stage="fine")
    for k, v in ICCP_MAP_ERROR_INTEGRITY.items():
        assert getattr(told, k) == v
    assert (white.region, white.max_sigma_ratio, white.max_p_worse) == ("square", np.inf,
                                                                        np.inf)


@pytest.fixture(scope="module")
def strong(smooth_grid):
    """A 20-fix track whose truth is the INS track shifted 600 m north, 500 m west."""
    lat, lon = _track()
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), 600.0, -500.0, 0.0)
    z = smooth_grid.sample(t_lat, t_lon, "bicubic")
    z = z + 0.3 * np.random.default_rng(2).normal(size=lat.size)
    return jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(z)


@pytest.mark.long  # one compile of the combined matcher (region "disc")
def test_no_harm_and_informativeness_tests_reject_and_keep_the_ins_track(smooth_grid, strong):
    lat, lon, z = strong
    match = lambda icp: match_entropy_iccp(smooth_grid, lat, lon, z, ENT, icp)  # noqa: E731
    base = match(ICP)
    assert bool(base.accepted) and int(base.status) & (512 | NOT_BETTER) == 0
    size = match_entropy_iccp._cache_size()
    # the tests at their defaults: the same fix (they only decide)
    told = match(dataclasses.replace(ICP, max_sigma_ratio=0.9, max_p_worse=0.3))
    assert bool(told.accepted)
    np.testing.assert_array_equal(np.asarray(told.lat), np.asarray(base.lat))
    # a fix 780 m out with a σ of tens of m is many σ from the INS track
    p = float(p_worse_than_ins(jnp.stack([base.offset_north_m, base.offset_east_m]),
                               base.covariance_m2))
    assert p < 1e-6, p
    for icp, bit in ((dataclasses.replace(ICP, max_p_worse=0.0), NOT_BETTER),
                     (dataclasses.replace(ICP, max_sigma_ratio=1e-6), 512)):
        r = match(icp)
        assert not bool(r.accepted) and int(r.status) & bit, int(r.status)
        np.testing.assert_array_equal(np.asarray(r.lat), np.asarray(lat))
        assert float(r.offset_north_m) == 0.0 and float(r.offset_east_m) == 0.0
    assert match_entropy_iccp._cache_size() == size  # traced thresholds: no retrace


@pytest.mark.long  # two compiles (region is static)
def test_flat_likelihood_spreads_over_the_searched_region_and_is_rejected(smooth_grid,
                                                                           strong):
    """Readings told a noise of 10⁴ mGal carry no information: the posterior is the uniform
    prior over the searched offsets (81 for the square, 49 in its disc), as wide as the
    region itself, on the INS track: both tests reject it."""
    lat, lon, z = strong
    for region in ("square", "disc"):
        icp = dataclasses.replace(ICP, noise=1e4, map_error_mgal=0.0, region=region,
                                  max_sigma_ratio=0.9, max_p_worse=0.3)
        r = match_entropy_iccp(smooth_grid, lat, lon, z, ENT, icp)
        count = int(region_mask(ENT.half_size, region)[0].sum())
        assert float(r.n_effective) == pytest.approx(count, rel=1e-4)
        assert not bool(r.accepted)
        assert int(r.status) & 512 and int(r.status) & NOT_BETTER, int(r.status)
        np.testing.assert_array_equal(np.asarray(r.lat), np.asarray(lat))


@pytest.mark.long
def test_vmap_equals_loop_with_the_integrity_tests(smooth_grid, strong):
    lat, lon, z = strong
    zs = jnp.stack([z, z + 0.5, z[::-1]])  # an accepted fix and others
    icp = dataclasses.replace(ICP, max_sigma_ratio=0.9, max_p_worse=0.3)
    batched = jax.vmap(match_entropy_iccp, in_axes=(None, None, None, 0, None, None))(
        smooth_grid, lat, lon, zs, ENT, icp)
    for i in range(zs.shape[0]):
        one = match_entropy_iccp(smooth_grid, lat, lon, zs[i], ENT, icp)
        for f in ("lat", "lon", "covariance_m2", "accepted", "status", "n_effective"):
            np.testing.assert_allclose(np.asarray(getattr(batched, f))[i],
                                       np.asarray(getattr(one, f)), rtol=1e-9, atol=1e-9)
