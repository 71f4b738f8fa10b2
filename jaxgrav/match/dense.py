"""Dense-offset correlation matching: every offset shifts the whole track.

The fast path of the correlation matcher. Paper A's constraint that the INS track
stays parallel to the true one is taken literally: a candidate track is the INS
track shifted by one offset of a regular grid of offsets (and, optionally, turned
by one of a few heading errors about its centroid). All candidates are scored in
one tensor operation with the same weighted least-squares scores as the chain path
(:mod:`~jaxgrav.match.scoring`), the map sampled by continuous interpolation at the
shifted fixes (no node quantisation). The best candidates are ranked, one is
selected (least score, or paper A's nearest-to-INS rule among the top k), and its
offset, heading error and bias are then refined below the offset spacing by a few
damped Gauss–Newton steps on the differentiable (bicubic) map; the refined offset is
clamped to the searched region: the square (``±half_size · spacing_m`` per axis) or,
with ``DenseConfig.region="disc"`` (:func:`~jaxgrav.match.sizing.config_for`'s
default), the disc of that radius, whose offsets alone are candidates then.

Work is done in local metres about the track's centroid and in fractional map
indices, which keeps float32 accurate. For one fix the shifted positions form a
regular lattice of map indices, so the map under all candidates is evaluated
separably (:mod:`~jaxgrav.match.offsets`, :mod:`~jaxgrav.lattice`: a few
short reads of spline coefficients and one small matrix product per fix) rather
than point by point; the block of map nodes this reads has a static size
(``DenseConfig.lattice_block``, or a larger one when the offsets span more cells),
and an offset grid coarser than the map falls back to sampling every shifted fix
on its own (same values, slower). The refinement
uses the analytic gradient of the bicubic patch and a closed-form solve of its 4 × 4
normal equations (:mod:`~jaxgrav.match.refine`). The map's spline coefficients may
be prepared once (a :class:`~jaxgrav.prepared.PreparedMap` as ``grid``, or its
:func:`lattice_table`) and passed in, as a hot loop over many calls should;
:func:`~jaxgrav.match.dense_batch.match_dense_batch` matches many tracks in
cache-sized chunks.

With a map error (``DenseConfig.map_error_mgal`` > 0) the candidates are scored by
the GLS likelihood of :mod:`~jaxgrav.match.gls` (one whitener per track, shared by
every shifted and turned candidate); every match reports the covariance of its fix
and an integrity decision (:mod:`~jaxgrav.match.integrity`).
"""


import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import interp
from jaxgrav.constants import DEG
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.lattice import patch_values
from jaxgrav.match.dense_config import DenseConfig
from jaxgrav.match.gaps import gap_score, gap_whitener, gls_gap_score
from jaxgrav.match.gls import gls_dof, gls_score, gls_whitener, track_covariance
from jaxgrav.match.integrity import fix_quality, region_mask
from jaxgrav.match.offsets import means, offset_scores, shifted_tracks, track_frame
from jaxgrav.match.refine import (
    gauss_newton,
    gls_residual_function,
    laplace_covariance,
    residual_function,
)
from jaxgrav.match.result import GAPPED, MatchResult, nearest_to_ins
from jaxgrav.match.scoring import (
    bias_precision,
    decreasing_weights,
    k_smallest,
    score_track,
    sums,
)
from jaxgrav.prepared import as_grid, prepare_map

__all__ = ["DenseConfig", "lattice_table", "match_dense"]


def lattice_table(grid, method="bicubic"):
    """The map as :func:`match_dense` reads it, to compute once per map and pass in.

    Parameters
    ----------
    grid : Grid or PreparedMap
        Anomaly map (mGal); a :class:`~jaxgrav.prepared.PreparedMap` gives its table
        without recomputing the spline.
    method : {"bicubic", "bilinear"}
        ``DenseConfig.method``.

    Returns
    -------
    Array
        ``bicubic``: the not-a-knot spline coefficients
        (:func:`jaxgrav.interp.bicubic_coefficients`) interleaved into one
        ``(2·ny, 2·nx)`` table (:func:`jaxgrav.lattice.interleave`);
        ``bilinear``: the node values ``(ny, nx)``.
    """
    interp.check_method(method)
    if method == "bilinear":
        return jnp.asarray(as_grid(grid).values)
    return prepare_map(grid).interleaved()


@jax.jit
def match_dense(grid, lat, lon, readings, config=DenseConfig(), prepared=None):  # noqa: B008
    """Match one track by scoring every shift of the INS track on an offset grid.

    Parameters
    ----------
    grid : Grid or PreparedMap
        Anomaly map (mGal); sampled continuously, so it need not be refined.
    lat, lon : Array, shape ``(N,)``
        INS-indicated fixes (degrees).
    readings : Array, shape ``(N,)``
        Gravimeter readings (mGal).
    config : DenseConfig
    prepared : Array, optional
        :func:`lattice_table` of ``grid`` for ``config.method``, computed once per map;
        taken from ``grid`` when omitted (computed here unless ``grid`` is a
        :class:`~jaxgrav.prepared.PreparedMap`; under ``vmap`` with the grid shared,
        once per call).

    Returns
    -------
    MatchResult
        ``work_constrained`` is the number of candidate tracks scored,
        ``work_pairs`` the number of map samples taken; ``covariance_m2``,
        ``accepted`` and the test statistics from the offset posterior
        (:func:`~jaxgrav.match.integrity.fix_quality`). A rejected fix is the INS track.
    """
    lat, lon, readings = (jnp.asarray(a) for a in (lat, lon, readings))
    table = lattice_table(grid, config.method) if prepared is None else prepared
    grid = as_grid(grid)
    f = 2 if config.method == "bicubic" else 1
    if table.shape != (f * grid.ny, f * grid.nx):
        raise ValueError(f"prepared must have shape {(f * grid.ny, f * grid.nx)} (lattice_table of "
                         f"the grid for method={config.method!r}); got {table.shape}")
    dtype = jnp.result_type(table.dtype, lat.dtype, float)
    lat, lon, readings = lat.astype(dtype), lon.astype(dtype), readings.astype(dtype)
    n = lat.shape[0]
    h = config.half_size
    d_1d = jnp.arange(-h, h + 1, dtype=dtype) * jnp.asarray(config.spacing_m, dtype)
    on, oe = (a.reshape(-1) for a in jnp.meshgrid(d_1d, d_1d, indexing="ij"))
    if config.n_rotations == 1:
        rot = jnp.zeros((1,), dtype)
    else:
        rot = jnp.linspace(-1.0, 1.0, config.n_rotations, dtype=dtype) * (
            jnp.asarray(config.max_rotation_deg, dtype) * DEG)
    d_n, d_e = jnp.tile(on, config.n_rotations), jnp.tile(oe, config.n_rotations)
    rr = jnp.repeat(rot, on.shape[0])
    w = decreasing_weights(n, config.weight_decay).astype(dtype)
    prior = bias_precision(w, config.noise_mgal, config.bias_sigma_mgal).astype(dtype)
    frame = track_frame(grid, lat, lon)
    scale = jnp.asarray(config.noise_mgal, dtype) ** 2 * jnp.sum(w**2)  # mGal² per unit χ²
    reach = h * config.spacing_m
    inside, _ = region_mask(h, config.region)

    def search(use_gls):
        """Grid search, selection and refinement: white (today's) or GLS score."""
        def run(_):
            gls = None
            if use_gls:
                cov = track_covariance(frame[4], frame[5], config.noise_mgal,
                                       config.map_error_mgal, config.map_error_length_m,
                                       config.map_error_order, weights=w)
                if config.reading_covariance is not None:
                    cov = cov + jnp.asarray(config.reading_covariance, cov.dtype)
                wh = gls_whitener(cov)
                gls = (wh, _gls_bias_sigma(config, dtype), scale, config.reading_coupling)
            scores, biases = offset_scores(table, grid, frame, readings, w, prior, d_1d, d_n,
                                           d_e, rot, config, gls)
            if config.region == "disc":
                scores = jnp.where(np.tile(inside, config.n_rotations), scores, jnp.inf)
            k = min(config.k_best, scores.shape[0])
            top = k_smallest(scores, k)
            topk_lat, topk_lon = shifted_tracks(lat, lon, d_n[top], d_e[top], rr[top])
            distance = (sums([jnp.hypot(*local_offsets_m(topk_lat, topk_lon, lat, lon))], -1)[0]
                        if config.selection == "nearest" else None)  # "best" needs none
            chosen = nearest_to_ins(scores[top], distance, config.selection)
            i = top[chosen]
            found = jnp.isfinite(scores[i])
            p0 = jnp.stack([d_n[i], d_e[i], rr[i], biases[i]])
            free = (True, True, config.n_rotations > 1,
                    config.score == "bias" or (use_gls and config.score != "absolute"))
            step_max = jnp.stack([
                jnp.asarray(config.spacing_m, dtype),
                jnp.asarray(config.spacing_m, dtype),
                jnp.asarray(config.max_rotation_deg, dtype) * DEG / max(config.n_rotations - 1, 1),
                jnp.asarray(jnp.inf, dtype),
            ])
            # survey gaps: the refinement fits the fixes present at the start
            present = (~jnp.isnan(_track_values(table, frame, p0, config.method))
                       if config.gap_fixes else None)
            if use_gls:
                inv, ones = ((wh.inv_chol, wh.ones) if present is None
                             else gap_whitener(wh, present))
                res = gls_residual_function(table, frame, readings, inv, ones, scale,
                                            jnp.maximum(gls[1], 1e-6), config.method, present)
            else:
                res = residual_function(table, frame, readings, w, config.score, prior,
                                        config.method, present)
            p = (gauss_newton(res, p0, free, step_max, config.damping, config.refine_steps)
                 if config.refine_steps else p0)
            # the refinement may not leave the searched region (its steps are capped
            # one by one, not in total: on a coarse map it walked far outside)
            p = p.at[:2].set(_clamp_offset(p[:2], reach, config.region))
            p = jnp.where(found, p, jnp.zeros_like(p))
            # the map along the refined track and the best candidate's, in one evaluation
            v, v0 = jax.vmap(lambda q: _track_values(table, frame, q, config.method))(
                jnp.stack([p, p0]))
            # clipped into a cell with a missing (NaN) corner: back to the best candidate
            ok = jnp.all(jnp.isfinite(v) if present is None else jnp.isfinite(v) | ~present)
            p, v = jnp.where(ok, p, p0), jnp.where(ok, v, v0)
            if use_gls:
                final_score, final_bias = (
                    gls_score(wh, readings - v, gls[1]) if present is None
                    else gls_gap_score(wh, readings - v, gls[1], config.gap_fixes))
                final_score = final_score * scale
                if free[3]:
                    final_bias = p[3]
            else:
                final_score, final_bias = (
                    score_track(readings, v, w, config.score, prior) if present is None
                    else gap_score(readings, v, w, config.score, prior, scale, config.gap_fixes))
                if config.score == "bias":
                    final_bias = p[3]
            laplace = laplace_covariance(res, p, free) * scale
            return (scores, top, topk_lat, topk_lon, chosen, found, p,
                    final_score, final_bias, laplace, jnp.sum(jnp.isnan(v)))

        return run

    if config.score_model == "auto":
        # today's white path runs outside the branch (a branch body compiles to other bits)
        white = search(False)(None)
        searched = jax.lax.cond(jnp.asarray(config.map_error_mgal) > 0, search(True),
                                lambda _: white, None)
    else:
        searched = search(config.score_model == "gls")(None)
    (scores, top, topk_lat, topk_lon, chosen, found, p, final_score, final_bias, laplace,
     n_gap) = searched
    topk_score = scores[top]
    chi2 = scores / jnp.maximum(scale, jnp.finfo(dtype).tiny)
    quality = fix_quality(chi2, config.n_rotations, on, oe, p[:2], laplace,
                          final_score / jnp.maximum(scale, jnp.finfo(dtype).tiny),
                          gls_dof(n, _gls_bias_sigma(config, dtype)), found, config)
    if config.fix == "posterior":
        p = p.at[:2].set(jnp.where(found, jnp.stack([quality.mean_north_m,
                                                     quality.mean_east_m]), 0.0))
    # survey gaps: a fix read mostly off the map is not one (the truth's neighbours, in
    # the gap, tie at their expectation; a fix there is a guess)
    thin = (n_gap > n // 2) if config.gap_fixes else jnp.zeros((), bool)
    accepted = quality.accepted & ~thin
    m_lat, m_lon = shifted_tracks(lat, lon, p[0], p[1], p[2])
    m_lat, m_lon = jnp.where(accepted, m_lat, lat), jnp.where(accepted, m_lon, lon)
    mean_off = means(*local_offsets_m(m_lat, m_lon, lat, lon))
    # on the disc's rim to rounding (a rim node or a clamped offset, in float32 too)
    edge = (jnp.hypot(p[0], p[1]) >= reach * (1 - 64 * jnp.finfo(dtype).eps)
            if config.region == "disc" else (jnp.abs(p[0]) >= reach) | (jnp.abs(p[1]) >= reach))
    n_searched = int(inside.sum()) * config.n_rotations  # offsets of the region, all turns
    n_off = jnp.asarray(n_searched, dtype)
    return MatchResult(
        lat=m_lat,
        lon=m_lon,
        offset_north_m=mean_off[0],
        offset_east_m=mean_off[1],
        rotation_deg=jnp.where(accepted, p[2], 0.0) / DEG,
        score=jnp.where(found, final_score, jnp.inf),
        bias=jnp.where(found, final_bias, 0.0) if config.score != "bias" else final_bias,
        topk_lat=topk_lat,
        topk_lon=topk_lon,
        topk_score=topk_score,
        chosen=chosen,
        n_candidates=jnp.full((n,), n_searched, jnp.int32),
        work_unconstrained=n_off**n,
        work_constrained=n_off,
        work_pairs=n_off * n,
        status=(jnp.where(found, 0, 1) | jnp.where(found & edge, 8, 0) | quality.status
                | jnp.where(found & thin, GAPPED, 0)),
        covariance_m2=quality.covariance_m2,
        accepted=accepted,
        n_effective=quality.n_effective,
        second_mode_ratio=quality.second_mode_ratio,
        edge_mass=quality.edge_mass,
        chi2_per_dof=quality.chi2_per_dof,
    )


def _clamp_offset(ne, reach, region):
    """The offset ``(north, east)`` (m) moved back into the searched square or disc."""
    if region == "disc":
        r = jnp.hypot(ne[0], ne[1])
        return ne * jnp.minimum(1.0, reach / jnp.where(r > 0, r, 1.0))
    return jnp.clip(ne, -reach, reach)


def _track_values(table, frame, p, method):
    """The map along the INS track shifted by ``p = (north, east, rotation, ·)``."""
    iy_c, ix_c, ky, kx, north, east = frame
    c, s = jnp.cos(p[2]), jnp.sin(p[2])
    return patch_values(table, iy_c + ky * (c * north - s * east + p[0]),
                        ix_c + kx * (s * north + c * east + p[1]), method)


def _gls_bias_sigma(config, dtype):
    """σ_b of the GLS score (mGal): 0 for ``absolute``, ``inf`` for ``difference``."""
    if config.score == "absolute":
        return jnp.zeros((), dtype)
    if config.score == "difference":
        return jnp.asarray(jnp.inf, dtype)
    return jnp.asarray(config.bias_sigma_mgal, dtype)
