"""The prepared map: one value for every form of the map the matchers read."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import interp
from jaxgrav.grid import make_sampler
from jaxgrav.match.contour import patch_coefficients
from jaxgrav.match.dense import lattice_table
from jaxgrav.match.entropy import EntropyConfig, match_entropy
from jaxgrav.match.lattice import interleave
from jaxgrav.prepared import PreparedMap, as_grid, prepare_map


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(11)
    return (jnp.asarray(rng.uniform(29.52, 30.48, 64)),
            jnp.asarray(rng.uniform(129.52, 130.48, 64)))


def test_prepared_map_equals_the_old_paths(smooth_grid, points):
    pm = prepare_map(smooth_grid)
    assert prepare_map(pm) is pm
    assert as_grid(pm) is smooth_grid and as_grid(smooth_grid) is smooth_grid
    lat, lon = points
    for method in ("bicubic", "bilinear"):
        np.testing.assert_allclose(pm.sample(lat, lon, method),
                                   make_sampler(smooth_grid, method)(lat, lon),
                                   rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(pm.sampler(method)(lat, lon), pm.sample(lat, lon, method))
    # prepare_map computes the coefficients as one compiled program, the old paths op by
    # op: equal to rounding (XLA fuses the spline products), not to the bit
    coef = interp.bicubic_coefficients(smooth_grid.values)
    np.testing.assert_allclose(pm.coefficients, coef, rtol=1e-13, atol=1e-11)
    np.testing.assert_allclose(pm.patches(), patch_coefficients(smooth_grid.values), rtol=1e-13,
                               atol=1e-11)
    np.testing.assert_allclose(pm.interleaved(), interleave(coef), rtol=1e-13, atol=1e-11)
    np.testing.assert_allclose(pm.lattice_table("bicubic"), lattice_table(smooth_grid),
                               rtol=1e-13, atol=1e-11)
    np.testing.assert_allclose(pm.lattice_table("bilinear"), smooth_grid.values, atol=0)
    # off the grid: NaN, as Grid.sample
    off = pm.sample(jnp.array([10.0, 29.9]), jnp.array([130.0, 140.0]))
    assert np.all(np.isnan(np.asarray(off)))
    with pytest.raises(ValueError, match="method"):
        pm.sample(lat, lon, "nearest")


@pytest.mark.long
def test_prepared_map_vmaps_over_points_and_jits_without_retrace(smooth_grid, points):
    pm = prepare_map(smooth_grid)
    lat, lon = points
    f = jax.jit(lambda m, la, lo: m.sample(la, lo))
    whole = f(pm, lat, lon)
    np.testing.assert_allclose(jax.vmap(pm.sample)(lat, lon), whole, rtol=1e-14)
    np.testing.assert_allclose(jax.vmap(f, in_axes=(None, 0, 0))(pm, lat, lon), whole, rtol=1e-14)
    size = f._cache_size()
    other = prepare_map(dataclasses.replace(smooth_grid, values=2.0 * smooth_grid.values))
    np.testing.assert_allclose(f(other, lat, lon), 2.0 * whole, rtol=1e-12)
    assert f._cache_size() == size  # a new map of the same shape is data, not a new program
    leaves = jax.tree.leaves(pm)
    assert len(leaves) == 2 and isinstance(pm, PreparedMap)  # values and coefficients


@pytest.mark.long
def test_prepared_map_gradient_against_finite_differences(smooth_grid, points):
    pm = prepare_map(smooth_grid)
    lat, lon = (a[:8] for a in points)
    v, d_lat, d_lon = jax.jit(pm.value_and_gradient)(lat, lon)
    np.testing.assert_allclose(v, pm.sample(lat, lon), rtol=1e-13)
    h = 1e-6
    fd_lat = (pm.sample(lat + h, lon) - pm.sample(lat - h, lon)) / (2 * h)
    fd_lon = (pm.sample(lat, lon + h) - pm.sample(lat, lon - h)) / (2 * h)
    np.testing.assert_allclose(d_lat, fd_lat, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(d_lon, fd_lon, rtol=1e-5, atol=1e-4)
    g_lat, g_lon = jax.vmap(jax.grad(lambda a, b: pm.sample(a, b), argnums=(0, 1)))(lat, lon)
    np.testing.assert_allclose(g_lat, d_lat, rtol=1e-10)
    np.testing.assert_allclose(g_lon, d_lon, rtol=1e-10)


def test_cores_take_a_prepared_map(smooth_grid):
    lat = jnp.asarray(29.85 + 0.0045 * np.arange(20))
    lon = jnp.asarray(129.85 + 0.0035 * np.arange(20))
    z = smooth_grid.sample(lat + 0.003, lon - 0.004, "bicubic")
    cfg = EntropyConfig(spacing_m=300.0, half_size=1)  # ENT1 of test_entropy_iccp: its compile
    a = match_entropy(smooth_grid, lat, lon, z, cfg)
    b = match_entropy(prepare_map(smooth_grid), lat, lon, z, cfg)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_allclose(np.asarray(y), np.asarray(x), rtol=1e-12, atol=1e-12)


@pytest.mark.long
def test_a_closed_over_map_is_not_constant_folded_and_stays_differentiable(smooth_grid):
    """A map closed over by a jitted caller is prepared at run time (XLA's constant folder
    spent ~15 s on a 289 × 289 map's spline products), with the same values, and the
    coefficients are still differentiable in the map's values."""
    v = np.asarray(smooth_grid.values)
    closed = jax.jit(lambda: interp.bicubic_coefficients(v))
    hlo = closed.lower().compile().as_text()
    assert " dot(" in hlo  # the spline solve is computed, not folded into a constant
    np.testing.assert_allclose(closed(), interp.bicubic_coefficients(v), rtol=1e-13, atol=1e-12)
    iy, ix = jnp.asarray([10.3, 40.7]), jnp.asarray([20.6, 70.2])

    def total(values):
        return jnp.sum(interp.bicubic(interp.bicubic_coefficients(values), iy, ix))

    g = jax.grad(total)(jnp.asarray(v))
    e = jnp.zeros_like(g).at[11, 21].set(1.0)
    h = 1e-4
    fd = (total(v + h * e) - total(v - h * e)) / (2 * h)
    np.testing.assert_allclose(g[11, 21], fd, rtol=1e-6)
    assert float(jnp.abs(g[11, 21])) > 1e-3  # a node of the patch: the derivative is not 0
    np.testing.assert_allclose(jax.vmap(interp.bicubic_coefficients)(jnp.stack([v, 2 * v]))[1],
                               2 * interp.bicubic_coefficients(v), rtol=1e-12, atol=1e-10)
