"""Entropy coarse match, then ICCP fine match: :func:`match_entropy_iccp`.

Both stages run on one prepared map. ICCP starts from each of the coarse stage's
best offsets and from the INS track; the fine result of least misfit replaces the
coarse one only if it fits *significantly* better (a likelihood-ratio test against
the reading noise, see :class:`~jaxgrav.match.iccp.IccpConfig`), otherwise status
bit 128 is raised and the coarse track is kept. Where the data cannot tell the two
apart, the combined match therefore does not move away from the coarse one.

Every match reports the covariance of its fix and an integrity decision. The entropy
score (a difference of sequence entropies) is no likelihood, so GLS does not apply to
it; the quality comes from what does: the GLS likelihood (:mod:`~jaxgrav.match.gls`,
covariance ``σ_n² I + C_map`` along the track, ``σ_n = iccp.noise``, no bias unless
``iccp.bias_sigma`` > 0, then marginalised) of every
offset of the entropy stage's grid gives a posterior over the offsets
(:func:`~jaxgrav.match.gls.offset_posterior`), and the Gauss–Newton curvature of the
whitened misfit at the returned transform (rotation marginalised) gives the local
covariance, scaled by the whitened misfit per degree of freedom when above 1. The
covariance of an ICCP (fine) fix is that Gauss–Newton one; of a coarse fix, the
posterior's spread about the fix (plus the offset cell's quantisation) when the grid
resolves the posterior, else that spread plus the Gauss–Newton covariance. With a map
error (``iccp.map_error_mgal`` > 0) the same GLS score also picks the best ICCP start
and makes the fine-vs-coarse test; ``iccp.fix="posterior"`` takes the posterior mean
over the offsets as the coarse fix (and as one more ICCP start).

Integrity (a rejected fix keeps the INS track): the thresholds of
:func:`~jaxgrav.match.fix_covariance.integrity_status` (512–4096), the dense matcher's
informativeness test (``iccp.max_sigma_ratio`` × the 1-σ of a uniform prior over the
searched offsets, :func:`~jaxgrav.match.integrity.region_sigma`, over the square grid or
``iccp.region="disc"``; 512), the distance from the INS track (``max_offset_m``, 65536)
and the no-harm test (``iccp.max_p_worse``, :func:`p_worse_than_ins`, 131072).
"""

import jax
import jax.numpy as jnp

from jaxgrav.constants import DEG
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match.contour import value_grad
from jaxgrav.match.entropy import EntropyConfig, coarse_stage, offset_grid
from jaxgrav.match.fix_covariance import (
    gauss_newton_information,
    integrity_status,
    offset_covariance,
    spread_about,
)
from jaxgrav.match.gls import (
    gls_dof,
    gls_score,
    gls_whitener,
    offset_posterior,
    track_covariance,
)
from jaxgrav.match.iccp import IccpConfig, iccp_fit, local_track_frame
from jaxgrav.match.integrity import (
    largest_sigma,
    p_worse_than_ins,
    region_mask,
    region_sigma,
)
from jaxgrav.match.offsets import shifted_tracks
from jaxgrav.match.result import STATUS, MatchResult
from jaxgrav.prepared import prepare_map

__all__ = ["COMBINED_STATUS", "FAR_FIX", "NOT_BETTER", "match_entropy_iccp", "p_worse_than_ins"]

FAR_FIX = 65536
"""Status bit: the fix lies beyond ``IccpConfig.max_offset_m`` from the INS track."""

NOT_BETTER = 131072
"""Status bit: the fix is not shown better than the INS track (``IccpConfig.max_p_worse``)."""

COMBINED_STATUS = {bit: STATUS[bit] for bit in (128, FAR_FIX, NOT_BETTER)}
"""The status bits raised by the combined matcher only (an excerpt of
:data:`~jaxgrav.match.result.STATUS`); it also raises the entropy and ICCP bits."""

_DEFAULT_ENTROPY = EntropyConfig()
_DEFAULT_ICCP = IccpConfig()


@jax.jit
def match_entropy_iccp(grid, lat, lon, readings, entropy=_DEFAULT_ENTROPY, iccp=_DEFAULT_ICCP):
    """Entropy coarse match followed by ICCP fine match, for one track (jitted).

    ICCP is started from each of the coarse stage's ``entropy.k_best`` best offsets and
    from the INS track itself (the search is cheap next to a wrong start); of these
    fine results the one with the least misfit is taken. It replaces the coarse track
    only if it fits significantly better, ``N·(m_coarse − m_fine)/σ² ≥
    iccp.accept_chi2`` with ``σ = iccp.noise`` (a likelihood-ratio test: the coarse
    offset lies outside the fine transform's confidence region); otherwise the coarse
    track is kept and status bit 128 raised.

    Parameters
    ----------
    grid : Grid or PreparedMap
        Map (nT or mGal); prepared here once for both stages unless already.
    lat, lon : Array, shape ``(N,)``
        INS-indicated fixes (degrees).
    readings : Array, shape ``(N,)``
        Measured values (map units); bias-free unless ``iccp.bias_sigma`` > 0.
    entropy : EntropyConfig
    iccp : IccpConfig
        ``window_m`` should cover the coarse stage's error (a few offset spacings
        to a map cell), not the whole INS drift.

    Returns
    -------
    MatchResult
        ``score`` is the mean squared misfit (map units²); ``topk_*`` hold the coarse
        and the fine track (in that order), ``chosen`` which one was returned;
        ``covariance_m2``, ``accepted`` (a rejected fix is the INS track) and the test
        statistics as the module docstring says, ``chi2_per_dof`` the fix's GLS
        score per fix.
    """
    lat, lon, readings = (jnp.asarray(x) for x in (lat, lon, readings))
    n = readings.shape[0]
    pm = prepare_map(grid)
    coarse, d_n, d_e, top_n, top_e, vals, index = coarse_stage(
        pm.sampler(entropy.method), lat, lon, readings, entropy)
    p0, field = local_track_frame(pm.patches(), pm.grid, lat, lon)
    dtype = p0.dtype
    z = readings.astype(dtype)
    zero = jnp.zeros((), dtype)
    told = jnp.asarray(iccp.map_error_mgal) > 0
    noise = jnp.asarray(iccp.noise, dtype)
    wh = gls_whitener(track_covariance(p0[:, 0], p0[:, 1], jnp.where(noise > 0, noise, 1.0),
                                       iccp.map_error_mgal, iccp.map_error_length_m,
                                       iccp.map_error_order))
    sb = jnp.asarray(iccp.bias_sigma, dtype)  # 0: bias-free readings (as ICCP assumes)
    gls_b = lambda f: gls_score(wh, z - f, sb)  # noqa: E731  (score, bias)
    g_n, g_e = offset_grid(entropy, dtype)
    # the GLS scores along the grid's offsets from the map the coarse stage read there
    # (bicubic; else the bicubic map is read along them)
    if entropy.method != "bicubic":
        vals, _ = value_grad(field, p0 + jnp.stack([g_n, g_e], -1)[:, None, :])
    j_grid, b_grid = gls_b(vals.astype(dtype))
    dof = gls_dof(n, sb)  # n, or n − 1 when a free bias takes one
    # the posterior's support: the square grid, or its disc (static); outside: no weight
    inside, ring = region_mask(entropy.half_size, iccp.region)
    j_grid = jnp.where(inside, j_grid, jnp.inf)
    post = offset_posterior(j_grid, g_n, g_e, entropy.spacing_m, dof=dof, edge=ring)
    if iccp.fix == "posterior":
        d_n = jnp.where(post.valid, post.mean_north_m, d_n).astype(d_n.dtype)
        d_e = jnp.where(post.valid, post.mean_east_m, d_e).astype(d_e.dtype)
    starts = _starts(top_n, top_e, d_n, d_e, dtype)  # the last start is the coarse fix
    if iccp.fix == "posterior":  # the fix is off the grid: its GLS bias read there
        b_s = gls_b(value_grad(field, p0 + starts[:, None, :])[0])[1]
    else:  # every start is an offset of the grid
        b_s = b_grid[index]
    # each start fits the readings less the GLS bias there (none when bias_sigma = 0)
    b_starts = jnp.where(jnp.isfinite(b_s), b_s, 0.0)
    fits = jax.vmap(lambda t0, b: iccp_fit(field, p0, z - b, iccp, t0=t0))(starts, b_starts)
    # the map and the GLS scores along the fits and the coarse fix, in one evaluation
    f_s, g_s = value_grad(field, jnp.concatenate(
        [_moved(p0, fits.rotation, fits.translation), (p0 + starts[-1])[None]]))
    j_s, b_s = gls_b(f_s)
    g_fits, j_fits = g_s[:-1], j_s[:-1]
    # the coarse fix's misfit and, with a bias, each fit's misfit at its own GLS bias
    m_s = jnp.mean((z - b_s[:, None] - f_s) ** 2, -1)
    fits = fits._replace(misfit=jnp.where(sb > 0, m_s[:-1], fits.misfit))
    misfits = jnp.where(jnp.isfinite(fits.misfit), fits.misfit, jnp.inf)
    best = jnp.argmin(jnp.where(told, jnp.where(jnp.isfinite(j_fits), j_fits, jnp.inf),
                                misfits))
    st = jax.tree.map(lambda x: x[best], fits)
    j_coarse, b_coarse, coarse_misfit = j_s[-1], b_s[-1], m_s[-1]
    gain = n * (coarse_misfit - st.misfit)
    use_fine = jnp.isfinite(st.misfit) & jnp.where(
        told, ~(j_coarse - j_fits[best] < iccp.accept_chi2),
        ~(gain < iccp.accept_chi2 * iccp.noise**2))
    rot = jnp.arctan2(st.rotation[1, 0], st.rotation[0, 0])
    if iccp.fix == "posterior":
        coarse_lat, coarse_lon = shifted_tracks(lat, lon, d_n, d_e, zero)
        c_n, c_e = jnp.mean(jnp.stack(local_offsets_m(coarse_lat, coarse_lon, lat, lon)), -1)
        coarse = coarse._replace(lat=coarse_lat, lon=coarse_lon, offset_north_m=c_n,
                                 offset_east_m=c_e)
    f_lat, f_lon = shifted_tracks(lat, lon, st.translation[0], st.translation[1], rot)
    # the fine fix's mean offset (one sum of both: see rigid.kabsch_moments)
    f_n, f_e = jnp.mean(jnp.stack(local_offsets_m(f_lat, f_lon, lat, lon)), -1)
    pick = lambda a, b: jnp.where(use_fine, a, b)  # noqa: E731
    found = jnp.isfinite(st.misfit) | jnp.isfinite(coarse_misfit)
    t_fix = pick(st.translation, jnp.stack([d_n, d_e]).astype(dtype))
    j_fix = pick(j_fits[best], j_coarse)
    cov, chi2 = _fix_covariance(pick(g_fits[best], g_s[-1]), p0, wh,
                                pick(st.rotation, jnp.eye(2, dtype=dtype)), t_fix, j_fix,
                                use_fine, post, j_grid, g_n, g_e, entropy, iccp, dof - n)
    reject = integrity_status(cov, post.second_mode_ratio, chi2, post.edge_mass, iccp)
    # the informativeness test (the dense matcher's): the readings must narrow the search
    prior_sigma = region_sigma(g_n, g_e, entropy.spacing_m, jnp.isfinite(j_grid))
    reject = reject | jnp.where(largest_sigma(cov) > iccp.max_sigma_ratio * prior_sigma,
                                512, 0).astype(reject.dtype)
    # ICCP can walk a weak or biased fix far past the drift the search was sized for
    # (15 km at a 4.7 km drift radius, accepted): beyond max_offset_m it is rejected
    off_ne = jnp.stack([pick(f_n, coarse.offset_north_m), pick(f_e, coarse.offset_east_m)])
    off = jnp.hypot(off_ne[0], off_ne[1])
    reject = reject | jnp.where(off > iccp.max_offset_m, FAR_FIX, 0).astype(reject.dtype)
    # no harm: a fix the truth may well lie nearer the INS track than is not taken
    reject = reject | jnp.where(p_worse_than_ins(off_ne, cov) > iccp.max_p_worse,
                                NOT_BETTER, 0).astype(reject.dtype)
    accepted = found & (reject == 0)
    keep = lambda a, b: jnp.where(accepted, pick(a, b), jnp.zeros_like(a))  # noqa: E731
    status = (
        (coarse.status & ~1)
        | jnp.where(found, 0, 1)
        | jnp.where(use_fine & ~st.converged, 16, 0)
        | jnp.where(st.starved, 64, 0)
        | jnp.where(use_fine, 0, 128)
        | jnp.where(found, reject, 0)
    ).astype(jnp.int32)
    iters = jnp.sum(fits.n_iter).astype(dtype)
    return MatchResult(
        lat=jnp.where(accepted, pick(f_lat, coarse.lat), lat),
        lon=jnp.where(accepted, pick(f_lon, coarse.lon), lon),
        offset_north_m=keep(f_n, coarse.offset_north_m),
        offset_east_m=keep(f_e, coarse.offset_east_m),
        rotation_deg=keep(rot / DEG, coarse.rotation_deg),
        score=pick(st.misfit, coarse_misfit),
        bias=jnp.where(sb > 0, pick(b_s[best], b_coarse), coarse.bias),
        topk_lat=jnp.stack([coarse.lat, f_lat]),
        topk_lon=jnp.stack([coarse.lon, f_lon]),
        topk_score=jnp.stack([coarse_misfit, st.misfit]),
        chosen=use_fine.astype(jnp.int32),
        n_candidates=jnp.full((n,), st.n_used, jnp.int32),
        work_unconstrained=coarse.work_unconstrained,
        work_constrained=coarse.work_constrained + iters,
        work_pairs=coarse.work_pairs + iters * n * (iccp.newton_steps + 1),
        status=status,
        covariance_m2=cov,
        accepted=accepted,
        n_effective=post.n_effective.astype(dtype),
        second_mode_ratio=post.second_mode_ratio.astype(dtype),
        edge_mass=post.edge_mass.astype(dtype),
        chi2_per_dof=chi2,
    )


def _moved(p0, rotation, translation):
    """Points ``R p0 + t`` ``(..., N, 2)`` for transforms ``(..., 2, 2)``, ``(..., 2)``."""
    return jnp.einsum("...ij,nj->...ni", rotation, p0) + translation[..., None, :]


def _starts(top_n, top_e, d_n, d_e, dtype):
    """ICCP's starts ``(k + 2, 2)`` (m): the coarse stage's best offsets, the INS track and
    the coarse fix ``(d_n, d_e)``, last."""
    zero = jnp.zeros((), top_n.dtype)
    return jnp.stack([jnp.concatenate([top_n, jnp.stack([zero, d_n])]),
                      jnp.concatenate([top_e, jnp.stack([zero, d_e])])], -1).astype(dtype)


def _fix_covariance(g, p0, wh, rotation, translation, j_fix, fine, post, j_grid, g_n,
                    g_e, entropy, iccp, bias_dof=0):
    """2 × 2 covariance (m²) of the fix and its GLS χ² per fix (``bias_dof``: −1 when a
    free bias takes a degree of freedom); ``g`` ``(N, 2)``: the map's gradient along the
    fix's track ``rotation · p0 + translation``."""
    n = p0.shape[0]
    turned = p0 @ rotation.T
    d_theta = jnp.sum(g * jnp.stack([-turned[:, 1], turned[:, 0]], -1), axis=-1)
    info = gauss_newton_information(wh, jnp.concatenate([d_theta[:, None], g], -1),
                                    jnp.asarray(iccp.bias_sigma, g.dtype))
    # a fine fix marginalises the rotation; a coarse one (no rotation) is offset_covariance
    # of info[1:, 1:], which is the Schur complement with the coupling info[0, 1:] zeroed
    couple = jnp.arange(3) > 0
    keep = fine | ~(couple[:, None] ^ couple[None, :])
    gn = offset_covariance(jnp.where(keep, info, 0.0))
    chi2 = j_fix / n
    dof = jnp.where(fine, n - 3, n - 2) + bias_dof
    gn = gn * jnp.maximum(1.0, j_fix / jnp.maximum(dof, 1))
    spread, _, _ = spread_about(j_grid, g_n, g_e, translation[0], translation[1])
    cell = jnp.asarray(entropy.spacing_m, spread.dtype) ** 2 / 12.0
    resolved = post.n_effective >= iccp.resolved_n_effective
    coarse = jnp.where(resolved, spread + cell * jnp.eye(2, dtype=spread.dtype), spread + gn)
    cov = jnp.where(fine, gn, coarse)
    cov = 0.5 * (cov + cov.T)  # exactly symmetric
    return cov.astype(p0.dtype), chi2.astype(p0.dtype)
