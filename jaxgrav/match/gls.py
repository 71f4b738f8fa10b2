"""Generalised least-squares scores for readings whose error is correlated along the track.

Readings minus a map that is not the truth carry white reading noise plus the map's
own error, correlated over distance: ``Σ = σ_n² I + C_map(‖x_i − x_j‖)`` along a track
(:func:`track_covariance`). Candidates that are the same track shifted (and turned)
share the distances, ``Σ`` and its Cholesky factor ``L``: the factor is prepared once
per track (:func:`gls_whitener`), each candidate whitened by one product (:func:`whiten`).

The score (:func:`gls_score`) is the GLS misfit with a common reading bias ``b``
marginalised, in χ² units (dimensionless), for residuals ``r = g − m``:
``J = min_b (r − b1)ᵀ Σ⁻¹ (r − b1) + b²/σ_b²`` = ``rᵀ (Σ + σ_b² 11ᵀ)⁻¹ r``
(σ_b = ∞: flat prior, ``J = rᵀΣ⁻¹r − (1ᵀΣ⁻¹r)²/1ᵀΣ⁻¹1``). The likelihood of a
candidate is ``∝ exp(−J/2)``; ``J + gls_log_normaliser(...)`` is ``−2 log p(r)``.
With no map error and the fixes' noise variances ``σ_n² Σμ²/μ_i`` (normalised weights
μ; σ_n² for equal weights), ``J`` times ``σ_n² Σμ²`` is exactly the ``bias`` score of
:func:`~jaxgrav.match.scoring.score_track` with the prior
:func:`~jaxgrav.match.scoring.bias_precision`, and the bias estimates are equal.

:func:`offset_posterior` (of :mod:`~jaxgrav.match.posterior`, importable from here)
turns the scores over a lattice of offsets into the likelihood-weighted posterior of the
offset: its mean and 2 × 2 covariance, and the diagnostics an integrity decision needs.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._validate import concrete
from jaxgrav.fields.random import MarkovSpectrum
from jaxgrav.match.posterior import OffsetPosterior, offset_posterior

__all__ = [
    "GlsWhitener",
    "OffsetPosterior",
    "cholesky_scan",
    "forward_substitution",
    "gls_dof",
    "gls_log_normaliser",
    "gls_score",
    "gls_whitener",
    "offset_posterior",
    "track_covariance",
    "whiten",
]


def _check(x, name, zero_ok):
    arr = concrete(x)
    if arr is None:
        return
    ok = np.isfinite(arr) & ((arr >= 0) if zero_ok else (arr > 0))
    if not np.all(ok):
        want = "non-negative" if zero_ok else "positive"
        raise ValueError(f"{name} must be {want} and finite; got {arr}")


def track_covariance(north_m, east_m, noise_sigma, map_sigma, map_length_m, order=2,
                     weights=None):
    """Covariance of readings minus map along one track: white noise plus map error.

    Parameters
    ----------
    north_m, east_m : Array, shape ``(N,)``
        Fixes in local metres (any common origin; only distances matter).
    noise_sigma : float or Array, scalar or ``(N,)``
        Reading noise σ_n (map units, e.g. mGal), > 0.
    map_sigma : float or Array
        Map-error standard deviation σ_m (map units), ≥ 0; 0 gives ``σ_n² I``.
    map_length_m : float or Array
        Map-error correlation length L (m), ≥ 0; 0 makes the map error white (it
        adds σ_m² to every fix's variance).
    order : {1, 2}
        Markov covariance (static): 1: ``σ_m² e^{−d/L}``; 2 (default):
        ``σ_m² (1 + d/L) e^{−d/L}``, as :class:`~jaxgrav.fields.random.MarkovSpectrum`.
    weights : Array, shape ``(N,)``, optional
        Score weights μ_i (e.g. :func:`~jaxgrav.match.scoring.decreasing_weights`):
        the noise variance of fix i becomes ``σ_n² Σμ²/μ_i`` (μ normalised), the
        variance under which the weighted score of :mod:`~jaxgrav.match.scoring` is a
        likelihood.

    Returns
    -------
    Array, shape ``(N, N)``
        Σ in map units². A concrete σ_n not positive and finite, σ_m or L negative,
        NaN or infinite, or ``order`` not 1 or 2 raise ``ValueError``.
    """
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2; got {order!r}")
    _check(noise_sigma, "noise_sigma", zero_ok=False)
    _check(map_sigma, "map_sigma", zero_ok=True)
    _check(map_length_m, "map_length_m", zero_ok=True)
    north, east = jnp.asarray(north_m), jnp.asarray(east_m)
    dtype = jnp.result_type(north.dtype, east.dtype, float)
    d2 = (north[:, None] - north[None, :]) ** 2 + (east[:, None] - east[None, :]) ** 2
    same = d2 == 0
    d = jnp.where(same, 0.0, jnp.sqrt(jnp.where(same, 1.0, d2)))  # finite gradients at 0
    length = jnp.asarray(map_length_m, dtype)
    corr = length > 0
    c = MarkovSpectrum(jnp.asarray(map_sigma, dtype), jnp.where(corr, length, 1.0),
                       order).covariance(d)
    c = jnp.where(corr, c, jnp.where(same, jnp.asarray(map_sigma, dtype) ** 2, 0.0))
    var = jnp.broadcast_to(jnp.asarray(noise_sigma, dtype) ** 2, north.shape)
    if weights is not None:
        mu = jnp.asarray(weights, dtype) / jnp.sum(weights)
        var = var * jnp.sum(mu**2) / mu
    return c + jnp.diag(var)


class GlsWhitener(NamedTuple):
    """The factorised covariance of one track, shared by all its candidates.

    Attributes
    ----------
    chol : Array, shape ``(N, N)``
        Lower Cholesky factor L of Σ (map units).
    inv_chol : Array, shape ``(N, N)``
        L⁻¹ (lower triangular, 1/map units): whitening is one matrix product.
    ones : Array, shape ``(N,)``
        The whitened ones-vector ``u = L⁻¹ 1``.
    ones_norm2 : Array
        ``uᵀu = 1ᵀ Σ⁻¹ 1`` (1/map units²), the bias's data precision.
    log_det : Array
        ``log det Σ`` (Σ in map units²).
    """

    chol: jax.Array
    inv_chol: jax.Array
    ones: jax.Array
    ones_norm2: jax.Array
    log_det: jax.Array


def cholesky_scan(a):
    """Lower Cholesky factor of an SPD ``a`` ``(N, N)``, column by column in a ``lax.scan``
    of N steps of O(N²) work: no unrolling, no LAPACK call under ``vmap`` (see
    :func:`gls_whitener`). NaN where ``a`` is not positive definite."""
    a = jnp.asarray(a)
    idx = jnp.arange(a.shape[-1])

    def column(low, j):
        row = low[j]  # entries before j only
        d = jnp.sqrt(a[j, j] - jnp.sum(row * row))
        col = (a[:, j] - low @ row) / d
        return low.at[:, j].set(jnp.where(idx > j, col, jnp.where(idx == j, d, 0.0))), None

    chol, _ = jax.lax.scan(column, jnp.zeros_like(a), idx)
    return chol


def forward_substitution(chol, b):
    """``X`` with ``chol X = b`` (``chol`` lower triangular ``(N, N)``, ``b`` ``(N, K)``),
    row by row in a ``lax.scan`` (no LAPACK call)."""
    b = jnp.asarray(b)
    idx = jnp.arange(chol.shape[-1])

    def row(x, i):
        return x.at[i].set((b[i] - chol[i] @ x) / chol[i, i]), None

    x, _ = jax.lax.scan(row, jnp.zeros_like(b), idx)
    return x


def gls_whitener(cov):
    """:class:`GlsWhitener` of one track's SPD covariance ``cov`` ``(N, N)`` (map units²).

    Plain JAX operations, no LAPACK call: :func:`cholesky_scan` and its inverse by
    :func:`forward_substitution`. Under ``vmap`` ``jnp.linalg.cholesky`` and the
    triangular solve become batched LAPACK calls, and two independent ones in one
    program (a ``lax.map`` remainder batch beside the full ones, two branches) deadlock
    XLA's CPU thread pool on jaxlib 0.10.x (see :mod:`jaxgrav._linalg`). NaN where
    ``cov`` is not positive definite.
    """
    chol = cholesky_scan(cov)
    inv_chol = forward_substitution(chol, jnp.eye(chol.shape[-1], dtype=chol.dtype))
    ones = jnp.sum(inv_chol, axis=-1)  # L⁻¹ 1
    return GlsWhitener(chol, inv_chol, ones, jnp.sum(ones**2),
                       2.0 * jnp.sum(jnp.log(jnp.diagonal(chol))))


def whiten(whitener, v, solve=False):
    """Whitened values ``L⁻¹ v`` of one or many candidates (of one :class:`GlsWhitener`).

    Parameters
    ----------
    v : Array, shape ``(N,)`` or ``(..., N)``
        Residuals (map units), fixes along the last axis; leading axes are candidates.
    solve : bool
        Static. False: one product with ``inv_chol`` (on CPU far faster than a
        triangular solve); True: :func:`forward_substitution` with ``chol``.

    Returns
    -------
    Array, shape of ``v``
        Dimensionless: white, unit variance when ``v`` has covariance Σ.
    """
    v = jnp.asarray(v)
    if not solve:
        return v @ whitener.inv_chol.T
    n = v.shape[-1]
    z = forward_substitution(whitener.chol, v.reshape(-1, n).T)
    return z.T.reshape(v.shape)


def gls_score(whitener, residuals, bias_prior_sigma=float("inf")):
    """GLS misfit of candidates with the common reading bias marginalised.

    Parameters
    ----------
    whitener : GlsWhitener
        Of the track (:func:`gls_whitener`).
    residuals : Array, shape ``(N,)`` or ``(C, N)``
        Readings minus map along each candidate (map units); NaN (off the map) gives
        an infinite score.
    bias_prior_sigma : float or Array
        σ_b of a zero-mean Gaussian prior on the bias (map units); ``inf`` (default)
        is a flat prior, 0 no bias.

    Returns
    -------
    score : Array, shape ``(C,)`` (or scalar)
        ``J = min_b ‖L⁻¹(r − b1)‖² + b²/σ_b²`` (χ², dimensionless).
    bias : Array, shape ``(C,)`` (or scalar)
        The minimising (posterior mean) bias (map units).
    """
    r = jnp.asarray(residuals)
    bad = jnp.any(jnp.isnan(r), axis=-1)
    z = whiten(whitener, jnp.where(jnp.isnan(r), 0.0, r))
    u, uu = whitener.ones, whitener.ones_norm2
    s1 = z @ u
    shrink = 1.0 / (1.0 + jnp.asarray(bias_prior_sigma, z.dtype) ** 2 * uu)  # 1: no bias
    bias = (1.0 - shrink) * s1 / uu
    e = z - bias[..., None] * u
    score = jnp.sum(e * e, axis=-1) + shrink * s1 * bias  # prior term b²/σ_b²
    return jnp.where(bad, jnp.inf, score), bias


def gls_log_normaliser(whitener, bias_prior_sigma=float("inf")):
    """The term that makes ``J`` a negative log-likelihood: ``−2 log p(r) = J + c``.

    A constant within one track; needed to compare tracks, covariances or noise
    levels. Gaussian prior: ``c = N log 2π + log det(Σ + σ_b² 11ᵀ)``, with
    ``log det(Σ + σ_b² 11ᵀ) = log det Σ + log(1 + σ_b² 1ᵀΣ⁻¹1)``. Flat prior
    (``bias_prior_sigma`` inf): the restricted (bias-free) likelihood,
    ``c = (N − 1) log 2π + log det Σ + log 1ᵀΣ⁻¹1``. Returns ``c`` (dimensionless,
    Σ in map units²), for a :class:`GlsWhitener` and σ_b as for :func:`gls_score`.
    """
    n = whitener.ones.shape[-1]
    var_b = jnp.asarray(bias_prior_sigma, whitener.log_det.dtype) ** 2
    uu = whitener.ones_norm2
    flat = (n - 1) * jnp.log(2 * jnp.pi) + whitener.log_det + jnp.log(uu)
    finite = jnp.isfinite(var_b)
    gauss = (n * jnp.log(2 * jnp.pi) + whitener.log_det
             + jnp.log1p(jnp.where(finite, var_b, 0.0) * uu))
    return jnp.where(finite, gauss, flat)


def gls_dof(n, bias_prior_sigma=float("inf")):
    """Expected score of the truth: ``N − 1`` with a flat bias prior, ``N`` otherwise."""
    return jnp.where(jnp.isinf(jnp.asarray(bias_prior_sigma)), n - 1, n)
