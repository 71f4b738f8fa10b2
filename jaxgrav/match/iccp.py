"""ICCP fine matching (paper B, second stage): Iterative Closest Contour Point.

Work is done in local metres ``(north, east)`` about the INS track's centroid, the
frame of :func:`~jaxgrav.match.dense.shifted_tracks`, so a result is exactly a
shift plus a rotation of the INS track about its centroid. Each iteration:

1. Transform the INS points: ``y_n = R p_n + t``.
2. Closest contour point: from ``y_n``, a few Newton projection steps onto the level
   set ``{x : f(x) = z_n}`` of the *bicubic interpolant* f of the map,
   ``x ← x − (f(x) − z_n) ∇f / |∇f|²`` (each step at most ``max_step_m`` long;
   the gradient comes from ``jax.value_and_grad`` of the differentiable sampler).
   For a locally linear field one step is the exact foot of the perpendicular.
3. Sliding window: a contour point is used only if it lies within ``window_m`` of
   its current point ``y_n`` (the window moves with the estimate) and the map there
   matches ``z_n`` within ``contour_tol``; others get weight 0.
4. Rigid transform ``R, t`` minimising ``Σ w_n ‖x_n − (R p_n + t)‖²`` by the SVD
   (Kabsch) solution, with the reflection guard.
5. Stop when no point moved more than ``tol_m`` (convergence mask; the loop runs a
   fixed ``max_iter`` and converged tracks stay frozen, so it vmaps).

ICCP assumes the truth near the indicated track: good after a coarse match, poor
alone for large initial errors (see ``examples/paper_b_entropy_iccp.py``).
"""

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._pytree import static_field
from jaxgrav.constants import DEG
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.grid import make_sampler
from jaxgrav.match.candidates import local_offsets_m
from jaxgrav.match.dense import shifted_tracks
from jaxgrav.match.result import MatchResult

__all__ = ["ICCP_STATUS", "IccpConfig", "IccpState", "iccp_local", "kabsch_2d", "match_iccp"]

ICCP_STATUS = {
    16: "ICCP did not converge within max_iter iterations",
    64: "ICCP: fewer than 3 contour points inside the window at some iteration (transform kept)",
}
"""Status bits raised by the ICCP matcher, in addition to :data:`~jaxgrav.match.STATUS` bit 1."""



@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class IccpConfig:
    """Settings of the ICCP matcher.

    Attributes
    ----------
    window_m : float
        Sliding-window radius (m): a contour point farther than this from its current
        point is not used.
    max_step_m : float
        Longest single Newton step (m).
    contour_tol : float
        Largest ``|f(x) − z|`` (map units) of a usable contour point.
    tol_m : float
        Convergence: largest point movement in one iteration (m).
    max_iter : int
        Iterations (static).
    newton_steps : int
        Newton projection steps per iteration (static).
    method : {"bicubic"}
        Map interpolation (static); projection needs a smooth gradient.
    """

    window_m: float = 3000.0
    max_step_m: float = 1000.0
    contour_tol: float = float("inf")
    tol_m: float = 1.0
    max_iter: int = static_field(30)
    newton_steps: int = static_field(3)
    method: str = static_field("bicubic")

    def __post_init__(self):
        if isinstance(self.max_iter, int) and self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1; got {self.max_iter!r}")
        if isinstance(self.newton_steps, int) and self.newton_steps < 1:
            raise ValueError(f"newton_steps must be >= 1; got {self.newton_steps!r}")
        if isinstance(self.method, str) and self.method != "bicubic":
            raise ValueError(f"method must be 'bicubic' (a smooth gradient); got {self.method!r}")


def kabsch_2d(p, x, w=None):
    """Rigid 2-D transform minimising ``Σ w_n ‖x_n − (R p_n + t)‖²`` (Kabsch, by SVD).

    Parameters
    ----------
    p, x : Array, shape ``(N, 2)``
        Source and target points (m).
    w : Array, shape ``(N,)``, optional
        Non-negative weights (default equal); zero weights drop points.

    Returns
    -------
    tuple of Array
        ``(R, t)``: rotation ``(2, 2)`` with det +1 and translation ``(2,)`` (m).
        With fewer than two weighted points the identity is returned.
    """
    p, x = jnp.asarray(p), jnp.asarray(x)
    w = jnp.ones(p.shape[:-1], p.dtype) if w is None else jnp.asarray(w, p.dtype)
    total = jnp.sum(w)
    ok = total > 0
    wn = w / jnp.where(ok, total, 1.0)
    p_c = wn @ p
    x_c = wn @ x
    h = (p - p_c).T @ ((x - x_c) * wn[:, None])
    u, _, vt = jnp.linalg.svd(h)
    d = jnp.sign(jnp.linalg.det(vt.T @ u.T))
    d = jnp.where(d == 0, 1.0, d)
    r = vt.T @ jnp.diag(jnp.stack([jnp.ones_like(d), d])) @ u.T
    eye = jnp.eye(2, dtype=r.dtype)
    good = ok & (jnp.sum(w > 0) >= 2) & jnp.all(jnp.isfinite(r))
    r = jnp.where(good, r, eye)
    t = jnp.where(good, x_c - r @ p_c, jnp.zeros(2, r.dtype))
    return r, t


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
    """

    rotation: jax.Array
    translation: jax.Array
    converged: jax.Array
    n_iter: jax.Array
    n_used: jax.Array
    starved: jax.Array


def _local_frame(lat, lon):
    """Centroid and metres-per-degree of the frame of :func:`shifted_tracks`."""
    lat_c, lon_c = jnp.mean(lat), jnp.mean(lon)
    m_c = meridian_radius(lat_c) * DEG
    n_c = prime_vertical_radius(lat_c) * jnp.cos(lat_c * DEG) * DEG
    return lat_c, lon_c, m_c, n_c


def iccp_local(field, p0, z, config, r0=None, t0=None):
    """ICCP on a field given in local metres (the jit-free core).

    Parameters
    ----------
    field : callable
        ``f(north, east) -> value`` for arrays of points (m), differentiable, NaN off the map.
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

    def f_pt(x):
        return field(x[0], x[1])

    vg = jax.vmap(jax.value_and_grad(f_pt))

    def project(y):
        def step(_, x):
            v, g = vg(x)
            g2 = jnp.sum(g * g, axis=-1)
            ok = jnp.isfinite(v) & (g2 > 0)
            d = -jnp.where(ok, v - z, 0.0)[:, None] * g / jnp.where(ok, g2, 1.0)[:, None]
            length = jnp.linalg.norm(d, axis=-1)
            scale = jnp.minimum(1.0, config.max_step_m / jnp.where(length > 0, length, 1.0))
            return x + d * scale[:, None]

        x = jax.lax.fori_loop(0, config.newton_steps, step, y)
        v = jax.vmap(f_pt)(x)
        ok = (
            jnp.all(jnp.isfinite(x), axis=-1)
            & jnp.isfinite(v)
            & (jnp.abs(v - z) <= config.contour_tol)
            & (jnp.linalg.norm(x - y, axis=-1) <= config.window_m)
        )
        return jnp.where(ok[:, None], x, y), ok

    def body(_, s):
        r, t, done, it, _, starved = s
        y = p0 @ r.T + t
        x, ok = project(y)
        n_ok = jnp.sum(ok).astype(jnp.int32)
        r_new, t_new = kabsch_2d(p0, x, ok.astype(dtype))
        y_new = p0 @ r_new.T + t_new
        move = jnp.max(jnp.linalg.norm(y_new - y, axis=-1))
        enough = n_ok >= 3
        update = ~done & enough
        r = jnp.where(update, r_new, r)
        t = jnp.where(update, t_new, t)
        conv = done | (enough & (move <= config.tol_m))
        return r, t, conv, it + update.astype(jnp.int32), n_ok, starved | (~done & ~enough)

    init = (r0, t0, jnp.asarray(False), jnp.asarray(0, jnp.int32), jnp.asarray(0, jnp.int32),
            jnp.asarray(False))
    r, t, conv, it, n_ok, starved = jax.lax.fori_loop(0, config.max_iter, body, init)
    return IccpState(r, t, conv, it, n_ok, starved)


def _iccp_result(sample, lat, lon, readings, config, start_n=0.0, start_e=0.0):
    """ICCP from the INS track shifted by ``(start_n, start_e)`` m; returns MatchResult."""
    lat, lon, readings = (jnp.asarray(a) for a in (lat, lon, readings))
    n = lat.shape[0]
    lat_c, lon_c, m_c, n_c = _local_frame(lat, lon)
    p0 = jnp.stack([(lat - lat_c) * m_c, (lon - lon_c) * n_c], axis=-1)

    def field(north, east):
        return sample(lat_c + north / m_c, lon_c + east / n_c)

    t0 = jnp.stack([jnp.asarray(start_n, p0.dtype), jnp.asarray(start_e, p0.dtype)])
    st = iccp_local(field, p0, readings, config, t0=t0)
    rot = jnp.arctan2(st.rotation[1, 0], st.rotation[0, 0])
    m_lat, m_lon = shifted_tracks(lat, lon, st.translation[0], st.translation[1], rot)
    misfit = jnp.mean((readings - sample(m_lat, m_lon)) ** 2)
    off_n, off_e = local_offsets_m(m_lat, m_lon, lat, lon)
    found = jnp.isfinite(misfit)
    status = (
        jnp.where(found, 0, 1)
        | jnp.where(st.converged, 0, 16)
        | jnp.where(st.starved, 64, 0)
    ).astype(jnp.int32)
    dtype = p0.dtype
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
def match_iccp(grid, lat, lon, readings, config=IccpConfig()):
    """ICCP fine match of one track (jitted; vmap it over tracks).

    Parameters
    ----------
    grid : Grid
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
        ``work_constrained`` the iterations run; status bits in :data:`ICCP_STATUS`.
    """
    return _iccp_result(make_sampler(grid, config.method), lat, lon, readings, config)
