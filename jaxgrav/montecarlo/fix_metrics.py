"""Per-run fix metrics of a matcher: accepted, size of the fix's covariance, coverage.

:func:`fix_metrics` is computed in JAX inside the vmapped run (one run, scalars), for
every matcher: a matcher that gives no covariance (NaN: ``entropy`` and ``iccp`` alone;
``dense``, ``chains`` and ``entropy+iccp`` give one) reports ``sigma_max_m`` NaN and
``covered95`` NaN. :data:`FIX_METRIC_ATTRS`
holds the NetCDF ``units``/``long_name`` of the metrics, and
:func:`fix_summary` the shares the summaries print (a rejected fix counts at the INS
error: its track *is* the INS track).
"""

import jax.numpy as jnp
import numpy as np

from jaxgrav.geodesy import local_offsets_m

__all__ = ["CHI2_2_95", "FIX_METRIC_ATTRS", "covered", "fix_metrics", "fix_summary",
           "sigma_max"]

CHI2_2_95 = 5.991464547107979
"""95 % quantile of χ²(2): the squared Mahalanobis radius of a 2-D 95 % ellipse."""

FIX_METRIC_ATTRS = {
    "accepted": dict(units="1", long_name="the matcher accepted its fix (else the INS "
                                          "track is returned)"),
    "sigma_max_m": dict(units="m", long_name="largest 1-sigma of the fix's 2x2 north/east "
                                             "covariance (NaN: the matcher gives none)"),
    "covered95": dict(units="1", long_name="true mean-track offset inside the fix's 95 % "
                                           "ellipse (chi2(2) <= 5.991); NaN: no covariance"),
    "ins_err_m": dict(units="m", long_name="mean horizontal error of the INS track"),
    "err_m": dict(units="m", long_name="mean horizontal error of the returned track"),
    "nees": dict(units="1", long_name="mean position NEES over the second half (filters; 2 "
                                      "expected)"),
    "bound_m": dict(units="m", long_name="posterior Cramer-Rao bound of the horizontal "
                                         "position error, RMS over the second half (filters)"),
}
"""NetCDF variable attributes of the per-run metrics."""


def sigma_max(cov):
    """Largest 1-σ of 2 × 2 covariances ``(..., 2, 2)`` (m²) in m: √ of the larger
    eigenvalue; NaN where any entry is not finite."""
    cov = jnp.asarray(cov)
    a, b, c = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    lam = 0.5 * (a + c) + jnp.sqrt(0.25 * (a - c) ** 2 + b**2)
    ok = jnp.isfinite(a) & jnp.isfinite(b) & jnp.isfinite(c)
    return jnp.where(ok, jnp.sqrt(jnp.maximum(jnp.where(ok, lam, 0.0), 0.0)), jnp.nan)


def covered(cov, err_north_m, err_east_m, chi2=CHI2_2_95):
    """1.0 if the error ``(north, east)`` (m) lies inside the ellipse ``eᵀ C⁻¹ e ≤ chi2``
    of the covariance ``C`` ``(..., 2, 2)`` (m²), 0.0 if outside, NaN where ``C`` is
    not finite and positive definite."""
    cov = jnp.asarray(cov)
    a, b, c = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    det = a * c - b**2
    ok = jnp.isfinite(a) & jnp.isfinite(b) & jnp.isfinite(c) & (a > 0) & (det > 0)
    maha = (c * err_north_m**2 - 2 * b * err_north_m * err_east_m
            + a * err_east_m**2) / jnp.where(ok, det, 1.0)
    return jnp.where(ok, (maha <= chi2).astype(maha.dtype), jnp.nan)


def fix_metrics(run, result):
    """The fix metrics of one run (JAX, inside the vmapped run).

    Parameters
    ----------
    run : MatchingRun or PaperBRun
        The simulated run (``truth.lat``, ``truth.lon``, degrees, ``(n_fixes,)``).
    result : MatchResult
        The matcher's result: ``accepted``, ``covariance_m2`` (m², NaN if none) and the
        returned track ``lat``, ``lon``.

    Returns
    -------
    dict
        ``accepted`` (bool), ``sigma_max_m`` (m, :func:`sigma_max`), ``covered95``
        (:func:`covered` of the returned track's mean north/east error from the truth;
        for a rejected fix that is the INS track's, so summaries use accepted runs only).
    """
    cov = jnp.asarray(result.covariance_m2)
    en, ee = local_offsets_m(result.lat, result.lon, run.truth.lat, run.truth.lon)
    return dict(accepted=jnp.asarray(result.accepted, bool), sigma_max_m=sigma_max(cov),
                covered95=covered(cov, jnp.mean(en), jnp.mean(ee)))


def fix_summary(results):
    """Shares over runs: ``accepted_rate`` and ``coverage95_accepted`` (mean of
    ``covered95`` over accepted runs with a covariance; NaN if none), ``covariance_rate``
    (runs with a covariance). ``results`` holds :func:`fix_metrics`'s arrays ``(n_runs,)``;
    without them an empty dict."""
    if "accepted" not in results:
        return {}
    acc = np.asarray(results["accepted"], bool)
    cov = np.asarray(results["covered95"], float)
    has = np.isfinite(cov)
    use = acc & has
    return dict(accepted_rate=float(acc.mean()),
                covariance_rate=float(has.mean()),
                coverage95_accepted=float(cov[use].mean()) if use.any() else float("nan"))
