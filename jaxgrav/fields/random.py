"""Stationary Gaussian random fields on regular grids (FFT spectral synthesis).

A field is drawn by colouring white noise in the Fourier domain: with ``w`` a
``(ny, nx)`` array of independent N(0, 1) samples,

.. math:: f = \\mathrm{IFFT}\\big(\\mathrm{FFT}(w)\\,A(\\mathbf k)\\big), \\qquad
          A(\\mathbf k)^2 = \\frac{S(|\\mathbf k|)}{\\Delta y\\,\\Delta x},

where ``S`` is the two-dimensional power spectral density, in the convention

.. math:: C(\\mathbf r) = \\frac{1}{(2\\pi)^2} \\int S(|\\mathbf k|)\\, e^{i\\mathbf k\\cdot
          \\mathbf r}\\, d^2k

(``C`` the covariance, ``k`` in rad/m, ``S`` in value²·m², e.g. mGal²·m²). The
result is exactly Gaussian and stationary with the *periodic* covariance
``C_per(r) = (1/N) Σ_k A(k)² e^{ik·r}`` (N = ny·nx): the grid wraps around, so
``C`` is folded at the domain size. Keep the correlation length a small fraction
of the domain (≲ 1/10) if the edges must be independent.

Normalisation
-------------
Each grid value has expected variance ``σ² = (1/N) Σ_k A(k)²`` — a Riemann sum of the
continuous variance ``∫ S d²k / (2π)²`` over the grid's wavenumbers. With
``zero_mean=True`` (default) the k = 0 term is dropped, so every realisation has a
spatial mean of exactly zero and the expected *sample* variance ``mean(f²)`` of one
realisation is exactly ``σ²``. Passing ``rms`` rescales ``A`` so that ``σ = rms``
exactly, whatever the spectrum's discretisation (recommended: a coarse grid
truncates high wavenumbers, a small domain the low ones). ``E|FFT(f)_k|² = N A(k)²``,
i.e. the periodogram ``|FFT(f)|²·Δy·Δx / N`` estimates ``S``.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import concrete
from jaxgrav.fields.spectral import check_shape, spacing_pair, wavenumbers

__all__ = [
    "MarkovSpectrum",
    "PowerLawSpectrum",
    "gaussian_random_field",
    "markov_spectrum",
    "power_law_spectrum",
]


def _check_positive(x, name):
    arr = concrete(x)
    if arr is not None and not (np.all(np.isfinite(arr)) and np.all(arr > 0)):
        raise ValueError(f"{name} must be positive and finite; got {arr}")


@pytree_dataclass
class MarkovSpectrum:
    """Isotropic Markov (Matérn half-integer) spectrum, as a callable of |k|.

    Covariance ``C(r) = rms² e^{−r/L}`` (``order=1``, exponential) or
    ``C(r) = rms² (1 + r/L) e^{−r/L}`` (``order=2``, second-order Gauss–Markov, the
    usual gravity-anomaly model), with power spectral density (2-D, convention of
    this module)

    * order 1: ``S(k) = 2π rms² L² (1 + k²L²)^{−3/2}``
    * order 2: ``S(k) = 6π rms² L² (1 + k²L²)^{−5/2}``.

    Build one with :func:`markov_spectrum`. ``rms`` and ``correlation_length`` are
    pytree data (traceable, sweepable without recompiling); ``order`` is static.

    Attributes
    ----------
    rms : Array, scalar
        Standard deviation of the field (value unit, e.g. mGal).
    correlation_length : Array, scalar
        L in metres. (For order 2, C(L) = 2/e ≈ 0.74 rms²; C falls to half at ≈ 1.68 L.)
    order : int
        1 or 2 (static).
    """

    rms: jax.Array
    correlation_length: jax.Array
    order: int = static_field(2)

    def __call__(self, k):
        """Power spectral density at wavenumber ``k`` (rad/m), in rms-unit²·m²."""
        kl2 = (jnp.asarray(k) * self.correlation_length) ** 2
        ll = self.correlation_length**2 * self.rms**2
        if self.order == 1:
            return 2.0 * jnp.pi * ll * (1.0 + kl2) ** -1.5
        return 6.0 * jnp.pi * ll * (1.0 + kl2) ** -2.5

    def covariance(self, r):
        """Covariance at lag ``r`` (m), in rms-unit²."""
        x = jnp.abs(jnp.asarray(r)) / self.correlation_length
        poly = 1.0 if self.order == 1 else 1.0 + x
        return self.rms**2 * poly * jnp.exp(-x)


@pytree_dataclass
class PowerLawSpectrum:
    """Power-law spectrum ``S(k) = amplitude · (k / k0)^(−exponent)`` for k > 0, 0 at k = 0.

    Build one with :func:`power_law_spectrum`. The variance of a power law is not
    finite over all wavenumbers, so pass ``rms`` to :func:`gaussian_random_field`
    to fix the level on a given grid. Gravity anomalies typically have exponents of
    3–4 (a 2-D spectrum falling as k^−3…k^−4).

    Attributes
    ----------
    exponent : Array, scalar
        Spectral exponent β (dimensionless).
    amplitude : Array, scalar
        Spectral density at k = k0 (value²·m²).
    reference_wavenumber : Array, scalar
        k0 in rad/m.
    """

    exponent: jax.Array
    amplitude: jax.Array
    reference_wavenumber: jax.Array

    def __call__(self, k):
        """Power spectral density at wavenumber ``k`` (rad/m), in value²·m²."""
        k = jnp.asarray(k)
        pos = k > 0
        safe = jnp.where(pos, k, 1.0)  # double where: finite gradients at k = 0
        s = self.amplitude * (safe / self.reference_wavenumber) ** (-self.exponent)
        return jnp.where(pos, s, 0.0)


def markov_spectrum(rms, correlation_length, order=2):
    """Markov anomaly spectrum (exponential or second-order Gauss–Markov covariance).

    Parameters
    ----------
    rms : float or array
        Field standard deviation (e.g. mGal), > 0.
    correlation_length : float or array
        Correlation length L (m), > 0.
    order : {1, 2}, default 2
        1: ``C = rms² e^{−r/L}``; 2: ``C = rms² (1 + r/L) e^{−r/L}``.

    Returns
    -------
    MarkovSpectrum
        Callable ``S(k)``; see the class for formulas.

    Raises
    ------
    ValueError
        If a concrete ``rms`` or ``correlation_length`` is not positive and finite, or
        ``order`` is not 1 or 2.
    """
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2; got {order!r}")
    _check_positive(rms, "rms")
    _check_positive(correlation_length, "correlation_length")
    dtype = jnp.result_type(float)
    return MarkovSpectrum(
        rms=jnp.asarray(rms, dtype=dtype),
        correlation_length=jnp.asarray(correlation_length, dtype=dtype),
        order=int(order),
    )


def power_law_spectrum(exponent, amplitude=1.0, reference_wavenumber=1.0e-3):
    """Power-law spectrum ``S(k) = amplitude · (k/k0)^(−exponent)``.

    Parameters
    ----------
    exponent : float or array
        Spectral exponent β ≥ 0.
    amplitude : float or array, default 1
        Spectral density at ``k0`` (value²·m²), > 0.
    reference_wavenumber : float or array, default 1e-3
        k0 (rad/m), > 0.

    Returns
    -------
    PowerLawSpectrum
        Callable ``S(k)``, zero at k = 0.

    Raises
    ------
    ValueError
        If a concrete parameter is negative, zero (amplitude, k0) or non-finite.
    """
    arr = concrete(exponent)
    if arr is not None and not (np.all(np.isfinite(arr)) and np.all(arr >= 0)):
        raise ValueError(f"exponent must be finite and >= 0; got {arr}")
    _check_positive(amplitude, "amplitude")
    _check_positive(reference_wavenumber, "reference_wavenumber")
    dtype = jnp.result_type(float)
    return PowerLawSpectrum(
        exponent=jnp.asarray(exponent, dtype=dtype),
        amplitude=jnp.asarray(amplitude, dtype=dtype),
        reference_wavenumber=jnp.asarray(reference_wavenumber, dtype=dtype),
    )


def gaussian_random_field(key, shape, spacing, power_spectrum, rms=None, *, zero_mean=True):
    """Draw a stationary, isotropic Gaussian random field on a regular grid.

    Parameters
    ----------
    key : jax.Array
        PRNG key (``jax.random.key`` or legacy ``PRNGKey``); the same key gives the
        same field.
    shape : tuple of int
        Grid shape ``(ny, nx)``; static (mark it ``static_argnames`` under ``jit``).
    spacing : tuple of float or array_like, shape (2,)
        Grid spacing ``(dy, dx)`` in metres.
    power_spectrum : callable
        ``S(k)``: 2-D power spectral density as a function of the wavenumber
        magnitude ``k`` (rad/m, an array), returning value²·m², non-negative and
        finite (see the module docstring for the convention). Use a preset
        (:func:`markov_spectrum`, :func:`power_law_spectrum`: pytrees, so they may be
        traced arguments under ``jit``) or any function (then pass it as a static
        argument or close over it).
    rms : float or array, optional
        If given, the spectrum is rescaled so that each grid value has standard
        deviation exactly ``rms`` (value unit). If None, the spectrum's absolute
        level is used.
    zero_mean : bool, default True
        Drop the k = 0 component: every realisation has zero spatial mean and its
        expected sample variance equals the target variance exactly. If False the
        k = 0 term ``S(0)/(ny·nx·dy·dx)`` is kept (ensemble mean is still zero).

    Returns
    -------
    Array, shape (ny, nx)
        Real field, rows along ``y`` (northing), in the unit of ``sqrt(S / m²)`` (or
        of ``rms``).

    Raises
    ------
    ValueError
        If ``shape`` or ``spacing`` are invalid, a concrete ``rms`` is not positive,
        or the spectrum evaluated on the grid is negative, non-finite or all zero
        (when it can be inspected, i.e. outside ``jit``).
    """
    ny, nx = check_shape(shape)
    if not callable(power_spectrum):
        raise TypeError(
            "power_spectrum must be a callable S(k) of the wavenumber in rad/m (e.g. "
            f"markov_spectrum(...)); got {type(power_spectrum).__name__}"
        )
    if rms is not None:
        _check_positive(rms, "rms")
    dy, dx = spacing_pair(spacing)
    leaves = jax.tree.leaves(power_spectrum)
    if len(leaves) == 1 and leaves[0] is power_spectrum:
        # not a pytree (a plain function): make it static, hashed by identity
        power_spectrum = jax.tree_util.Partial(power_spectrum)
    amp, finite, nonzero = _amplitude(
        dy, dx, power_spectrum, rms, shape=(ny, nx), zero_mean=bool(zero_mean)
    )
    finite, nonzero = concrete(finite), concrete(nonzero)
    if finite is not None and not finite:
        raise ValueError(
            "power_spectrum must return finite values >= 0 on the grid's wavenumbers "
            "(got a negative, NaN or infinite value)"
        )
    if nonzero is not None and not nonzero:
        raise ValueError(
            "power_spectrum is zero at every non-zero wavenumber of the grid; "
            "no field can be drawn"
        )
    return _colour(key, amp, shape=(ny, nx))


# Two jitted parts: the spectrum (cheap to compile, one per spectrum type) and the
# noise colouring (the PRNG is slow to compile, so it is kept independent of the
# spectrum and compiled once per grid shape and key type).


@functools.partial(jax.jit, static_argnames=("shape", "zero_mean"))
def _amplitude(dy, dx, power_spectrum, rms, *, shape, zero_mean):
    """Per-mode amplitude A(k) on the rfft grid plus two validity flags of the spectrum."""
    ny, nx = shape
    dtype = dy.dtype
    k_full = wavenumbers((ny, nx), (dy, dx)).k
    k_half = wavenumbers((ny, nx), (dy, dx), real=True).k
    s_full = jnp.broadcast_to(jnp.asarray(power_spectrum(k_full), dtype=dtype), k_full.shape)
    s_half = jnp.broadcast_to(jnp.asarray(power_spectrum(k_half), dtype=dtype), k_half.shape)
    finite = jnp.all(jnp.isfinite(s_full) & (s_full >= 0))
    if zero_mean:
        s_full = s_full.at[0, 0].set(0.0)
        s_half = s_half.at[0, 0].set(0.0)
    nonzero = jnp.any(s_full > 0)
    amp2 = s_half / (dy * dx)
    if rms is not None:
        variance = jnp.sum(s_full) / (dy * dx) / (ny * nx)
        amp2 = amp2 * (jnp.asarray(rms, dtype=dtype) ** 2 / variance)
    pos = amp2 > 0
    amp = jnp.where(pos, jnp.sqrt(jnp.where(pos, amp2, 1.0)), 0.0)  # finite grads at S = 0
    return amp, finite, nonzero


@functools.partial(jax.jit, static_argnames=("shape",))
def _colour(key, amp, *, shape):
    """White noise of ``shape`` coloured by the rfft-grid amplitude ``amp``."""
    noise = jax.random.normal(key, shape, dtype=amp.dtype)
    return jnp.fft.irfft2(jnp.fft.rfft2(noise) * amp, s=shape)
