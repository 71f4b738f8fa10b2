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

Work is done in local metres about the track's centroid and in fractional map
indices, which keeps float32 accurate. For one fix the shifted positions form a
regular lattice of map indices, so the map under all candidates is evaluated
separably (:mod:`~jaxgrav.match.offsets`, :mod:`~jaxgrav.match.lattice`: a few
short reads of spline coefficients and one small matrix product per fix) rather
than point by point; the block of map nodes this reads has a static size
(``DenseConfig.lattice_block``, or a larger one when the offsets span more cells),
and an offset grid coarser than the map falls back to sampling every shifted fix
on its own (same values, slower). The refinement
uses the analytic gradient of the bicubic patch and a closed-form solve of its 4 × 4
normal equations (:mod:`~jaxgrav.match.refine`). The map's spline coefficients may
be prepared once (a :class:`~jaxgrav.prepared.PreparedMap` as ``grid``, or its
:func:`lattice_table`) and passed in, as a hot loop over many calls should;
:func:`match_dense_batch` matches many tracks in cache-sized chunks.
"""

import functools

import jax
import jax.numpy as jnp

from jaxgrav import interp
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.constants import DEG
from jaxgrav.geodesy import local_offsets_m, meridian_radius, prime_vertical_radius
from jaxgrav.match.lattice import patch_values
from jaxgrav.match.offsets import means, offset_scores, track_frame
from jaxgrav.match.refine import gauss_newton, residual_function
from jaxgrav.match.result import MatchResult, nearest_to_ins
from jaxgrav.match.scoring import (
    SCORES,
    bias_precision,
    decreasing_weights,
    k_smallest,
    score_track,
    sums,
)
from jaxgrav.prepared import as_grid, prepare_map

__all__ = ["DenseConfig", "lattice_table", "match_dense", "match_dense_batch", "shifted_tracks"]


@pytree_dataclass
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
    lattice_block : int
        Map nodes per axis of the block from which each fix's offset lattice is
        evaluated separably (static; cost grows with it). Used when the offsets
        span at most ``lattice_block − 2`` map cells per axis (checked at run time
        from ``spacing_m`` and the map; the default 6 covers ±half_size·spacing_m up
        to 2 cells); otherwise a block of ``2·half_size + 2`` nodes, which fits
        whenever ``spacing_m`` is at most the node spacing; otherwise, or with 0,
        every shifted fix is sampled on its own (same values, slowest).
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
    lattice_block: int = static_field(6)

    def __post_init__(self):
        if isinstance(self.score, str) and self.score not in SCORES:
            raise ValueError(f"score must be one of {SCORES}; got {self.score!r}")
        if isinstance(self.n_rotations, int) and self.n_rotations < 1:
            raise ValueError(f"n_rotations must be >= 1; got {self.n_rotations!r}")
        if isinstance(self.lattice_block, int) and self.lattice_block < 0:
            raise ValueError(f"lattice_block must be >= 0; got {self.lattice_block!r}")


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
        ``(2·ny, 2·nx)`` table (:func:`jaxgrav.match.lattice.interleave`);
        ``bilinear``: the node values ``(ny, nx)``.
    """
    interp.check_method(method)
    if method == "bilinear":
        return jnp.asarray(as_grid(grid).values)
    return prepare_map(grid).interleaved()


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
    lat_c, lon_c = means(lat, lon)
    m_c = meridian_radius(lat_c) * DEG
    n_c = prime_vertical_radius(lat_c) * jnp.cos(lat_c * DEG) * DEG
    north, east = (lat - lat_c) * m_c, (lon - lon_c) * n_c
    c, s = jnp.cos(rotation_rad)[..., None], jnp.sin(rotation_rad)[..., None]
    rn = c * north - s * east + jnp.asarray(d_north)[..., None]
    re = s * north + c * east + jnp.asarray(d_east)[..., None]
    return lat_c + rn / m_c, lon_c + re / n_c


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
        ``work_pairs`` the number of map samples taken.
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
    scores, biases = offset_scores(table, grid, frame, readings, w, prior, d_1d, d_n, d_e,
                                   rot, config)
    k = min(config.k_best, scores.shape[0])
    top = k_smallest(scores, k)
    topk_score = scores[top]
    topk_lat, topk_lon = shifted_tracks(lat, lon, d_n[top], d_e[top], rr[top])  # (k, N)
    (distance,) = sums([jnp.hypot(*local_offsets_m(topk_lat, topk_lon, lat, lon))], -1)
    chosen = nearest_to_ins(topk_score, distance, config.selection)
    i = top[chosen]
    found = jnp.isfinite(scores[i])

    p0 = jnp.stack([d_n[i], d_e[i], rr[i], biases[i]])
    free = (True, True, config.n_rotations > 1, config.score == "bias")
    step_max = jnp.stack(
        [
            jnp.asarray(config.spacing_m, dtype),
            jnp.asarray(config.spacing_m, dtype),
            jnp.asarray(config.max_rotation_deg, dtype) * DEG / max(config.n_rotations - 1, 1),
            jnp.asarray(jnp.inf, dtype),
        ]
    )
    res = residual_function(table, frame, readings, w, config.score, prior, config.method)
    p = (
        gauss_newton(res, p0, free, step_max, config.damping, config.refine_steps)
        if config.refine_steps
        else p0
    )
    p = jnp.where(found, p, jnp.zeros_like(p))
    m_lat, m_lon = shifted_tracks(lat, lon, p[0], p[1], p[2])
    iy_c, ix_c, ky, kx, north, east = frame
    c, s = jnp.cos(p[2]), jnp.sin(p[2])
    v = patch_values(table, iy_c + ky * (c * north - s * east + p[0]),
                     ix_c + kx * (s * north + c * east + p[1]), config.method)
    final_score, final_bias = score_track(readings, v, w, config.score, prior)
    mean_off = means(*local_offsets_m(m_lat, m_lon, lat, lon))
    reach = h * config.spacing_m
    edge = (jnp.abs(p[0]) >= reach) | (jnp.abs(p[1]) >= reach)
    n_off = jnp.asarray(scores.shape[0], dtype)
    return MatchResult(
        lat=m_lat,
        lon=m_lon,
        offset_north_m=mean_off[0],
        offset_east_m=mean_off[1],
        rotation_deg=p[2] / DEG,
        score=jnp.where(found, final_score, jnp.inf),
        bias=jnp.where(found, final_bias, 0.0) if config.score != "bias" else p[3],
        topk_lat=topk_lat,
        topk_lon=topk_lon,
        topk_score=topk_score,
        chosen=chosen,
        n_candidates=jnp.full((n,), scores.shape[0], jnp.int32),
        work_unconstrained=n_off**n,
        work_constrained=n_off,
        work_pairs=n_off * n,
        status=jnp.where(found, 0, 1) | jnp.where(found & edge, 8, 0),
    )


@functools.partial(jax.jit, static_argnames=("chunk",))
def match_dense_batch(grid, lat, lon, readings, config=DenseConfig(), prepared=None, chunk=128):  # noqa: B008
    """:func:`match_dense` over a batch of tracks sharing one map, in chunks.

    Equal to ``jax.vmap(match_dense, in_axes=(None, 0, 0, 0, None, None))``; tracks
    are matched ``chunk`` at a time (vectorised within a chunk, a loop over chunks),
    which keeps the intermediates cache-sized: on CPU faster than one ``vmap`` over
    thousands of tracks.

    Parameters
    ----------
    grid : Grid or PreparedMap
        Anomaly map (mGal).
    lat, lon : Array, shape ``(B, N)``
        INS-indicated fixes of ``B`` tracks (degrees).
    readings : Array, shape ``(B, N)``
        Gravimeter readings (mGal).
    config : DenseConfig
    prepared : Array, optional
        :func:`lattice_table` of ``grid``; computed once here when omitted.
    chunk : int
        Most tracks per chunk (static); the batch is cut into equal chunks, the
        last one padded with copies of the first track (results dropped).

    Returns
    -------
    MatchResult
        Fields with a leading batch axis ``B``.
    """
    table = lattice_table(grid, config.method) if prepared is None else prepared
    grid = as_grid(grid)
    b = lat.shape[0]
    n_chunks = -(-b // chunk)
    size = -(-b // n_chunks)  # equal chunks: one compiled body (no remainder branch)
    pad = n_chunks * size - b
    xs = tuple(jnp.concatenate([a, jnp.broadcast_to(a[:1], (pad, *a.shape[1:]))])
               if pad else a for a in (lat, lon, readings))
    xs = tuple(a.reshape(n_chunks, size, *a.shape[1:]) for a in xs)
    out = jax.lax.map(jax.vmap(lambda x: match_dense(grid, *x, config, table)), xs)
    return jax.tree.map(lambda a: a.reshape(n_chunks * size, *a.shape[2:])[:b], out)
