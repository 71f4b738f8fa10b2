"""Weighted least-squares match scores shared by every correlation matcher.

A candidate track k puts map values ``m_i`` under the gravimeter readings ``g_i``
(i = 0 … N−1). Paper A scores it with weights μ_i that decrease along the track
(early fixes carry less INS drift, so more trust). Three forms:

``absolute``
    ``Σ μ_i (g_i − m_i)²`` — readings must already be Eötvös- and bias-corrected.
``difference``
    Paper A's Eötvös-free form, on consecutive differences:
    ``Σ_{i<N−1} μ_i [(g_{i+1} − g_i) − (m_{i+1} − m_i)]²``; a constant Eötvös effect
    or gravimeter bias cancels.
``bias``
    Absolute form with one common bias per candidate estimated by weighted least
    squares: ``b = Σ μ r / Σ μ`` with ``r = g − m``, score ``Σ μ (r − b)²``. It also
    cancels a constant bias but keeps the absolute information of every fix, so it is
    less noisy than differencing (which doubles the noise variance and correlates it).
    With a Gaussian prior on the bias (zero mean, σ_b; readings noise σ_n) the
    bias is the MAP estimate ``b = Σ μ r / (Σ μ + κ)`` and the score gains ``κ b²``,
    ``κ = (σ_n/σ_b)² Σ μ²/Σ μ``: σ_b = ∞ is the plain bias form, σ_b → 0 the
    absolute form. Use it when the readings are Eötvös-corrected with a velocity of
    known accuracy and the gravimeter bias is roughly known.

All functions broadcast over leading candidate axes: ``g`` is ``(N,)`` and ``m``
``(..., N)``. NaN map values (candidates off the map) give an infinite score.
"""

import jax.numpy as jnp

__all__ = ["SCORES", "bias_precision", "decreasing_weights", "score_track"]

SCORES = ("absolute", "difference", "bias")


def decreasing_weights(n, decay):
    """Weights μ_i = exp(−decay · i/(n−1)), normalised to sum to one.

    Parameters
    ----------
    n : int
        Number of fixes (static).
    decay : float or Array
        0 gives equal weights; 1 gives the last fix e⁻¹ of the first one's weight.

    Returns
    -------
    Array, shape ``(n,)``
    """
    s = jnp.linspace(0.0, 1.0, n)
    w = jnp.exp(-jnp.asarray(decay) * s)
    return w / jnp.sum(w)


def bias_precision(weights, noise_mgal, bias_sigma_mgal):
    """κ of the bias prior for normalised weights: ``(σ_n/σ_b)² Σ μ²`` (0 when σ_b = ∞)."""
    w = weights / jnp.sum(weights)
    return (jnp.asarray(noise_mgal) / jnp.asarray(bias_sigma_mgal)) ** 2 * jnp.sum(w**2)


def score_track(g, m, weights, kind="bias", prior=0.0):
    """Weighted least-squares misfit between readings and map values along candidate tracks.

    Parameters
    ----------
    g : Array, shape ``(N,)``
        Readings (mGal).
    m : Array, shape ``(..., N)``
        Map values under each candidate track (mGal).
    weights : Array, shape ``(N,)``
        μ_i, e.g. from :func:`decreasing_weights`.
    kind : {"absolute", "difference", "bias"}
        Score form (static); see the module docstring.
    prior : float or Array
        κ of the bias prior (``bias`` form only), e.g. from :func:`bias_precision`.

    Returns
    -------
    score : Array, shape ``(...)``
        Weighted misfit in mGal² (``inf`` where a map value is NaN).
    bias : Array, shape ``(...)``
        Estimated common bias ``mean(g − m)`` (weighted) in mGal; zero for ``absolute``.
    """
    if kind not in SCORES:
        raise ValueError(f"kind must be one of {SCORES}; got {kind!r}")
    bad = jnp.any(jnp.isnan(m), axis=-1)
    m = jnp.where(jnp.isnan(m), 0.0, m)  # harmless values first: finite gradients
    r = g - m
    w = weights / jnp.sum(weights)
    if kind == "absolute":
        score = jnp.sum(w * r**2, axis=-1)
        bias = jnp.zeros_like(score)
    elif kind == "difference":
        d = jnp.diff(r, axis=-1)
        wd = w[:-1] / jnp.sum(w[:-1])
        score = jnp.sum(wd * d**2, axis=-1)
        bias = jnp.sum(w * r, axis=-1)
    else:
        bias = jnp.sum(w * r, axis=-1) / (1.0 + prior)
        score = jnp.sum(w * (r - bias[..., None]) ** 2, axis=-1) + prior * bias**2
    return jnp.where(bad, jnp.inf, score), bias
