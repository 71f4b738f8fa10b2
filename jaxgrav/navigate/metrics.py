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

from jaxgrav.geodesy import local_offsets_m

__all__ = ["VoyageErrors", "hourly_rms", "voyage_errors"]


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
    nees = jnp.einsum("ni,nij,nj->n", e, jnp.linalg.inv(cov_north_east), e)
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
