"""rare_cond: lax.cond for one run; under vmap the taken side runs on the runs that take
it only (a padded block), and every run gets what it gets alone."""

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.rare_cond import rare_cond


def _noisy(op):
    x, key = op
    return 2.0 * x + jax.random.normal(key, x.shape, x.dtype), key


def _kept(op):
    return op


@jax.jit
def _alone(p, x, k):
    return jax.lax.cond(p, _noisy, _kept, (x, k))[0]


def _loop(preds, xs, keys):
    return np.stack([np.asarray(_alone(p, x, k))
                     for p, x, k in zip(preds, xs, keys, strict=True)])


_batched_quarter = jax.jit(jax.vmap(
    lambda p, x, k: rare_cond(p, _noisy, _kept, (x, k), share=0.25)[0]))  # compiled once


@pytest.mark.parametrize("taken", [[], [3], [0, 7], [1, 2, 5, 6], list(range(8))])
def test_vmap_equals_the_loop_below_at_and_over_the_capacity(taken):
    # 8 runs, share 0.25: a block of 2; none, 1, 2 (full), 4 and 8 (overflow) taken
    preds = jnp.zeros(8, bool).at[jnp.asarray(taken, int)].set(True)
    xs = jnp.arange(24.0).reshape(8, 3)
    keys = jax.random.split(jax.random.PRNGKey(0), 8)
    batched = _batched_quarter(preds, xs, keys)
    np.testing.assert_array_equal(np.asarray(batched), _loop(preds, xs, keys))
    assert np.all(np.asarray(batched)[~np.asarray(preds)] == np.asarray(xs)[~np.asarray(preds)])


def test_batched_each_side_is_traced_once_more_than_alone():
    # custom_vmap traces the one-run lax.cond (each side once); the batched rule then
    # once more: the blocks run in one loop, not a branch per case (a 3-way switch held
    # the true side twice and the false side three times: compile time)
    traced = {"true": 0, "false": 0}

    def doubled(x):
        traced["true"] += 1
        return 2.0 * x

    def same(x):
        traced["false"] += 1
        return x

    jax.jit(jax.vmap(lambda p, x: rare_cond(p, doubled, same, x, share=0.25))).lower(
        jnp.zeros(8, bool), jnp.ones((8, 3)))
    assert traced == {"true": 2, "false": 2}


def test_one_run_is_lax_cond_and_compiles_once():
    traces = []

    def run(p, x, k):
        traces.append(1)
        return rare_cond(p, _noisy, _kept, (x, k))[0]

    fn = jax.jit(run)
    x, k = jnp.ones(3), jax.random.PRNGKey(1)
    for p in (True, False, True):
        want = jax.lax.cond(p, _noisy, _kept, (x, k))[0]
        np.testing.assert_array_equal(np.asarray(fn(p, x, k)), np.asarray(want))
    assert len(traces) == 1


def test_unbatched_predicate_or_operand():
    xs = jnp.arange(6.0).reshape(3, 2)
    key = jax.random.PRNGKey(2)
    keys = jax.random.split(key, 3)
    # the predicate shared by the runs: an ordinary cond over the batch
    got = jax.jit(jax.vmap(lambda x, k: rare_cond(True, _noisy, _kept, (x, k))[0]))(xs, keys)
    np.testing.assert_array_equal(np.asarray(got), _loop([True] * 3, xs, keys))
    # the operand shared, the predicate batched: broadcast, then the block
    preds = jnp.asarray([False, True, False])
    got = jax.jit(jax.vmap(lambda p: rare_cond(p, _noisy, _kept, (xs[0], key))[0]))(preds)
    np.testing.assert_array_equal(np.asarray(got), _loop(preds, [xs[0]] * 3, [key] * 3))


def test_nested_vmap():
    preds = jnp.asarray([[False, True, False], [False, False, False]])
    xs = jnp.arange(18.0).reshape(2, 3, 3)
    keys = jax.random.split(jax.random.PRNGKey(3), 6).reshape(2, 3, -1)
    got = jax.jit(jax.vmap(jax.vmap(lambda p, x, k: rare_cond(p, _noisy, _kept, (x, k))[0])))(
        preds, xs, keys)
    want = _loop(preds.reshape(-1), xs.reshape(6, 3), keys.reshape(6, -1)).reshape(2, 3, 3)
    np.testing.assert_array_equal(np.asarray(got), want)


def _scaled(op):
    x, s = op
    return jnp.sin(x) * s, s


def test_grad_is_lax_cond_s_and_against_finite_differences():
    @partial(jax.jit, static_argnums=2)
    def f(x, p, cond):
        return jnp.sum(cond(p, _scaled, _kept, (x, 3.0))[0] ** 2)

    def ours(p, t, e, o):
        return rare_cond(p, t, e, o, share=0.5)

    x = jnp.asarray([0.3, -1.2, 2.0])
    for p in (True, False):
        g = jax.grad(f)(x, p, ours)
        np.testing.assert_allclose(np.asarray(g), np.asarray(jax.grad(f)(x, p, jax.lax.cond)),
                                   rtol=1e-12)
        h = 1e-6
        fd = [(f(x.at[i].add(h), p, ours) - f(x.at[i].add(-h), p, ours)) / (2 * h)
              for i in range(3)]
        np.testing.assert_allclose(np.asarray(g), np.asarray(fd), rtol=1e-6, atol=1e-8)
    # batched gradients: each run's as alone
    xs = jnp.stack([x, 2 * x, -x])
    preds = jnp.asarray([True, False, True])
    gb = jax.jit(jax.vmap(jax.grad(f), (0, 0, None)), static_argnums=2)(xs, preds, ours)
    gl = np.stack([np.asarray(jax.grad(f)(a, p, jax.lax.cond))
                   for a, p in zip(xs, preds, strict=True)])
    np.testing.assert_allclose(np.asarray(gb), gl, rtol=1e-12)


def test_grad_of_vmap_and_through_keys():
    # grad of a batched rare_cond (a lax.cond in the jvp failed to transpose here)
    preds = jnp.asarray([True, False, False])

    def total(x, cond):
        return jnp.sum(jax.vmap(lambda p, a: cond(p, _scaled, _kept, (a, 3.0))[0])(preds, x))

    def ours(p, t, e, o):
        return rare_cond(p, t, e, o, share=0.5)

    x = jnp.asarray([0.3, -1.2, 2.0])
    g = jax.jit(jax.grad(total), static_argnums=1)(x, ours)
    np.testing.assert_allclose(np.asarray(g), [3.0 * np.cos(0.3), 1.0, 1.0], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(g), np.asarray(jax.grad(total)(x, jax.lax.cond)),
                               rtol=1e-12)
    # a PRNG key in the operand (a float0 tangent) and in the output
    keys = jax.random.split(jax.random.PRNGKey(4), 3)
    gk = jax.jit(jax.grad(lambda x: jnp.sum(jax.vmap(
        lambda p, a, k: rare_cond(p, _noisy, _kept, (a, k), share=0.5)[0])(preds, x, keys))))(x)
    np.testing.assert_allclose(np.asarray(gk), [2.0, 1.0, 1.0], rtol=1e-12)


@pytest.mark.parametrize("share", [0.0, 1.5, float("nan"), "0.1", True])
def test_a_bad_share_is_a_clear_error(share):
    with pytest.raises(ValueError, match=r"share must be a number in \(0, 1\]"):
        rare_cond(True, _noisy, _kept, (jnp.ones(2), jax.random.PRNGKey(0)), share=share)


def test_numpy_shares_are_numbers():
    x, k = jnp.ones(2), jax.random.PRNGKey(0)
    for share in (np.float32(0.2), np.float64(0.5), 1):
        np.testing.assert_array_equal(np.asarray(rare_cond(False, _noisy, _kept, (x, k),
                                                           share=share)[0]), np.ones(2))
