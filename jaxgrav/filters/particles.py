"""Particle machinery shared by the particle filters: weights, resampling, roughening.

Weights are kept as normalised log-weights (``logsumexp = 0``) so that a reading far
in a particle's tail underflows no weight to an exact zero that a later reading could
not revive. Resampling is triggered by the effective sample size and draws a fixed
number of indices (static), so it runs under ``jit``/``vmap`` without Python loops:

* :func:`systematic_resample` — one uniform offset, ``N`` equally spaced positions on
  the cumulative weights (Kitagawa 1996; filterpy's ``systematic_resample``);
* :func:`residual_resample` — ``⌊N wᵢ⌋`` copies of each particle, the remaining
  draws multinomial on the residual weights (Liu & Chen 1998; filterpy's
  ``residual_resample``).

After resampling, :func:`roughen` spreads the copies with a Gaussian kernel of the
particles' own weighted covariance (the regularised particle filter of Musso, Oudjane
& Le Gland 2001, bandwidth a multiple of their optimal :func:`kernel_bandwidth`),
shrunk towards the mean so that the mean and covariance are kept (Liu & West 2001).
"""

import itertools
import math

import jax
import jax.numpy as jnp

from jaxgrav._linalg import psd_sqrt
from jaxgrav.rare_cond import rare_cond

__all__ = [
    "RESAMPLERS",
    "check_particle_settings",
    "effective_sample_size",
    "kernel_bandwidth",
    "normalise_log_weights",
    "particle_summary",
    "resample_regularised",
    "residual_resample",
    "roughen",
    "standard_normal",
    "systematic_resample",
    "weighted_moments",
]


def normalise_log_weights(log_w):
    """Log-weights shifted so that their exponentials sum to one.

    Parameters
    ----------
    log_w : Array, shape ``(N,)``

    Returns
    -------
    Array, shape ``(N,)``
        NaN everywhere if no weight is finite and positive (all ``−inf`` or NaN).
    """
    return log_w - jax.nn.logsumexp(log_w)


def effective_sample_size(log_w):
    """``1 / Σ wᵢ²`` of normalised log-weights: ``N`` for equal weights, 1 for one particle."""
    return jnp.exp(-jax.nn.logsumexp(2.0 * log_w))


def systematic_resample(key, log_w):
    """Indices of a systematic resampling.

    Parameters
    ----------
    key : PRNG key
    log_w : Array, shape ``(N,)``
        Normalised log-weights.

    Returns
    -------
    Array, shape ``(N,)``, int32
        Particle ``i`` appears ``⌊N wᵢ⌋`` or ``⌈N wᵢ⌉`` times; the positions are
        ``(u + j) / N`` with one ``u ~ U[0, 1)``, as filterpy's ``systematic_resample``.
    """
    n = log_w.shape[0]
    cum = jnp.cumsum(jnp.exp(log_w))
    positions = (jax.random.uniform(key, (), cum.dtype) + jnp.arange(n, dtype=cum.dtype)) / n
    idx = jnp.searchsorted(cum / cum[-1], positions, side="right")
    return jnp.minimum(idx, n - 1).astype(jnp.int32)  # a rounding of cum[-1] below 1


def residual_resample(key, log_w):
    """Indices of a residual resampling (deterministic copies, multinomial remainder).

    Parameters
    ----------
    key : PRNG key
    log_w : Array, shape ``(N,)``
        Normalised log-weights.

    Returns
    -------
    Array, shape ``(N,)``, int32
        The first ``Σ ⌊N wᵢ⌋`` entries hold ``⌊N wᵢ⌋`` copies of each ``i`` in order;
        the rest are drawn with probabilities ``∝ N wᵢ − ⌊N wᵢ⌋``.
    """
    n = log_w.shape[0]
    nw = n * jnp.exp(log_w)
    copies = jnp.floor(nw).astype(jnp.int32)
    fixed = jnp.repeat(jnp.arange(n, dtype=jnp.int32), copies, total_repeat_length=n)
    rest = nw - copies
    # all residuals zero (k = N) leaves no draw to make: any valid logits do
    logits = jnp.where(jnp.sum(rest) > 0.0, jnp.log(rest), 0.0)
    drawn = jax.random.categorical(key, logits, shape=(n,)).astype(jnp.int32)
    return jnp.where(jnp.arange(n) < jnp.sum(copies), fixed, drawn)


RESAMPLERS = {"systematic": systematic_resample, "residual": residual_resample}
"""Resampling schemes by name: ``(key, log_w) -> indices``."""


def standard_normal(key, shape, dtype):
    """Standard normal draws for the particles' noise, by Box–Muller on float32 uniforms.

    The particle filters draw ~13 normals per particle and step; ``jax.random.normal``
    costs ~43 ns a number in float64 on the 2-core CPU (XLA evaluates every branch of
    its inverse error function), this ~18 ns (two float32 uniforms give two normals).
    The draws are rounded to float32 before the cast to ``dtype``, a relative 6e-8 on a
    random number; the largest possible ``|z|`` is ``√(2 · 23 ln 2) ≈ 5.65`` (float32
    uniforms are multiples of ``2⁻²³``), beyond which a normal falls with probability
    ``1.6e-8``. Deterministic for a key, like ``jax.random.normal``, not equal to it.

    Parameters
    ----------
    key : PRNG key
    shape : tuple of int
    dtype : dtype
        Of the result.

    Returns
    -------
    Array, shape ``shape``
    """
    n = math.prod(shape)
    half = (n + 1) // 2
    u = jax.random.uniform(key, (2, half), jnp.float32)
    radius = jnp.sqrt(-2.0 * jnp.log1p(-u[0]))  # 1 − u in (0, 1]: no log(0)
    angle = (2.0 * math.pi) * u[1]
    z = jnp.concatenate([radius * jnp.cos(angle), radius * jnp.sin(angle)])[:n]
    return z.reshape(shape).astype(dtype)


def weighted_moments(log_w, x):
    """Weighted mean and covariance of particles.

    Parameters
    ----------
    log_w : Array, shape ``(N,)``
        Normalised log-weights.
    x : Array, shape ``(N, d)``

    Returns
    -------
    mean : Array, shape ``(d,)``
    cov : Array, shape ``(d, d)``
        ``Σ wᵢ (xᵢ − x̄)(xᵢ − x̄)ᵀ`` (symmetric).
    """
    w = jnp.exp(log_w)
    mean = w @ x
    dx = x - mean
    cov = (w[:, None] * dx).T @ dx
    return mean, 0.5 * (cov + cov.T)


def kernel_bandwidth(n, d):
    """Musso et al. (2001)'s optimal Gaussian-kernel bandwidth ``(4 / (N (d + 2)))^(1/(d+4))``."""
    return (4.0 / (n * (d + 2.0))) ** (1.0 / (d + 4.0))


def particle_summary(log_w, x, extra_var=None):
    """The per-step summary of weighted particles: mean, 1-σ per state, position covariance.

    Cheaper than :func:`weighted_moments` of all states (only the diagonal and the
    leading 2 × 2 block), which a filter needs every step.

    Parameters
    ----------
    log_w : Array, shape ``(N,)``
    x : Array, shape ``(N, d)``, or tuple of arrays, shapes ``(N, d_i)``
        Particles (position error first); a tuple is taken as its parts joined along
        the states (``d = Σ d_i``, the first part holding at least the two position
        states), without forming the joined ``(N, d)`` array.
    extra_var : Array, shape ``(d,)``, optional
        Added to the variances (a Rao–Blackwellised filter's shared Kalman part).

    Returns
    -------
    mean, sigma : Array, shape ``(d,)``
    p_pos : Array, shape ``(2, 2)``
    """
    w = jnp.exp(log_w)
    means, variances, dx_pos = [], [], None
    for part in (x if isinstance(x, tuple) else (x,)):
        m = w @ part
        dx = part - m
        means.append(m)
        variances.append(w @ dx**2)
        dx_pos = dx[:, :2] if dx_pos is None else dx_pos
    mean, var = (a[0] if len(a) == 1 else jnp.concatenate(a) for a in (means, variances))
    if extra_var is not None:
        var = var + extra_var
    p_pos = (w[:, None] * dx_pos).T @ dx_pos
    return mean, jnp.sqrt(jnp.clip(var, 0.0, None)), 0.5 * (p_pos + p_pos.T)


def resample_regularised(keys, log_w, x, resampler, roughening, ess_threshold):
    """Resample and regularise particles when their effective sample size is low.

    Parameters
    ----------
    keys : tuple of two PRNG keys
        For the resampling and for the regularisation.
    log_w : Array, shape ``(N,)``
        Normalised log-weights.
    x : Array, shape ``(N, d)``, or tuple of arrays, shapes ``(N, d_i)``
        The particles (all the states that are copied and spread together); a tuple
        is joined along the states (``d = Σ d_i``) inside the resampling branch only
        and returned as a tuple of the same shapes (a Rao–Blackwellised filter's
        positions and means: no ``(N, d)`` copy made at the steps that do not resample).
    resampler : callable
        ``(key, log_w) -> indices`` (:data:`RESAMPLERS`).
    roughening : float
        The kernel bandwidth as a share of :func:`kernel_bandwidth` ``(N, d)``.
    ess_threshold : float
        Resample when the effective sample size is below this share of ``N``.

    Returns
    -------
    x : Array, shape ``(N, d)``, or tuple of arrays
        As given.
    log_w : Array, shape ``(N,)``
        Equal weights where resampled, else the inputs unchanged.
    """
    parts = x if isinstance(x, tuple) else (x,)
    n, d = parts[0].shape[0], sum(a.shape[1] for a in parts)
    ends = tuple(itertools.accumulate(a.shape[1] for a in parts))
    k_idx, k_rough = keys
    # one dtype for both branches (float32 particles with float64 weights or a NumPy
    # float64 bandwidth would make the branches differ, which lax.cond refuses)
    dtype = jnp.result_type(*parts, log_w)
    parts, log_w = tuple(a.astype(dtype) for a in parts), log_w.astype(dtype)

    def resampled(op):
        k_idx, k_rough, log_w, parts = op
        x = parts[0] if len(parts) == 1 else jnp.concatenate(parts, axis=1)
        mean, cov = weighted_moments(log_w, x)
        moved = roughen(k_rough, x[resampler(k_idx, log_w)], mean, cov,
                        roughening * kernel_bandwidth(n, d)).astype(dtype)
        return (tuple(moved[:, e - a.shape[1]:e] for a, e in zip(parts, ends, strict=True)),
                jnp.full_like(log_w, -jnp.log(n)))

    # a branch, so a single run skips the work when the weights are fine; under vmap
    # only the runs that resample do it (2-3 % of paper D's steps per run)
    do = effective_sample_size(log_w) < ess_threshold * n
    out, log_w = rare_cond(do, resampled, lambda op: (op[3], op[2]),
                           (k_idx, k_rough, log_w, parts))
    return (out if isinstance(x, tuple) else out[0]), log_w


def roughen(key, x, mean, cov, bandwidth):
    """Regularise resampled particles with a moment-preserving Gaussian kernel.

    ``xᵢ ← a xᵢ + (1 − a) x̄ + h L εᵢ`` with ``a = √(1 − h²)``, ``L Lᵀ = Σ`` (Liu & West
    2001's shrinkage): the copies that resampling made are spread apart while the
    particles' mean and covariance are kept, so repeated resampling does not inflate
    the spread as plain roughening does.

    Parameters
    ----------
    key : PRNG key
    x : Array, shape ``(N, d)``
        Resampled particles.
    mean, cov : Array, shapes ``(d,)``, ``(d, d)``
        The particles' weighted mean and covariance before resampling
        (:func:`weighted_moments`); ``cov`` positive semi-definite (a zero direction
        gets no spread).
    bandwidth : float
        ``h`` in ``[0, 1)``; 0 returns the particles unchanged.

    Returns
    -------
    Array, shape ``(N, d)``
    """
    if isinstance(bandwidth, (int, float)) and bandwidth == 0:
        return x
    a = jnp.sqrt(1.0 - bandwidth**2)
    eps = standard_normal(key, x.shape, x.dtype)
    return a * x + (1.0 - a) * mean + bandwidth * eps @ psd_sqrt(cov).T


def check_particle_settings(n_particles, resample, ess_threshold, roughening):
    """Validate a particle filter's settings; returns the resampling function.

    Raises
    ------
    ValueError
        ``n_particles`` not an int ≥ 2, an unknown ``resample``, ``ess_threshold``
        or ``roughening`` outside ``[0, 1]``.
    """
    if isinstance(n_particles, bool) or not isinstance(n_particles, int) or n_particles < 2:
        raise ValueError(f"n_particles must be an int >= 2; got {n_particles!r}")
    if resample not in RESAMPLERS:
        raise ValueError(f"resample must be one of {sorted(RESAMPLERS)}; got {resample!r}")
    if not 0.0 <= float(ess_threshold) <= 1.0:
        raise ValueError(f"ess_threshold must be in [0, 1] (a share of the particles); got "
                         f"{ess_threshold!r}")
    if not 0.0 <= float(roughening) <= 1.0:
        raise ValueError(f"roughening must be in [0, 1] (a share of the optimal kernel "
                         f"bandwidth); got {roughening!r}")
    return RESAMPLERS[resample]
