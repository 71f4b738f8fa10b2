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
    "compatibility",
    "count_chains",
    "eliminate",
    "kbest_chains",
    "kmin",
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
    float32 resolution may come out in either order.
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
    ins_len = jnp.hypot(step_north, step_east)
    cand_len = jnp.hypot(sn, se)
    ok_len = jnp.abs(cand_len - ins_len) <= step_tol_m
    # angle between candidate and INS steps <= tol  <=>  s·d >= |s||d| cos(tol)  (no arctan)
    ratio = jnp.minimum(step_tol_m / jnp.maximum(ins_len, 1e-9), 1.0)
    tol = jnp.minimum(angle_tol_deg * DEG + jnp.arcsin(ratio), jnp.pi)
    dot = sn * step_north + se * step_east
    ok_dir = dot >= cand_len * ins_len * jnp.cos(tol)
    return ok_len & ok_dir


def _steps(cands, steps):
    """Per-step inputs for the scans: (INS step, offsets of fix i, offsets of fix i+1)."""
    sn, se = steps
    return (sn, se, cands.north_m[:-1], cands.east_m[:-1], cands.north_m[1:], cands.east_m[1:])


def eliminate(cands, steps, step_tol_m, angle_tol_deg):
    """Forward and backward elimination of candidates that lie on no complete chain.

    Parameters
    ----------
    cands : CandidateSet
        Candidates of N fixes, capacity C.
    steps : tuple of Array
        ``(north, east)`` INS steps between consecutive fixes, each ``(N−1,)`` (m).
    step_tol_m, angle_tol_deg : Array
        Constraint tolerances.

    Returns
    -------
    Array of bool, shape ``(N, C)``
        Surviving candidates.
    """
    xs = _steps(cands, steps)

    def fwd(alive, x):
        compat = compatibility(*x[:6], step_tol_m, angle_tol_deg)
        nxt = x[6] & jnp.any(alive[:, None] & compat, axis=0)
        return nxt, nxt

    _, rest = jax.lax.scan(fwd, cands.mask[0], (*xs, cands.mask[1:]))
    fwd_alive = jnp.concatenate([cands.mask[:1], rest], axis=0)

    def bwd(alive_next, x):
        compat = compatibility(*x[:6], step_tol_m, angle_tol_deg)
        here = x[6] & jnp.any(compat & alive_next[None, :], axis=1)
        return here, here

    _, back = jax.lax.scan(bwd, fwd_alive[-1], (*xs, fwd_alive[:-1]), reverse=True)
    return jnp.concatenate([back, fwd_alive[-1:]], axis=0)


def count_chains(cands, alive, steps, step_tol_m, angle_tol_deg):
    """Number of complete chains through surviving candidates (float, may be huge)."""
    xs = _steps(cands, steps)
    dtype = jnp.result_type(float)

    def fwd(n, x):
        compat = compatibility(*x[:6], step_tol_m, angle_tol_deg) & x[6][None, :]
        nxt = jnp.sum(jnp.where(compat, n[:, None], 0.0), axis=0)
        return nxt, None

    n, _ = jax.lax.scan(fwd, alive[0].astype(dtype), (*xs, alive[1:]))
    return jnp.sum(n)


def kbest_chains(cands, alive, steps, step_tol_m, angle_tol_deg, unary, pair_fn, k):
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
        ``pair_fn(i, value_i (C,), value_next (C,)) -> (C, C)`` cost of each transition.
    k : int
        Number of chains (static).

    Returns
    -------
    ChainSearch
    """
    n_fix, cap = alive.shape
    inf = jnp.asarray(jnp.inf, dtype=unary.dtype)
    d0 = jnp.full((cap, k), inf).at[:, 0].set(jnp.where(alive[0], unary[0], inf))
    xs = (
        *_steps(cands, steps),
        alive[1:],
        unary[1:],
        cands.value[:-1],
        cands.value[1:],
        jnp.arange(n_fix - 1),
    )

    def fwd(d, x):
        compat = compatibility(*x[:6], step_tol_m, angle_tol_deg) & x[6][None, :]
        pair = jnp.where(compat, pair_fn(x[10], x[8], x[9]), inf) + x[7][None, :]  # (C, C)
        # The K best partial chains ending at each next candidate come from the K
        # previous candidates with the cheapest best (head) chains, each contributing
        # its K cheapest chains: select K rows, then K of K*K (exact, no full sort).
        heads = (d[:, 0][:, None] + pair).T  # (C_next, C_prev)
        _, rows = kmin(heads, k)  # (C_next, K)
        sub = d[rows] + jnp.take_along_axis(pair.T, rows, axis=1)[..., None]  # (C_next, K, K)
        vals, flat = kmin(sub.reshape(cap, k * k), k)
        prev = jnp.take_along_axis(rows, flat // k, axis=1)
        return vals, prev * k + flat % k

    d_last, ptrs = jax.lax.scan(fwd, d0, xs)  # ptrs: (N-1, C, K)
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
