"""Chain search on the node lattice: paper A's step constraints as a displacement stencil.

With every window node a candidate slot
(:func:`~jaxgrav.match.candidates.lattice_candidates`), the nodes of fix i that can
precede a node of fix i+1 are those whose displacement to it is a step the constraints
accept (:func:`~jaxgrav.match.chains.step_ok`): an annular sector around the INS step
that spans only a few nodes. So every node gets a padded neighbour list (jax-md
style) of the ``S × S`` node displacements of the sector's bounding box, with a mask
(inside the window, and the exact constraint on the pair) and an overflow flag when
the box is wider than ``S`` nodes. Elimination, chain count and the k-best programme
then cost O(C·S²) per step instead of the O(C²) of :mod:`~jaxgrav.match.chains`, with
the same result as :mod:`~jaxgrav.match.chains` on all window nodes: pairs outside the
box cannot satisfy the constraints.

Offsets are separable: a node's north offset from its INS fix depends on its row only
and its east offset on its column only, so the step of every (node, displacement) pair
is an outer sum of two ``(s, S)`` tables.
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match.chains import (
    kbest_backtrack,
    kbest_run,
    kbest_start,
    kbest_step,
    step_bounds,
    step_region,
    step_within,
)

__all__ = [
    "LatticeSteps",
    "count_chains_lattice",
    "displacement_box",
    "eliminate_lattice",
    "kbest_chains_lattice",
    "lattice_steps",
    "search_lattice",
    "stencil_size_for",
    "stencil_size_for_step",
]


class LatticeSteps(NamedTuple):
    """Geometry of the N−1 steps between consecutive windows (:func:`lattice_steps`).

    Attributes
    ----------
    step_north, step_east : Array, shape ``(N−1,)``
        INS steps (m).
    north0, east0 : Array, shape ``(N−1, s)``
        North offset of each window row and east offset of each window column from
        INS fix i (m).
    north1, east1 : Array, shape ``(N−1, s)``
        The same for fix i+1.
    row_base, col_base : Array of int, shape ``(N−1,)``
        A node at window row ``r'`` of fix i+1 and stencil row ``a`` is preceded by
        window row ``r' + row_base − a`` of fix i (columns alike).
    overflow : Array of bool, shape ``(N−1,)``
        The accepted steps span more than ``size`` nodes along an axis: pairs outside
        the stencil were not considered.
    size : int
        Stencil side ``S`` in nodes (static).
    """

    step_north: jax.Array
    step_east: jax.Array
    north0: jax.Array
    east0: jax.Array
    north1: jax.Array
    east1: jax.Array
    row_base: jax.Array
    col_base: jax.Array
    overflow: jax.Array
    size: int


def displacement_box(step_north, step_east, step_tol_m, angle_tol_deg):
    """Bounding box (m) of the steps :func:`~jaxgrav.match.chains.step_ok` accepts.

    The accepted steps form an annular sector (:func:`~jaxgrav.match.chains.step_region`);
    its box is spanned by the sector's four corners and the points of its outer arc
    due north, east, south and west, where those directions lie inside it.

    Returns
    -------
    tuple of Array
        ``(north_min, north_max, east_min, east_max)``, broadcast with the inputs.
    """
    r_lo, r_hi, half, _ = step_region(step_north, step_east, step_tol_m, angle_tol_deg)
    bearing = jnp.arctan2(step_east, step_north)
    angles = [bearing - half, bearing + half]
    north, east = [], []
    for a in angles:
        for r in (r_lo, r_hi):
            north.append(r * jnp.cos(a))
            east.append(r * jnp.sin(a))
    for axis in (0.0, 0.5 * jnp.pi, jnp.pi, -0.5 * jnp.pi):
        off = jnp.abs(jnp.mod(axis - bearing + jnp.pi, 2 * jnp.pi) - jnp.pi)
        inside = off <= half
        north.append(jnp.where(inside, r_hi * math.cos(axis), north[0]))
        east.append(jnp.where(inside, r_hi * math.sin(axis), east[0]))
    north, east = jnp.stack(north), jnp.stack(east)
    return north.min(0), north.max(0), east.min(0), east.max(0)


_DISPLACEMENT_BOX = jax.jit(displacement_box)
""":func:`displacement_box` jitted, for sizing on the host (:func:`stencil_size_for_step`)."""

ROUNDING_MARGIN = 0.01
"""Nodes added to each side of a step's box against rounding of the offsets (float32
positions in degrees carry ~0.1–0.5 m; 1 % of a node is 5 m on 500 m nodes)."""


def _node_range(lo_m, hi_m, node_m, eps_m):
    """Node displacements D with ``D·node_m`` in ``[lo_m − eps_m, hi_m + eps_m]``:
    ``(first, width)``."""
    eps_m = eps_m + ROUNDING_MARGIN * node_m
    first = jnp.ceil((lo_m - eps_m) / node_m).astype(int)
    last = jnp.floor((hi_m + eps_m) / node_m).astype(int)
    return first, last - first + 1


def _node_span(grid, lat, north_next_max, east_next_max, steps, step_tol_m, angle_tol_deg):
    """First node displacement and width (nodes) of each step's box, rows and columns.

    A node pair ``D`` rows apart makes the step ``D·dy_i + e`` with ``|e|`` at most the
    next fix's largest offset times the relative change of the metres per node between
    the two fixes; the box is widened by that and by :data:`ROUNDING_MARGIN`.
    """
    sn, se = steps
    n_lo, n_hi, e_lo, e_hi = displacement_box(sn, se, step_tol_m, angle_tol_deg)
    dy, dx = grid.spacing_m(lat)
    r_lo, r_width = _node_range(n_lo, n_hi, dy[:-1], north_next_max * jnp.abs(1 - dy[:-1] / dy[1:]))
    c_lo, c_width = _node_range(e_lo, e_hi, dx[:-1], east_next_max * jnp.abs(1 - dx[:-1] / dx[1:]))
    return r_lo, r_width, c_lo, c_width


def lattice_steps(grid, cands, origin, lat, steps, step_tol_m, angle_tol_deg, size):
    """Per-step geometry of the stencil search.

    Parameters
    ----------
    grid : Grid
        The map the candidates come from.
    cands : CandidateSet
        :func:`~jaxgrav.match.candidates.lattice_candidates` of N fixes, windows of
        ``s × s`` nodes.
    origin : tuple of Array of int
        ``(row0, col0)`` of each window, each ``(N,)`` (same function).
    lat : Array, shape ``(N,)``
        INS fixes (degrees).
    steps : tuple of Array
        INS steps ``(north, east)``, each ``(N−1,)`` (m), from fix i's local frame.
    step_tol_m, angle_tol_deg : Array
        Constraint tolerances (:func:`~jaxgrav.match.chains.compatibility`).
    size : int
        Stencil side ``S`` in nodes (static).

    Returns
    -------
    LatticeSteps
    """
    n, c = cands.north_m.shape
    s = math.isqrt(c)
    north = cands.north_m.reshape(n, s, s)[:, :, 0]
    east = cands.east_m.reshape(n, s, s)[:, 0, :]
    r_lo, r_width, c_lo, c_width = _node_span(
        grid, jnp.asarray(lat), jnp.max(jnp.abs(north[1:]), axis=1),
        jnp.max(jnp.abs(east[1:]), axis=1), steps, step_tol_m, angle_tol_deg)
    row0, col0 = origin
    row_base, col_base = jnp.diff(row0) - r_lo, jnp.diff(col0) - c_lo
    # a window jump that the INS step does not explain (the seam of a global map, where
    # the windows' column indices wrap) leaves no links at all: flag it too
    jump = (jnp.abs(row_base) >= s + size) | (jnp.abs(col_base) >= s + size)
    return LatticeSteps(
        steps[0], steps[1], north[:-1], east[:-1], north[1:], east[1:], row_base, col_base,
        (r_width > size) | (c_width > size) | jump, size,
    )


def stencil_size_for(grid, lat, lon, step_tol_m, angle_tol_deg):
    """Smallest stencil side (nodes) that holds every accepted step of a track.

    For sizing :class:`~jaxgrav.match.correlation.ChainConfig` outside jit.

    Parameters
    ----------
    grid : Grid
    lat, lon : array_like, shape ``(N,)`` or ``(B, N)``
        INS fixes (degrees), one track or a batch.
    step_tol_m, angle_tol_deg : float or array_like, shape ``(B,)``
        Constraint tolerances, as :func:`~jaxgrav.match.correlation.match_chains`
        applies them to each track
        (:func:`~jaxgrav.match.correlation.chain_tolerances`: the step tolerance
        includes the node allowance at the track's mean latitude).

    Returns
    -------
    int
    """
    lat, lon = np.atleast_2d(np.asarray(lat, float)), np.atleast_2d(np.asarray(lon, float))
    steps = local_offsets_m(lat[:, 1:], lon[:, 1:], lat[:, :-1], lon[:, :-1])
    # no offset from a fix exceeds the map's extent
    dy, dx = grid.spacing_m()
    far = max(grid.ny * dy, grid.nx * dx) * np.ones(lat.shape[1] - 1)
    tol = np.broadcast_to(np.asarray(step_tol_m, float), lat.shape[:1])
    ang = np.broadcast_to(np.asarray(angle_tol_deg, float), lat.shape[:1])
    spans = jax.vmap(lambda la, sn, se, t, a: _node_span(grid, la, far, far, (sn, se), t, a))(
        lat, *steps, tol, ang)
    return int(max(np.max(spans[1]), np.max(spans[3])))


def stencil_size_for_step(grid, step_m, step_tol_m, angle_tol_deg):
    """Stencil side (nodes) that holds every accepted step of length ``step_m`` (m), for
    any heading, anywhere on ``grid`` (at its northern and southern rows).

    For sizing :class:`~jaxgrav.match.correlation.ChainConfig` from a scenario rather
    than from a track (:func:`stencil_size_for`); pass the largest step tolerance that
    occurs on the grid.
    """
    bearing = np.deg2rad(np.arange(0.0, 360.0, 0.5))
    # one compiled program: op by op, the box's ~50 operations each compiled on its own
    # took ~1.8 s of CPU time at the chain matcher's first sizing (a cold process)
    box = _DISPLACEMENT_BOX(step_m * np.cos(bearing), step_m * np.sin(bearing), step_tol_m,
                            angle_tol_deg)
    n_lo, n_hi, e_lo, e_hi = (np.asarray(v) for v in box)
    size = 0
    for lat in (grid.lat0, grid.lat0 + grid.dlat * (grid.ny - 1)):
        dy, dx = (float(v) for v in grid.spacing_m(lat))
        # the radii change between fixes: 1 % of a node more (ample for any real step)
        rows = _node_range(n_lo, n_hi, dy, ROUNDING_MARGIN * dy)[1]
        cols = _node_range(e_lo, e_hi, dx, ROUNDING_MARGIN * dx)[1]
        size = max(size, int(np.max(rows)), int(np.max(cols)))
    return size


def _scan_inputs(geo, step_tol_m, angle_tol_deg):
    """Scan inputs of each step (everything but the static size and the overflow), with
    the constraint's per-step constants (:func:`~jaxgrav.match.chains.step_bounds`)
    computed for every step before the scan."""
    bounds = step_bounds(geo.step_north, geo.step_east, step_tol_m, angle_tol_deg)
    return (geo.step_north, geo.step_east, geo.north0, geo.east0, geo.north1, geo.east1,
            geo.row_base, geo.col_base, bounds)


def _links(x, s, size, backward):
    """Neighbour list of one step: ``(index (s², S²), ok (s², S²))``.

    Forward: for each node of fix i+1, the nodes of fix i that may precede it;
    backward: for each node of fix i, the nodes of fix i+1 that may follow it.
    ``ok`` is the exact constraint on the pair and false outside the window.
    """
    sn0, se0, n0, e0, n1, e1, row_base, col_base, bounds = x
    p, a = jnp.arange(s)[:, None], jnp.arange(size)[None, :]
    if backward:
        qr, qc = p - row_base + a, p - col_base + a
    else:
        qr, qc = p + row_base - a, p + col_base - a
    vr, vc = (qr >= 0) & (qr < s), (qc >= 0) & (qc < s)
    qr, qc = jnp.clip(qr, 0, s - 1), jnp.clip(qc, 0, s - 1)
    if backward:
        sn, se = sn0 + n1[qr] - n0[:, None], se0 + e1[qc] - e0[:, None]
    else:
        sn, se = sn0 + n1[:, None] - n0[qr], se0 + e1[:, None] - e0[qc]
    ok = step_within(sn[:, None, :, None], se[None, :, None, :], sn0, se0, bounds)
    ok = ok & vr[:, None, :, None] & vc[None, :, None, :]
    index = qr[:, None, :, None] * s + qc[None, :, None, :]
    return index.reshape(s * s, size * size), ok.reshape(s * s, size * size)


def _side(cands):
    return math.isqrt(cands.mask.shape[1])


def eliminate_lattice(cands, geo, step_tol_m, angle_tol_deg):
    """Forward and backward elimination on the lattice (as :func:`~jaxgrav.match.chains.eliminate`).

    Parameters
    ----------
    cands : CandidateSet
        :func:`~jaxgrav.match.candidates.lattice_candidates`.
    geo : LatticeSteps
    step_tol_m, angle_tol_deg : Array
        Constraint tolerances.

    Returns
    -------
    Array of bool, shape ``(N, s²)``
        Candidates on at least one complete chain.
    """
    s, size = _side(cands), geo.size
    xs = _scan_inputs(geo, step_tol_m, angle_tol_deg)

    def fwd(alive, x):
        index, ok = _links(x[:-1], s, size, backward=False)
        nxt = x[-1] & jnp.any(ok & alive[index], axis=1)
        return nxt, nxt

    _, rest = jax.lax.scan(fwd, cands.mask[0], (*xs, cands.mask[1:]))
    return _eliminate_backward(jnp.concatenate([cands.mask[:1], rest], axis=0), xs, s, size)


def _eliminate_backward(fwd_alive, xs, s, size):
    """Backward elimination: the nodes of ``fwd_alive`` ``(N, s²)`` that reach the last fix."""

    def bwd(alive_next, x):
        index, ok = _links(x[:-1], s, size, backward=True)
        here = x[-1] & jnp.any(ok & alive_next[index], axis=1)
        return here, here

    _, back = jax.lax.scan(bwd, fwd_alive[-1], (*xs, fwd_alive[:-1]), reverse=True)
    return jnp.concatenate([back, fwd_alive[-1:]], axis=0)


def count_chains_lattice(cands, alive, geo, step_tol_m, angle_tol_deg):
    """Number of complete chains through the surviving nodes (float, may be huge)."""
    s, size = _side(cands), geo.size
    dtype = jnp.result_type(float)

    def fwd(n, x):
        index, ok = _links(x[:-1], s, size, backward=False)
        nxt = jnp.where(x[-1], jnp.sum(jnp.where(ok, n[index], 0.0), axis=1), 0.0)
        return nxt, None

    xs = (*_scan_inputs(geo, step_tol_m, angle_tol_deg), alive[1:])
    n, _ = jax.lax.scan(fwd, alive[0].astype(dtype), xs)
    return jnp.sum(n)


def kbest_chains_lattice(cands, alive, geo, step_tol_m, angle_tol_deg, unary, pair_fn, k):
    """K cheapest complete chains on the lattice (as :func:`~jaxgrav.match.chains.kbest_chains`).

    Parameters
    ----------
    cands : CandidateSet
        :func:`~jaxgrav.match.candidates.lattice_candidates`.
    alive : Array of bool, shape ``(N, s²)``
        :func:`eliminate_lattice`.
    geo : LatticeSteps
    step_tol_m, angle_tol_deg : Array
    unary : Array, shape ``(N, s²)``
    pair_fn : callable
        Element-wise transition cost ``pair_fn(i, value_i, value_next)``.
    k : int
        Number of chains (static).

    Returns
    -------
    ChainSearch
        ``index`` holds lattice slots.
    """
    s, size = _side(cands), geo.size
    inf = jnp.asarray(jnp.inf, dtype=unary.dtype)
    xs = (*_scan_inputs(geo, step_tol_m, angle_tol_deg), alive[1:], unary[1:],
          cands.value[:-1], cands.value[1:], jnp.arange(alive.shape[0] - 1))

    def fwd(d, x):
        x, (alive_next, unary_next, v0, v1, i) = x[:-5], x[-5:]
        index, ok = _links(x, s, size, backward=False)
        cost = jnp.where(ok & alive_next[:, None], pair_fn(i, v0[index], v1[:, None]), inf)
        return kbest_step(d, cost + unary_next[:, None], index, k)

    return kbest_run(fwd, xs, alive[0], unary[0], k)


def search_lattice(cands, geo, step_tol_m, angle_tol_deg, unary, pair_fn, k):
    """Survivors, chain count and the k best chains: the results of
    :func:`eliminate_lattice`, :func:`count_chains_lattice` and
    :func:`kbest_chains_lattice` (same arguments) in two scans.

    The forward scan runs the chain count and the programme on the valid nodes, each
    step's neighbour list and constraint computed once for both: a node is reachable
    from the first fix when its count is positive (the forward elimination), and the
    counts and partial chains of the nodes that reach the last fix are those of the
    survivors (their predecessors are survivors too), so the count and the chains are
    the same. The backward scan then eliminates the nodes that do not reach the last
    fix.

    Returns
    -------
    alive : Array of bool, shape ``(N, s²)``
    count : Array (scalar)
    search : ChainSearch
    """
    s, size = _side(cands), geo.size
    mask = cands.mask
    inf = jnp.asarray(jnp.inf, dtype=unary.dtype)
    steps = _scan_inputs(geo, step_tol_m, angle_tol_deg)
    xs = (*steps, mask[1:], unary[1:], cands.value[:-1], cands.value[1:],
          jnp.arange(mask.shape[0] - 1))

    def fwd(carry, x):
        d, n = carry
        x, (mask_next, unary_next, v0, v1, i) = x[:-5], x[-5:]
        index, ok = _links(x, s, size, backward=False)
        cost = jnp.where(ok & mask_next[:, None], pair_fn(i, v0[index], v1[:, None]), inf)
        # the count reads the constraint off the (finite) costs: XLA would otherwise
        # evaluate the constraint again inside the count's kernel
        n_next = jnp.sum(jnp.where(cost < inf, n[index], 0.0), axis=1)
        d_next, ptr = kbest_step(d, cost + unary_next[:, None], index, k)
        return (d_next, n_next), (ptr, n_next > 0)

    n0 = mask[0].astype(jnp.result_type(float))
    (d_last, n_last), (ptrs, reached) = jax.lax.scan(
        fwd, (kbest_start(mask[0], unary[0], k), n0), xs)
    alive = _eliminate_backward(jnp.concatenate([mask[:1], reached], axis=0), steps, s, size)
    return alive, jnp.sum(n_last), kbest_backtrack(d_last, ptrs, k)
