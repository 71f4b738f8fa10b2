"""The result of a match and the status bits, shared by every matcher."""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from scipy.special import chdtrc

__all__ = ["CORRELATION_STATUS", "GAPPED", "IMPLAUSIBLE_FIT", "P_IMPLAUSIBLE", "STATUS",
           "MatchResult", "fit_p_value", "nearest_to_ins", "status_messages"]

STATUS = {
    1: "no candidate track survived (tolerances too tight, the track off the map, or every "
       "candidate touching missing map cells)",
    2: "candidate capacity overflowed in some window (best-fitting points kept)",
    4: "a search window met the map edge and was shifted inside",
    8: "the best candidate lies on the edge of the search region (drift may exceed it)",
    256: "a step's accepted displacements exceed the chain stencil (pairs outside it not "
         "considered; raise stencil_size)",
    32: "entropy coarse match: no candidate beat the INS track's RMS misfit; INS track kept",
    16: "ICCP did not converge within max_iter iterations",
    64: "ICCP: fewer than 3 contour points inside the window at some iteration (transform kept)",
    128: "entropy+ICCP: the ICCP result did not fit significantly better than the coarse "
         "match; coarse track kept",
    512: ("fix rejected: the posterior of the offset is too wide (max_sigma_m, or "
          "max_sigma_ratio of the searched region's own spread); INS track kept"),
    1024: "fix rejected: a distinct second mode is nearly as likely (max_second_mode); INS "
          "track kept",
    2048: "fix rejected: the best candidate's misfit is inconsistent with the error model "
          "(max_chi2_per_dof); INS track kept",
    4096: "fix rejected: posterior mass at the edge of the search region (max_edge_mass); "
          "INS track kept",
    8192: "the search region holds missing (NaN) map nodes: read as land, candidates "
          "touching them were dropped and the fix is the best of the rest (if the map is "
          "missing survey data there, the truth may lie in the dropped part: dense reads "
          "gaps with missing='gaps', --missing gaps); read as survey gaps (dense, and by "
          "default when the INS track crosses them), each candidate was scored on its "
          "fixes over present cells",
    16384: "the fix fits the readings far worse than the stated noise and map error allow "
           "(chi-squared p < 1e-3): a wrong map, unit, noise or an untold map error; the "
           "fix and its covariance are not trustworthy as stated",
    32768: "fix rejected: more than half of the fix's readings lie over survey gaps of the "
           "map (missing='gaps'); INS track kept",
    65536: "fix rejected: the fix lies farther from the INS track than the drift allows "
           "(max_offset_m, 1.5 x the drift radius); INS track kept",
    131072: "fix rejected: not shown better than the INS track (under the fix's covariance "
            "the truth may well lie nearer the INS track than the fix); INS track kept",
}
"""Bit flags of :attr:`MatchResult.status`, for every method (one table).

``dense`` raises 1 and 8, the integrity bits 512, 1024, 2048, 4096 and 131072 (a
rejected fix: :attr:`MatchResult.accepted` false), and with survey gaps 32768
(rejected too); ``chains`` 1, 2, 4, 8, 256 and the
integrity bits 512, 1024, 2048; ``entropy`` 1, 8 and 32;
``iccp`` 1, 16 and 64; ``entropy+iccp`` those of entropy and ICCP, 128, the
integrity bits 512–4096, 65536 (a fix beyond ``max_offset_m``, rejected) and
131072 (a fix not shown better than the INS track, rejected). Every
method, through :func:`~jaxgrav.match.match_track`:
8192 when the map has missing nodes within the drift radius of the track, and 16384
when the fix's χ² is implausible for the stated error model (:func:`fit_p_value`
below :data:`P_IMPLAUSIBLE`; a warning, not a rejection: ``accepted`` is unchanged).
"""

GAPPED = 32768
"""Status bit: ``dense`` with survey gaps, fix over gaps at most of its fixes (rejected)."""

IMPLAUSIBLE_FIT = 16384
"""Status bit: the fix's misfit is statistically implausible (see :data:`STATUS`)."""

P_IMPLAUSIBLE = 1e-3
"""A fit whose χ² exceeds its (1 − 10⁻³) quantile is flagged (:data:`IMPLAUSIBLE_FIT`)."""

CORRELATION_STATUS = {bit: STATUS[bit] for bit in (1, 2, 4, 8, 256, 512, 1024, 2048, 4096,
                                                   32768, 131072)}
"""The bits of the correlation matchers (``dense``, ``chains``): an excerpt of :data:`STATUS`."""


class MatchResult(NamedTuple):
    """Estimated track and diagnostics of one match.

    Attributes
    ----------
    lat, lon : Array, shape ``(N,)``
        Matched positions (degrees).
    offset_north_m, offset_east_m : Array
        Mean offset of the matched track from the INS track (m).
    rotation_deg : Array
        Rotation of the matched track about the INS track's centroid (degrees;
        zero for the chain path).
    score : Array
        Score of the chosen track (mGal²).
    bias : Array
        Estimated common bias, readings minus map (mGal): Eötvös residual plus
        gravimeter bias.
    topk_lat, topk_lon : Array, shape ``(K, N)``
        The K best candidate tracks, best score first.
    topk_score : Array, shape ``(K,)``
        Their scores (``inf`` where fewer than K candidates exist).
    chosen : Array of int
        Index into the top-K of the returned track.
    n_candidates : Array, shape ``(N,)``
        Iso-points (chain path) or offsets (dense path) per fix.
    work_unconstrained : Array
        ``∏ N_i``: candidate tracks an exhaustive search would score.
    work_constrained : Array
        Complete candidate tracks left after constraint elimination (chain path), or
        tracks scored (dense path).
    work_pairs : Array
        Transitions evaluated by the dynamic programme (chain path) or map samples
        taken (dense path).
    status : Array of int
        Bit flags, see :data:`STATUS`; 0 is a clean match.
    covariance_m2 : Array, shape ``(2, 2)``
        Covariance of the mean-track position error (m², north/east). ``dense``: from
        the likelihood-weighted posterior over the offsets (or the Gauss–Newton
        curvature when the posterior is narrower than the offset grid); ``chains``:
        the GLS-likelihood-weighted spread of the best chains' mean offsets plus the
        Gauss–Newton curvature at the chosen chain (:mod:`~jaxgrav.match.correlation`);
        ``entropy+iccp``: the GLS posterior over the entropy offsets and the
        Gauss–Newton curvature at the fix (:mod:`~jaxgrav.match.combined`); ``entropy``
        and ``iccp`` alone: NaN (not estimated).
    accepted : Array of bool
        Integrity decision; a rejected fix returns the INS track (status bits 512–4096).
        True for the matchers without a test (``entropy``, ``iccp`` alone).
    n_effective : Array
        ``dense``, ``entropy+iccp``: offsets sharing the posterior mass (``1/Σp²``);
        ``chains``: chains sharing it; NaN otherwise.
    second_mode_ratio : Array
        ``dense``, ``entropy+iccp``: likelihood ratio of the best offset outside the
        mode to the best; ``chains``: of the best chain outside it.
    edge_mass : Array
        ``dense``, ``entropy+iccp``: posterior mass on the outermost offsets.
    chi2_per_dof : Array
        ``dense``, ``chains``, ``entropy+iccp``: GLS score of the fix over its degrees
        of freedom (χ², about 1 when the error model is right; ``entropy+iccp``: per
        fix).
    """

    lat: jax.Array
    lon: jax.Array
    offset_north_m: jax.Array
    offset_east_m: jax.Array
    rotation_deg: jax.Array
    score: jax.Array
    bias: jax.Array
    topk_lat: jax.Array
    topk_lon: jax.Array
    topk_score: jax.Array
    chosen: jax.Array
    n_candidates: jax.Array
    work_unconstrained: jax.Array
    work_constrained: jax.Array
    work_pairs: jax.Array
    status: jax.Array
    covariance_m2: jax.Array = np.full((2, 2), np.nan, np.float32)
    accepted: jax.Array = np.bool_(True)
    n_effective: jax.Array = np.float32(np.nan)
    second_mode_ratio: jax.Array = np.float32(np.nan)
    edge_mass: jax.Array = np.float32(np.nan)
    chi2_per_dof: jax.Array = np.float32(np.nan)


def nearest_to_ins(topk_score, distance, selection):
    """Paper A step 6: among the K best tracks pick the one nearest the INS track.

    Parameters
    ----------
    topk_score : Array, shape ``(K,)``
        Scores, ascending; ``inf`` marks missing tracks.
    distance : Array, shape ``(K,)``
        ``Σ_i ‖T_i − S_i‖`` between each track and the INS track (m).
    selection : {"nearest", "best"}
        ``"nearest"`` is the paper's rule; ``"best"`` takes the least score.

    Returns
    -------
    Array of int
        Index into the K tracks.
    """
    if selection == "best":
        return jnp.asarray(0)
    if selection != "nearest":
        raise ValueError(f"selection must be 'nearest' or 'best'; got {selection!r}")
    return jnp.argmin(jnp.where(jnp.isfinite(topk_score), distance, jnp.inf))


def status_messages(status):
    """Messages of the bits set in a status bit field (any method), in :data:`STATUS` order.

    Parameters
    ----------
    status : int
        :attr:`MatchResult.status` (a Python int or a scalar array).

    Returns
    -------
    list of str
    """
    return [msg for bit, msg in STATUS.items() if int(status) & bit]


def fit_p_value(chi2_per_dof, dof):
    """Probability of a misfit at least this large if the error model is right.

    Parameters
    ----------
    chi2_per_dof : float
        The fix's χ² over its degrees of freedom (:attr:`MatchResult.chi2_per_dof`).
    dof : int
        Its degrees of freedom (``N − 3`` for ``N`` fixes: a bias and two offsets).

    Returns
    -------
    float
        ``P(χ²(dof) ≥ dof · chi2_per_dof)``; NaN when ``chi2_per_dof`` is not finite
        (a matcher without a χ²) or ``dof < 1``.
    """
    c = float(chi2_per_dof)
    if not (math.isfinite(c) and dof >= 1):
        return float("nan")
    return float(chdtrc(dof, c * dof))
