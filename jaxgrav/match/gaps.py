"""Survey gaps: candidate tracks scored on the fixes whose map cells are present.

A missing (NaN) map node is either land, where the vehicle cannot be (candidates
touching it are dropped: the default of every matcher), or a gap in the survey, where
it may well be and the map only does not say what it reads there. For gaps, a
candidate is scored on its fixes over present cells, and each fix over a missing cell
adds the χ² it is expected to add under the truth (1; in the white score's units
``σ_n² Σμ²``), so that candidates with and without gaps compare on one scale: the
truth's expected score is the same however many of its fixes fall in gaps. A
candidate with more than ``max_gaps`` such fixes is dropped (``inf``).

Charging a gap more than its expectation (``1 + log(1 + σ_g²/σ_n²)``, the cost of a
reading whose map value has an independent prior σ_g, the map's spread) was tried and
measured worse (``examples/missing_nodes.py``): along a track the unknown values over
a gap are strongly correlated, so independent priors overcharge the truth, and the
matcher then prefers wrong candidates that avoid the gap.

The gap score is a pseudo-likelihood, not a likelihood: the exact marginal of the
present fixes would also carry ``log|Σ_p|``, the log-determinant of the readings'
covariance restricted to them, which differs between candidates with different gaps.
It is left out on purpose: with the unknown map values over the gap, no candidate's
Σ_p is the truth's, and charging the expectation keeps the truth's score (the
quantity compared) independent of its gaps, which the tests check.

Both scores equal their gap-free forms when no fix is missing:
:func:`gap_score` is :func:`~jaxgrav.match.scoring.score_track`, :func:`gls_gap_score`
is :func:`~jaxgrav.match.gls.gls_score` (there the readings' covariance restricted to
the present fixes is factorised per candidate, since the gaps differ between
candidates).
"""

import jax
import jax.numpy as jnp

from jaxgrav.match.gls import cholesky_scan, forward_substitution, gls_whitener
from jaxgrav.match.scoring import sums

__all__ = ["gap_score", "gap_whitener", "gls_gap_score"]


def gap_score(g, m, weights, kind, prior, unit, max_gaps):
    """:func:`~jaxgrav.match.scoring.score_track` on the present fixes, gaps at their expectation.

    Parameters
    ----------
    g : Array, shape ``(N,)``
        Readings (mGal).
    m : Array, shape ``(..., N)``
        Map values under each candidate (mGal); NaN over a missing cell.
    weights : Array, shape ``(N,)``
        μ_i.
    kind : {"absolute", "difference", "bias"}
        Score form (static).
    prior : Array
        κ of the bias prior (``bias`` form).
    unit : Array
        mGal² per unit χ², ``σ_n² Σμ²`` (μ normalised): fix i has variance ``unit/μ_i``.
    max_gaps : int
        Most fixes over missing cells a candidate may have (static).

    Returns
    -------
    score, bias : Array, shape ``(...)``
        mGal² (``inf`` with more than ``max_gaps`` gaps or none present) and mGal.
    """
    m = jnp.asarray(m)
    present = ~jnp.isnan(m)
    r = jnp.where(present, g - jnp.where(present, m, 0.0), 0.0)
    w = weights / jnp.sum(weights)
    wp = w * present
    n_gap = jnp.sum(~present, -1)
    s0 = jnp.sum(wp, -1)  # not in the variadic reduction: no tangent (grad fails on it)
    (s1,) = sums([wp * r], -1)
    penalty = unit * n_gap
    if kind == "difference":
        pair = present[..., 1:] & present[..., :-1]
        wd = w[:-1] / jnp.sum(w[:-1])
        expected = wd * unit * (1.0 / w[:-1] + 1.0 / w[1:])  # of a missing difference
        (score,) = sums([jnp.where(pair, wd * jnp.diff(r) ** 2, expected)], -1)
        bias = s1 / jnp.maximum(s0, jnp.finfo(r.dtype).tiny)
    elif kind == "absolute":
        (score,) = sums([wp * r * r], -1)
        score, bias = score + penalty, jnp.zeros_like(score)
    else:
        bias = s1 / (s0 + prior)
        (s2,) = sums([wp * (r - bias[..., None]) ** 2], -1)
        score = s2 + prior * bias**2 + penalty
    bad = (n_gap > max_gaps) | (s0 <= 0)
    return jnp.where(bad, jnp.inf, score), jnp.where(bad, 0.0, bias)


def _restricted(cov, present):
    """Σ restricted to the present fixes, the identity on the others (SPD, ``(..., N, N)``)."""
    both = present[..., :, None] & present[..., None, :]
    eye = jnp.eye(cov.shape[-1], dtype=cov.dtype)
    return jnp.where(both, cov, 0.0) + eye * (~present)[..., None, :]


def gls_gap_score(whitener, residuals, bias_prior_sigma, max_gaps):
    """:func:`~jaxgrav.match.gls.gls_score` on the present fixes, gaps at their expectation.

    Parameters
    ----------
    whitener : GlsWhitener
        Of the whole track (:func:`~jaxgrav.match.gls.gls_whitener`); its Σ is
        restricted to each candidate's present fixes and factorised again.
    residuals : Array, shape ``(C, N)``
        Readings minus map (map units); NaN over a missing cell.
    bias_prior_sigma : float or Array
        σ_b (map units): ``inf`` flat, 0 no bias.
    max_gaps : int
        Most fixes over missing cells a candidate may have (static).

    Returns
    -------
    score : Array, shape ``(C,)``
        ``J`` of the present fixes plus one per missing fix (χ², dimensionless);
        ``inf`` with more than ``max_gaps`` gaps.
    bias : Array, shape ``(C,)``
        Posterior mean bias (map units).
    """
    r = jnp.asarray(residuals)
    present = ~jnp.isnan(r)
    n_gap = jnp.sum(~present, -1)
    cov = whitener.chol @ whitener.chol.T
    restricted = _restricted(cov, present)  # (..., N, N), one per candidate
    n = restricted.shape[-1]
    rhs = jnp.stack([jnp.where(present, r, 0.0), present.astype(r.dtype)], axis=-1)
    # per candidate without LAPACK (batched LAPACK calls can deadlock: gls_whitener)
    chol = jax.vmap(cholesky_scan)(restricted.reshape(-1, n, n))
    z = jax.vmap(forward_substitution)(chol, rhs.reshape(-1, n, 2)).reshape(rhs.shape)
    zr, u = z[..., 0], z[..., 1]
    s1, uu = jnp.sum(zr * u, -1), jnp.sum(u * u, -1)
    shrink = 1.0 / (1.0 + jnp.asarray(bias_prior_sigma, r.dtype) ** 2 * uu)
    bias = (1.0 - shrink) * s1 / jnp.maximum(uu, jnp.finfo(r.dtype).tiny)
    e = zr - bias[..., None] * u
    score = jnp.sum(e * e, -1) + shrink * s1 * bias + n_gap
    bad = (n_gap > max_gaps) | (uu <= 0)
    return jnp.where(bad, jnp.inf, score), jnp.where(bad, 0.0, bias)


def gap_whitener(whitener, present):
    """Whitening of one candidate with fixed gaps, for the refinement.

    Returns ``(inv_chol, ones)``: ``L⁻¹`` of Σ restricted to the ``present`` fixes
    (the identity elsewhere) and ``L⁻¹ p`` (``p`` the present fixes' indicator), so
    that ``‖L⁻¹(r·p − b·p)‖²`` is the GLS misfit of the present fixes.
    """
    w = gls_whitener(_restricted(whitener.chol @ whitener.chol.T, present))
    return w.inv_chol, w.inv_chol @ present.astype(w.inv_chol.dtype)
