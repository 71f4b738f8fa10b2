"""A branch that few runs of a batch take: ``lax.cond`` whose ``vmap`` runs the taken
side only on the runs that take it, up to a capacity.

Under ``vmap`` a ``lax.cond`` with a batched predicate becomes a select: every run
computes both sides. A particle filter resamples after a few per cent of its readings
(2.7 % of paper D's steps, 1000 particles), so a batch of runs pays for resampling
every run at every step. :func:`rare_cond` is ``lax.cond`` for one run; batched, it
gathers the runs whose predicate is true into a padded block of ``capacity`` lanes
(``jnp.nonzero(size=...)``, jax-md's neighbour-list pattern), runs the true side on
that block only and scatters the results back. No run takes it: the false side
alone. More than ``capacity`` runs take it (the overflow): one block of ``capacity``
after another (a ``while`` loop over the blocks, so each side is compiled once). Each
run's side is computed on its own operand (its own keys), so ``vmap`` equals the loop
up to rounding; the rounding of a
batched computation may depend on how many other runs take the branch at that step
(8e-7 relative on float32 particles, 1e-14 on float64 ones: a particle filter then
differs between chunk sizes of the Monte Carlo runner at that level).

Limits: the sparsity is the innermost ``vmap``'s (under an outer ``vmap`` the choice
of blocks is itself batched: correct, not faster);
``true_fun`` and ``false_fun`` may close over constants and unbatched values only
(``custom_vmap`` refuses a batched closure with an ``AssertionError``; pass such values
in ``operand``). Differentiable in both modes, batched or not: the derivative is
computed from both sides and a select (``custom_vmap`` has no reverse mode of its own),
so a side that is not taken must have a finite derivative, as with ``jnp.where``.
"""

import math
import numbers

import jax
import jax.numpy as jnp

__all__ = ["rare_cond"]


def rare_cond(pred, true_fun, false_fun, operand, *, share=0.1):
    """``lax.cond(pred, true_fun, false_fun, operand)``, batched sparsely.

    Parameters
    ----------
    pred : Array, shape ``()``, bool
    true_fun, false_fun : callable
        ``operand -> out``, pure functions of the operand only (closures over Python
        constants, never over traced values), with outputs of equal structure.
    operand : pytree of arrays
    share : float
        Under ``vmap`` over ``B`` runs, the capacity of the true side's block is
        ``max(1, ceil(share · B))`` runs (at most ``B``); in ``(0, 1]``.

    Returns
    -------
    pytree
        ``true_fun(operand)`` where ``pred``, else ``false_fun(operand)``.

    Raises
    ------
    ValueError
        ``share`` not a number in ``(0, 1]``.
    """
    if not (isinstance(share, numbers.Real) and not isinstance(share, bool)
            and 0.0 < float(share) <= 1.0):
        raise ValueError(f"share must be a number in (0, 1] (a share of the batch's runs); "
                         f"got {share!r}")

    def plain(pred, operand):
        return jax.lax.cond(pred, true_fun, false_fun, operand)

    @jax.custom_batching.custom_vmap
    def sparse(pred, operand):
        return plain(pred, operand)

    @sparse.def_vmap
    def rule(axis_size, in_batched, pred, operand):
        pred_batched, op_batched = in_batched
        operand = jax.tree.map(
            lambda a, b: a if b else jnp.broadcast_to(a, (axis_size, *jnp.shape(a))),
            operand, op_batched)
        if not pred_batched:
            out = jax.lax.cond(pred, jax.vmap(true_fun), jax.vmap(false_fun), operand)
        else:
            out = _batched_branches(pred, true_fun, false_fun, operand, axis_size,
                                   min(axis_size, max(1, math.ceil(share * axis_size))))
        return out, jax.tree.map(lambda _: True, out)

    @jax.custom_jvp
    def branch(pred, operand):
        return sparse(pred, operand)

    @branch.defjvp
    def branch_jvp(primals, tangents):
        # both sides and a select, not lax.cond: a lax.cond on a batched predicate
        # inside a custom_jvp cannot be transposed (grad of vmap failed; JAX issues
        # 22011 and 39219)
        pred, operand = primals
        taken = jax.jvp(true_fun, (operand,), (tangents[1],))
        other = jax.jvp(false_fun, (operand,), (tangents[1],))
        return tuple(jax.tree.map(lambda a, b: _select(pred, a, b), t, o)
                     for t, o in zip(taken, other, strict=True))

    return branch(pred, operand)


def _select(pred, a, b):
    """``a`` where ``pred`` else ``b``; a float0 tangent (of an integer or key leaf) is
    zero on both sides and passes as it is."""
    if jnp.asarray(a).dtype == jax.dtypes.float0:
        return a
    return jnp.where(pred, a, b)


def _batched_branches(pred, true_fun, false_fun, operand, size, capacity):
    """The batched rule of :func:`rare_cond`.

    The false side on every run, then the true side on blocks of ``capacity`` of the
    runs that take it, one block after another in a ``while`` loop (none: no block;
    up to ``capacity``: one; more: as many as needed). Each side is traced and compiled
    once (three branches of a ``lax.switch`` held two copies of the true side and three
    of the false one: ~17 % of a voyage RBPF program's kernels).

    Parameters
    ----------
    pred : Array, shape ``(size,)``, bool
    true_fun, false_fun : callable
        As :func:`rare_cond`'s, on one run.
    operand : pytree of arrays
        Every leaf with a leading axis of ``size`` runs.
    size, capacity : int
        Runs, and lanes of the true side's block.

    Returns
    -------
    pytree
        Every leaf with a leading axis of ``size`` runs.
    """
    blocks = -(-size // capacity)
    # the taking runs in order, padded with an out-of-range index (dropped when scattered)
    order = jnp.nonzero(pred, size=blocks * capacity, fill_value=size)[0]
    order = order.reshape(blocks, capacity)
    n_blocks = (jnp.sum(pred, dtype=order.dtype) + capacity - 1) // capacity

    def block(i, out):
        idx = order[i]
        taken = jax.vmap(true_fun)(jax.tree.map(lambda a: a[jnp.minimum(idx, size - 1)],
                                                operand))
        return jax.tree.map(lambda a, t: a.at[idx].set(t, mode="drop"), out, taken)

    return jax.lax.fori_loop(0, n_blocks, block, jax.vmap(false_fun)(operand))
