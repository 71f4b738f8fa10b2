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

from jaxgrav.match.contour import value_grad

__all__ = ["kabsch_2d", "refine_local", "rotation_matrix"]


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
    total = jnp.sum(w)
    wn = w / jnp.where(total > 0, total, 1.0)
    p_c = wn @ p
    x_c = wn @ x
    pp, xx = p - p_c, x - x_c
    a = jnp.sum(wn * (pp[:, 0] * xx[:, 0] + pp[:, 1] * xx[:, 1]))
    b = jnp.sum(wn * (pp[:, 0] * xx[:, 1] - pp[:, 1] * xx[:, 0]))
    rho2 = a * a + b * b
    enough = (total > 0) & (jnp.sum(w > 0) >= 2)
    good = enough & (rho2 > 0) & jnp.isfinite(rho2)
    inv = jax.lax.rsqrt(jnp.where(good, rho2, 1.0))
    c = jnp.where(good, a * inv, 1.0)
    s = jnp.where(good, b * inv, 0.0)
    if max_rotation_rad is not None:
        bound = jnp.asarray(max_rotation_rad, p.dtype)
        outside = c < jnp.cos(bound)
        s = jnp.where(outside, jnp.where(s < 0, -1.0, 1.0) * jnp.sin(bound), s)
        c = jnp.where(outside, jnp.cos(bound), c)
    r = jnp.stack([jnp.stack([c, -s]), jnp.stack([s, c])])
    t = jnp.where(enough & jnp.all(jnp.isfinite(x_c)), x_c - r @ p_c, jnp.zeros(2, p.dtype))
    return r, t


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

    def evaluate(theta, t):
        rp = p0 @ rotation_matrix(theta).T
        f, g = value_grad(field, rp + t)
        res = jnp.where(jnp.isfinite(f), f - z, 0.0)
        jac = jnp.stack([g[:, 1] * rp[:, 0] - g[:, 0] * rp[:, 1], g[:, 0], g[:, 1]], -1)
        return jnp.mean((f - z) ** 2), res, jac

    def step(_, s):
        theta, t, m, res, jac, lam = s
        a = jac.T @ jac
        a = a + lam * jnp.diag(jnp.diag(a))
        d = _solve3(a, -(jac.T @ res))
        theta_n = jnp.clip(theta + d[0], -max_rotation_rad, max_rotation_rad)
        t_n = t + d[1:]
        m_n, res_n, jac_n = evaluate(theta_n, t_n)
        keep = m_n < m  # False for NaN
        pick = lambda a, b: jnp.where(keep, a, b)  # noqa: E731
        return (pick(theta_n, theta), pick(t_n, t), pick(m_n, m), pick(res_n, res),
                pick(jac_n, jac), jnp.where(keep, 0.3 * lam, 10.0 * lam))

    init = (theta0, t, *evaluate(theta0, t), jnp.asarray(1e-3, p0.dtype))
    theta, t, m, *_ = jax.lax.fori_loop(0, steps, step, init)
    return rotation_matrix(theta), t, m


def _solve3(a, b):
    """Solve a 3×3 linear system by Cramer's rule (zero where singular)."""
    c0 = jnp.cross(a[1], a[2])
    det = a[0] @ c0
    ok = jnp.abs(det) > 0
    inv_t = jnp.stack([c0, jnp.cross(a[2], a[0]), jnp.cross(a[0], a[1])])  # adj(a)ᵀ
    return jnp.where(ok, (inv_t.T @ b) / jnp.where(ok, det, 1.0), 0.0)
