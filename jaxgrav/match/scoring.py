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

import jax
import jax.numpy as jnp

__all__ = ["SCORES", "bias_precision", "decreasing_weights", "k_smallest", "score_track", "sums"]

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


def score_track(g, m, weights, kind="bias", prior=0.0, axis=-1):
    """Weighted least-squares misfit between readings and map values along candidate tracks.

    Parameters
    ----------
    g : Array, shape ``(N,)``
        Readings (mGal).
    m : Array, shape ``(..., N)`` (``N`` along ``axis``)
        Map values under each candidate track (mGal).
    weights : Array, shape ``(N,)``
        μ_i, e.g. from :func:`decreasing_weights`.
    kind : {"absolute", "difference", "bias"}
        Score form (static); see the module docstring.
    prior : float or Array
        κ of the bias prior (``bias`` form only), e.g. from :func:`bias_precision`.
    axis : int
        Axis of ``m`` along the fixes (static); the others are candidate axes, e.g.
        ``(N, A, B)`` map values of an offset lattice with ``axis=0``.

    Returns
    -------
    score : Array, shape ``(...)``
        Weighted misfit in mGal² (``inf`` where a map value is NaN).
    bias : Array, shape ``(...)``
        Estimated common bias ``mean(g − m)`` (weighted) in mGal; zero for ``absolute``.
    """
    if kind not in SCORES:
        raise ValueError(f"kind must be one of {SCORES}; got {kind!r}")
    g, m, weights = jnp.asarray(g), jnp.asarray(m), jnp.asarray(weights)
    axis = axis % m.ndim
    trail = (1,) * (m.ndim - axis - 1)  # g and weights along `axis`, broadcast over the rest
    bad = jnp.any(jnp.isnan(m), axis=axis)
    m = jnp.where(jnp.isnan(m), 0.0, m)  # harmless values first: finite gradients
    r = jnp.reshape(g, g.shape + trail) - m
    w = weights / jnp.sum(weights)
    wa = jnp.reshape(w, w.shape + trail)
    if kind == "absolute":
        (score,) = sums([wa * r**2], axis)
        bias = jnp.zeros_like(score)
    elif kind == "difference":
        d = jnp.diff(r, axis=axis)
        wd = w[:-1] / jnp.sum(w[:-1])
        wd = jnp.reshape(wd, wd.shape + trail)
        d2 = jnp.concatenate([wd * d**2, jnp.zeros_like(jnp.take(d, jnp.array([0]), axis=axis))],
                             axis=axis)
        score, bias = sums([d2, wa * r], axis)
    else:
        (s1,) = sums([wa * r], axis)
        bias = s1 / (1.0 + prior)
        (s2,) = sums([wa * (r - jnp.expand_dims(bias, axis)) ** 2], axis)
        score = s2 + prior * bias**2
    return jnp.where(bad, jnp.inf, score), bias


def sums(xs, axis):
    """Sums of same-shape arrays along ``axis``, as one variadic reduction.

    Equal to ``[jnp.sum(x, axis) for x in xs]``. On CPU, XLA hands a plain sum to a
    library kernel that is several times slower for short middle or last axes; a
    variadic reduction is compiled in line and fuses with its producers.

    Parameters
    ----------
    xs : sequence of Array
        Arrays of one shape.
    axis : int
        Axis to sum over.

    Returns
    -------
    list of Array
    """
    xs = [jnp.asarray(x) for x in xs]
    single = len(xs) == 1
    if single:  # a second, ignored operand keeps the reduction variadic
        xs = [*xs, xs[0]]
    axis = axis % xs[0].ndim

    def add(a, b):
        out = tuple(u + v for u, v in zip(a, b, strict=True))
        return (out[0], a[1]) if single else out

    zeros = tuple(jnp.zeros((), x.dtype) for x in xs)
    out = jax.lax.reduce(tuple(xs), zeros, add, (axis,))
    return list(out[:1] if single else out)


def k_smallest(x, k):
    """Indices of the ``k`` smallest entries along the last axis, ascending.

    The ranking of ``jax.lax.top_k(-x.astype(float32), k)`` (float32 values, ties to
    the lower index, ``inf`` last), by ``k`` arg-min passes over order-preserving
    integer keys instead of a full sort: much cheaper on CPU when ``k`` is small.

    Parameters
    ----------
    x : Array, shape ``(..., M)``
        Scores (no NaN).
    k : int
        How many (static, ≤ M).

    Returns
    -------
    Array of int32, shape ``(..., k)``
    """
    v = jnp.asarray(x).astype(jnp.float32)
    v = jnp.where(v == 0.0, 0.0, v)  # -0 ties with +0, as in top_k
    bits = jax.lax.bitcast_convert_type(v, jnp.int32)
    key = jnp.where(bits < 0, bits ^ jnp.int32(0x7FFFFFFF), bits)  # monotone in v
    iota = jax.lax.broadcasted_iota(jnp.int32, key.shape, key.ndim - 1)
    top = jnp.iinfo(jnp.int32).max  # above every key, +inf's included
    out = []
    for _ in range(k):
        i = jnp.argmin(key, axis=-1).astype(jnp.int32)
        out.append(i)
        key = jnp.where(iota == i[..., None], top, key)
    return jnp.stack(out, axis=-1)
