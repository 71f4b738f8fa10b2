"""A reading's known linear part in the point-mass filter (:attr:`Step.h_lin`).

The point-mass filter (:mod:`~jaxgrav.filters.pmf`) grids the position error ``d`` and
keeps the other error states ``o`` as one Gaussian conditional on it,
``o | d ~ N(μ(d), C)`` with ``μ(d) = x̄ + K (d − d̄)``, ``K = P_{·d} P_dd⁻¹``,
``C = P − K P_{d·}``. A reading that is linear in those states besides the map,

    z = Δg_M(d) + b + ε + h_lin · x + noise,

(the Eötvös effect of the velocity error, ``∂E/∂v · δv``) then has, in cell ``c``, the
known mean ``h_d · d_c + h_o · μ(d_c)`` and the extra variance ``h_o C h_oᵀ``
(:func:`conditional_reading`), and each cell's Gaussian takes its own Kalman update,
``μ⁺_c = μ(d_c) + C h_oᵀ ν_c / s_c``, ``C⁺_c = C − C h_oᵀ h_o C / s_c``. The new
Gaussian of the whole state is the mixture's moments over the updated cell weights
(:func:`mixture_update`): exact first and second moments, and the linear-in-``d`` form
of the prediction restored by the regression at the next step.

The gravimeter bias (and a map-error state) stay per cell, so their columns of
``h_lin`` are ignored here (the bias is in the reading already), and their correlation
with the Gaussian states, which a reading's Eötvös part creates (both explain the same
innovation), is not kept; ``h_d`` (position columns) is taken exactly per cell.
"""

import jax.numpy as jnp

from jaxgrav._linalg import inv_2x2
from jaxgrav.sim.ins import GRAV, N_STATES

__all__ = ["conditional_reading", "mixture_update"]


def conditional_reading(x, p, h_lin, dn, de):
    """The reading's linear part in every cell, and what its update needs.

    Parameters
    ----------
    x : Array, shape ``(13,)``
        Mean of the error state (its position block the grid's mean).
    p : Array, shape ``(13, 13)``
        Its covariance.
    h_lin : Array, shape ``(n,)``
        The step's linear part (mGal per state unit), ``n ≥ 13``; columns past the 13
        INS error states and the gravimeter bias column are not used.
    dn, de : Array, shape ``(G, G)``
        Position error of each cell (m, north and east).

    Returns
    -------
    mean : Array, shape ``(G, G)``
        ``h_d · d_c + h_o · μ(d_c)`` (mGal).
    var : Array
        ``h_o C h_oᵀ`` (mGal²).
    mu : Array, shape ``(G, G, 13)``
        ``μ(d_c)``, the states' conditional mean in each cell (position = the cell).
    c : Array, shape ``(13, 13)``
        The conditional covariance ``C`` (zero position rows and columns).
    ch : Array, shape ``(13,)``
        ``C h_oᵀ``.
    """
    h = jnp.asarray(h_lin)[:N_STATES]
    h_d = h[:2]
    h_o = h.at[:2].set(0.0).at[GRAV].set(0.0)
    k = p[:, :2] @ inv_2x2(p[:2, :2])  # (13, 2), its position rows the identity
    c = p - k @ p[:2, :]
    c = 0.5 * (c + c.T)
    d = jnp.stack([dn - x[0], de - x[1]], -1)
    mu = x + d @ k.T
    ch = c @ h_o
    mean = h_d[0] * dn + h_d[1] * de + mu @ h_o
    return mean, h_o @ ch, mu, c, ch


def mixture_update(w, mu, c, ch, gain, shrink, pos_mean, pos_cov):
    """Mean and covariance of the whole state after the reading, from the cells' updates.

    Parameters
    ----------
    w : Array, shape ``(G, G)``
        Cell weights after the reading (normalised).
    mu, c, ch : Array
        From :func:`conditional_reading`.
    gain : Array, shape ``(G, G)``
        ``ν_c / s_c`` per cell (1/mGal): ``μ⁺_c = μ_c + C h_oᵀ · gain_c``.
    shrink : Array
        ``Σ_c w_c / s_c`` (1/mGal²): ``C̄⁺ = C − C h_oᵀ h_o C · shrink``.
    pos_mean, pos_cov : Array, shapes ``(2,)``, ``(2, 2)``
        The grid's moments (the cell quantisation included), which the position block
        is set to.

    Returns
    -------
    x : Array, shape ``(13,)``
    p : Array, shape ``(13, 13)``
    """
    mu = mu + gain[..., None] * ch
    x = jnp.einsum("ij,ijk->k", w, mu)
    dev = mu - x
    p = c - shrink * jnp.outer(ch, ch) + jnp.einsum("ij,ijk,ijl->kl", w, dev, dev)
    p = p.at[:2, :2].set(pos_cov)
    x = x.at[:2].set(pos_mean)
    return x, 0.5 * (p + p.T)
