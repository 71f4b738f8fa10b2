"""ICCP fine matching (paper B, second stage): Iterative Closest Contour Point.

Work is done in local metres ``(north, east)`` about the INS track's centroid, the
frame of :func:`~jaxgrav.match.offsets.shifted_tracks`, so a result is exactly a
shift plus a rotation of the INS track about its centroid. Each iteration:

1. Transform the INS points: ``y_n = R p_n + t``.
2. Closest contour point: from ``y_n``, a few Newton projection steps onto the level
   set ``{x : f(x) = z_n}`` of the *bicubic interpolant* f of the map
   (:func:`~jaxgrav.match.contour.project_to_contours`, a loop of Newton steps, on
   spline coefficients prepared once per map, with the analytic gradient).
3. Sliding window: a contour point is used only if it lies within ``window_m`` of
   its current point ``y_n`` (the window moves with the estimate) and the map there
   matches ``z_n`` within ``contour_tol``; others get weight 0.
4. Rigid transform ``R, t`` minimising ``Σ w_n ‖x_n − (R p_n + t)‖²`` (Kabsch, closed
   form in 2-D), with ``|θ| ≤ max_rotation_deg``: the INS heading-error bound, a
   prior that keeps ICCP from turning a track along an ambiguous contour.
5. Stop when no point moved more than ``tol_m`` (convergence mask; at most
   ``max_iter`` iterations, converged tracks stay frozen, so it vmaps).

ICCP minimises distances to contours, not the misfit ``mean((z − f)²)`` itself; the
result carries the misfit so a caller can compare it with other estimates
(:func:`~jaxgrav.match.combined.match_entropy_iccp` does). ICCP assumes the truth
near the indicated track: good after a coarse match, poor alone for large initial
errors (see ``examples/paper_b_entropy_iccp.py``).
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.constants import DEG
from jaxgrav.geodesy import local_offsets_m, meridian_radius, prime_vertical_radius
from jaxgrav.match.contour import local_field, project_to_contours, value_grad_ne
from jaxgrav.match.iccp_config import IccpConfig
from jaxgrav.match.offsets import shifted_tracks
from jaxgrav.match.result import STATUS, MatchResult
from jaxgrav.match.rigid import kabsch_2d, kabsch_ne, refine_local
from jaxgrav.prepared import prepare_map

__all__ = [
    "ICCP_STATUS",
    "IccpConfig",
    "IccpState",
    "iccp_fit",
    "iccp_local",
    "iccp_result",
    "kabsch_2d",
    "local_track_frame",
    "match_iccp",
    "match_iccp_batch",
    "refine_local",
]

ICCP_STATUS = {bit: STATUS[bit] for bit in (16, 64)}
"""The status bits raised by the ICCP matcher only (an excerpt of
:data:`~jaxgrav.match.result.STATUS`); it also raises bit 1."""



class IccpState(NamedTuple):
    """Outcome of :func:`iccp_local`.

    Attributes
    ----------
    rotation : Array, shape ``(2, 2)``
        R acting on ``(north, east)`` (m).
    translation : Array, shape ``(2,)``
        t (m).
    converged : Array of bool
    n_iter : Array of int
        Iterations that changed the estimate.
    n_used : Array of int
        Contour points used at the last iteration.
    starved : Array of bool
        Some iteration had fewer than 3 usable contour points.
    misfit : Array
        Mean squared misfit ``mean((z − f(R p + t))²)`` of the result (map units²;
        NaN if a point is off the map).
    """

    rotation: jax.Array
    translation: jax.Array
    converged: jax.Array
    n_iter: jax.Array
    n_used: jax.Array
    starved: jax.Array
    misfit: jax.Array


def _local_frame(lat, lon):
    """Centroid and metres-per-degree of the frame of :func:`shifted_tracks`."""
    lat_c, lon_c = jnp.mean(lat), jnp.mean(lon)
    m_c = meridian_radius(lat_c) * DEG
    n_c = prime_vertical_radius(lat_c) * jnp.cos(lat_c * DEG) * DEG
    return lat_c, lon_c, m_c, n_c


def iccp_local(field, p0, z, config, r0=None, t0=None):
    """ICCP on a map prepared in local metres (the jit-free core).

    Parameters
    ----------
    field : LocalField
        The map about the frame's origin (:func:`~jaxgrav.match.contour.local_field`).
    p0 : Array, shape ``(N, 2)``
        Indicated points ``(north, east)`` (m).
    z : Array, shape ``(N,)``
        Measured values (map units).
    config : IccpConfig
    r0, t0 : Array, optional
        Starting transform (default identity).

    Returns
    -------
    IccpState
    """
    dtype = p0.dtype
    r0 = jnp.eye(2, dtype=dtype) if r0 is None else r0
    t0 = jnp.zeros(2, dtype) if t0 is None else t0
    bound = jnp.deg2rad(jnp.asarray(config.max_rotation_deg, dtype))
    bound = (jnp.cos(bound), jnp.sin(bound))
    p_n, p_e = p0[:, 0], p0[:, 1]
    window2 = config.window_m * jnp.abs(config.window_m)

    def body(s):
        c, sn, t_n, t_e, _, k, it, _, starved = s
        y_n = c * p_n - sn * p_e + t_n
        y_e = sn * p_n + c * p_e + t_e
        x_n, x_e, f, g_n, g_e = project_to_contours(field, y_n, y_e, z, config.newton_steps,
                                         config.max_step_m)
        ok = (jnp.isfinite(f) & (jnp.abs(f - z) <= config.contour_tol)
              & ((x_n - y_n) ** 2 + (x_e - y_e) ** 2 <= window2))
        w = ok.astype(dtype)
        if config.weights == "gradient":
            w = w * (g_n * g_n + g_e * g_e)
        # materialised once: otherwise each Kabsch sum's fusion recomputes the tests
        w, n_ok, x_n, x_e = jax.lax.optimization_barrier(
            (w, jnp.sum(ok, dtype=jnp.int32), jnp.where(ok, x_n, y_n), jnp.where(ok, x_e, y_e)))
        c_new, s_new, tn_new, te_new = kabsch_ne(p_n, p_e, x_n, x_e, w, bound)
        move2 = jnp.max((c_new * p_n - s_new * p_e + tn_new - y_n) ** 2
                        + (s_new * p_n + c_new * p_e + te_new - y_e) ** 2)
        enough = n_ok >= 3
        pick = lambda a, b: jnp.where(enough, a, b)  # noqa: E731
        conv = enough & (jnp.sqrt(move2) <= config.tol_m)
        return (pick(c_new, c), pick(s_new, sn), pick(tn_new, t_n), pick(te_new, t_e), conv,
                k + 1, it + enough.astype(jnp.int32), n_ok, starved | ~enough)

    def cond(s):
        return ~s[4] & (s[5] < config.max_iter)

    zero = jnp.asarray(0, jnp.int32)
    init = (r0[0, 0], r0[1, 0], t0[0], t0[1], jnp.asarray(False), zero, zero, zero,
            jnp.asarray(False))
    c, sn, t_n, t_e, conv, _, it, n_ok, starved = jax.lax.while_loop(cond, body, init)
    f, _, _ = value_grad_ne(field, c * p_n - sn * p_e + t_n, sn * p_n + c * p_e + t_e)
    r = jnp.stack([jnp.stack([c, -sn]), jnp.stack([sn, c])])
    return IccpState(r, jnp.stack([t_n, t_e]), conv, it, n_ok, starved, jnp.mean((z - f) ** 2))


def iccp_fit(field, p0, z, config, r0=None, t0=None):
    """ICCP (:func:`iccp_local`) then ``config.refine_steps`` least-squares steps.

    Returns
    -------
    IccpState
        With the refined transform and its misfit.
    """
    st = iccp_local(field, p0, z, config, r0, t0)
    if config.refine_steps == 0:
        return st
    bound = jnp.deg2rad(jnp.asarray(config.max_rotation_deg, p0.dtype))
    r, t, m = refine_local(field, p0, z, st.rotation, st.translation, bound,
                           config.refine_steps)
    return st._replace(rotation=r, translation=t, misfit=m)


def local_track_frame(coef, grid, lat, lon):
    """INS points in the local frame of :func:`shifted_tracks` and the map prepared in it.

    Parameters
    ----------
    coef : Array, shape ``(ny−1, nx−1, 16)``
        :meth:`~jaxgrav.prepared.PreparedMap.patches` of the map.
    grid : Grid or PreparedMap
        The map's geometry.
    lat, lon : Array, shape ``(N,)``
        INS fixes (degrees).

    Returns
    -------
    p0 : Array, shape ``(N, 2)``
        Fixes ``(north, east)`` about the centroid (m).
    field : LocalField
    """
    lat_c, lon_c, m_c, n_c = _local_frame(lat, lon)
    dtype = jnp.result_type(coef.dtype, lat.dtype, float)
    p0 = jnp.stack([(lat - lat_c) * m_c, (lon - lon_c) * n_c], axis=-1).astype(dtype)
    return p0, local_field(coef, grid, lat_c, lon_c, m_c, n_c)


def iccp_result(coef, grid, lat, lon, readings, config, start_n=0.0, start_e=0.0):
    """ICCP from the INS track shifted by ``(start_n, start_e)`` m (the jit-free core).

    Parameters
    ----------
    coef : Array, shape ``(ny−1, nx−1, 16)``
        :meth:`~jaxgrav.prepared.PreparedMap.patches` of the map, prepared once by
        the caller (outside any loop over tracks or starts).
    grid : Grid or PreparedMap
        The map's geometry.
    lat, lon, readings : Array, shape ``(N,)``
        INS fixes (degrees) and measured values (map units).
    config : IccpConfig
    start_n, start_e : float or Array
        Starting translation (m), north and east.

    Returns
    -------
    MatchResult
        As :func:`match_iccp`.
    """
    lat, lon, readings = (jnp.asarray(a) for a in (lat, lon, readings))
    n = lat.shape[0]
    p0, field = local_track_frame(coef, grid, lat, lon)
    dtype = p0.dtype
    t0 = jnp.stack([jnp.asarray(start_n, dtype), jnp.asarray(start_e, dtype)])
    st = iccp_fit(field, p0, readings.astype(dtype), config, t0=t0)
    rot = jnp.arctan2(st.rotation[1, 0], st.rotation[0, 0])
    m_lat, m_lon = shifted_tracks(lat, lon, st.translation[0], st.translation[1], rot)
    off_n, off_e = local_offsets_m(m_lat, m_lon, lat, lon)
    misfit = st.misfit
    status = (
        jnp.where(jnp.isfinite(misfit), 0, 1)
        | jnp.where(st.converged, 0, 16)
        | jnp.where(st.starved, 64, 0)
    ).astype(jnp.int32)
    return MatchResult(
        lat=m_lat,
        lon=m_lon,
        offset_north_m=jnp.mean(off_n),
        offset_east_m=jnp.mean(off_e),
        rotation_deg=rot / DEG,
        score=misfit,
        bias=jnp.zeros((), dtype),
        topk_lat=m_lat[None],
        topk_lon=m_lon[None],
        topk_score=misfit[None],
        chosen=jnp.asarray(0),
        n_candidates=jnp.full((n,), st.n_used, jnp.int32),
        work_unconstrained=jnp.asarray(1.0, dtype),
        work_constrained=st.n_iter.astype(dtype),
        work_pairs=(st.n_iter * n * (config.newton_steps + 1)).astype(dtype),
        status=status,
    )


@jax.jit
def match_iccp(grid, lat, lon, readings, config=IccpConfig()):  # noqa: B008
    """ICCP fine match of one track (jitted; vmap it over tracks).

    Parameters
    ----------
    grid : Grid or PreparedMap
        Map (nT or mGal), sampled by its bicubic interpolant.
    lat, lon : Array, shape ``(N,)``
        INS-indicated fixes (degrees).
    readings : Array, shape ``(N,)``
        Measured values (map units), bias-free (ICCP has no bias term).
    config : IccpConfig

    Returns
    -------
    MatchResult
        The INS track moved by the estimated rigid transform: ``rotation_deg`` about
        the INS centroid (clockwise), ``score`` the mean squared misfit (map units²),
        ``n_candidates`` the contour points used at the last iteration,
        ``work_constrained`` the iterations that changed the estimate; status bits in
        :data:`ICCP_STATUS`.
    """
    pm = prepare_map(grid)
    return iccp_result(pm.patches(), pm.grid, lat, lon, readings, config)


@functools.partial(jax.jit, static_argnames=("chunk",))
def match_iccp_batch(grid, lat, lon, readings, config=IccpConfig(), chunk=100):  # noqa: B008
    """:func:`match_iccp` over a batch of tracks sharing one map, in chunks (jitted).

    Equal to ``jax.vmap(match_iccp, in_axes=(None, 0, 0, 0, None))``, but the map is
    prepared once and tracks are matched ``chunk`` at a time (vectorised within a
    chunk, a loop over chunks): each chunk's per-point arrays stay bounded (the
    gathered bicubic coefficients are 16 numbers per point), and each chunk's
    iteration loop stops when *its* tracks have converged. Measured on a 2-core CPU
    (``benchmarks/match_iccp.py``, 1000 tracks): as fast as one ``vmap`` when the
    machine is idle, up to ~1.5× less CPU time when it is loaded by other jobs.

    Parameters
    ----------
    grid : Grid or PreparedMap
        Map (nT or mGal).
    lat, lon : Array, shape ``(B, N)``
        INS-indicated fixes of ``B`` tracks (degrees).
    readings : Array, shape ``(B, N)``
        Measured values (map units), bias-free.
    config : IccpConfig
    chunk : int
        Most tracks per chunk (static); the batch is cut into equal chunks, the last
        one padded with copies of the first track (results dropped).

    Returns
    -------
    MatchResult
        Fields with a leading batch axis ``B``.
    """
    if chunk < 1:
        raise ValueError(f"chunk must be a positive number of tracks; got {chunk!r}")
    pm = prepare_map(grid)
    coef, grid = pm.patches(), pm.grid
    b = lat.shape[0]
    n_chunks = -(-b // chunk)
    size = -(-b // n_chunks)  # equal chunks: one compiled body
    pad = n_chunks * size - b
    xs = tuple(jnp.concatenate([a, jnp.broadcast_to(a[:1], (pad, *a.shape[1:]))])
               if pad else a for a in (lat, lon, readings))
    xs = tuple(a.reshape(n_chunks, size, *a.shape[1:]) for a in xs)
    out = jax.lax.map(jax.vmap(lambda x: iccp_result(coef, grid, *x, config)), xs)
    return jax.tree.map(lambda a: a.reshape(n_chunks * size, *a.shape[2:])[:b], out)
