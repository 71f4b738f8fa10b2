"""Rigid 2-D transforms of a track in local metres (paper B, ICCP's transform step).

- :func:`kabsch_2d`: the weighted least-squares rotation and translation between two
  point sets, in closed form (in 2-D the Kabsch SVD reduces to one angle), with an
  optional bound on the angle — the INS heading-error bound;
- :func:`refine_local`: Levenberg–Marquardt refinement of a transform on the misfit
  between measured values and the map along the moved track.

Rotations act on ``(north, east)``: ``R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]]``,
positive θ turns north towards east (clockwise seen from above).
"""

import jax
import jax.numpy as jnp

from jaxgrav.match.contour import value_grad_ne

__all__ = ["kabsch_2d", "kabsch_ne", "refine_local", "rotation_matrix", "solve3"]


def kabsch_2d(p, x, w=None, max_rotation_rad=None):
    """Rigid 2-D transform minimising ``Σ w_n ‖x_n − (R p_n + t)‖²`` (Kabsch, closed form).

    In 2-D the SVD of the Kabsch solution reduces to one angle: with centred points,
    ``a = Σ w P·X`` and ``b = Σ w P×X``, the optimum is ``cos θ = a/ρ``, ``sin θ = b/ρ``
    (``ρ = √(a² + b²)``), always a proper rotation (no reflection to guard against).
    The objective is ``const − ρ cos(θ − θ*)``, so the optimum under a bound
    ``|θ| ≤ θ_max`` is the bound nearest θ* (the sign of ``b``) — exact, not a clip of
    an unconstrained answer that would move the translation.

    Parameters
    ----------
    p, x : Array, shape ``(N, 2)``
        Source and target points (m).
    w : Array, shape ``(N,)``, optional
        Non-negative weights (default equal); zero weights drop points.
    max_rotation_rad : float or Array, optional
        Bound on ``|θ|`` (radians, ≤ π/2 is meaningful); default none.

    Returns
    -------
    tuple of Array
        ``(R, t)``: rotation ``(2, 2)`` with det +1 and translation ``(2,)`` (m).
        With fewer than two weighted points the identity is returned.
    """
    p, x = jnp.asarray(p), jnp.asarray(x)
    w = jnp.ones(p.shape[:-1], p.dtype) if w is None else jnp.asarray(w, p.dtype)
    bound = None
    if max_rotation_rad is not None:
        bound = jnp.asarray(max_rotation_rad, p.dtype)
        bound = (jnp.cos(bound), jnp.sin(bound))
    c, s, t_n, t_e = kabsch_ne(p[:, 0], p[:, 1], x[:, 0], x[:, 1], w, bound)
    return jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])]), jnp.stack([t_n, t_e])


def kabsch_ne(p_n, p_e, x_n, x_e, w, bound=None):
    """:func:`kabsch_2d` on coordinate arrays (the hot-loop form).

    Parameters
    ----------
    p_n, p_e, x_n, x_e : Array, shape ``(N,)``
        Source and target points, north and east (m).
    w : Array, shape ``(N,)``
        Non-negative weights.
    bound : tuple of Array, optional
        ``(cos θ_max, sin θ_max)`` of the rotation bound.

    Returns
    -------
    tuple of Array
        ``(cos θ, sin θ, t_north, t_east)``; the identity with fewer than two
        weighted points.
    """
    total = jnp.sum(w)
    enough = (total > 0) & (jnp.sum(jnp.where(w > 0, 1.0, 0.0)) >= 2)
    inv_w = 1.0 / jnp.where(total > 0, total, 1.0)
    pc_n, pc_e = jnp.sum(w * p_n) * inv_w, jnp.sum(w * p_e) * inv_w
    xc_n, xc_e = jnp.sum(w * x_n) * inv_w, jnp.sum(w * x_e) * inv_w
    # centred sums, without forming the centred arrays: Σw P·X = Σw p·x − W pc·xc, etc.
    a = jnp.sum(w * (p_n * x_n + p_e * x_e)) * inv_w - (pc_n * xc_n + pc_e * xc_e)
    b = jnp.sum(w * (p_n * x_e - p_e * x_n)) * inv_w - (pc_n * xc_e - pc_e * xc_n)
    rho2 = a * a + b * b
    good = enough & (rho2 > 0) & jnp.isfinite(rho2)
    inv = jax.lax.rsqrt(jnp.where(good, rho2, 1.0))
    c = jnp.where(good, a * inv, 1.0)
    s = jnp.where(good, b * inv, 0.0)
    if bound is not None:
        cos_b, sin_b = bound
        outside = c < cos_b
        s = jnp.where(outside, jnp.where(s < 0, -sin_b, sin_b), s)
        c = jnp.where(outside, cos_b, c)
    ok = enough & jnp.isfinite(xc_n) & jnp.isfinite(xc_e)
    t_n = jnp.where(ok, xc_n - (c * pc_n - s * pc_e), 0.0)
    t_e = jnp.where(ok, xc_e - (s * pc_n + c * pc_e), 0.0)
    return c, s, t_n, t_e


def rotation_matrix(theta):
    """``R(θ)`` (2, 2) for an angle θ (radians)."""
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])


def refine_local(field, p0, z, r, t, max_rotation_rad, steps):
    """Least-squares refinement of a rigid transform on the misfit (Levenberg–Marquardt).

    Minimises ``mean((f(R(θ) p + t) − z)²)`` over ``(θ, t)`` from ``(r, t)``, with
    ``|θ| ≤ max_rotation_rad`` (the step is projected onto the bound). A step is kept
    only if it lowers the misfit; the damping falls ×0.3 after a kept step and rises
    ×10 after a rejected one. The 3×3 normal equations are solved in closed form.

    Parameters
    ----------
    field : LocalField
    p0 : Array, shape ``(N, 2)``
        Indicated points (m).
    z : Array, shape ``(N,)``
        Measured values (map units).
    r, t : Array
        Starting rotation ``(2, 2)`` and translation ``(2,)`` (m).
    max_rotation_rad : Array
    steps : int
        LM steps (static).

    Returns
    -------
    tuple of Array
        ``(R, t, misfit)``.
    """
    theta0 = jnp.arctan2(r[1, 0], r[0, 0])
    p_n, p_e = p0[:, 0], p0[:, 1]

    def evaluate(theta, t):
        c, s = jnp.cos(theta), jnp.sin(theta)
        rp_n, rp_e = c * p_n - s * p_e, s * p_n + c * p_e
        f, g_n, g_e = value_grad_ne(field, rp_n + t[0], rp_e + t[1])
        res = jnp.where(jnp.isfinite(f), f - z, 0.0)
        j_th = g_e * rp_n - g_n * rp_e  # d f / d theta
        cols = (j_th, g_n, g_e)
        jtj = jnp.stack([jnp.stack([jnp.sum(u * v) for v in cols]) for u in cols])
        jtr = jnp.stack([jnp.sum(u * res) for u in cols])
        return jnp.mean((f - z) ** 2), jtj, jtr

    def step(i, s):
        # evaluate the trial point, keep it if it lowers the misfit (the first one, the
        # starting point, always), then the next trial: one evaluation in the program
        theta, t, m, jtj, jtr, lam, theta_n, t_n = s
        m_n, jtj_n, jtr_n = (a.astype(dtype) for a in evaluate(theta_n, t_n))
        first = i == 0
        keep = first | (m_n < m)  # False for NaN
        pick = lambda a, b: jnp.where(keep, a, b)  # noqa: E731
        theta, t, m, jtj, jtr = (pick(theta_n, theta), pick(t_n, t), pick(m_n, m),
                                 pick(jtj_n, jtj), pick(jtr_n, jtr))
        lam = jnp.where(first, lam, jnp.where(keep, 0.3 * lam, 10.0 * lam))
        d = solve3(jtj + lam * jnp.diag(jnp.diag(jtj)), -jtr)
        theta_n = jnp.clip(theta + d[0], -max_rotation_rad, max_rotation_rad)
        return theta, t, m, jtj, jtr, lam, theta_n, t + d[1:]

    dtype = jnp.result_type(theta0, t, p0, z, *field)
    init = (theta0, t, jnp.zeros((), dtype), jnp.zeros((3, 3), dtype), jnp.zeros(3, dtype),
            jnp.asarray(1e-3, dtype), theta0, t)
    theta, t, m, *_ = jax.lax.fori_loop(0, steps + 1, step, init)
    return rotation_matrix(theta), t, m


def solve3(a, b):
    """Solve a 3×3 linear system by Cramer's rule (zero where singular)."""
    c0 = jnp.cross(a[1], a[2])
    det = a[0] @ c0
    ok = jnp.abs(det) > 0
    inv_t = jnp.stack([c0, jnp.cross(a[2], a[0]), jnp.cross(a[0], a[1])])  # adj(a)ᵀ
    return jnp.where(ok, (inv_t.T @ b) / jnp.where(ok, det, 1.0), 0.0)
