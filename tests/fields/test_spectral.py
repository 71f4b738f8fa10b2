"""FFT upward continuation against harmonica and against the exact point-mass field."""

import warnings

import harmonica as hm
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr
import xrft
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgrav import constants as c
from jaxgrav.fields.spectral import PAD_MODES, upward_continuation, wavenumbers

DY, DX = 100.0, 120.0
NY, NX = 120, 140
# three buried point masses (easting, northing, depth) in a 14 km × 14.4 km window
_SRC = np.array([[7000.0, 6500.0, 1500.0], [8500.0, 7200.0, 2500.0], [6000.0, 5000.0, 1000.0]])
_MASS = np.array([2e11, -1.5e11, 1e11])


def _point_field(z):
    """Exact downward attraction (mGal) of the masses on the grid at height z (m)."""
    north = np.arange(NY)[:, None] * DY
    east = np.arange(NX)[None, :] * DX
    g = np.zeros((NY, NX))
    for (e0, n0, d0), m in zip(_SRC, _MASS, strict=True):
        dz = z + d0
        g += c.G_NEWTON * m * dz / ((east - e0) ** 2 + (north - n0) ** 2 + dz**2) ** 1.5
    return g / c.MGAL


G0 = _point_field(0.0)


def test_wavenumbers_match_numpy():
    wn = wavenumbers((6, 5), (DY, DX))
    ky, kx = np.meshgrid(
        2 * np.pi * np.fft.fftfreq(6, DY), 2 * np.pi * np.fft.fftfreq(5, DX), indexing="ij"
    )
    np.testing.assert_allclose(wn.ky, ky, rtol=1e-15)
    np.testing.assert_allclose(wn.kx, kx, rtol=1e-15)
    np.testing.assert_allclose(wn.k, np.hypot(kx, ky), rtol=1e-15)
    real = wavenumbers((6, 5), (DY, DX), real=True)
    assert real.k.shape == (6, 3)
    np.testing.assert_allclose(real.kx[0], 2 * np.pi * np.fft.rfftfreq(5, DX), rtol=1e-15)


def test_equals_harmonica_with_the_same_padding():
    py, px = 30, 35
    grid = xr.DataArray(
        G0,
        coords={"northing": np.arange(NY) * DY, "easting": np.arange(NX) * DX},
        dims=("northing", "easting"),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # xarray/xrft deprecations
        # constant_values=None: xrft always forwards it, which numpy rejects for "edge"
        padded = xrft.pad(grid, {"northing": py, "easting": px}, mode="edge", constant_values=None)
        ref = hm.upward_continuation(padded, 500.0)
        ref = xrft.unpad(ref, {"northing": py, "easting": px}).values
    ours = upward_continuation(G0, (DY, DX), 500.0, pad="edge", pad_width=(py, px), taper=False)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_matches_exact_point_mass_field_at_500_m():
    exact = _point_field(500.0)
    peak = np.abs(exact).max()
    ours = np.asarray(upward_continuation(G0, (DY, DX), 500.0))
    err = np.abs(ours - exact)
    b = 10  # cells from the border
    # measured: 0.21 % of the peak over the whole grid, 0.10 % in the interior (the
    # field is truncated at the borders, where it is still 0.85 % of its peak)
    assert err.max() < 4e-3 * peak
    assert err[b:-b, b:-b].max() < 2e-3 * peak
    # the default (edge padding + taper) beats no padding clearly
    bare = np.abs(np.asarray(upward_continuation(G0, (DY, DX), 500.0, pad=None)) - exact)
    assert bare.max() > 3 * err.max()


def test_height_zero_is_identity_for_every_mode():
    small = G0[:24, :30]
    for mode in (*PAD_MODES, None):
        out = upward_continuation(small, (DY, DX), 0.0, pad=mode)
        np.testing.assert_allclose(out, small, rtol=0, atol=1e-12 * np.abs(small).max())


def test_single_fourier_mode_is_damped_exactly_and_grad_in_height():
    # a periodic mode on a periodic grid: no padding, exact exp(−k h) damping
    ny, nx = 32, 48
    ky, kx = 2 * np.pi * 3 / (ny * DY), 2 * np.pi * 5 / (nx * DX)
    y, x = np.meshgrid(np.arange(ny) * DY, np.arange(nx) * DX, indexing="ij")
    f = np.cos(kx * x + ky * y)
    k = np.hypot(kx, ky)

    @jax.jit
    def cont(h):
        return upward_continuation(f, (DY, DX), h, pad=None)

    h = 700.0
    np.testing.assert_allclose(cont(h), np.exp(-k * h) * f, atol=1e-12)
    np.testing.assert_allclose(
        upward_continuation(f, (DY, DX), h, pad="wrap", pad_width=(ny, nx), taper=False),
        np.exp(-k * h) * f,
        atol=1e-12,
    )
    # d/dh of Σ f·out = −k e^{−kh} Σ f²: reverse, forward and finite differences agree
    def score(h):
        return jnp.sum(cont(h) * f)

    g_rev = jax.grad(score)(h)
    g_fwd = jax.jacfwd(score)(h)
    fd = (score(h + 1.0) - score(h - 1.0)) / 2.0
    np.testing.assert_allclose(g_rev, -k * np.exp(-k * h) * np.sum(f**2), rtol=1e-10)
    np.testing.assert_allclose(g_fwd, g_rev, rtol=1e-12)
    np.testing.assert_allclose(fd, g_rev, rtol=1e-4)  # O(k² δh²) central-difference error


def test_semigroup_without_padding():
    once = upward_continuation(G0, (DY, DX), 800.0, pad=None)
    twice = upward_continuation(
        upward_continuation(G0, (DY, DX), 300.0, pad=None), (DY, DX), 500.0, pad=None
    )
    np.testing.assert_allclose(twice, once, atol=1e-12 * np.abs(G0).max())
    np.testing.assert_allclose(jnp.mean(once), G0.mean(), rtol=1e-12)  # k = 0 untouched


def test_linear_in_values_and_grad_in_values():
    v = jnp.asarray(G0[:40, :50])
    dv = jnp.asarray(np.random.default_rng(0).normal(size=v.shape))

    w = jnp.asarray(np.random.default_rng(1).normal(size=v.shape))

    def cont(x):
        return upward_continuation(x, (DY, DX), 250.0)

    @jax.jit
    def everything(v, dv, w):
        out, tangent = jax.jvp(cont, (v,), (dv,))
        _, vjp = jax.vjp(cont, v)
        return out, tangent, cont(dv), cont(2.0 * v + dv), vjp(w)[0]

    out, tangent, c_dv, c_comb, adj = everything(v, dv, w)
    np.testing.assert_allclose(tangent, c_dv, atol=1e-12)
    np.testing.assert_allclose(c_comb, 2.0 * out + c_dv, atol=1e-10)
    # reverse mode is the adjoint: <J dv, w> == <dv, Jᵀ w>
    np.testing.assert_allclose(jnp.vdot(c_dv, w), jnp.vdot(dv, adj), rtol=1e-10)


def test_height_sweep_broadcasts_and_does_not_retrace():
    traces = []

    @jax.jit
    def cont(values, h):
        traces.append(1)
        return upward_continuation(values, (DY, DX), h)

    heights = jnp.array([0.0, 200.0, 500.0])
    swept = cont(G0, heights)
    assert swept.shape == (3, NY, NX)
    for i, h in enumerate(heights):
        np.testing.assert_allclose(swept[i], cont(G0, h), atol=1e-12)
    assert len(traces) == 2  # one for the (3,) heights, one for the scalar
    # a batch of grids with one height each
    batch = jnp.stack([G0, 2.0 * G0])
    out = cont(batch, jnp.array([500.0, 500.0]))
    np.testing.assert_allclose(out[1], 2.0 * out[0], atol=1e-12)
    np.testing.assert_allclose(out[0], swept[2], atol=1e-12)
    assert len(traces) == 3  # the batched grid is a new input shape
    # vmap over grids equals the loop
    vm = jax.vmap(lambda g: upward_continuation(g, (DY, DX), 500.0))(batch)
    np.testing.assert_allclose(vm, out, atol=1e-12)


# --- validation --------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(
    st.floats(max_value=-1e-9, allow_infinity=True) | st.just(np.nan) | st.just(np.inf)
)
def test_negative_or_non_finite_height_is_rejected(h):
    with pytest.raises(ValueError, match="height"):
        upward_continuation(G0[:8, :8], (DY, DX), h)


@settings(max_examples=25, deadline=None)
@given(st.floats(max_value=0.0) | st.just(np.nan) | st.just(np.inf))
def test_bad_spacing_is_rejected(d):
    with pytest.raises(ValueError, match="spacing"):
        upward_continuation(G0[:8, :8], (DY, d), 10.0)
    with pytest.raises(ValueError, match="spacing"):
        wavenumbers((8, 8), (d, DX))


def test_other_bad_inputs():
    with pytest.raises(ValueError, match="Downward continuation"):
        upward_continuation(G0[:8, :8], (DY, DX), jnp.array([10.0, -1.0]))
    with pytest.raises(ValueError, match="values must be finite"):
        upward_continuation(np.full((8, 8), np.nan), (DY, DX), 10.0)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., ny, nx\)"):
        upward_continuation(np.zeros(8), (DY, DX), 10.0)
    with pytest.raises(ValueError, match="pad must be one of"):
        upward_continuation(G0[:8, :8], (DY, DX), 10.0, pad="zeros")
    with pytest.raises(ValueError, match="pad_width"):
        upward_continuation(G0[:8, :8], (DY, DX), 10.0, pad_width=-1)
    with pytest.raises(ValueError, match="does not broadcast"):
        upward_continuation(np.zeros((2, 8, 8)), (DY, DX), np.ones(3))
    with pytest.raises(ValueError, match=r"pair \(dy, dx\)"):
        upward_continuation(G0[:8, :8], (DY, DX, 1.0), 10.0)
    with pytest.raises(ValueError, match="two positive integers"):
        wavenumbers((8,), (DY, DX))
