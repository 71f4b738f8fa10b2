"""Steps 1–3 of paper A: search windows, iso-value masks and padded candidate sets.

Around each INS fix a fixed-size window of map nodes is searched for *iso-value
points*, nodes whose map value is within a tolerance of the reading:
``|g_i − M(x_k, y_k)| ≤ δ_k``. The tolerance is the user's δ (an array, so it can
be swept without recompiling) plus a discretisation allowance: the true position
is in general not a node, and the nearest node can differ from it by up to the
local map slope times half the cell diagonal. With ``slope_factor = 1`` that
allowance is exactly |∇M| · diag/2, so in a noiseless, locally linear field the
node nearest the truth is never rejected; ``slope_factor = 0`` is the paper's
plain tolerance.

The iso-points of each window are packed into a padded set of fixed capacity
(jax-md style): positions, values, a validity mask, the count actually found and
an overflow flag. On overflow the best-fitting points (smallest
``|g − M| / δ_k``) are kept and the flag is raised; nothing is dropped silently.
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match.chains import kmin

__all__ = ["CandidateSet", "iso_candidates", "lattice_candidates"]


class CandidateSet(NamedTuple):
    """Padded iso-value points of every fix.

    Attributes
    ----------
    lat, lon : Array, shape ``(N, C)``
        Node coordinates (degrees).
    north_m, east_m : Array, shape ``(N, C)``
        Offset of each node from its INS fix (m, local north/east).
    value : Array, shape ``(N, C)``
        Map value at the node (mGal).
    mask : Array of bool, shape ``(N, C)``
        Valid slots.
    count : Array of int, shape ``(N,)``
        Iso-points found in each window (may exceed C).
    overflow : Array of bool, shape ``(N,)``
        ``count > C``: only the C best-fitting points were kept.
    window_complete : Array of bool, shape ``(N,)``
        False where the window met the map edge and was shifted inside.
    """

    lat: jax.Array
    lon: jax.Array
    north_m: jax.Array
    east_m: jax.Array
    value: jax.Array
    mask: jax.Array
    count: jax.Array
    overflow: jax.Array
    window_complete: jax.Array


def iso_candidates(grid, lat, lon, readings, *, half_size, capacity, delta, slope_factor=1.0):
    """Iso-value candidate points of each fix in a fixed window around it.

    Parameters
    ----------
    grid : Grid
        Map (mGal), usually refined (:meth:`Grid.refine`).
    lat, lon : Array, shape ``(N,)``
        INS-indicated fixes (degrees).
    readings : Array, shape ``(N,)``
        Gravimeter readings, corrected as far as known (mGal).
    half_size : int
        Window half-width in nodes (static); windows are ``(2k+1)²`` nodes.
    capacity : int
        Candidate slots per fix (static).
    delta : float or Array, broadcastable to ``(N,)``
        Iso-value tolerance δ (mGal).
    slope_factor : float or Array
        Weight of the discretisation allowance (see module docstring).

    Returns
    -------
    CandidateSet
    """
    win, node_lat, node_lon, misfit = _window_misfit(grid, lat, lon, readings, half_size, delta,
                                                     slope_factor)
    s = 2 * half_size + 1
    iso = misfit <= 1.0
    count = jnp.sum(iso, axis=(-2, -1))
    flat_fit = jnp.where(iso, misfit, jnp.inf).reshape(misfit.shape[0], s * s)
    capacity = min(int(capacity), s * s)
    fit, idx = kmin(flat_fit, capacity)  # best-fitting first
    mask = jnp.isfinite(fit)
    r, c = idx // s, idx % s
    take = jax.vmap(lambda a, i: a[i])
    c_lat = take(node_lat, r)
    c_lon = take(node_lon, c)
    value = take(win.values.reshape(-1, s * s), idx)
    north, east = local_offsets_m(
        c_lat, c_lon, jnp.asarray(lat)[:, None], jnp.asarray(lon)[:, None]
    )
    return CandidateSet(
        c_lat, c_lon, north, east, value, mask, count, count > capacity, win.complete
    )


def lattice_candidates(grid, lat, lon, readings, *, half_size, delta, slope_factor=1.0):
    """Iso-value points of each fix on its window's node lattice (every node a slot).

    The same iso-value test as :func:`iso_candidates`, with the window's ``(2k+1)²``
    nodes as the slots in row-major order (``slot = row·(2k+1) + col``) and the
    iso-mask as validity: no capacity, so no overflow, and the neighbours of a node
    are found by index arithmetic (:mod:`~jaxgrav.match.lattice_chains`).

    Parameters
    ----------
    grid, lat, lon, readings, half_size, delta, slope_factor
        As :func:`iso_candidates`.

    Returns
    -------
    cands : CandidateSet
        Capacity ``(2k+1)²``; ``overflow`` is all false.
    origin : tuple of Array of int
        ``(row0, col0)``, each ``(N,)``: the grid indices of each window's first node.
    """
    win, node_lat, node_lon, misfit = _window_misfit(grid, lat, lon, readings, half_size, delta,
                                                     slope_factor)
    n, s = misfit.shape[0], 2 * half_size + 1
    iso = misfit <= 1.0
    # a node's north offset depends on its row only, its east offset on its column only:
    # 2s evaluations per fix instead of s², then broadcast (the same numbers)
    north_row, east_col = local_offsets_m(
        node_lat, node_lon, jnp.asarray(lat)[:, None], jnp.asarray(lon)[:, None]
    )
    by_row = lambda a: jnp.broadcast_to(a[:, :, None], (n, s, s)).reshape(n, s * s)  # noqa: E731
    by_col = lambda a: jnp.broadcast_to(a[:, None, :], (n, s, s)).reshape(n, s * s)  # noqa: E731
    c_lat, north = by_row(node_lat), by_row(north_row)
    c_lon, east = by_col(node_lon), by_col(east_col)
    count = jnp.sum(iso, axis=(-2, -1))
    cands = CandidateSet(c_lat, c_lon, north, east, win.values.reshape(n, s * s),
                         iso.reshape(n, s * s), count, jnp.zeros(n, bool), win.complete)
    return cands, (win.row0, win.col0)


def _window_misfit(grid, lat, lon, readings, half_size, delta, slope_factor):
    """Window, node coordinates ``(N, s)`` and ``|g − M| / tolerance`` ``(N, s, s)``."""
    win = grid.window(lat, lon, half_size)
    s = 2 * half_size + 1
    rows = win.row0[:, None] + jnp.arange(s)  # (N, s)
    cols = win.col0[:, None] + jnp.arange(s)
    node_lat = grid.lat0 + grid.dlat * rows
    node_lon = grid.lon0 + grid.dlon * cols
    # largest change to any of the 8 neighbours of each window node (edge-padded)
    v = win.values
    pad = jnp.pad(v, ((0, 0), (1, 1), (1, 1)), mode="edge")
    shifts = [pad[:, 1 + a : 1 + a + s, 1 + b : 1 + b + s] for a in (-1, 0, 1) for b in (-1, 0, 1)]
    # a running maximum, one elementwise kernel: stacking the 9 slices first made XLA:CPU
    # copy them into a (9, N, s, s) array, ~85 % of the candidates' time
    spread = functools.reduce(jnp.maximum, [jnp.abs(x - v) for x in shifts])
    tol = jnp.asarray(delta)[..., None, None] + 0.75 * slope_factor * spread
    misfit = jnp.abs(jnp.asarray(readings)[:, None, None] - win.values) / tol  # (N, s, s)
    return win, node_lat, node_lon, misfit
