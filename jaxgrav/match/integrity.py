"""How good a dense-offset fix is: its covariance, test statistics and integrity decision.

The dense matcher scores every offset of a lattice; the scores (χ² units) define the
likelihood-weighted posterior of the offset (:func:`~jaxgrav.match.gls.offset_posterior`).
:func:`fix_quality` turns it into the fix's 2 × 2 covariance (the posterior's, with
the cell quantisation term, or, when the posterior is narrower than the lattice, the
Laplace covariance of the Gauss–Newton refinement), the test statistics, and the
integrity decision of :class:`~jaxgrav.match.dense.DenseConfig`'s thresholds with
the status bits of :data:`~jaxgrav.match.result.STATUS` (512, 1024, 2048, 4096,
131072).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import ndtr

from jaxgrav._linalg import inv_2x2
from jaxgrav.match.gls import offset_posterior

__all__ = ["FixQuality", "fix_quality", "largest_sigma", "p_worse_than_ins", "region_mask",
           "region_sigma", "region_spread"]


class FixQuality(NamedTuple):
    """Posterior of the offset and the integrity decision of one track.

    Attributes
    ----------
    mean_north_m, mean_east_m : Array
        Posterior mean offset (m), or the refined best offset when unresolved.
    covariance_m2 : Array, shape ``(2, 2)``
        Covariance of the offset (m², north/east).
    resolved : Array of bool
        The posterior spreads over at least ``resolved_n_effective`` offsets.
    n_effective, second_mode_ratio, edge_mass, chi2_per_dof : Array
        Test statistics (:class:`~jaxgrav.match.gls.OffsetPosterior`; ``chi2_per_dof``
        of the refined best track).
    accepted : Array of bool
    status : Array of int
        Integrity bits of a rejected fix (0 when accepted).
    """

    mean_north_m: jax.Array
    mean_east_m: jax.Array
    covariance_m2: jax.Array
    resolved: jax.Array
    n_effective: jax.Array
    second_mode_ratio: jax.Array
    edge_mass: jax.Array
    chi2_per_dof: jax.Array
    accepted: jax.Array
    status: jax.Array


def largest_sigma(cov):
    """Square root of the larger eigenvalue of 2 × 2 covariances ``(..., 2, 2)`` (m)."""
    a, b, d = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    return jnp.sqrt(0.5 * (a + d) + jnp.sqrt(0.25 * (a - d) ** 2 + b * b))


def p_worse_than_ins(offset_m, covariance_m2):
    """Probability that the truth lies nearer the INS track than the fix does.

    The truth ``x`` (the offset from the INS track, m) distributed ``N(m, C)`` about
    the fix ``m``: the fix is worse than the INS track where ``|x − m| > |x|``, the
    half-plane ``x·m < |m|²/2`` on the INS side of the bisector, whose probability is
    ``Φ(−|m|² / (2 √(mᵀ C m)))``: 0.5 for a fix on the INS track, small for a fix
    many of its σ away from it (along the line joining them).

    Parameters
    ----------
    offset_m : Array, shape ``(..., 2)``
        The fix's mean offset from the INS track (m; north, east).
    covariance_m2 : Array, shape ``(..., 2, 2)``
        Its covariance (m²).

    Returns
    -------
    Array, shape ``(...)``
        In ``[0, 0.5]``; 0.5 for a zero offset, NaN for a non-finite covariance.
    """
    m = jnp.asarray(offset_m)
    c = jnp.asarray(covariance_m2)
    mm = jnp.sum(m * m, axis=-1)
    mcm = jnp.einsum("...i,...ij,...j->...", m, c, m)
    z = jnp.where(mm > 0, 0.5 * mm / jnp.sqrt(jnp.where(mm > 0, mcm, 1.0)), 0.0)
    return ndtr(-z)


def region_mask(half_size, region):
    """The searched offsets of a ``(2·half_size + 1)²`` lattice and its outermost ring.

    Parameters
    ----------
    half_size : int
        Offsets per side of the centre (static).
    region : {"square", "disc"}
        :attr:`~jaxgrav.match.dense.DenseConfig.region`: every offset, or those with
        ``i² + j² ≤ half_size²`` (lattice indices i, j; exact in any float precision).

    Returns
    -------
    inside, ring : numpy.ndarray of bool, shape ``((2·half_size + 1)²,)``
        North-major like the dense matcher's offsets. ``ring``: the searched offsets
        on the region's edge (the outermost rows and columns, or ``i² + j² >
        (half_size − 1)²`` within the disc).
    """
    i = np.arange(-half_size, half_size + 1)
    r2 = i[:, None] ** 2 + i[None, :] ** 2
    if region == "disc":
        inside = r2 <= half_size**2
        ring = inside & (r2 > (half_size - 1) ** 2)
    else:
        inside = np.ones_like(r2, bool)
        ring = (np.abs(i)[:, None] == half_size) | (np.abs(i)[None, :] == half_size)
    return inside.reshape(-1), ring.reshape(-1)


def region_sigma(d_n, d_e, cell_m, inside):
    """1-σ per axis (m) of a uniform prior over the searched offsets.

    The posterior's covariance when the readings carry no information: the second
    moment of the offsets in ``inside`` about the INS track (isotropic for a square
    or a disc) plus the cell's ``cell_m²/12``.

    Parameters
    ----------
    d_n, d_e : Array, shape ``(A²,)``
        The lattice of offsets (m), centred on the INS track.
    cell_m : float or Array
        Lattice spacing (m).
    inside : Array of bool, shape ``(A²,)``
        The prior's support: the searched offsets (:func:`region_mask`) that could
        be scored (a missing map node or the map's edge takes offsets away).

    Returns
    -------
    Array
        Scalar (m); NaN when ``inside`` is empty.
    """
    d_n, d_e = jnp.asarray(d_n), jnp.asarray(d_e)
    r2 = d_n**2 + d_e**2
    second = 0.5 * jnp.sum(jnp.where(inside, r2, 0.0)) / jnp.sum(inside)
    return jnp.sqrt(second + jnp.asarray(cell_m, r2.dtype) ** 2 / 12.0)


def region_spread(config):
    """1-σ per axis (m) of a uniform prior over a dense configuration's searched region.

    :func:`region_sigma` over all of :func:`region_mask`'s offsets (the matcher itself
    also leaves out offsets that could not be scored).

    Parameters
    ----------
    config : DenseConfig
        ``half_size``, ``spacing_m`` and ``region``.

    Returns
    -------
    Array
        Scalar (m).
    """
    h = config.half_size
    d = jnp.arange(-h, h + 1) * jnp.asarray(config.spacing_m)
    on, oe = (a.reshape(-1) for a in jnp.meshgrid(d, d, indexing="ij"))
    return region_sigma(on, oe, config.spacing_m, region_mask(h, config.region)[0])


def fix_quality(chi2, n_rot, d_n, d_e, best_ne, laplace_m2, final_chi2, dof, found, config):
    """Covariance, statistics and integrity decision of one dense match.

    Parameters
    ----------
    chi2 : Array, shape ``(R·A²,)``
        Scores of every candidate in χ² units, rotation-major (inf: invalid).
    n_rot : int
        R, heading errors tried (static); the posterior is marginalised over them
        first (``−2 logsumexp(−J/2)``).
    d_n, d_e : Array, shape ``(A²,)``
        The offsets (m).
    best_ne : Array, shape ``(2,)``
        Refined best offset (m): the fix when the posterior is unresolved.
    laplace_m2 : Array, shape ``(2, 2)``
        Gauss–Newton (Laplace) covariance at the refined best (m²).
    final_chi2 : Array
        χ² of the refined best track.
    dof : Array
        Its degrees of freedom (:func:`~jaxgrav.match.gls.gls_dof`).
    found : Array of bool
        Whether any candidate was valid.
    config : DenseConfig
        ``spacing_m``, ``half_size``, ``region``, ``resolved_n_effective``, the thresholds
        ``max_sigma_m``, ``max_sigma_ratio``, ``max_second_mode``, ``max_chi2_per_dof``,
        ``max_edge_mass``, ``max_p_worse`` (:func:`p_worse_than_ins` of the fix, 131072),
        and ``offset_prior_m2``: with it (a 2 × 2 covariance) the posterior is the
        likelihood times a Gaussian prior of that covariance about the searched track
        (an unresolved one: the Laplace Gaussian times the prior).

    Returns
    -------
    FixQuality
    """
    j = chi2.reshape(n_rot, -1)
    j = j[0] if n_rot == 1 else -2.0 * jax.nn.logsumexp(-0.5 * j, axis=0)
    inside, ring = region_mask(config.half_size, config.region)
    prior = getattr(config, "offset_prior_m2", None)
    if prior is not None:
        s_inv = inv_2x2(jnp.asarray(prior, j.dtype))
        j = j + s_inv[0, 0] * d_n**2 + 2.0 * s_inv[0, 1] * d_n * d_e + s_inv[1, 1] * d_e**2
    post = offset_posterior(j, d_n, d_e, config.spacing_m, dof=dof, edge=ring)
    prior_sigma = region_sigma(d_n, d_e, config.spacing_m, inside & jnp.isfinite(j))
    resolved = post.n_effective >= config.resolved_n_effective
    lap_ok = jnp.all(jnp.isfinite(laplace_m2)) & (laplace_m2[0, 0] > 0) & (laplace_m2[1, 1] > 0)
    if prior is not None:  # the Laplace Gaussian times the prior
        lap_info = inv_2x2(laplace_m2)
        laplace_m2 = inv_2x2(lap_info + s_inv)
        best_ne = jnp.where(lap_ok, laplace_m2 @ (lap_info @ best_ne), best_ne)
    cov = jnp.where(resolved | ~lap_ok, post.covariance_m2, laplace_m2)
    chi2_dof = final_chi2 / dof
    sigma = largest_sigma(cov)
    status = (jnp.where((sigma > config.max_sigma_m)
                        | (sigma > config.max_sigma_ratio * prior_sigma), 512, 0)
              | jnp.where(post.second_mode_ratio > config.max_second_mode, 1024, 0)
              | jnp.where(chi2_dof > config.max_chi2_per_dof, 2048, 0)
              | jnp.where(post.edge_mass > config.max_edge_mass, 4096, 0))
    mean_ne = jnp.where(resolved, jnp.stack([post.mean_north_m, post.mean_east_m]), best_ne)
    status = status | jnp.where(p_worse_than_ins(mean_ne, cov) > config.max_p_worse, 131072, 0)
    status = jnp.where(found, status, 0)
    return FixQuality(
        mean_north_m=mean_ne[0],
        mean_east_m=mean_ne[1],
        covariance_m2=cov,
        resolved=resolved,
        n_effective=post.n_effective,
        second_mode_ratio=post.second_mode_ratio,
        edge_mass=post.edge_mass,
        chi2_per_dof=chi2_dof,
        accepted=found & (status == 0),
        status=status,
    )
