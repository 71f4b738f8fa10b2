"""The INS error Kalman filter of loosely coupled navigation, at the fix rate.

The filter's state is the 13-state INS error of :mod:`jaxgrav.sim.ins` (INS − true),
with the same dynamics the simulator uses, discretised once at the voyage's mean
latitude. A matcher fix is the *mean* position error over the fixes of a segment that
ends now: ``z = H̄ x_now + v`` with ``H̄ = mean_k H F^{−k}`` over the segment's INS steps
``k`` back in time (the error evolves deterministically over a segment; the process
noise of a navigation-grade INS over an hour is a few metres, far below any fix's σ).

:func:`error_kf_tables` precomputes, once per voyage, the powers of ``F`` forward (to
spread an estimate over the steps until the next fix) and backward (to put the current
estimate on the segment's past steps), the accumulated process noise, and ``H̄``.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._linalg import inv_2x2
from jaxgrav.sim.ins import transition

__all__ = ["ErrorKFTables", "error_kf_tables", "fix_update", "innovation_nis", "posterior_update",
           "spread"]


class ErrorKFTables(NamedTuple):
    """Precomputed transition tables of one voyage (see the module notes).

    Attributes
    ----------
    forward : Array, shape ``(S, 13, 13)``
        ``F^i``, i = 0 … S − 1 (S INS steps between fixes).
    noise : Array, shape ``(S, 13, 13)``
        Process noise accumulated over i steps.
    step_f, step_q : Array, shape ``(13, 13)``
        ``F^S`` and its accumulated noise: one fix interval.
    backward : Array, shape ``(W, 13, 13)``
        ``F^{−k}``, k = W … 1: the segment's W INS steps, oldest first.
    h_mean : Array, shape ``(2, 13)``
        ``H̄``: the segment's mean position error (north, east; m) from the state now.
    """

    forward: jax.Array
    noise: jax.Array
    step_f: jax.Array
    step_q: jax.Array
    backward: jax.Array
    h_mean: jax.Array


def error_kf_tables(model, lat_deg, dt, steps_between, segment_steps):
    """The tables of :class:`ErrorKFTables` for one voyage.

    Parameters
    ----------
    model : INSErrorModel
        The filter's error model.
    lat_deg : float
        Latitude of the discretisation (degrees).
    dt : float
        INS step (s).
    steps_between : int
        INS steps between fixes (static).
    segment_steps : int
        INS steps a segment spans (static).
    """
    f, q = transition(model, lat_deg, dt)

    def fwd(carry, _):
        p, qq = carry
        return (f @ p, f @ qq @ f.T + q), carry

    eye = jnp.eye(f.shape[0], dtype=f.dtype)
    (step_f, step_q), (forward, noise) = jax.lax.scan(
        fwd, (eye, jnp.zeros_like(f)), None, length=steps_between)
    f_inv, _ = transition(model, lat_deg, -dt)  # expm(−A Δt) = F⁻¹, exact; no LAPACK call

    def back(p, _):
        p = f_inv @ p
        return p, p

    _, backward = jax.lax.scan(back, eye, None, length=segment_steps)
    backward = backward[::-1]  # F^{-W} … F^{-1}: oldest step first
    h_mean = jnp.mean(backward[:, :2, :], axis=0)
    return ErrorKFTables(forward, noise, step_f, 0.5 * (step_q + step_q.T), backward, h_mean)


def spread(tables, x, p):
    """The estimate and covariance at each INS step until the next fix.

    Parameters
    ----------
    tables : ErrorKFTables
    x : Array, shape ``(13,)``
    p : Array, shape ``(13, 13)``

    Returns
    -------
    xs : Array, shape ``(S, 13)``
    pos_cov : Array, shape ``(S, 2, 2)``
        Covariance of the position error (m²).
    """
    xs = jnp.einsum("sij,j->si", tables.forward, x)
    fp = tables.forward[:, :2, :]
    pos_cov = jnp.einsum("sij,jk,slk->sil", fp, p, fp) + tables.noise[:, :2, :2]
    return xs, pos_cov


def _innovation_inverse(p, r, h):
    """``S⁻¹`` of a position fix, ``S = H P Hᵀ + R`` symmetrised."""
    s = h @ p @ h.T + r
    return inv_2x2(0.5 * (s + s.T))


def innovation_nis(p, innovation, r, h):
    """Normalised innovation squared ``νᵀ S⁻¹ ν`` of a position fix (2 degrees of freedom).

    Parameters
    ----------
    p : Array, shape ``(13, 13)``
    innovation : Array, shape ``(2,)``
        Fix minus predicted measurement (m).
    r : Array, shape ``(2, 2)``
        Fix covariance (m²).
    h : Array, shape ``(2, 13)``
    """
    return innovation @ _innovation_inverse(p, r, h) @ innovation


def fix_update(x, p, innovation, r, h, accept):
    """Kalman update with a position fix (Joseph form), applied where ``accept``.

    Parameters
    ----------
    x, p : Array, shapes ``(13,)``, ``(13, 13)``
        Predicted state and covariance.
    innovation : Array, shape ``(2,)``
        Fix minus predicted measurement (m).
    r : Array, shape ``(2, 2)``
        Fix covariance (m²).
    h : Array, shape ``(2, 13)``
    accept : Array of bool

    Returns
    -------
    x, p : the updated state and covariance (unchanged where not ``accept``)
    nis : Array
        Normalised innovation squared ``νᵀ S⁻¹ ν`` (2 degrees of freedom).
    """
    s_inv = _innovation_inverse(p, r, h)
    k = p @ h.T @ s_inv
    nis = innovation @ s_inv @ innovation
    a = jnp.eye(x.shape[0], dtype=p.dtype) - k @ h
    p_new = a @ p @ a.T + k @ r @ k.T
    x_new = x + k @ innovation
    return (jnp.where(accept, x_new, x), jnp.where(accept, 0.5 * (p_new + p_new.T), p), nis)


def posterior_update(x, p, h, shift, cov, accept):
    """Set the filter's ``H x`` to a posterior found with its own prior (Gaussian conditioning).

    A matcher that weighed its offsets by the filter's prior ``N(H x, S = H P Hᵀ)`` returns
    the posterior of ``H x``: moved by ``shift`` with covariance ``cov``. The other states
    follow by their regression on ``H x``: ``x + P Hᵀ S⁻¹ shift``,
    ``P − P Hᵀ S⁻¹ (S − cov) S⁻¹ H P`` (the Kalman update when the posterior is that of
    a linear Gaussian measurement; a posterior wider than the prior widens ``P``).

    Parameters
    ----------
    x, p : Array, shapes ``(13,)``, ``(13, 13)``
    h : Array, shape ``(2, 13)``
    shift : Array, shape ``(2,)``
        Posterior mean of ``H x`` minus the prior's (m).
    cov : Array, shape ``(2, 2)``
        Posterior covariance of ``H x`` (m²).
    accept : Array of bool

    Returns
    -------
    x, p : the updated state and covariance (unchanged where not ``accept``)
    nis : Array
        ``shiftᵀ S⁻¹ shift``: how far the posterior moved, in the prior's σ (the
        innovation gate's statistic; at most the equivalent measurement's NIS).
    """
    s = h @ p @ h.T
    s_inv = inv_2x2(0.5 * (s + s.T))
    gain = p @ h.T @ s_inv  # (13, 2)
    x_new = x + gain @ shift
    p_new = p - gain @ (s - cov) @ gain.T
    nis = shift @ s_inv @ shift
    return (jnp.where(accept, x_new, x), jnp.where(accept, 0.5 * (p_new + p_new.T), p), nis)
