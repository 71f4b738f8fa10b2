"""Steering XLA's CPU fusion: values computed once instead of inside every consumer."""

import jax
import jax.numpy as jnp

__all__ = ["computed_once"]


def computed_once(xs, like):
    """``xs`` unchanged, but computed once rather than inside every consumer element.

    XLA fuses cheap element-wise producers into their consumers and recomputes
    them per consumer element: a per-row sine broadcast over a grid is then computed
    once per grid cell and consumer, not once per row (the map lattices' positions,
    cells and Hermite weights; the point-mass filter's cell anomalies). A floating
    division is "expensive" to XLA and is not duplicated, so dividing by a run-time
    one (from ``like``, not a constant that would fold away, nor a broadcast one
    that XLA turns into a multiplication) makes XLA compute the values once.
    ``jax.lax.optimization_barrier`` does not survive XLA's CPU pipeline.

    Parameters
    ----------
    xs : pytree of Array
        Values of one shape (the shape of ``like``, or broadcastable to it).
    like : Array
        A run-time array of that shape (finite where the values are used).

    Returns
    -------
    pytree of Array
        ``xs``, numerically unchanged.
    """
    leaves, tree = jax.tree.flatten(xs)
    one = 1.0 + 0.0 * jnp.abs(like)
    stacked = jnp.stack(leaves) / one  # one pass for all of them
    return jax.tree.unflatten(tree, list(stacked))
