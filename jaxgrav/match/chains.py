"""Steps 4–5 of paper A: constraint propagation and weighted least squares over chains.

A *chain* picks one candidate per fix. Over a short track the INS track is nearly
parallel to the true one, so consecutive candidates of a plausible chain keep the
INS step: its length within ``step_tol_m`` and its direction within
``angle_tol_deg``. These constraints are boolean compatibility matrices between
the candidates of fix i and fix i+1, computed on the fly inside ``lax.scan`` so
that memory stays ``O(N·C)`` per track.

* Forward elimination keeps candidates reachable from some candidate of fix 0,
  backward elimination those that reach fix N−1: together exactly the candidates
  lying on at least one complete chain (masked reductions, no Python loops).
* The number of complete chains (the paper's "constrained work") is counted by the
  same recursion with sums instead of ``any``.
* The k best chains under a sum of per-step costs are found by k-best min-sum
  dynamic programming (list Viterbi): every candidate keeps its K cheapest partial
  chains.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.constants import DEG

__all__ = [
    "ChainSearch",
    "compact",
    "compatibility",
    "count_chains",
    "eliminate",
    "kbest_backtrack",
    "kbest_chains",
    "kbest_run",
    "kbest_start",
    "kbest_step",
    "kmin",
    "step_bounds",
    "step_compatibility",
    "step_ok",
    "step_region",
    "step_within",
]


class ChainSearch(NamedTuple):
    """Result of :func:`kbest_chains`.

    Attributes
    ----------
    score : Array, shape ``(K,)``
        Total cost of each chain, ascending (``inf`` for missing chains).
    index : Array of int, shape ``(K, N)``
        Candidate slot of each fix along each chain.
    """

    score: jax.Array
    index: jax.Array


def kmin(x, k):
    """The k smallest entries along the last axis, ascending, and their indices.

    Ranks in float32 (XLA's CPU top-k is many times faster in float32 than in
    float64) and returns the exact values gathered from ``x``; entries closer than
    float32 resolution may come out in either order. (For the k = 16 of the chain
    search a sort beats k arg-min passes, unlike the dense path's k = 5.)
    """
    _, idx = jax.lax.top_k(-x.astype(jnp.float32), k)
    return jnp.take_along_axis(x, idx, axis=-1), idx


def compatibility(step_north, step_east, north0, east0, north1, east1, step_tol_m, angle_tol_deg):
    """Which candidates of fix i can follow which candidates of fix i+1.

    Parameters
    ----------
    step_north, step_east : Array (scalar)
        INS step from fix i to fix i+1 (m).
    north0, east0 : Array, shape ``(C,)``
        Candidate offsets from INS fix i (m).
    north1, east1 : Array, shape ``(C,)``
        Candidate offsets from INS fix i+1 (m).
    step_tol_m : Array
        Tolerance on the step length (m).
    angle_tol_deg : Array
        Tolerance on the step direction (degrees), to which the largest turn that a
        displacement of ``step_tol_m`` can cause, ``asin(step_tol_m / |INS step|)``, is
        added (any direction when the step is shorter than ``step_tol_m``).

    Returns
    -------
    Array of bool, shape ``(C, C)``
        ``[j, k]`` true when candidate j of fix i and k of fix i+1 keep the INS step.
    """
    sn = step_north + north1[None, :] - north0[:, None]
    se = step_east + east1[None, :] - east0[:, None]
    return step_ok(sn, se, step_north, step_east, step_tol_m, angle_tol_deg)


def step_ok(sn, se, step_north, step_east, step_tol_m, angle_tol_deg):
    """Whether steps ``(sn, se)`` (m, any broadcast shapes) keep the INS step.

    The test of :func:`compatibility` on given candidate steps: length within
    ``step_tol_m`` of the INS step's, direction within ``angle_tol_deg`` plus
    ``asin(step_tol_m / |INS step|)``.
    """
    bounds = step_bounds(step_north, step_east, step_tol_m, angle_tol_deg)
    return step_within(sn, se, step_north, step_east, bounds)


def step_within(sn, se, step_north, step_east, bounds):
    """:func:`step_ok` with the per-step constants of :func:`step_bounds` given, so that
    a scan over steps can compute them for every step before the loop."""
    lo, hi, dir_sq, obtuse, any_dir = bounds
    # |len - ins_len| <= tol and (angle <= tol <=> s·d >= |s||d| cos(tol)), on squares:
    # no square root or arc function per pair
    len_sq = sn * sn + se * se
    ok_len = (len_sq <= hi) & (len_sq >= lo)
    dot = sn * step_north + se * step_east
    cross = dot * dot
    ok_dir = jnp.where(obtuse, (dot >= 0) | (cross <= len_sq * dir_sq),
                       (dot >= 0) & (cross >= len_sq * dir_sq))
    return ok_len & (ok_dir | any_dir)


def step_compatibility(cands, steps, step_tol_m, angle_tol_deg):
    """Compatibility of every step at once, ``(N−1, C, C)`` (for small capacities).

    Computed once and shared by the elimination, the chain count and the dynamic
    programme (which otherwise recompute it inside their scans).
    """
    sn, se, n0, e0, n1, e1 = _steps(cands, steps)
    return jax.vmap(compatibility, in_axes=(0, 0, 0, 0, 0, 0, None, None))(
        sn, se, n0, e0, n1, e1, step_tol_m, angle_tol_deg)


def compact(cands, alive, capacity):
    """The surviving candidates of each fix moved to the first ``capacity`` slots.

    Parameters
    ----------
    cands : CandidateSet
        Candidates of N fixes, capacity C.
    alive : Array of bool, shape ``(N, C)``
        Survivors (:func:`eliminate`).
    capacity : int
        Slots kept per fix (static, ≤ C).

    Returns
    -------
    cands : CandidateSet
        Capacity ``capacity``; slot order (best fit first) is kept, ``mask`` marks
        the survivors, ``count`` and ``window_complete`` are unchanged.
    overflow : Array of bool, shape ``(N,)``
        More survivors than ``capacity`` (the best-fitting ones are kept).
    """
    csum = jnp.cumsum(alive, axis=1)
    want = jnp.arange(1, capacity + 1)
    slot = jax.vmap(lambda c: jnp.searchsorted(c, want, side="left"))(csum)
    slot = jnp.minimum(slot, alive.shape[1] - 1)
    take = lambda a: jnp.take_along_axis(a, slot, axis=1)  # noqa: E731
    mask = want[None, :] <= csum[:, -1:]
    out = cands._replace(lat=take(cands.lat), lon=take(cands.lon), north_m=take(cands.north_m),
                         east_m=take(cands.east_m), value=take(cands.value), mask=mask)
    return out, csum[:, -1] > capacity


def _xs(xs, compat):
    """Scan inputs: the step geometry, or the precomputed compatibility."""
    return xs if compat is None else (compat,)


def _compat_getter(compat, step_tol_m, angle_tol_deg):
    if compat is None:
        return lambda x: compatibility(*x[:6], step_tol_m, angle_tol_deg)
    return lambda x: x[0]


def step_region(step_north, step_east, step_tol_m, angle_tol_deg):
    """The steps :func:`step_ok` accepts, as an annular sector.

    Returns
    -------
    tuple of Array
        ``(r_lo, r_hi, half_angle, ins_len)``: step lengths ``r_lo ≤ |s| ≤ r_hi`` (m)
        at most ``half_angle`` (rad, ≤ π) off the INS step's direction; ``ins_len``
        is the INS step's length (m).
    """
    ins_len = jnp.hypot(step_north, step_east)
    ratio = jnp.minimum(step_tol_m / jnp.maximum(ins_len, 1e-9), 1.0)
    half_angle = jnp.minimum(angle_tol_deg * DEG + jnp.arcsin(ratio), jnp.pi)
    # a displacement of step_tol_m can turn an INS step no longer than it any way
    half_angle = jnp.where(ins_len <= step_tol_m, jnp.pi, half_angle)
    return jnp.maximum(ins_len - step_tol_m, 0.0), ins_len + step_tol_m, half_angle, ins_len


def step_bounds(step_north, step_east, step_tol_m, angle_tol_deg):
    """Per-step constants of :func:`step_ok` (any broadcast shapes).

    Returns
    -------
    tuple of Array
        ``(lo, hi, dir_sq, obtuse, any_dir)``: bounds on the squared step length (m²),
        ``(|d| cos tol)²`` (m²), whether the direction tolerance exceeds 90° and
        whether it admits every direction.
    """
    lo, hi, tol, ins_len = step_region(step_north, step_east, step_tol_m, angle_tol_deg)
    cos_tol = jnp.cos(tol)
    return lo * lo, hi * hi, (ins_len * cos_tol) ** 2, cos_tol < 0, tol >= jnp.pi


def _steps(cands, steps):
    """Per-step inputs for the scans: (INS step, offsets of fix i, offsets of fix i+1)."""
    sn, se = steps
    return (sn, se, cands.north_m[:-1], cands.east_m[:-1], cands.north_m[1:], cands.east_m[1:])


def eliminate(cands, steps, step_tol_m, angle_tol_deg, compat=None):
    """Forward and backward elimination of candidates that lie on no complete chain.

    Parameters
    ----------
    cands : CandidateSet
        Candidates of N fixes, capacity C.
    steps : tuple of Array
        ``(north, east)`` INS steps between consecutive fixes, each ``(N−1,)`` (m).
    step_tol_m, angle_tol_deg : Array
        Constraint tolerances.
    compat : Array of bool, shape ``(N−1, C, C)``, optional
        :func:`step_compatibility`, if already computed.

    Returns
    -------
    Array of bool, shape ``(N, C)``
        Surviving candidates.
    """
    xs = _steps(cands, steps)
    get = _compat_getter(compat, step_tol_m, angle_tol_deg)

    def fwd(alive, x):
        nxt = x[-1] & jnp.any(alive[:, None] & get(x), axis=0)
        return nxt, nxt

    _, rest = jax.lax.scan(fwd, cands.mask[0], (*_xs(xs, compat), cands.mask[1:]))
    fwd_alive = jnp.concatenate([cands.mask[:1], rest], axis=0)

    def bwd(alive_next, x):
        here = x[-1] & jnp.any(get(x) & alive_next[None, :], axis=1)
        return here, here

    _, back = jax.lax.scan(bwd, fwd_alive[-1], (*_xs(xs, compat), fwd_alive[:-1]), reverse=True)
    return jnp.concatenate([back, fwd_alive[-1:]], axis=0)


def count_chains(cands, alive, steps, step_tol_m, angle_tol_deg, compat=None):
    """Number of complete chains through surviving candidates (float, may be huge).

    ``compat`` is :func:`step_compatibility`, if already computed.
    """
    xs = _steps(cands, steps)
    get = _compat_getter(compat, step_tol_m, angle_tol_deg)
    dtype = jnp.result_type(float)

    def fwd(n, x):
        c = get(x) & x[-1][None, :]
        nxt = jnp.sum(jnp.where(c, n[:, None], 0.0), axis=0)
        return nxt, None

    n, _ = jax.lax.scan(fwd, alive[0].astype(dtype), (*_xs(xs, compat), alive[1:]))
    return jnp.sum(n)


def kbest_chains(cands, alive, steps, step_tol_m, angle_tol_deg, unary, pair_fn, k,
                 compat=None):
    """K cheapest complete chains by k-best min-sum dynamic programming.

    Parameters
    ----------
    cands : CandidateSet
    alive : Array of bool, shape ``(N, C)``
        Surviving candidates (:func:`eliminate`).
    steps : tuple of Array
        INS steps ``(north, east)``, each ``(N−1,)`` (m).
    step_tol_m, angle_tol_deg : Array
        Constraint tolerances.
    unary : Array, shape ``(N, C)``
        Per-candidate cost.
    pair_fn : callable
        ``pair_fn(i, value_i, value_next)`` → cost of the transitions from candidates
        of value ``value_i`` at fix i to candidates of value ``value_next`` at fix
        i+1, element-wise with broadcasting.
    k : int
        Number of chains (static).
    compat : Array of bool, shape ``(N−1, C, C)``, optional
        :func:`step_compatibility`, if already computed.

    Returns
    -------
    ChainSearch
    """
    inf = jnp.asarray(jnp.inf, dtype=unary.dtype)
    get = _compat_getter(compat, step_tol_m, angle_tol_deg)
    xs = (
        *_xs(_steps(cands, steps), compat),
        alive[1:],
        unary[1:],
        cands.value[:-1],
        cands.value[1:],
        jnp.arange(alive.shape[0] - 1),
    )

    def fwd(d, x):
        x, (alive_next, unary_next, v0, v1, i) = x[:-5], x[-5:]
        ok = (get(x) & alive_next[None, :]).T  # (C_next, C_prev)
        cost = jnp.where(ok, pair_fn(i, v0[None, :], v1[:, None]), inf) + unary_next[:, None]
        return kbest_step(d, cost, None, k)

    return kbest_run(fwd, xs, alive[0], unary[0], k)


def kbest_step(d, cost, index, k):
    """One step of the k-best min-sum programme.

    Parameters
    ----------
    d : Array, shape ``(C_prev, K)``
        The K cheapest partial chains ending at each candidate of fix i, ascending.
    cost : Array, shape ``(C_next, M)``
        Cost of reaching each candidate of fix i+1 from each of its M possible
        predecessors (transition plus its own unary cost; ``inf`` = not allowed).
    index : Array of int, shape ``(C_next, M)``, or None
        Predecessor slots in fix i; ``None`` when ``M = C_prev`` and predecessor m is
        slot m.
    k : int
        Chains kept per candidate (static).

    Returns
    -------
    tuple of Array
        ``(d_next (C_next, K), pointer (C_next, K))``, the pointer coding the
        predecessor slot and its chain rank as ``slot·K + rank``.
    """
    head = d[:, 0]
    # The K best partial chains ending at each next candidate come from the K
    # predecessors with the cheapest best (head) chains, each contributing its K
    # cheapest chains: select K rows, then K of K*K (exact, no full sort; with fewer
    # than K predecessors, all of them: still exact).
    heads = cost + (head[None, :] if index is None else head[index])
    _, rows = kmin(heads, min(k, cost.shape[1]))  # (C_next, K')
    src = rows if index is None else jnp.take_along_axis(index, rows, axis=1)
    sub = d[src] + jnp.take_along_axis(cost, rows, axis=1)[..., None]  # (C_next, K', K)
    vals, flat = kmin(sub.reshape(cost.shape[0], -1), k)
    prev = jnp.take_along_axis(src, flat // k, axis=1)
    return vals, (prev * k + flat % k).astype(jnp.int32)


def kbest_start(alive0, unary0, k):
    """The programme's first partial chains ``(C, K)``: each alive candidate of the first
    fix at its unary cost (rank 0), ``inf`` elsewhere."""
    inf = jnp.asarray(jnp.inf, dtype=unary0.dtype)
    return jnp.full((alive0.shape[0], k), inf).at[:, 0].set(jnp.where(alive0, unary0, inf))


def kbest_run(step_fn, xs, alive0, unary0, k):
    """Run the k-best programme (``lax.scan`` of ``step_fn`` over ``xs``) and backtrack.

    ``step_fn(d, x) -> (d_next, pointer)`` is one step (usually :func:`kbest_step`);
    the first fix's partial chains are :func:`kbest_start`.
    """
    d_last, ptrs = jax.lax.scan(step_fn, kbest_start(alive0, unary0, k), xs)  # (N-1, C, K)
    return kbest_backtrack(d_last, ptrs, k)


def kbest_backtrack(d_last, ptrs, k):
    """The K cheapest chains from the programme's last partial chains and pointers.

    Parameters
    ----------
    d_last : Array, shape ``(C, K)``
        The K cheapest partial chains ending at each candidate of the last fix.
    ptrs : Array of int, shape ``(N−1, C, K)``
        Pointers of every step (:func:`kbest_step`: ``slot·K + rank``).
    k : int
        Number of chains (static).

    Returns
    -------
    ChainSearch
    """
    total, best = kmin(d_last.reshape(-1), k)
    last_c, last_r = best // k, best % k

    def back(state, ptr):
        c, r = state
        p = ptr[c, r]
        prev = (p // k, p % k)
        return prev, c

    (c0, _), idx = jax.lax.scan(back, (last_c, last_r), ptrs, reverse=True)
    index = jnp.concatenate([c0[None, :], idx], axis=0).T  # (K, N)
    return ChainSearch(total, index)
