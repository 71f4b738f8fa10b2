"""The likelihood-weighted posterior of a track's offset over a set of scored offsets.

Given χ² scores ``J`` of candidate offsets (:func:`~jaxgrav.match.gls.gls_score` over a
lattice, or a white-noise score in χ² units), the offsets carry weights
``p ∝ exp(−J/2)``; :func:`offset_posterior` returns their mean and 2 × 2 covariance and
the diagnostics an integrity decision needs (the mode's curvature, a second mode, the
mass on the search edge).

It is written as a few array operations so that, under ``vmap`` inside a Monte Carlo
chunk, it compiles to few XLA kernels (each costs compile time whatever its size):
the sums over the offsets are one stacked reduction, the 9 offsets nearest the best one
``lax.top_k``, the quadratic fit's normal equations one product and their 6 × 6 solve
one ``fori_loop`` (:func:`jaxgrav._linalg.solve_spd`).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._linalg import solve_spd

__all__ = ["OffsetPosterior", "curvature_covariance", "offset_posterior"]


class OffsetPosterior(NamedTuple):
    """Likelihood-weighted posterior of a track's offset over a set of offsets.

    Attributes
    ----------
    mean_north_m, mean_east_m : Array
        Posterior mean offset (m); 0 when ``valid`` is false.
    covariance_m2 : Array, shape ``(2, 2)``
        Posterior covariance (m², north/east) plus ``cell²/12`` per axis; ``inf`` on
        the diagonal when ``valid`` is false.
    best_index, best_score : Array
        Index (into the flattened scores) and value of the least score (``inf`` if none).
    chi2_per_dof : Array
        ``best_score / dof``: about 1 when the error model is right.
    n_effective : Array
        ``1 / Σ p²`` of the normalised weights p: offsets sharing the posterior mass.
    second_mode_ratio : Array
        ``exp(−(J₂ − J_best)/2)``, J₂ the least score outside the mode's
        neighbourhood: near 1 for a second mode nearly as likely, at most
        ``exp(−exclusion_chi2/2)`` for a quadratic score, 0 when nothing is outside;
        1 when ``valid`` is false.
    curvature_covariance_m2 : Array, shape ``(2, 2)``
        ``2 H⁻¹`` (:func:`curvature_covariance`) from a quadratic fit of the score at
        the 9 valid offsets nearest the
        best (H its Hessian, 1/m²): the Laplace covariance of the mode (no
        quantisation term); ``inf`` diagonal when ``curvature_ok`` is false.
    curvature_ok : Array of bool
        The fit was determined and its Hessian positive definite.
    log_evidence : Array
        ``log Σ exp(−J/2)`` over the valid offsets.
    edge_mass : Array
        Posterior mass on the outermost offsets (least or greatest north or east):
        more than a little means the truth may lie beyond the searched region.
    n_valid, n_invalid, valid : Array
        Offsets with a finite score, with ``inf`` or NaN (zero weight); any valid.
    """

    mean_north_m: jax.Array
    mean_east_m: jax.Array
    covariance_m2: jax.Array
    best_index: jax.Array
    best_score: jax.Array
    chi2_per_dof: jax.Array
    n_effective: jax.Array
    second_mode_ratio: jax.Array
    curvature_covariance_m2: jax.Array
    curvature_ok: jax.Array
    log_evidence: jax.Array
    edge_mass: jax.Array
    n_valid: jax.Array
    n_invalid: jax.Array
    valid: jax.Array


def _nearest(dist2, k):
    """Indices ``(k,)`` of the ``k`` least ``dist2``, ascending: the ranking of
    :func:`~jaxgrav.match.scoring.k_smallest` (float32 values, ties to the lower index,
    ``inf`` last) by ``lax.top_k``."""
    v = dist2.astype(jnp.float32)
    return jax.lax.top_k(-jnp.where(v == 0.0, 0.0, v), k)[1]


def curvature_covariance(j, d, ok, best):
    """Laplace covariance ``2 H⁻¹`` (m²) from a quadratic fit of the score near the best offset.

    Parameters
    ----------
    j : Array, shape ``(M,)``
        χ² scores, ``inf`` where invalid.
    d : Array, shape ``(M, 2)``
        Offsets about the best one (m; north, east).
    ok : Array of bool, shape ``(M,)``
        Valid offsets.
    best : Array of int
        Index of the least score.

    Returns
    -------
    cov : Array, shape ``(2, 2)``
        ``2 H⁻¹`` (m²) of ``J ≈ q₀ + q₁x + q₂y + q₃x² + q₄xy + q₅y²`` fitted by least
        squares at the 9 valid offsets nearest the best (x, y scaled by the farthest of
        them); ``inf`` diagonal when the fit is undetermined (fewer than 6 offsets, a
        singular system) or ``H`` is not positive definite.
    fine : Array of bool
        The fit was determined and ``H`` positive definite.
    """
    k = min(9, j.shape[0])
    dist2 = jnp.where(ok, jnp.sum(d * d, axis=-1), jnp.inf)
    near = jnp.stack([d[:, 0], d[:, 1], j, dist2, ok.astype(j.dtype)], axis=-1)[
        _nearest(dist2, k)]  # (k, 5): one gather
    used = near[:, 4] > 0
    s = jnp.sqrt(jnp.max(jnp.where(used, near[:, 3], 0.0))) + 1e-30
    x, y = near[:, 0] / s, near[:, 1] / s
    rows = jnp.stack([jnp.ones_like(x), x, y, x * x, x * y, y * y, near[:, 2] - j[best]],
                     axis=-1)
    rows = jnp.where(used[:, None], rows, 0.0)  # (k, 7): the design and the right side
    normal = rows[:, :6].T @ rows  # (6, 7): [AᵀA | Aᵀr] in one product
    q = solve_spd(normal[:, :6], normal[:, 6])
    hxx, hxy, hyy = 2 * q[3] / s**2, q[4] / s**2, 2 * q[5] / s**2  # H (1/m²)
    det = hxx * hyy - hxy**2
    fine = (jnp.sum(used) >= 6) & jnp.all(jnp.isfinite(q)) & (hxx > 0) & (det > 0)
    cov = 2.0 * jnp.stack([jnp.stack([hyy, -hxy]), jnp.stack([-hxy, hxx])]) / jnp.where(
        fine, det, 1.0)
    return jnp.where(fine, cov, jnp.diag(jnp.array([jnp.inf, jnp.inf], cov.dtype))), fine


def offset_posterior(scores, offsets_north_m, offsets_east_m, cell_m=0.0, *, dof=1,
                     exclusion_m=0.0, exclusion_chi2=9.0, edge=None):
    """Posterior of the offset over a lattice, weights ``∝ exp(−score/2)``.

    Parameters
    ----------
    scores : Array, shape ``(C,)`` (or any shape, flattened)
        χ² scores of the offsets (:func:`~jaxgrav.match.gls.gls_score`; a white-noise
        :func:`~jaxgrav.match.scoring.score_track` divided by ``σ_n² Σμ²``). ``inf``
        or NaN marks an invalid offset (zero weight, counted).
    offsets_north_m, offsets_east_m : Array, shape of ``scores``
        The offsets (m).
    cell_m : float or Array, scalar or ``(2,)``
        Lattice spacing (m; north, east): adds ``cell²/12`` per axis (0: none).
    dof : int or Array
        Degrees of freedom of a score (:func:`~jaxgrav.match.gls.gls_dof`), for
        ``chi2_per_dof``.
    exclusion_m : float or Array
        Radius (m) of the mode's neighbourhood for ``second_mode_ratio``; 0 (default):
        the neighbourhood is ``dᵀ K⁻¹ d ≤ exclusion_chi2`` about the best offset, K the
        curvature covariance (or, when its fit fails, the posterior covariance).
    exclusion_chi2 : float or Array
        Squared Mahalanobis radius of the default neighbourhood (9: 3 σ).
    edge : Array of bool, shape of ``scores``, optional
        The offsets whose mass is ``edge_mass`` (e.g. a disc's outer ring); None
        (default): the lattice's outermost rows and columns.

    Returns
    -------
    OffsetPosterior
        Of one track; ``jax.vmap`` it over tracks.
    """
    j = jnp.asarray(scores).reshape(-1)
    dtype = jnp.result_type(j.dtype, float)
    j = j.astype(dtype)
    d0 = jnp.stack([jnp.asarray(offsets_north_m, dtype).reshape(-1),
                    jnp.asarray(offsets_east_m, dtype).reshape(-1)], axis=-1)
    if edge is None:  # the outermost rows and columns: least and greatest in one reduction
        least = jnp.min(jnp.concatenate([d0, -d0], axis=-1), axis=0)
        edge = jnp.any((d0 == least[:2]) | (d0 == -least[2:]), axis=-1)
    edge = jnp.asarray(edge, bool).reshape(-1)
    ok = jnp.isfinite(j)
    j = jnp.where(ok, j, jnp.inf)
    best = jnp.argmin(j)
    j_best = jnp.where(ok[best], j[best], 0.0)
    d = d0 - d0[best]  # about the best offset: accurate in float32
    w = jnp.where(ok, jnp.exp(-0.5 * (jnp.where(ok, j, j_best) - j_best)), 0.0)
    # every sum over the offsets in one reduction: count, Σw, Σw², edge's Σw, Σw d
    sums = jnp.sum(jnp.stack([ok.astype(dtype), w, w * w, jnp.where(edge, w, 0.0),
                              w * d[:, 0], w * d[:, 1]], axis=-1), axis=0)
    n_valid = sums[0].astype(int)
    valid = n_valid > 0
    z = jnp.where(valid, sums[1], 1.0)
    mean = sums[4:] / z
    e = d - mean
    cov = (w[:, None] * e).T @ e / z
    cov = cov + jnp.diag(jnp.broadcast_to(jnp.asarray(cell_m, dtype) ** 2 / 12.0, (2,)))
    curv, curv_ok = curvature_covariance(j, d, ok, best)
    metric = jnp.where(curv_ok, curv, cov)
    det = metric[0, 0] * metric[1, 1] - metric[0, 1] ** 2
    maha = (metric[1, 1] * d[:, 0] ** 2 - 2 * metric[0, 1] * d[:, 0] * d[:, 1]
            + metric[0, 0] * d[:, 1] ** 2) / jnp.where(det > 0, det, 1.0)
    radius = jnp.asarray(exclusion_m, dtype)
    dist2 = jnp.sum(d * d, axis=-1)
    outside = jnp.where(radius > 0, dist2 > radius**2,
                        jnp.where(det > 0, maha > exclusion_chi2, dist2 > 0))
    j2 = jnp.min(jnp.where(ok & outside, j, jnp.inf))
    mean = mean + d0[best]
    return OffsetPosterior(
        mean_north_m=jnp.where(valid, mean[0], 0.0),
        mean_east_m=jnp.where(valid, mean[1], 0.0),
        covariance_m2=jnp.where(valid, cov, curv),  # curv has an inf diagonal then
        best_index=best,
        best_score=jnp.where(valid, j_best, jnp.inf),
        chi2_per_dof=jnp.where(valid, j_best, jnp.inf) / jnp.asarray(dof, dtype),
        n_effective=jnp.where(valid, z * z / sums[2], 0.0),
        second_mode_ratio=jnp.where(valid, jnp.exp(-0.5 * (j2 - j_best)), 1.0),
        curvature_covariance_m2=curv,
        curvature_ok=curv_ok & valid,
        log_evidence=jnp.where(valid, jnp.log(z) - 0.5 * j_best, -jnp.inf),
        edge_mass=sums[3] / z,
        n_valid=n_valid,
        n_invalid=j.shape[0] - n_valid,
        valid=valid,
    )
