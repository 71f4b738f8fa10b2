"""How well a voyage was navigated: errors against the truth, per hour, and NEES.

The figures the voyage issue asks for, for any navigation result with a corrected
track and its position covariance (loosely or tightly coupled): radial error of the
navigation solution and of the free INS at every step, their RMS per hour, the ratio
per hour (harm is a ratio above 1), and the position NEES (2 expected when the stated
covariance is honest).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._linalg import inv_2x2
from jaxgrav.geodesy import local_offsets_m

__all__ = ["VoyageErrors", "hourly_rms", "voyage_errors", "voyage_summary"]


class VoyageErrors(NamedTuple):
    """Errors of one navigated voyage, each shape ``(N,)``.

    Attributes
    ----------
    nav_m, free_m : Array
        Radial position error (m) of the navigation solution and of the free INS.
    nees : Array
        ``eᵀ P⁻¹ e`` of the navigation solution's position error (2 degrees of freedom).
    """

    nav_m: jax.Array
    free_m: jax.Array
    nees: jax.Array


def voyage_errors(voyage, nav, cov_north_east):
    """Errors of a navigation solution against a simulated voyage's truth.

    Parameters
    ----------
    voyage : Voyage
        With ``truth``.
    nav : Track
        Navigation solution at the voyage's steps.
    cov_north_east : Array, shape ``(N, 2, 2)``
        Its stated position covariance (m²).

    Returns
    -------
    VoyageErrors
    """
    if voyage.truth is None:
        raise ValueError("voyage.truth is None: errors need a simulated voyage's truth")
    t = voyage.truth
    e_n, e_e = local_offsets_m(nav.lat, nav.lon, t.lat, t.lon)
    f_n, f_e = local_offsets_m(voyage.ins.lat, voyage.ins.lon, t.lat, t.lon)
    e = jnp.stack([e_n, e_e], axis=-1)
    nees = jnp.einsum("ni,nij,nj->n", e, jax.vmap(inv_2x2)(cov_north_east), e)
    return VoyageErrors(jnp.hypot(e_n, e_e), jnp.hypot(f_n, f_e), nees)


def hourly_rms(error_m, dt, period_s=3600.0):
    """RMS of an error series over consecutive periods (the last partial one dropped).

    Parameters
    ----------
    error_m : Array, shape ``(..., N)``
        Errors at steps ``dt`` apart, the first at time 0 (which is left out).
    dt : float
        Step (s), static.
    period_s : float
        Period (s), static; a multiple of ``dt``.

    Returns
    -------
    Array, shape ``(..., H)``
        RMS over steps ``(h·k, (h+1)·k]``, k = period_s / dt.
    """
    k = round(period_s / dt)
    h = (error_m.shape[-1] - 1) // k
    blocks = error_m[..., 1:h * k + 1].reshape(*error_m.shape[:-1], h, k)
    return jnp.sqrt(jnp.mean(blocks**2, axis=-1))


def voyage_summary(nav_hourly, free_hourly, nees):
    """The voyage issue's figures over many voyages, as plain numbers.

    Parameters
    ----------
    nav_hourly, free_hourly : array_like, shape ``(runs, H)``
        Hourly RMS radial error (m) of the navigation solution and of the free INS
        (:func:`hourly_rms`).
    nees : array_like, shape ``(runs,)``
        Each voyage's mean position NEES.

    Returns
    -------
    dict
        ``hourly_rms_nav_m``, ``hourly_rms_free_m`` (RMS over voyages per hour, m),
        ``last_hour_ratio`` (nav / free, last hour; goal ≤ 0.1),
        ``last_over_second_hour`` (goal ≤ 1.5), ``share_worse_than_free_some_hour``
        (voyages whose hourly RMS exceeds the free INS's in some hour from the second
        on; goal 0), ``worst_hourly_ratio`` (over those hours), ``nees`` (mean over
        voyages; 2 expected) and ``nees_median`` (median of the voyages' means). A
        figure the voyage does not have is NaN: ``last_over_second_hour`` needs three
        whole hours (with two, the last hour is the second), the hours from the second
        need two. ``nonfinite_voyages``: voyages with a non-finite hourly error or NEES;
        such a voyage counts as worse than the free INS, and makes the hourly RMS and
        the NEES over voyages NaN (nothing is dropped unannounced).
    """
    nav, free = np.asarray(nav_hourly, float), np.asarray(free_hourly, float)
    nees = np.asarray(nees, float)
    rms_nav, rms_free = np.sqrt(np.mean(nav**2, 0)), np.sqrt(np.mean(free**2, 0))
    ratio = nav / free
    later = ratio[:, 1:]
    nan = float("nan")
    nonfinite = ~np.all(np.isfinite(nav) & np.isfinite(free), axis=1) | ~np.isfinite(nees)
    return {"hourly_rms_nav_m": rms_nav.round(0).tolist(),
            "hourly_rms_free_m": rms_free.round(0).tolist(),
            "last_hour_ratio": float(rms_nav[-1] / rms_free[-1]),
            "last_over_second_hour": (float(rms_nav[-1] / rms_nav[1]) if rms_nav.size >= 3
                                      else nan),
            "share_worse_than_free_some_hour": (
                float(np.mean(np.any(~np.isfinite(later) | (later > 1.0), axis=1)))
                if later.shape[1] else nan),
            "worst_hourly_ratio": float(later.max()) if later.size else nan,
            "nees": float(np.mean(nees)),
            "nees_median": float(np.median(nees)),
            "nonfinite_voyages": int(np.sum(nonfinite))}
