"""Blocks of innovations tested against the filter's predicted variance: the one rule.

A filter that has lost its position can still state a small covariance; what gives it
away is its innovations, larger than it predicts. :func:`innovation_blocks` cuts the
used readings of a run into consecutive blocks (:data:`INNOVATION_BLOCK`, the last one
takes the remainder) and gives each block's summed normalised innovations squared, its
degrees of freedom and the χ² tail probability; a block with ``p <``
:data:`~jaxgrav.match.result.P_IMPLAUSIBLE` (10⁻³) is implausible. Blocks do not
overlap, so a consistent filter flags a block with probability 10⁻³ (about one 12 h
voyage in 14 at a reading every 10 s). ``jaxgrav filter`` and ``jaxgrav navigate`` flag
the rows of such blocks (:func:`implausible_rows`), and the voyage Monte Carlo methods
count them per run (:func:`implausible_block_count`) with the same function, inside
``jit`` and ``vmap`` (fixed shapes: a segment sum over block indices).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaincc

from jaxgrav.match.result import P_IMPLAUSIBLE

__all__ = ["INNOVATION_BLOCK", "InnovationBlocks", "implausible_block_count",
           "implausible_rows", "innovation_blocks"]

INNOVATION_BLOCK = 60
"""Readings per block (10 min at a reading every 10 s)."""


class InnovationBlocks(NamedTuple):
    """The blocks of a run's innovations; ``B = ceil(N / block)`` slots, of which the
    first ``ceil(used / block)`` hold blocks (the rest have ``dof`` 0 and ``p`` 1).

    Attributes
    ----------
    nis : Array, shape ``(B,)``
        Sum of the block's normalised innovations squared.
    dof : Array, shape ``(B,)``
        Readings in the block.
    p : Array, shape ``(B,)``
        χ²(dof) tail probability of ``nis`` (1 for an empty slot).
    first, last : Array of int, shape ``(B,)``
        Row of the block's first and last reading (``N`` and ``-1`` for an empty slot).
    """

    nis: jax.Array
    dof: jax.Array
    p: jax.Array
    first: jax.Array
    last: jax.Array


def innovation_blocks(innovation, innovation_sigma, block=INNOVATION_BLOCK):
    """Consecutive blocks of the used readings' innovations and their χ² test.

    Parameters
    ----------
    innovation, innovation_sigma : array_like, shape ``(N,)``
        Reading minus prediction and its predicted 1-σ (the same units, e.g. mGal); a row
        with either non-finite, or a 1-σ ≤ 0, used no reading.
    block : int
        Readings per block (static).

    Returns
    -------
    InnovationBlocks
    """
    if not (isinstance(block, int) and block >= 1):
        raise ValueError(f"block must be a whole number of readings >= 1; got {block!r}")
    nu, s = jnp.asarray(innovation), jnp.asarray(innovation_sigma)
    if nu.ndim != 1 or s.shape != nu.shape:
        raise ValueError(f"innovation and innovation_sigma must be 1-D of one length; got "
                         f"shapes {nu.shape} and {s.shape}")
    n = nu.shape[0]
    slots = -(-n // block)
    used = jnp.isfinite(nu) & jnp.isfinite(s) & (s > 0)
    z2 = jnp.where(used, (jnp.where(used, nu, 0.0) / jnp.where(used, s, 1.0)) ** 2, 0.0)
    # a used row's block is its rank among the used rows // block; unused rows go to a
    # spare slot that is dropped
    slot = jnp.where(used, (jnp.cumsum(used) - 1) // block, slots)
    rows = jnp.arange(n)
    nis = jax.ops.segment_sum(z2, slot, slots + 1)[:slots]
    dof = jax.ops.segment_sum(used.astype(z2.dtype), slot, slots + 1)[:slots]
    first = jax.ops.segment_min(jnp.where(used, rows, n), slot, slots + 1)[:slots]
    last = jax.ops.segment_max(jnp.where(used, rows, -1), slot, slots + 1)[:slots]
    p = jnp.where(dof > 0, gammaincc(jnp.maximum(dof, 1.0) / 2, nis / 2), 1.0)
    return InnovationBlocks(nis, dof, p, jnp.minimum(first, n), jnp.maximum(last, -1))


def implausible_block_count(innovation, innovation_sigma, block=INNOVATION_BLOCK):
    """Number of implausible blocks of a run (``p < P_IMPLAUSIBLE``; arguments as
    :func:`innovation_blocks`); traceable, for ``vmap`` over runs.

    Returns
    -------
    Array of int32, shape ``()``
    """
    blocks = innovation_blocks(innovation, innovation_sigma, block)
    return jnp.sum(blocks.p < P_IMPLAUSIBLE).astype(jnp.int32)


def implausible_rows(innovation, innovation_sigma, block=INNOVATION_BLOCK):
    """Rows whose block of innovations is implausible for the filter's predicted variance.

    A block with ``p <`` :data:`~jaxgrav.match.result.P_IMPLAUSIBLE` flags every row
    from its first reading to its last (arguments as :func:`innovation_blocks`).

    Returns
    -------
    numpy.ndarray of bool, shape ``(N,)``
    """
    nu = np.asarray(innovation, float)
    if nu.shape[0] == 0:
        return np.zeros(0, bool)
    blocks = jax.tree.map(np.asarray, innovation_blocks(
        nu, np.asarray(innovation_sigma, float), block))
    bad = blocks.p < P_IMPLAUSIBLE
    flagged = np.zeros(nu.shape[0] + 1, int)
    np.add.at(flagged, blocks.first[bad], 1)
    np.add.at(flagged, blocks.last[bad] + 1, -1)
    return np.cumsum(flagged[:-1]) > 0
