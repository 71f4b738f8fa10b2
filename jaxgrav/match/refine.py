"""Sub-cell refinement of a dense-offset match: damped Gauss–Newton on the bicubic map.

The parameters are ``p = (north, east, rotation, bias)``: shift (m) and turn (rad,
about the centroid) of the INS track, and the common reading bias (mGal). The
weighted residuals are those whose squared norm is the match score
(:func:`~jaxgrav.match.scoring.score_track`); their Jacobian is analytic (gradient
of the bicubic patch, chain rule through the turn and shift), residuals and
Jacobian are kept from the last accepted step, and the 4 × 4 normal equations are
solved in closed form (unrolled Cholesky, :func:`solve_spd`), so that a ``vmap`` over
many tracks is a few element-wise operations per step rather than per-track LAPACK
calls. The Laplace covariance, computed once, solves its two columns in one loop
(:func:`jaxgrav._linalg.solve_spd`), which compiles to a few kernels where the unrolled
solves were ~23 of the dense matcher's Monte Carlo program.
"""

import jax
import jax.numpy as jnp

from jaxgrav._fusion import computed_once
from jaxgrav._linalg import solve_spd as solve_spd_loop
from jaxgrav.lattice import patch_values
from jaxgrav.match.scoring import sums

__all__ = ["gauss_newton", "gls_residual_function", "laplace_covariance", "residual_function",
           "solve_spd"]


def residual_function(table, frame, g, w, kind, prior, method, present=None):
    """Weighted residuals of ``p = (north, east, rotation, bias)`` and their Jacobian.

    Parameters
    ----------
    table : Array
        Lattice table (:func:`jaxgrav.match.dense.lattice_table`).
    frame : tuple
        ``(iy_c, ix_c, ky, kx, north, east)``: centroid in map indices, index steps
        per metre north and east, fixes' offsets from the centroid (m), ``(N,)``.
    g, w : Array, shape ``(N,)``
        Readings (mGal) and weights μ_i.
    kind : {"absolute", "difference", "bias"}
        Score form (static).
    prior : Array
        κ of the bias prior.
    method : {"bicubic", "bilinear"}
    present : Array of bool, shape ``(N,)``, optional
        Survey gaps (:mod:`~jaxgrav.match.gaps`): only these fixes enter (the others'
        residuals and Jacobian rows are 0); a present fix that moves into a missing
        cell gives NaN, so the step is refused.

    Returns
    -------
    callable
        ``res(p) -> (r, cols, extra)``: residuals of the fixes ``r`` ``(M,)``, the
        columns of ``J = dr/dp`` (four ``(M,)`` arrays) and, for the bias form with
        a prior, the prior's residual row ``(r_κ, j_κ)`` (scalar, ``(4,)``; zeros
        otherwise), kept apart so that no concatenation splits XLA's fusions.
    """
    iy_c, ix_c, ky, kx, north, east = frame
    sqrt_w = jnp.sqrt(w / jnp.sum(w))
    sqrt_wd = jnp.sqrt(w[:-1] / jnp.sum(w[:-1]))
    zero = jnp.zeros_like(north)
    no_prior = jnp.zeros((), north.dtype), jnp.zeros((4,), north.dtype)

    def res(p):
        c, s = jnp.cos(p[2]), jnp.sin(p[2])
        rn, re = c * north - s * east, s * north + c * east
        v, v_y, v_x = patch_values(table, iy_c + ky * (rn + p[0]), ix_c + kx * (re + p[1]),
                                   method, gradient=True)
        # computed once: each of the normal equations' 15 products would recompute them
        v, v_y, v_x = computed_once((v, v_y, v_x), v)
        r = g - v
        a, b = v_y * ky, v_x * kx  # dv/d(north), dv/d(east)
        if present is not None:
            r, a, b = (jnp.where(present, x, 0.0) for x in (r, a, b))
        cols = (-a, -b, a * re - b * rn)  # dr/dp for the shift and turn
        if kind == "difference":
            swd = sqrt_wd if present is None else sqrt_wd * (present[1:] & present[:-1])
            d_cols = (*(swd * jnp.diff(x) for x in cols), zero[1:])
            return swd * jnp.diff(r), d_cols, no_prior
        if kind == "bias":
            sp = jnp.sqrt(prior)
            j_prior = jnp.zeros((4,), north.dtype).at[3].set(sp)
            sw = sqrt_w if present is None else sqrt_w * present
            return (sw * (r - p[3]), (*(sqrt_w * x for x in cols), -sw),
                    (sp * p[3], j_prior))
        return sqrt_w * r, (*(sqrt_w * x for x in cols), zero), no_prior

    return res


def gls_residual_function(table, frame, g, inv_chol, ones, scale, bias_sigma, method,
                          present=None):
    """Whitened residuals ``√s·W(g − v(p) − b)`` of ``p`` and their Jacobian (GLS refinement).

    As :func:`residual_function`, for readings whose error has covariance Σ = L Lᵀ
    (:func:`~jaxgrav.match.gls.gls_whitener`): ``W = L⁻¹`` ``(N, N)``, ``ones = W 1``,
    the Jacobian ``√s·W ∂v/∂p``, bias column ``−√s·W 1``, prior row ``√s·b/σ_b``.
    ``scale`` s (mGal²) puts the squared norm on the mGal² scale of the white score
    (χ² · s); ``bias_sigma`` σ_b (mGal, ``inf`` flat, a large finite value for none).
    With survey gaps, ``present`` masks the fixes as in :func:`residual_function` and
    ``inv_chol``, ``ones`` come from :func:`~jaxgrav.match.gaps.gap_whitener`.
    """
    iy_c, ix_c, ky, kx, north, east = frame
    root = jnp.sqrt(scale)
    wt = inv_chol.T * root
    sp = root / bias_sigma
    j_prior = jnp.zeros((4,), north.dtype).at[3].set(sp)

    def res(p):
        c, s = jnp.cos(p[2]), jnp.sin(p[2])
        rn, re = c * north - s * east, s * north + c * east
        v, v_y, v_x = patch_values(table, iy_c + ky * (rn + p[0]), ix_c + kx * (re + p[1]),
                                   method, gradient=True)
        a, b = v_y * ky, v_x * kx
        r = g - v - p[3]
        if present is not None:
            r, a, b = (jnp.where(present, x, 0.0) for x in (r, a, b))
        m = jnp.stack([r, -a, -b, a * re - b * rn]) @ wt
        return m[0], (m[1], m[2], m[3], -ones * root), (sp * p[3], j_prior)

    return res


def laplace_covariance(res, p, free):
    """``(JᵀJ)⁻¹`` of the north/east offset at ``p`` (m² per unit of ``‖r‖²``), ``(2, 2)``.

    The other free parameters (turn, bias) marginalised; multiply by the scale that
    makes ``‖r‖²`` a χ² to get the Laplace covariance of the offset.
    """
    jtj, _, _ = _normal_equations(*res(p), free)
    fixed = jnp.diag(1.0 - jnp.asarray(free, p.dtype))
    a = jtj + fixed
    eye = jnp.eye(p.shape[0], dtype=p.dtype)
    # both columns in one batched loop (jaxgrav._linalg.solve_spd), not two unrolled
    # Cholesky solves: ~5 kernels instead of ~23 under vmap
    return jax.vmap(lambda e: solve_spd_loop(a, e))(eye[:2])[:, :2]


def solve_spd(a, b):
    """Solve ``a x = b`` for a small symmetric positive definite ``a`` (unrolled Cholesky).

    Parameters
    ----------
    a : Array, shape ``(n, n)``
    b : Array, shape ``(n,)``

    Returns
    -------
    Array, shape ``(n,)``

    Notes
    -----
    ``a`` is equilibrated by its diagonal first. Scalar operations only, so a
    ``vmap`` over many systems stays element-wise.
    """
    n = b.shape[-1]
    d = 1.0 / jnp.sqrt(jnp.diagonal(a))
    a = a * d[:, None] * d[None, :]
    b = b * d
    low = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            t = a[i, j] - sum(low[i][k] * low[j][k] for k in range(j))
            low[i][j] = jnp.sqrt(t) if i == j else t / low[j][j]
    y = []
    for i in range(n):
        y.append((b[i] - sum(low[i][k] * y[k] for k in range(i))) / low[i][i])
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = (y[i] - sum(low[k][i] * x[k] for k in range(i + 1, n))) / low[i][i]
    return jnp.stack(x) * d


def _normal_equations(r, cols, extra, free):
    """``JᵀJ``, ``Jᵀr`` and ``rᵀr`` in one reduction (tiny; batched dots are slower on CPU).

    ``cols`` are the columns of ``J`` over the fixes, ``extra = (r_κ, j_κ)`` one more
    row (the bias prior); ``free`` (static tuple of bools) zeroes the fixed
    parameters' rows and columns.
    """
    n = len(cols)
    pairs = [(a, b) for a in range(n) for b in range(a, n) if free[a] and free[b]]
    terms = [cols[a] * cols[b] for a, b in pairs] + [cols[a] * r for a in range(n) if free[a]]
    out = list(sums([jnp.stack([*terms, r * r])], 1)[0])
    r_x, j_x = extra
    mask = jnp.asarray(free, r.dtype)
    j_x = j_x * mask
    zero = jnp.zeros_like(out[-1])
    m = dict(zip(pairs, out, strict=False))
    jtj = jnp.stack([jnp.stack([m.get((min(a, b), max(a, b)), zero) for b in range(n)])
                     for a in range(n)]) + j_x[:, None] * j_x[None, :]
    it = iter(out[len(pairs):-1])
    jtr = jnp.stack([next(it) if free[a] else zero for a in range(n)]) + j_x * r_x
    return jtj, jtr, out[-1] + r_x * r_x


def gauss_newton(res, p0, free, step_max, damping, n_steps):
    """Damped Gauss–Newton (Levenberg–Marquardt) on the free parameters.

    A step is kept only if it lowers the cost; the normal equations of the current
    point are reused when a step is rejected (one evaluation per step).

    Parameters
    ----------
    res : callable
        From :func:`residual_function`.
    p0 : Array, shape ``(4,)``
        Start.
    free : tuple of bool
        Which of the four parameters are free (static).
    step_max : Array, shape ``(4,)``
        Largest step per parameter (a longer step is scaled down as a whole).
    damping : float or Array
        Initial damping, relative to the diagonal of ``JᵀJ``.
    n_steps : int
        Steps (static).

    Returns
    -------
    Array, shape ``(4,)``
    """
    mask = jnp.asarray(free, p0.dtype)
    fixed = jnp.diag(1.0 - mask) + 1e-12 * jnp.eye(p0.shape[0], dtype=p0.dtype)

    def body(i, state):
        p, jtj, jtr, c, lam = state
        a = jtj + lam * jnp.diag(jnp.diag(jtj)) + fixed
        dp = -solve_spd(a, jtr) * mask  # unrolled: the loop form ran 11 % slower here
        scale = jnp.minimum(1.0, jnp.min(step_max / jnp.maximum(jnp.abs(dp), 1e-30)))
        trial = p + scale * dp
        jtj_new, jtr_new, c_new = _normal_equations(*res(trial), free)
        better = jnp.isfinite(c_new) & (c_new < c)
        keep = lambda new, old: jnp.where(better, new, old)  # noqa: E731
        lam = jnp.where(i == 0, lam, jnp.where(better, lam * 0.3, lam * 10.0))
        return keep(trial, p), keep(jtj_new, jtj), keep(jtr_new, jtr), keep(c_new, c), lam

    # iteration 0 evaluates the start (a zero step: Jᵀr = 0), so the residuals are
    # traced once, in the loop, not once more before it (a fifth less to compile)
    n = p0.shape[0]
    state = (p0, jnp.eye(n, dtype=p0.dtype), jnp.zeros((n,), p0.dtype),
             jnp.asarray(jnp.inf, p0.dtype), jnp.asarray(damping, p0.dtype))
    return jax.lax.fori_loop(0, n_steps + 1, body, state)[0]
