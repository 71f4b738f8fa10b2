"""Separable lattice evaluation and patch sampling equal the point-wise interpolants."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import interp
from jaxgrav.lattice import interleave, lattice_values, patch_values
from jaxgrav.match.refine import solve_spd

RNG = np.random.default_rng(5)
VALUES = jnp.asarray(RNG.normal(size=(23, 31)))


def _lattices(n_lat, a, b, span_y, span_x, margin=0.0):
    """Random ascending lattices; ``margin`` > 0 lets them run off the map."""
    y0 = RNG.uniform(-margin, 22 - span_y + margin, (n_lat, 1))
    x0 = RNG.uniform(-margin, 30 - span_x + margin, (n_lat, 1))
    rows = y0 + np.linspace(0.0, span_y, a)
    cols = x0 + np.linspace(0.0, span_x, b)
    return jnp.asarray(rows), jnp.asarray(cols)


@pytest.mark.parametrize("method", ["bicubic", "bilinear"])
@pytest.mark.long
def test_lattice_equals_pointwise(method):
    coef = interp.bicubic_coefficients(VALUES)
    table = interleave(coef) if method == "bicubic" else VALUES
    rows, cols = _lattices(40, 9, 7, 3.7, 2.2, margin=1.5)
    block = 6  # spans of up to 4 cells fit
    v, in_y, in_x = lattice_values(table, rows, cols, block, method)
    iy, ix = rows[:, :, None], cols[:, None, :]
    ref = interp.bicubic(coef, iy, ix) if method == "bicubic" else interp.bilinear(VALUES, iy, ix)
    inside = np.asarray(in_y[:, :, None] & in_x[:, None, :])
    np.testing.assert_array_equal(inside, np.isfinite(ref))
    assert inside.any() and not inside.all()  # both cases exercised
    np.testing.assert_allclose(np.asarray(v)[inside], np.asarray(ref)[inside], rtol=0,
                               atol=1e-12)


def test_the_old_import_path_reexports():
    from jaxgrav.match import lattice as old

    assert old.lattice_values is lattice_values and old.patch_values is patch_values


@pytest.mark.parametrize("method", ["bicubic",
                                    pytest.param("bilinear", marks=pytest.mark.long)])
def test_lattice_nan_cells_equal_pointwise(method):
    """With ``nan_cells`` a missing node makes exactly the points of its cells NaN, as the
    point-wise interpolants do (without it, it spreads along the lattice rows)."""
    # jitted, as the matchers call them: eager dispatch of their many small ops took 7 s
    lattice = jax.jit(lattice_values, static_argnums=(3, 4), static_argnames="nan_cells")
    missing = ([5, 12, 6, 17], [7, 20, 8, 3])
    coef = jax.jit(interp.bicubic_coefficients)(VALUES).at[missing].set(jnp.nan)
    values = VALUES.at[missing].set(jnp.nan)
    table = interleave(coef) if method == "bicubic" else values
    rows, cols = _lattices(80, 9, 7, 3.7, 2.2, margin=1.5)
    v, in_y, in_x = lattice(table, rows, cols, 6, method, nan_cells=True)
    iy, ix = rows[:, :, None], cols[:, None, :]
    ref = jax.jit(interp.bicubic if method == "bicubic" else interp.bilinear)(
        coef if method == "bicubic" else values, iy, ix)
    inside = np.asarray(in_y[:, :, None] & in_x[:, None, :])
    v, ref = np.asarray(v)[inside], np.asarray(ref)[inside]
    np.testing.assert_array_equal(np.isnan(v), np.isnan(ref))
    assert np.isnan(ref).any() and np.isfinite(ref).any()  # both cases exercised
    ok = np.isfinite(ref)
    np.testing.assert_allclose(v[ok], ref[ok], rtol=0, atol=1e-12)
    # the matchers' default keeps its hot path: NaN spreads along the rows
    spread, _, _ = lattice(table, rows, cols, 6, method)
    assert np.isnan(np.asarray(spread)[inside]).sum() > np.isnan(v).sum()


@pytest.mark.long
def test_lattice_at_the_map_edges():
    coef = interp.bicubic_coefficients(VALUES)
    rows = jnp.asarray([[0.0, 0.5, 1.0], [20.0, 21.0, 22.0]])
    cols = jnp.asarray([[28.0, 29.5, 30.0], [0.0, 0.25, 0.5]])
    v, in_y, in_x = lattice_values(interleave(coef), rows, cols, 4)
    assert np.all(in_y) and np.all(in_x)
    ref = interp.bicubic(coef, rows[:, :, None], cols[:, None, :])
    np.testing.assert_allclose(v, ref, rtol=0, atol=1e-12)


@pytest.mark.long
def test_patch_values_and_gradient():
    coef = interp.bicubic_coefficients(VALUES)
    iy = jnp.asarray(RNG.uniform(-0.5, 22.5, 300))
    ix = jnp.asarray(RNG.uniform(-0.5, 30.5, 300))
    v, dy, dx = patch_values(interleave(coef), iy, ix, gradient=True)
    rv, rdy, rdx = interp.bicubic_value_and_gradient(coef, iy, ix)
    np.testing.assert_array_equal(np.isnan(v), np.isnan(rv))
    ok = np.isfinite(rv)
    for a, b in ((v, rv), (dy, rdy), (dx, rdx)):
        np.testing.assert_allclose(np.asarray(a)[ok], np.asarray(b)[ok], rtol=0, atol=1e-12)
    # the analytic gradient is the derivative of the interpolant
    g = jax.vmap(jax.grad(lambda a, b: interp.bicubic(coef, a, b), (0, 1)))(iy, ix)
    np.testing.assert_allclose(np.asarray(rdy)[ok], np.asarray(g[0])[ok], atol=1e-12)
    np.testing.assert_allclose(np.asarray(rdx)[ok], np.asarray(g[1])[ok], atol=1e-12)
    lin = patch_values(VALUES, iy, ix, "bilinear")
    np.testing.assert_allclose(lin, interp.bilinear(VALUES, iy, ix), atol=1e-12)


def test_solve_spd():
    m = RNG.normal(size=(4, 6))
    a = m @ m.T + np.diag([1e-3, 1.0, 1e3, 1e-6])  # badly scaled: equilibration matters
    b = RNG.normal(size=4)
    np.testing.assert_allclose(solve_spd(jnp.asarray(a), jnp.asarray(b)),
                               np.linalg.solve(a, b), rtol=1e-9)
