"""The segment's shape: what a fix's readings say about the INS error beyond its offset.

The dense matcher of the loop fits a segment's *mean* position error (its offset ``o``)
and, with ``segment_error="conditional"``, treats the rest of the readings' error that
the filter's error explains — the Eötvös error of the residual velocity and the map
misread by the segment's stretch and bend, ``G δ`` (:func:`~jaxgrav.navigate.loose_match.
segment_error_covariance`) — as noise given ``o``: it marginalises it. That error is not
noise to the filter: it is linear in the residual error ``δ`` and tells its velocity,
tilt and bias components, which position fixes observe poorly (a segment-mean fix sees
an 84-min Schuler oscillation through a 2 h mean, attenuated to about a fifth).

Given the offset, the readings' information on ``δ`` is a linear Gaussian update (the
chain rule ``p(o, δ | y) = p(o | y) p(δ | o, y)``; the matcher gave the first factor):
with the map linearised at the matched segment ``p_k + ô``,

    y_k = g_k − m(p_k + ô) = H_k δ − ∇m_k · ô + w_k,
    H_k = −∇m_k B_p,k + (∂E/∂v)_k B_v,k + e_bias,

``w`` the reading noise and the map error told (:func:`~jaxgrav.match.gls.
track_covariance`) and the map's second order over the fixes' position uncertainty
(a Gaussian second-order filter's mean ``½ tr(∇²m_k Σ_kk)`` and covariance
``½ tr(∇²m_k Σ_kl ∇²m_l Σ_lk)``, ``Σ_kl`` the fixes' position cross-covariance after
the fix: without it, on a perfect map, the linearised update was over-confident).
The update's gain is taken with the filter's covariance *given*
``H̄ δ`` (``P_c = P − P H̄ᵀ (H̄ P H̄ᵀ)⁻¹ H̄ P``), so it leaves the segment's mean position
(the matcher's answer, counted once) where the fix put it; the innovation's covariance
``H P Hᵀ + R`` carries the offset's own uncertainty through the map's gradient, and the
covariance is updated in Joseph form, valid for this gain.
"""

import math
import statistics

import jax
import jax.numpy as jnp

from jaxgrav._linalg import inv_2x2
from jaxgrav.constants import DEG
from jaxgrav.geodesy import (
    eotvos_jacobian,
    local_offsets_m,
    meridian_radius,
    prime_vertical_radius,
)
from jaxgrav.match.gls import gls_whitener, track_covariance
from jaxgrav.sim.drift import apply_drift
from jaxgrav.sim.ins import GRAV

__all__ = ["SHAPE_GATE_P", "chi2_quantile", "shape_update"]

SHAPE_GATE_P = 0.999
"""The shape update is skipped where its innovation's ``νᵀ S⁻¹ ν`` is above this quantile
of χ²(n): the readings do not fit the segment at the matched offset (a wrong mode, or the
map far from linear there), and their linearised information would mislead the filter."""


def chi2_quantile(p, dof):
    """The ``p`` quantile of χ²(``dof``) (Wilson–Hilferty; within 0.6 % for dof ≥ 10 and
    p ≤ 0.999).

    Parameters
    ----------
    p : float
        Probability, in (0, 1).
    dof : int
        Degrees of freedom (static).

    Returns
    -------
    float
    """
    z = statistics.NormalDist().inv_cdf(p)
    c = 2.0 / (9.0 * dof)
    return dof * (1.0 - c + z * math.sqrt(c)) ** 3


def _gradient_m(grid, lat, lon):
    """Map value (mGal) and gradient (mGal per m, north then east) at the points."""
    value, d_lat, d_lon = grid.value_and_gradient(lat, lon)
    grad = jnp.stack([d_lat / (meridian_radius(lat) * DEG), d_lon / (
        prime_vertical_radius(lat) * jnp.cos(lat * DEG) * DEG)], -1)
    return value, grad


def shape_update(grid, matcher, lat, lon, g, v_east, v_north, backward, h_mean, x_ref, x, p,
                 offset, noise_scale, accept):
    """Update the filter with a segment's readings given its matched offset (module notes).

    Parameters
    ----------
    grid : PreparedMap
        The map (its bicubic value and gradient at the matched fixes).
    matcher : DenseConfig
        Its ``noise_mgal`` and told map error (``map_error_mgal``, ``map_error_length_m``,
        ``map_error_order``) make the readings' noise ``R``.
    lat, lon : Array, shape ``(n,)``
        The corrected segment's fixes (degrees), corrected with ``x_ref``.
    g : Array, shape ``(n,)``
        Their readings, Eötvös-corrected with the corrected velocity (mGal).
    v_east, v_north : Array, shape ``(n,)``
        The corrected velocity (m/s).
    backward : Array, shape ``(n, 4, 13)``
        Rows north, east position and north, east velocity of ``B_k``, each fix's block
        mean of ``F^{−j}`` (the state now to the fix).
    h_mean : Array, shape ``(2, 13)``
        ``H̄``: the segment's mean position error.
    x_ref : Array, shape ``(13,)``
        The state the segment was corrected with (the prediction).
    x, p : Array, shapes ``(13,)``, ``(13, 13)``
        The filter after the fix's update (its ``H̄ x − H̄ x_ref = −offset``).
    offset : Array, shape ``(2,)``
        The fix: matched − corrected (north, east; m).
    noise_scale : float or Array
        ``R`` is multiplied by it (the readings' reuse by overlapping segments).
    accept : Array of bool
        Update only where true.

    Returns
    -------
    x, p : Array
        Updated where ``accept``, the readings fit (``nis`` within the
        :data:`SHAPE_GATE_P` quantile of χ²(n)) and every value is finite, else as given.
    nis : Array
        The innovation's ``νᵀ S⁻¹ ν`` (``n`` degrees of freedom expected; NaN where not
        ``accept``).
    """
    lat_m, lon_m = apply_drift(lat, lon, offset[0], offset[1])
    value, grad = _gradient_m(grid, lat_m, lon_m)
    hess = jax.vmap(lambda la, lo: jax.hessian(
        lambda d: grid.sample(*apply_drift(la, lo, d[0], d[1])))(jnp.zeros(2, lat.dtype)))(
        lat_m, lon_m)  # (n, 2, 2) mGal/m²
    hess = jnp.where(jnp.isfinite(hess), hess, 0.0)
    jac = eotvos_jacobian(lat, v_east, v_north)  # (n, 2) mGal per m/s, north then east
    h = (-jnp.einsum("ki,kij->kj", grad, backward[:, :2])
         + jnp.einsum("ki,kij->kj", jac, backward[:, 2:4]))
    h = h.at[:, GRAV].add(1.0)  # the gravimeter's systematic error adds to every reading
    # predicted: H δ̂ less the offset read through the gradient (H̄ δ̂ = −offset: the
    # stretch about the mean and the Eötvös error), and the bias the readings still hold
    delta = x - x_ref
    # the map's second order over the fixes' position covariance (Gaussian second-order
    # filter): mean ½ tr(∇²m_k Σ_kk), covariance ½ tr(∇²m_k Σ_kl ∇²m_l Σ_lk)
    sig = jnp.einsum("kai,ij,lbj->klab", backward[:, :2], p, backward[:, :2])
    curv_mean = 0.5 * jnp.einsum("kab,kkba->k", hess, sig)
    curv_cov = 0.5 * jnp.einsum("kab,klbc,lcd,klad->kl", hess, sig, hess, sig)
    nu = g - value - h @ delta - x_ref[GRAV] + grad @ offset - curv_mean
    north, east = local_offsets_m(lat, lon, lat[0], lon[0])
    r = (track_covariance(north, east, matcher.noise_mgal, matcher.map_error_mgal,
                          matcher.map_error_length_m, matcher.map_error_order)
         + curv_cov) * noise_scale
    ph = p @ h_mean.T
    s_bar = h_mean @ ph
    p_c = p - ph @ inv_2x2(0.5 * (s_bar + s_bar.T)) @ ph.T
    s = h @ p @ h.T + r
    # no LAPACK call: batched under vmap, LAPACK solves deadlock XLA:CPU (jaxgrav._linalg)
    inv_chol = gls_whitener(0.5 * (s + s.T)).inv_chol  # L⁻¹, S = L Lᵀ
    a_w, nu_w = inv_chol @ h, inv_chol @ nu
    gain = p_c @ a_w.T @ inv_chol  # P_c Hᵀ S⁻¹, (13, n)
    nis = nu_w @ nu_w
    a = jnp.eye(x.shape[0], dtype=p.dtype) - gain @ h
    p_new = a @ p @ a.T + gain @ r @ gain.T
    x_new = x + gain @ nu
    fits = nis <= chi2_quantile(SHAPE_GATE_P, nu.shape[0])
    ok = accept & fits & jnp.all(jnp.isfinite(x_new)) & jnp.all(jnp.isfinite(p_new))
    return (jnp.where(ok, x_new, x), jnp.where(ok, 0.5 * (p_new + p_new.T), p),
            jnp.where(accept, nis, jnp.nan))
