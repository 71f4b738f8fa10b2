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
damped Gauss–Newton steps on the differentiable (bicubic) map.
"""

import dataclasses

import jax
import jax.numpy as jnp

from jaxgrav._pytree import static_field
from jaxgrav.constants import DEG
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.grid import make_sampler
from jaxgrav.match.candidates import local_offsets_m
from jaxgrav.match.result import MatchResult, nearest_to_ins
from jaxgrav.match.scoring import SCORES, bias_precision, decreasing_weights, score_track

__all__ = ["DenseConfig", "match_dense", "shifted_tracks"]



@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class DenseConfig:
    """Settings of the dense-offset matcher.

    Attributes
    ----------
    spacing_m : float
        Spacing of the offset grid (m).
    max_rotation_deg : float
        Largest heading error tried (degrees); rotations are spread evenly over
        ±max_rotation_deg.
    weight_decay : float
        μ_i = exp(−decay · i/(N−1)).
    noise_mgal : float
        Reading noise σ_n (mGal), used with ``bias_sigma_mgal``.
    bias_sigma_mgal : float
        Prior σ_b of the common bias (mGal) for ``score="bias"``; ``inf`` (default)
        estimates it freely, see :mod:`~jaxgrav.match.scoring`.
    damping : float
        Levenberg–Marquardt damping of the refinement (relative to the diagonal).
    half_size : int
        Offsets per side (static): ``(2·half_size + 1)²`` offsets, covering
        ±half_size·spacing_m.
    n_rotations : int
        Heading errors tried (static; 1 = none, and the refinement keeps heading fixed).
    refine_steps : int
        Gauss–Newton steps after the grid search (static; 0 = none).
    k_best : int
        Candidates ranked before selection (static).
    method : {"bicubic", "bilinear"}
        Map interpolation (static); the refinement needs bicubic's smooth gradient.
    score : {"bias", "difference", "absolute"}
        Score form (static), see :mod:`~jaxgrav.match.scoring`.
    selection : {"best", "nearest"}
        Least score, or paper A's nearest-to-INS rule among the k best (static).
    """

    spacing_m: float = 500.0
    max_rotation_deg: float = 2.0
    weight_decay: float = 0.0
    noise_mgal: float = 1.0
    bias_sigma_mgal: float = float("inf")
    damping: float = 1e-3
    half_size: int = static_field(10)
    n_rotations: int = static_field(1)
    refine_steps: int = static_field(8)
    k_best: int = static_field(5)
    method: str = static_field("bicubic")
    score: str = static_field("bias")
    selection: str = static_field("best")

    def __post_init__(self):
        if isinstance(self.score, str) and self.score not in SCORES:
            raise ValueError(f"score must be one of {SCORES}; got {self.score!r}")
        if isinstance(self.n_rotations, int) and self.n_rotations < 1:
            raise ValueError(f"n_rotations must be >= 1; got {self.n_rotations!r}")


def shifted_tracks(lat, lon, d_north, d_east, rotation_rad):
    """INS track shifted by offsets and turned about its centroid.

    Parameters
    ----------
    lat, lon : Array, shape ``(N,)``
        INS fixes (degrees).
    d_north, d_east : Array, shape ``S``
        Offsets (m).
    rotation_rad : Array, shape ``S``
        Heading errors (rad, clockwise), broadcast with the offsets.

    Returns
    -------
    tuple of Array
        ``(lat, lon)`` of shape ``(*S, N)`` in degrees.
    """
    lat_c, lon_c = jnp.mean(lat), jnp.mean(lon)
    m_c = meridian_radius(lat_c) * DEG
    n_c = prime_vertical_radius(lat_c) * jnp.cos(lat_c * DEG) * DEG
    north, east = (lat - lat_c) * m_c, (lon - lon_c) * n_c
    c, s = jnp.cos(rotation_rad)[..., None], jnp.sin(rotation_rad)[..., None]
    rn = c * north - s * east + jnp.asarray(d_north)[..., None]
    re = s * north + c * east + jnp.asarray(d_east)[..., None]
    return lat_c + rn / m_c, lon_c + re / n_c


def _residuals(sample, lat, lon, g, w, kind, prior):
    """Weighted residual vector of parameters p = (north, east, rotation, bias).

    Its squared norm is :func:`~jaxgrav.match.scoring.score_track` of the shifted track.
    """
    sqrt_w = jnp.sqrt(w / jnp.sum(w))
    sqrt_wd = jnp.sqrt(w[:-1] / jnp.sum(w[:-1]))

    def res(p):
        la, lo = shifted_tracks(lat, lon, p[0], p[1], p[2])
        r = g - sample(la, lo)
        if kind == "difference":
            return sqrt_wd * jnp.diff(r)
        if kind == "bias":
            return jnp.concatenate([sqrt_w * (r - p[3]), jnp.sqrt(prior)[None] * p[3:4]])
        return sqrt_w * r

    return res


def _refine(res, p0, free, step_max, damping, n_steps):
    """Damped Gauss–Newton on the free parameters; a step is kept only if it lowers the cost."""
    cost = lambda p: jnp.sum(res(p) ** 2)  # noqa: E731

    def body(_, state):
        p, c, lam = state
        r = res(p)
        j = jax.jacfwd(res)(p) * free
        jtj = j.T @ j
        a = jtj + lam * jnp.diag(jnp.diag(jtj)) + jnp.diag(1.0 - free) + 1e-12 * jnp.eye(4)
        dp = -jnp.linalg.solve(a, j.T @ r) * free
        scale = jnp.minimum(1.0, jnp.min(step_max / jnp.maximum(jnp.abs(dp), 1e-30)))
        trial = p + scale * dp
        c_new = cost(trial)
        better = jnp.isfinite(c_new) & (c_new < c)
        return (
            jnp.where(better, trial, p),
            jnp.where(better, c_new, c),
            jnp.where(better, lam * 0.3, lam * 10.0),
        )

    p, _, _ = jax.lax.fori_loop(0, n_steps, body, (p0, cost(p0), jnp.asarray(damping, p0.dtype)))
    return p


@jax.jit
def match_dense(grid, lat, lon, readings, config=DenseConfig()):
    """Match one track by scoring every shift of the INS track on an offset grid.

    Parameters
    ----------
    grid : Grid
        Anomaly map (mGal); sampled continuously, so it need not be refined.
    lat, lon : Array, shape ``(N,)``
        INS-indicated fixes (degrees).
    readings : Array, shape ``(N,)``
        Gravimeter readings (mGal).
    config : DenseConfig

    Returns
    -------
    MatchResult
        ``work_constrained`` is the number of candidate tracks scored,
        ``work_pairs`` the number of map samples taken.
    """
    lat, lon, readings = (jnp.asarray(a) for a in (lat, lon, readings))
    n = lat.shape[0]
    sample = make_sampler(grid, config.method)
    h = config.half_size
    grid_1d = jnp.arange(-h, h + 1) * config.spacing_m
    on, oe = (a.reshape(-1) for a in jnp.meshgrid(grid_1d, grid_1d, indexing="ij"))
    if config.n_rotations == 1:
        rot = jnp.zeros((1,), on.dtype)
    else:
        rot = jnp.linspace(-1.0, 1.0, config.n_rotations) * config.max_rotation_deg * DEG
    d_n, d_e = jnp.tile(on, config.n_rotations), jnp.tile(oe, config.n_rotations)
    rr = jnp.repeat(rot, on.shape[0])
    la, lo = shifted_tracks(lat, lon, d_n, d_e, rr)  # (R*O, N)
    w = decreasing_weights(n, config.weight_decay)
    prior = bias_precision(w, config.noise_mgal, config.bias_sigma_mgal)
    scores, biases = score_track(readings, sample(la, lo), w, config.score, prior)
    k = min(config.k_best, scores.shape[0])
    _, top = jax.lax.top_k(-scores.astype(jnp.float32), k)
    topk_score = scores[top]
    distance = jnp.sum(jnp.hypot(*local_offsets_m(la[top], lo[top], lat, lon)), axis=-1)
    chosen = nearest_to_ins(topk_score, distance, config.selection)
    i = top[chosen]
    found = jnp.isfinite(scores[i])

    p0 = jnp.stack([d_n[i], d_e[i], rr[i], biases[i]])
    free = jnp.array(
        [1.0, 1.0, 1.0 if config.n_rotations > 1 else 0.0, 1.0 if config.score == "bias" else 0.0],
        p0.dtype,
    )
    step_max = jnp.stack(
        [
            config.spacing_m,
            config.spacing_m,
            config.max_rotation_deg * DEG / max(config.n_rotations - 1, 1),
            jnp.asarray(jnp.inf, p0.dtype),
        ]
    ).astype(p0.dtype)
    res = _residuals(sample, lat, lon, readings, w, config.score, prior)
    p = (
        _refine(res, p0, free, step_max, config.damping, config.refine_steps)
        if config.refine_steps
        else p0
    )
    p = jnp.where(found, p, jnp.zeros_like(p))
    m_lat, m_lon = shifted_tracks(lat, lon, p[0], p[1], p[2])
    final_score, final_bias = score_track(readings, sample(m_lat, m_lon), w, config.score, prior)
    off_n, off_e = local_offsets_m(m_lat, m_lon, lat, lon)
    reach = h * config.spacing_m
    edge = (jnp.abs(p[0]) >= reach) | (jnp.abs(p[1]) >= reach)
    dtype = scores.dtype
    n_off = jnp.asarray(scores.shape[0], dtype)
    return MatchResult(
        lat=m_lat,
        lon=m_lon,
        offset_north_m=jnp.mean(off_n),
        offset_east_m=jnp.mean(off_e),
        rotation_deg=p[2] / DEG,
        score=jnp.where(found, final_score, jnp.inf),
        bias=jnp.where(found, final_bias, 0.0) if config.score != "bias" else p[3],
        topk_lat=la[top],
        topk_lon=lo[top],
        topk_score=topk_score,
        chosen=chosen,
        n_candidates=jnp.full((n,), scores.shape[0], jnp.int32),
        work_unconstrained=n_off**n,
        work_constrained=n_off,
        work_pairs=n_off * n,
        status=jnp.where(found, 0, 1) | jnp.where(found & edge, 8, 0),
    )
