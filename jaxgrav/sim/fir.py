"""Linear-phase low-pass FIR filtering of gravimeter records (paper D).

Paper D separates the gravity anomaly from the vehicle's disturbance accelerations
by frequency: swell moves a submerged vehicle at 0.05–0.5 Hz, while the anomaly seen
by a vehicle crossing a map of node spacing ``n_d`` at speed ``v`` varies at
``f_t = v / n_d``. A Parks–McClellan (equiripple) low-pass filter with its pass
band edge in 0.05π–0.1π rad/sample keeps the anomaly and removes the swell, provided
``f_t`` stays below the disturbance band divided by 2.5 — which bounds the speed
(:mod:`jaxgrav.sim.speed_bound`, whose functions this module re-exports).

Design runs once, in NumPy/SciPy (:func:`design_lowpass`, ``scipy.signal.remez``),
and checks the frequency response against the requested ripples. Filtering is JAX
(:func:`apply_fir`): a convolution, jit-able and vmappable over records, with the
group delay ``(M − 1)/2`` of an ``M``-tap filter removed so that output sample ``n``
estimates the input at sample ``n``. Frequencies are in cycles per sample unless a
sampling rate ``fs`` is given (then in Hz); π rad/sample is 0.5 cycles/sample.

Edges
-----
Output sample ``n`` uses inputs ``n − d … n + d`` (``d = (M − 1)/2``). For the first
and last ``d`` samples part of that window lies outside the record; those outputs are
transients, returned as NaN with ``valid = False`` (never zero-padded garbage). In
real time the aligned estimate for epoch ``n`` becomes available at epoch ``n + d``.
"""

import math
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import check_finite
from jaxgrav.sim.speed_bound import max_speed, min_map_spacing, signal_frequency

__all__ = [
    "PAPER_CUTOFF_RANGE",
    "FilteredRecord",
    "LowpassFIR",
    "apply_fir",
    "design_lowpass",
    "estimate_numtaps",
    "max_speed",
    "min_map_spacing",
    "signal_frequency",
]

PAPER_CUTOFF_RANGE = (0.025, 0.05)
"""Paper D's cut-off range, 0.05π–0.1π rad/sample, in cycles/sample."""

_N_FREQ = 1 << 16  # frequency grid for checking a design (points on [0, 0.5))


@pytree_dataclass
class LowpassFIR:
    """A designed linear-phase (type I, odd length) low-pass FIR filter.

    Attributes
    ----------
    taps : Array, shape ``(M,)``
        Impulse response, symmetric, ``M`` odd (pytree data).
    cutoff, stop_edge : float
        Pass band edge and stop band edge (cycles/sample).
    ripple_pass, ripple_stop : float
        Requested pass band ripple δ1 (max ``| |H| − 1 |``) and stop band ripple δ2
        (max ``|H|``), linear.
    achieved_pass, achieved_stop : float
        Ripples of the design measured on a 65 536-point frequency grid.
    """

    taps: jax.Array
    cutoff: float = static_field()
    stop_edge: float = static_field()
    ripple_pass: float = static_field()
    ripple_stop: float = static_field()
    achieved_pass: float = static_field()
    achieved_stop: float = static_field()

    @property
    def numtaps(self):
        """Number of taps ``M``."""
        return int(self.taps.shape[0])

    @property
    def delay(self):
        """Group delay ``(M − 1)/2`` in samples (compensated by :func:`apply_fir`)."""
        return (self.numtaps - 1) // 2


class FilteredRecord(NamedTuple):
    """Output of :func:`apply_fir`.

    Attributes
    ----------
    values : Array, shape ``(N,)``
        Filtered record aligned with the input, NaN where ``valid`` is False.
    valid : Array of bool, shape ``(N,)``
        True where the whole filter window lies inside the record
        (``d ≤ n ≤ N − 1 − d``).
    """

    values: jax.Array
    valid: jax.Array


def estimate_numtaps(transition, ripple_pass, ripple_stop):
    """Number of taps of an equiripple low-pass filter (Herrmann et al., 1973).

    ``M ≈ D∞(δ1, δ2)/Δf − f(δ1, δ2) Δf + 1``, the formula behind MATLAB's
    ``firpmord``, rounded up to the next odd integer.

    Parameters
    ----------
    transition : float
        Transition band width Δf (cycles/sample), in (0, 0.5).
    ripple_pass, ripple_stop : float
        Pass and stop band ripples δ1, δ2 (linear), in (0, 1).

    Returns
    -------
    int
        Estimated (odd) number of taps, at least 3.
    """
    _check_ripples(ripple_pass, ripple_stop)
    df = float(transition)
    if not 0.0 < df < 0.5:
        raise ValueError(f"transition must be in (0, 0.5) cycles/sample; got {transition!r}")
    d1, d2 = math.log10(ripple_pass), math.log10(ripple_stop)
    d_inf = d2 * (5.309e-3 * d1**2 + 7.114e-2 * d1 - 4.761e-1) + (
        -2.66e-3 * d1**2 - 5.941e-1 * d1 - 4.278e-1
    )
    f_k = 11.01217 + 0.51244 * (d1 - d2)
    m = max(3, math.ceil(d_inf / df - f_k * df + 1.0))
    return m + 1 - m % 2


def design_lowpass(
    cutoff=0.025, transition=0.025, ripple_pass=1e-3, ripple_stop=1e-4, *, numtaps=None, fs=1.0
):
    """Design a Parks–McClellan equiripple low-pass filter and verify its ripples.

    Parameters
    ----------
    cutoff : float
        Pass band edge, in cycles/sample (or Hz when ``fs`` is given). Paper D uses
        0.05π–0.1π rad/sample, i.e. 0.025–0.05 cycles/sample; values outside that
        range are allowed with a warning.
    transition : float
        Width of the transition band (same unit); the stop band starts at
        ``cutoff + transition``, which must stay below Nyquist (``fs/2``).
    ripple_pass, ripple_stop : float
        Pass band ripple δ1 (max ``| |H| − 1 |``) and stop band ripple δ2 (max
        ``|H|``), linear, in (0, 1). 10 cm/s² of swell is 10⁴ mGal, so δ2 = 10⁻⁴
        leaves about 1 mGal; δ1 = 10⁻³ keeps a 100 mGal anomaly within 0.1 mGal.
    numtaps : int, optional
        Odd number of taps. By default the Herrmann estimate
        (:func:`estimate_numtaps`), increased two taps at a time (up to twice the
        estimate) until the design meets both ripples.
    fs : float
        Sampling rate of ``cutoff`` and ``transition`` (1 = cycles/sample).

    Returns
    -------
    LowpassFIR

    Raises
    ------
    ValueError
        Bad band edges or ripples, an even ``numtaps``, or a design that does not
        meet the ripples (with the achieved values).
    """
    fs = float(fs)
    if not (math.isfinite(fs) and fs > 0):
        raise ValueError(f"fs must be a positive sampling rate; got {fs!r}")
    fp, df = float(cutoff) / fs, float(transition) / fs
    if not 0.0 < fp < 0.5:
        raise ValueError(
            f"cutoff must lie in (0, {fs / 2}) (0–0.5 cycles/sample); got {cutoff!r}"
        )
    if not (df > 0 and fp + df < 0.5):
        raise ValueError(
            f"transition must be positive with cutoff + transition < {fs / 2} (Nyquist); "
            f"got transition={transition!r}, cutoff={cutoff!r}"
        )
    _check_ripples(ripple_pass, ripple_stop)
    lo, hi = PAPER_CUTOFF_RANGE
    if not lo <= fp <= hi:
        warnings.warn(
            f"cutoff {fp:.4g} cycles/sample ({2 * fp:.3g}π rad/sample) is outside paper D's "
            f"0.05π–0.1π rad/sample ({lo}–{hi} cycles/sample)",
            UserWarning,
            stacklevel=2,
        )
    if numtaps is not None:
        if int(numtaps) != numtaps or numtaps < 3 or numtaps % 2 == 0:
            raise ValueError(
                f"numtaps must be an odd integer ≥ 3 (integer group delay); got {numtaps!r}"
            )
        candidates = [int(numtaps)]
    else:
        m0 = estimate_numtaps(df, ripple_pass, ripple_stop)
        candidates = range(m0, 2 * m0 + 2, 2)
    for m in candidates:
        taps = _remez(m, fp, df, ripple_pass / ripple_stop)
        if taps is None:
            continue
        dp, ds = _ripples(taps, fp, fp + df)
        if dp <= ripple_pass and ds <= ripple_stop:
            return LowpassFIR(jnp.asarray(taps), fp, fp + df, float(ripple_pass),
                              float(ripple_stop), dp, ds)
    got = "Remez did not converge" if taps is None else f"achieved δ1={dp:.3g}, δ2={ds:.3g}"
    raise ValueError(
        f"no {m}-tap equiripple design meets ripple_pass={ripple_pass!r}, "
        f"ripple_stop={ripple_stop!r} with cutoff={fp:.4g}, transition={df:.4g} "
        f"cycles/sample ({got}); widen the transition, relax the ripples or add taps"
    )


def _check_ripples(ripple_pass, ripple_stop):
    for name, val in (("ripple_pass", ripple_pass), ("ripple_stop", ripple_stop)):
        if not 0.0 < float(val) < 1.0:
            raise ValueError(f"{name} must be a linear ripple in (0, 1); got {val!r}")


def _signal():
    """``scipy.signal``, imported on first use: it takes ~1 s (half of the command line's
    start-up on the 2-core machine) and only the filter design, run once, needs it."""
    import scipy.signal  # deliberately here, not at the top: start-up cost (docstring)

    return scipy.signal


def _remez(m, fp, df, weight_stop):
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            return _signal().remez(
                m, [0.0, fp, fp + df, 0.5], [1.0, 0.0], weight=[1.0, weight_stop], fs=1.0,
                maxiter=100,
            )
        except (ValueError, RuntimeWarning):
            return None


def _ripples(taps, f_pass, f_stop):
    """Measured pass band ``max | |H| − 1 |`` and stop band ``max |H|`` (linear)."""
    f, h = _signal().freqz(taps, worN=_N_FREQ, fs=1.0)
    mag = np.abs(h)
    return float(np.max(np.abs(mag[f <= f_pass] - 1.0))), float(np.max(mag[f >= f_stop]))


def apply_fir(record, fir):
    """Low-pass filter one record with the group delay compensated.

    ``y[n] = Σ_k h[k] x[n + d − k]`` with ``d = (M − 1)/2``: the causal output
    (``scipy.signal.lfilter(h, 1, x)``) shifted ``d`` samples earlier, so that a
    slow signal passes unshifted. Jit-able; vmap it for a batch of records.

    Parameters
    ----------
    record : array_like, shape ``(N,)``
        Samples (any unit, e.g. mGal); ``N ≥ M``; must be finite.
    fir : LowpassFIR or array_like, shape ``(M,)``
        The filter, or raw taps of odd length ``M``.

    Returns
    -------
    FilteredRecord
        ``values`` (``(N,)``, same unit, NaN in the ``d``-sample transients at both
        ends) and the ``valid`` mask.

    Raises
    ------
    ValueError
        Record not 1-D, shorter than the filter, or (when concrete) not finite;
        even-length taps.
    """
    taps = fir.taps if isinstance(fir, LowpassFIR) else jnp.asarray(fir)
    record = jnp.asarray(record)
    if taps.ndim != 1 or taps.shape[0] % 2 == 0:
        raise ValueError(f"fir taps must be 1-D with an odd length; got shape {taps.shape}")
    if record.ndim != 1:
        raise ValueError(
            f"record must be one 1-D record of shape (N,); got shape {record.shape} "
            "(use jax.vmap(apply_fir, in_axes=(0, None)) for a batch)"
        )
    if record.shape[0] < taps.shape[0]:
        raise ValueError(
            f"record has {record.shape[0]} samples, fewer than the filter's "
            f"{taps.shape[0]} taps; need at least {taps.shape[0]}"
        )
    check_finite(record, "record")
    return apply_fir_compiled(record, taps)


@jax.jit
def apply_fir_compiled(record, taps):
    """The compiled core of :func:`apply_fir` (no validation; package-internal)."""
    n, m = record.shape[0], taps.shape[0]
    d = (m - 1) // 2
    dtype = jnp.result_type(record.dtype, taps.dtype, float)
    full = jnp.convolve(record.astype(dtype), taps.astype(dtype), mode="full",
                        precision=jax.lax.Precision.HIGHEST)
    idx = jnp.arange(n)
    valid = (idx >= d) & (idx <= n - 1 - d)
    return FilteredRecord(jnp.where(valid, full[d:d + n], jnp.nan), valid)
