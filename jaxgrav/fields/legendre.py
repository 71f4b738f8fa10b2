"""Scaled recursion of fully normalised Legendre functions, summed against coefficients.

:func:`order_sums` runs the forward-column recursion of Holmes & Featherstone (2002,
J. Geodesy 76:279) for the fully normalised P̄nm on the scaled values
``X̄nm = 10⁻²⁸⁰ P̄nm / cos^m φ`` (the sectorals X̄mm are constants, :func:`_sectorals`),
over degree n for all orders at once, and accumulates the per-order sums that
:mod:`jaxgrav.fields.harmonics` turns into fields; :func:`unscale_factors` gives the factors
``10²⁸⁰ cos^m φ`` applied to each order's sum at the end. The heights enter the
recursion, ``(R/r)^n`` being folded into it. The scaled recursion is valid at every
latitude up to degree ≈2700 (H&F; beyond it X̄nm overflows near the poles); terms that
underflow are below 1e-280 of the field and are dropped. float64 is required.
∂P̄nm/∂φ uses ``cos φ ∂P̄nm/∂φ = −n sin φ P̄nm + f_nm P̄(n−1)m`` for m ≥ 1 and
``∂P̄n0/∂φ = √(n(n+1)/2) P̄n1``, so no division by cos φ occurs.

**Cost.** ``O(N²)`` per (φ, r) value. Degrees run in up to four blocks, each carrying
only the orders ``m < n_block_end`` (≈⅜ less work at high degree), two degrees per
loop iteration for N ≥ 128. Each block is one more compiled loop. Reverse-mode
gradients recompute each block (``jax.checkpoint``), so their memory grows with
``N²/blocks`` per value.

Package-internal: :func:`order_sums` and :func:`unscale_factors` serve
:mod:`jaxgrav.fields.harmonics`, which is the public interface.
"""

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np

_LOG_SCALE = 280.0 * math.log(10.0)  # ln(1e280): the H&F scale factor
_DEG_PER_STEP = 2  # degrees per loop iteration for N ≥ 128 (fewer passes over the sums)
_DEGREES_PER_BLOCK = 90  # at least this many degrees per block
_MAX_BLOCKS = 4  # degree blocks: −20 % run time per doubling, +1.5 s compile


def _recursion_tables(nmax, width, dtype):
    """Per-degree recursion coefficients, each shape (nmax+1, width), built in-graph."""
    n = jnp.arange(nmax + 1, dtype=dtype)[:, None]
    m = jnp.arange(width, dtype=dtype)[None, :]
    d = n - m
    ok1 = d >= 1
    ok2 = d >= 2
    nm = jnp.where(ok1, d * (n + m), 1.0)
    a = jnp.where(ok1, jnp.sqrt((2 * n - 1) * (2 * n + 1) / nm), 0.0)
    den = jnp.where(ok2, 2 * n - 3, 1) * nm
    b = jnp.where(ok2, jnp.sqrt((2 * n + 1) * (n + m - 1) * (d - 1) / den), 0.0)
    f = jnp.where(ok1, jnp.sqrt((2 * n + 1) / jnp.where(ok1, 2 * n - 1, 1) * nm), 0.0)
    return a, b, f


def _sectorals(nmax):
    """Scaled sectorals 1e-280·P̄mm/cos^m φ for m = 0..nmax (NumPy, shape (nmax+1,))."""
    k = np.arange(max(nmax, 1) + 1, dtype=np.float64)
    ratio = np.ones(k.size)
    ratio[1] = math.sqrt(3.0)
    ratio[2:] = np.sqrt((2 * k[2:] + 1) / (2 * k[2:]))
    return 1e-280 * np.cumprod(ratio)[: nmax + 1]


def order_sums(c, s, t, q):
    """Per-order sums for a batch of (φ, r) values.

    Parameters
    ----------
    c, s : Array, shape (N+1, W)
        Coefficients (W = max(N+1, 2) columns, zero-padded).
    t, q : Array, shape (P,)
        sin φ and R/r.

    Returns
    -------
    tuple of 6 Arrays, shape (P, W)
        ``Σ_n (R/r)^n X̄nm c[n, m]`` and the same with ``s`` (potential), the same
        weighted by ``n + 1`` (radial derivative), and ``Σ_n (R/r)^n c[n, m] ∂P̄nm/∂φ``
        divided by ``1e280 cos^|m−1| φ`` (latitude derivative); X̄nm = 1e-280 P̄nm /
        cos^m φ. :func:`unscale_factors` gives the factors that undo the scaling.

    Notes
    -----
    With Y = q^n X̄, ``Σ_n c_n ∂P̄nm/∂φ`` is ``q Σ_n c_n f_n Y(n−1) − t Σ_n n c_n Y(n)``
    for m ≥ 1 and ``Σ_n c_n √(n(n+1)/2) Y(n, 1)`` for m = 0 (accumulated in column 0
    of the f-sums), so the loop only carries multiply-adds.
    """
    nmax, width = c.shape[0] - 1, c.shape[1]
    dtype = c.dtype
    k = _DEG_PER_STEP if nmax >= 128 else 1  # small N: compile time dominates
    nd = -(-(nmax + 1) // k) * k  # degrees padded to a multiple of k (zero coefficients)
    c, s = (jnp.pad(x, ((0, nd - nmax - 1), (0, 0))) for x in (c, s))
    a_tab, b_tab, f_tab = _recursion_tables(nd - 1, width, dtype)
    nn = jnp.arange(nd, dtype=dtype)
    f_tab = f_tab.at[:, 0].set(jnp.sqrt(nn * (nn + 1) / 2))  # ∂P̄n0/∂φ = √(n(n+1)/2) P̄n1
    cf, sf = c * f_tab, s * f_tab
    sect = jnp.asarray(np.pad(_sectorals(nmax), (0, nd - nmax - 1)), dtype)
    p = t.shape[0]
    tq, q2 = (t * q)[:, None], (q * q)[:, None]
    nblocks = max(1, min(_MAX_BLOCKS, nd // _DEGREES_PER_BLOCK))
    edges = np.unique(np.round(np.linspace(0, nd // k, nblocks + 1)).astype(int) * k)

    def block(carry, xs, wk):
        midx = jnp.arange(wk, dtype=dtype)

        def step(carry, x):
            y1, y2, qn, ac, as_, nc, ns, fc, fs = carry
            n, sec, a, b, cr, sr, cfr, sfr = x  # tuples of k per-degree rows
            ys = [y2, y1]
            for j in range(k):
                onehot = jnp.where(midx == n[j], sec[j], 0.0)  # start of column m = n
                ys.append(a[j] * tq * ys[-1] - b[j] * q2 * ys[-2] + onehot * qn[:, None])
                qn = qn * q
            y = ys[2:]
            # f-sums: column 0 takes Y(n, m=1) for ∂P̄n0/∂φ, the others Y(n−1, m)
            yp = [jnp.where(midx == 0, yn[:, 1:2], yo) for yn, yo in zip(y, ys[1:-1], strict=True)]
            ac, as_ = _madd(ac, cr, y), _madd(as_, sr, y)
            nc = _madd(nc, [nj * cj for nj, cj in zip(n, cr, strict=True)], y)
            ns = _madd(ns, [nj * sj for nj, sj in zip(n, sr, strict=True)], y)
            fc, fs = _madd(fc, cfr, yp), _madd(fs, sfr, yp)
            return (ys[-1], ys[-2], qn, ac, as_, nc, ns, fc, fs), None

        # k strided row tables rather than one (steps, k, W) table: XLA vectorises
        # the plain 2-D per-step slices far better (measured ×2)
        xs = tuple(tuple(x[j::k] for j in range(k)) for x in xs)
        return jax.lax.scan(step, carry, xs)[0]

    def widen(x, wk):
        return x if x.ndim == 1 else jnp.pad(x, ((0, 0), (0, wk - x.shape[1])))

    # reverse mode recomputes each block (only useful when there are several)
    run_block = jax.checkpoint(block, static_argnums=(2,)) if len(edges) > 2 else block
    zeros = jnp.zeros((p, 2), dtype)
    carry = (zeros, zeros, jnp.ones((p,), dtype)) + (zeros,) * 6
    for lo, hi in itertools.pairwise(edges):
        wk = int(min(max(hi, 2), width))  # orders m ≤ n < hi (and column 1 for ∂P̄n0)
        carry = tuple(widen(x, wk) for x in carry)
        rows = (a_tab, b_tab, c, s, cf, sf)
        xs = (nn[lo:hi], sect[lo:hi], *(x[lo:hi, :wk] for x in rows))
        carry = run_block(carry, xs, wk)
    ac, as_, nc, ns, fc, fs = (widen(x, width) for x in carry[3:])
    qq, tt = q[:, None], t[:, None]
    m0 = jnp.arange(width) == 0
    dc = jnp.where(m0, fc, qq * fc - tt * nc)
    ds = jnp.where(m0, fs, qq * fs - tt * ns)
    return ac, as_, ac + nc, as_ + ns, dc, ds


def _madd(acc, coefs, vals):
    """``acc + Σ_j coefs[j] * vals[j]`` (one fused pass over ``acc``)."""
    for cj, vj in zip(coefs, vals, strict=True):
        acc = acc + cj * vj
    return acc


def unscale_factors(u, width):
    """Factors 1e280·cos^m φ and 1e280·cos^|m−1| φ, each shape (P, W)."""
    m = jnp.arange(width, dtype=u.dtype)
    logu = jnp.log(jnp.maximum(u, 1e-300))[:, None]  # u ≥ 6e-17 for |lat| ≤ 90°
    return jnp.exp(m * logu + _LOG_SCALE), jnp.exp(jnp.abs(m - 1) * logu + _LOG_SCALE)
