"""Covariance and integrity decision of a fix from a set of scored candidates.

The chain matcher (:mod:`~jaxgrav.match.correlation`) and the entropy + ICCP matcher
(:mod:`~jaxgrav.match.combined`) do not score a regular lattice of rigid offsets
as the dense matcher does, so :func:`~jaxgrav.match.integrity.fix_quality` does not
apply as it is. Their fix quality is built from two parts that do:

* the local curvature of the GLS misfit at the returned fix: the Gauss–Newton
  (Laplace) covariance ``(Gᵀ Σ̃⁻¹ G)⁻¹`` of the fix's parameters, G the map's gradient
  along the track (:func:`gauss_newton_information`, with the bias marginalised as in
  :func:`~jaxgrav.match.gls.gls_score`);
* the likelihood-weighted spread (weights ``∝ exp(−J/2)``, J the GLS scores in χ²
  units) of the candidates' mean offsets about the returned fix
  (:func:`spread_about`): other chains or offsets nearly as likely widen it.

:func:`integrity_status` turns a covariance and the test statistics into the
rejection bits 512, 1024, 2048 and 4096 of :data:`~jaxgrav.match.result.STATUS`.

The track's whitening is :func:`~jaxgrav.match.gls.gls_whitener`, free of LAPACK calls
(under ``vmap`` they can deadlock XLA's CPU thread pool, see :mod:`jaxgrav._linalg`).
"""

import jax.numpy as jnp

from jaxgrav._linalg import inv_2x2
from jaxgrav.match.gls import whiten
from jaxgrav.match.integrity import largest_sigma

__all__ = [
    "gauss_newton_information",
    "integrity_status",
    "offset_covariance",
    "second_mode_ratio",
    "spread_about",
]


def gauss_newton_information(whitener, jac, bias_prior_sigma=float("inf")):
    """Fisher information ``Gᵀ (Σ + σ_b² 11ᵀ)⁻¹ G`` of parameters moving the track.

    Parameters
    ----------
    whitener : GlsWhitener
        Of the track (:func:`~jaxgrav.match.gls.gls_whitener`).
    jac : Array, shape ``(N, P)``
        Derivative of the map values along the track with respect to the P
        parameters (map units per parameter unit), e.g. the map gradient (per metre).
    bias_prior_sigma : float or Array
        σ_b of the common reading bias (map units): ``inf`` marginalises a free bias
        (its direction is projected out), 0 has no bias.

    Returns
    -------
    Array, shape ``(P, P)``
        In 1/parameter units²; its inverse is the Laplace covariance of the
        parameters when the GLS score is ``−2 log`` likelihood.
    """
    g = whiten(whitener, jnp.swapaxes(jnp.asarray(jac), -1, -2))  # (P, N), whitened
    u, uu = whitener.ones, whitener.ones_norm2
    var_b = jnp.asarray(bias_prior_sigma, g.dtype) ** 2
    # (Σ + σ_b² 11ᵀ)⁻¹ = Σ⁻¹ − Σ⁻¹11ᵀΣ⁻¹ σ_b²/(1 + σ_b² 1ᵀΣ⁻¹1), in whitened form
    frac = jnp.where(jnp.isinf(var_b), 1.0 / uu, var_b / (1.0 + jnp.where(
        jnp.isinf(var_b), 0.0, var_b) * uu))
    gu = g @ u
    return g @ g.T - frac * gu[:, None] * gu[None, :]


def offset_covariance(info):
    """2 × 2 covariance (m²) of the offset from a ``(P, P)`` information matrix.

    The offset (north, east) is the last two parameters; a first one (e.g. a
    rotation) is marginalised (Schur complement). An information not positive definite gives
    an ``inf`` diagonal.
    """
    if info.shape[-1] not in (2, 3):
        raise ValueError(f"info must be 2 x 2 or 3 x 3; got shape {info.shape}")
    schur = info
    if info.shape[-1] == 3:  # marginalise the first parameter
        a, b = info[0, 0], info[0, 1:]
        schur = info[1:, 1:] - b[:, None] * b[None, :] / jnp.where(a > 0, a, jnp.inf)
    det = schur[0, 0] * schur[1, 1] - schur[0, 1] ** 2
    ok = jnp.all(jnp.isfinite(schur)) & (schur[0, 0] > 0) & (det > 0)
    cov = inv_2x2(jnp.where(ok, schur, jnp.eye(2, dtype=schur.dtype)))
    cov = 0.5 * (cov + cov.T)
    return jnp.where(ok, cov, jnp.diag(jnp.full((2,), jnp.inf, schur.dtype)))


def spread_about(scores, north_m, east_m, fix_north_m, fix_east_m):
    """Likelihood-weighted second moment of candidate offsets about the fix.

    Parameters
    ----------
    scores : Array, shape ``(K,)``
        GLS scores (χ² units); ``inf`` or NaN: no candidate.
    north_m, east_m : Array, shape ``(K,)``
        Mean offsets of the candidates (m).
    fix_north_m, fix_east_m : Array
        The returned fix (m).

    Returns
    -------
    cov : Array, shape ``(2, 2)``
        ``Σ p_k (o_k − fix)(o_k − fix)ᵀ`` (m²), ``p ∝ exp(−J/2)``; zero if none.
    n_effective : Array
        ``1/Σp²``.
    weights : Array, shape ``(K,)``
        The normalised weights p.
    """
    j = jnp.asarray(scores)
    ok = jnp.isfinite(j)
    j_best = jnp.min(jnp.where(ok, j, jnp.inf))
    j_best = jnp.where(jnp.isfinite(j_best), j_best, 0.0)
    p = jnp.where(ok, jnp.exp(-0.5 * (jnp.where(ok, j, j_best) - j_best)), 0.0)
    p = p / jnp.maximum(jnp.sum(p), jnp.finfo(p.dtype).tiny)
    e = jnp.stack([north_m - fix_north_m, east_m - fix_east_m], axis=-1)
    e = jnp.where(ok[:, None], e, 0.0)
    cov = (p[:, None] * e).T @ e
    return cov, 1.0 / jnp.maximum(jnp.sum(p * p), jnp.finfo(p.dtype).tiny), p


def second_mode_ratio(scores, north_m, east_m, best, metric, exclusion_chi2=9.0):
    """``exp(−(J₂ − J_best)/2)``, J₂ the least score of a candidate outside the mode.

    A candidate is outside when its offset from candidate ``best`` exceeds the squared
    Mahalanobis radius ``exclusion_chi2`` under the 2 × 2 ``metric`` (m²); 0 when no
    candidate is outside.
    """
    j = jnp.where(jnp.isfinite(scores), scores, jnp.inf)
    d = jnp.stack([north_m - north_m[best], east_m - east_m[best]], axis=-1)
    det = metric[0, 0] * metric[1, 1] - metric[0, 1] ** 2
    fine = jnp.isfinite(det) & (det > 0)
    maha = (metric[1, 1] * d[:, 0] ** 2 - 2 * metric[0, 1] * d[:, 0] * d[:, 1]
            + metric[0, 0] * d[:, 1] ** 2) / jnp.where(fine, det, 1.0)
    outside = jnp.where(fine, maha > exclusion_chi2, jnp.sum(d * d, axis=-1) > 0)
    j2 = jnp.min(jnp.where(outside, j, jnp.inf))
    return jnp.exp(-0.5 * (j2 - j[best]))


def integrity_status(cov, second_mode, chi2_per_dof, edge_mass, config):
    """Rejection bits of a fix (0: accepted), from the thresholds of ``config``.

    ``config.max_sigma_m`` (bit 512, on the largest 1-σ of ``cov``),
    ``max_second_mode`` (1024), ``max_chi2_per_dof`` (2048), ``max_edge_mass`` (4096);
    a NaN statistic never rejects.
    """
    sigma = largest_sigma(cov)
    return (jnp.where(sigma > config.max_sigma_m, 512, 0)
            | jnp.where(second_mode > config.max_second_mode, 1024, 0)
            | jnp.where(chi2_per_dof > config.max_chi2_per_dof, 2048, 0)
            | jnp.where(edge_mass > config.max_edge_mass, 4096, 0)
            ).astype(jnp.int32)
