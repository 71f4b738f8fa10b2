"""Canaries for XLA:CPU miscompiles that return wrong numbers without an error.

jax/jaxlib 0.10.2 compile some reductions wrongly on the CPU once an array is large
enough (jax-ml/jax#39103, fixed upstream; 0.10.1 is correct). jaxgrav met it in the
layered DOV interpolation: the vertical combination of the layers, a weighted sum over
a leading axis of 3, gave η = a copy of ξ's pattern (errors of ~25″) at more than
2¹⁴ = 16 384 points, in float32, under ``jit`` only. ``pyproject.toml`` excludes 0.10.2; these tests
fail loudly if an environment still runs a JAX with the fault.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import dov


def _eager_and_jit(f, *args):
    with jax.disable_jit():
        eager = np.asarray(f(*args))
    return eager, np.asarray(jax.jit(f)(*args))


@pytest.mark.parametrize("n", [20_000, 40_000])
def test_weighted_sum_over_a_short_leading_axis_float32(n):
    rng = np.random.default_rng(0)
    vals = jnp.asarray(rng.standard_normal((3, 4, n)), jnp.float32)
    w = jnp.asarray(rng.standard_normal((3, n)), jnp.float32)
    eager, jitted = _eager_and_jit(lambda v, w: jnp.sum(w[:, None] * v[:, :2], axis=0), vals, w)
    np.testing.assert_allclose(jitted, eager, rtol=0, atol=1e-5)


@pytest.mark.parametrize(("dtype", "n"), [(jnp.float64, 16_385), (jnp.float32, 32_769)])
def test_vmapped_matvec_then_sum(dtype, n):
    """The reproducer of jax-ml/jax#39103, in our words."""
    i = jnp.arange(n, dtype=dtype)
    x = jnp.stack((i, jnp.zeros_like(i), jnp.zeros_like(i)), axis=1)
    m = jnp.eye(3, dtype=dtype)
    eager, jitted = _eager_and_jit(jax.vmap(lambda row: jnp.sum((m @ row) ** 2)), x)
    np.testing.assert_allclose(jitted, eager, rtol=1e-12 if dtype == jnp.float64 else 1e-6)


@pytest.mark.long  # its op-by-op reference compiles ~170 programs (13 s alone, 16-53 s in
# full runs); the fast tier keeps the fault's pattern in the weighted-sum canary above
def test_dov_interpolation_at_many_points_float32():
    """Where jaxgrav met the fault (a float32 interpolator inside jit, as in
    ``benchmarks/dov.py``): both channels right at 2·10⁴ points."""
    layers64 = dov.paper_c_layers()
    layers = dov.LayeredGrid(jnp.asarray(layers64.values, jnp.float32),
                             jnp.asarray(layers64.heights, jnp.float32), layers64.lat0,
                             layers64.dlat, layers64.lon0, layers64.dlon)
    rng = np.random.default_rng(1)
    n = 20_000  # the fault needs more than 2**14 points
    pts = [jnp.asarray(rng.uniform(a, b, n), jnp.float32)
           for a, b in ((33.5, 39.5), (106.5, 112.5), (0.0, 20000.0))]
    f = jax.jit(lambda lay, la, lo, h: dov.make_interpolator(lay)(la, lo, h)[0])
    jitted = np.asarray(f(layers, *pts))
    with jax.disable_jit():
        eager = np.asarray(f(layers, *pts))
    np.testing.assert_allclose(jitted, eager, rtol=0, atol=1e-4)
