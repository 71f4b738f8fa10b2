"""Dense matching of many tracks against one map, in cache-sized chunks."""

import functools

import jax
import jax.numpy as jnp

from jaxgrav.match.dense import DenseConfig, lattice_table, match_dense
from jaxgrav.prepared import as_grid

__all__ = ["match_dense_batch"]


@functools.partial(jax.jit, static_argnames=("chunk",))
def match_dense_batch(grid, lat, lon, readings, config=DenseConfig(), prepared=None, chunk=128):  # noqa: B008
    """:func:`~jaxgrav.match.dense.match_dense` over a batch of tracks sharing one map, in chunks.

    Equal to ``jax.vmap(match_dense, in_axes=(None, 0, 0, 0, None, None))``; tracks
    are matched ``chunk`` at a time (vectorised within a chunk, a loop over chunks),
    which keeps the intermediates cache-sized: on CPU faster than one ``vmap`` over
    thousands of tracks.

    Parameters
    ----------
    grid : Grid or PreparedMap
        Anomaly map (mGal).
    lat, lon : Array, shape ``(B, N)``
        INS-indicated fixes of ``B`` tracks (degrees).
    readings : Array, shape ``(B, N)``
        Gravimeter readings (mGal).
    config : DenseConfig
    prepared : Array, optional
        :func:`~jaxgrav.match.dense.lattice_table` of ``grid``; computed once here when omitted.
    chunk : int
        Most tracks per chunk (static); the batch is cut into equal chunks, the
        last one padded with copies of the first track (results dropped).

    Returns
    -------
    MatchResult
        Fields with a leading batch axis ``B``.
    """
    table = lattice_table(grid, config.method) if prepared is None else prepared
    grid = as_grid(grid)
    b = lat.shape[0]
    n_chunks = -(-b // chunk)
    size = -(-b // n_chunks)  # equal chunks: one compiled body (no remainder branch)
    pad = n_chunks * size - b
    xs = tuple(jnp.concatenate([a, jnp.broadcast_to(a[:1], (pad, *a.shape[1:]))])
               if pad else a for a in (lat, lon, readings))
    xs = tuple(a.reshape(n_chunks, size, *a.shape[1:]) for a in xs)
    out = jax.lax.map(jax.vmap(lambda x: match_dense(grid, *x, config, table)), xs)
    return jax.tree.map(lambda a: a.reshape(n_chunks * size, *a.shape[2:])[:b], out)
