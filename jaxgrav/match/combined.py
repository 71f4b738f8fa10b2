"""Entropy coarse match, then ICCP fine match: :func:`match_entropy_iccp`.

Both stages run on one prepared map. ICCP starts from each of the coarse stage's
best offsets and from the INS track; the fine result of least misfit replaces the
coarse one only if it fits *significantly* better (a likelihood-ratio test against
the reading noise, see :class:`~jaxgrav.match.iccp.IccpConfig`), otherwise status
bit 128 is raised and the coarse track is kept. Where the data cannot tell the two
apart, the combined match therefore does not move away from the coarse one.
"""

import jax
import jax.numpy as jnp

from jaxgrav.constants import DEG
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match.contour import value_grad
from jaxgrav.match.dense import shifted_tracks
from jaxgrav.match.entropy import EntropyConfig, coarse_offsets
from jaxgrav.match.iccp import IccpConfig, iccp_fit, local_track_frame
from jaxgrav.match.result import STATUS, MatchResult
from jaxgrav.prepared import prepare_map

__all__ = ["COMBINED_STATUS", "match_entropy_iccp"]

COMBINED_STATUS = {bit: STATUS[bit] for bit in (128,)}
"""The status bit raised by the combined matcher only (an excerpt of
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
        Measured values (map units), bias-free.
    entropy : EntropyConfig
    iccp : IccpConfig
        ``window_m`` should cover the coarse stage's error (a few offset spacings
        to a map cell), not the whole INS drift.

    Returns
    -------
    MatchResult
        ``score`` is the mean squared misfit (map units²); ``topk_*`` hold the coarse
        and the fine track (in that order), ``chosen`` which one was returned.
    """
    lat, lon, readings = (jnp.asarray(x) for x in (lat, lon, readings))
    n = readings.shape[0]
    pm = prepare_map(grid)
    coarse, d_n, d_e, top_n, top_e = coarse_offsets(pm.sampler(entropy.method), lat, lon,
                                                    readings, entropy)
    p0, field = local_track_frame(pm.patches(), pm.grid, lat, lon)
    dtype = p0.dtype
    z = readings.astype(dtype)
    starts = jnp.stack([jnp.append(top_n, 0.0), jnp.append(top_e, 0.0)], -1).astype(dtype)
    fits = jax.vmap(lambda t0: iccp_fit(field, p0, z, iccp, t0=t0))(starts)
    misfits = jnp.where(jnp.isfinite(fits.misfit), fits.misfit, jnp.inf)
    best = jnp.argmin(misfits)
    st = jax.tree.map(lambda x: x[best], fits)
    f_c, _ = value_grad(field, p0 + jnp.stack([d_n, d_e]).astype(dtype))
    coarse_misfit = jnp.mean((z - f_c) ** 2)
    gain = n * (coarse_misfit - st.misfit)
    use_fine = jnp.isfinite(st.misfit) & ~(gain < iccp.accept_chi2 * iccp.noise**2)
    rot = jnp.arctan2(st.rotation[1, 0], st.rotation[0, 0])
    f_lat, f_lon = shifted_tracks(lat, lon, st.translation[0], st.translation[1], rot)
    f_n, f_e = local_offsets_m(f_lat, f_lon, lat, lon)
    pick = lambda a, b: jnp.where(use_fine, a, b)  # noqa: E731
    status = (
        (coarse.status & ~1)
        | jnp.where(jnp.isfinite(st.misfit) | jnp.isfinite(coarse_misfit), 0, 1)
        | jnp.where(use_fine & ~st.converged, 16, 0)
        | jnp.where(st.starved, 64, 0)
        | jnp.where(use_fine, 0, 128)
    ).astype(jnp.int32)
    iters = jnp.sum(fits.n_iter).astype(dtype)
    return MatchResult(
        lat=pick(f_lat, coarse.lat),
        lon=pick(f_lon, coarse.lon),
        offset_north_m=pick(jnp.mean(f_n), coarse.offset_north_m),
        offset_east_m=pick(jnp.mean(f_e), coarse.offset_east_m),
        rotation_deg=pick(rot / DEG, coarse.rotation_deg),
        score=pick(st.misfit, coarse_misfit),
        bias=coarse.bias,
        topk_lat=jnp.stack([coarse.lat, f_lat]),
        topk_lon=jnp.stack([coarse.lon, f_lon]),
        topk_score=jnp.stack([coarse_misfit, st.misfit]),
        chosen=use_fine.astype(jnp.int32),
        n_candidates=jnp.full((n,), st.n_used, jnp.int32),
        work_unconstrained=coarse.work_unconstrained,
        work_constrained=coarse.work_constrained + iters,
        work_pairs=coarse.work_pairs + iters * n * (iccp.newton_steps + 1),
        status=status,
    )
