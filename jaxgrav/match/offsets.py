"""Grid search of the dense matcher: every offset of a regular grid scored at once.

Works in the frame of :func:`~jaxgrav.match.offsets.shifted_tracks` expressed in map
indices (:func:`track_frame`): a fix turned and shifted to local ``(north, east)``
metres about the track's centroid lies at a fractional map index that is linear in
them. For one fix the shifted positions over the offset grid are then a regular
lattice of map indices, evaluated separably (:func:`jaxgrav.lattice.lattice_values`)
from a block of map nodes of static size; :func:`offset_scores` picks the smallest
block that fits at run time (a branch that depends on the map and the config only,
so it stays one branch under ``vmap`` over tracks), or samples every shifted fix on
its own when none does.
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._fusion import computed_once
from jaxgrav.constants import DEG
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.lattice import lattice_values, patch_values
from jaxgrav.match.gaps import gap_score, gls_gap_score
from jaxgrav.match.gls import gls_score
from jaxgrav.match.scoring import score_track, sums

__all__ = ["lattice_scores", "means", "offset_scores", "shifted_tracks", "track_frame"]


def means(*xs):
    """Means over the last axis, as one variadic reduction (:func:`~.scoring.sums`)."""
    return [t / xs[0].shape[-1] for t in sums(xs, -1)]


def _centroid_frame(lat, lon):
    """Centroid ``(lat_c, lon_c)`` (degrees), metres per degree north ``m_c`` and east
    ``n_c`` there, and the fixes' offsets from it ``(north, east)`` (m)."""
    lat_c, lon_c = means(lat, lon)
    m_c = meridian_radius(lat_c) * DEG
    n_c = prime_vertical_radius(lat_c) * jnp.cos(lat_c * DEG) * DEG
    return lat_c, lon_c, m_c, n_c, (lat - lat_c) * m_c, (lon - lon_c) * n_c


def track_frame(grid, lat, lon):
    """The frame of :func:`shifted_tracks` in map indices.

    Returns ``(iy_c, ix_c, ky, kx, north, east)``: fractional map index of the
    centroid (longitude taken within 180° of the map's middle), index steps per
    metre north and east, and the fixes' offsets from the centroid (m). A fix
    turned and shifted to local ``(rn, re)`` lies at index ``(iy_c + ky·rn, ix_c + kx·re)``.
    """
    lat_c, lon_c, m_c, n_c, north, east = _centroid_frame(lat, lon)
    lon_mid = grid.lon0 + 0.5 * (grid.nx - 1) * grid.dlon
    iy_c = (lat_c - grid.lat0) / grid.dlat
    ix_c = (jnp.mod(lon_c - lon_mid + 180.0, 360.0) - 180.0 + (lon_mid - grid.lon0)) / grid.dlon
    frame = iy_c, ix_c, 1.0 / (m_c * grid.dlat), 1.0 / (n_c * grid.dlon), north, east
    # the fixes' offsets computed once, not again inside each of the matcher's many
    # consumers (XLA fuses cheap producers into them: voyage-dense compiled 665
    # instructions for the frame, now 274); in their own dtype
    return (*frame[:4], *(computed_once(f, lat).astype(f.dtype) for f in frame[4:]))


def _lattice_fits(grid, half_size, spacing_m, block):
    """Whether every fix's offset lattice fits a block of ``block`` nodes (traced bool).

    Depends on the map and the offset grid only (not on the track), so under ``vmap``
    over tracks the branch stays one branch. A track's centroid can only produce
    an all-on-map candidate within ``half_size·spacing_m`` of the map, so the bound
    is taken over the map's latitudes widened by that reach.
    """
    span_lon = (grid.nx - 1) * grid.dlon
    extent = 2.0 * half_size * jnp.asarray(spacing_m)
    m_min = meridian_radius(0.0) * DEG  # smallest metres per degree of latitude
    reach_deg = 0.5 * extent / m_min
    lat_hi = jnp.minimum(
        jnp.maximum(abs(grid.lat0), abs(grid.lat0 + (grid.ny - 1) * grid.dlat)) + reach_deg, 89.0
    )
    n_min = prime_vertical_radius(lat_hi) * jnp.cos(lat_hi * DEG) * DEG
    return (
        (extent / (m_min * grid.dlat) <= min(block, grid.ny) - 2)
        & (extent / (n_min * grid.dlon) <= min(block, grid.nx) - 2)
        & (0.5 * extent / n_min < 180.0 - 0.5 * span_lon)
    )


class _Geometry(NamedTuple):
    """The static node geometry :func:`_lattice_fits` reads (a Grid's fields)."""

    lat0: float
    dlat: float
    ny: int
    dlon: float
    nx: int


def _fits_each(geometry, half_size, spacing_m, blocks):
    return jnp.stack([_lattice_fits(_Geometry(*geometry), half_size, spacing_m, b)
                      for b in blocks])


@functools.lru_cache(maxsize=64)
def _static_fits(geometry, half_size, spacing_m, blocks):
    """:func:`_lattice_fits` of each block at a static spacing, as Python booleans.

    Compiled as one small program and run at once, also inside a trace (evaluated op
    by op there, its ~20 operations had each been compiled on its own: 0.35 s CPU in
    every trace of the voyages' dense loop); cached per geometry and settings.
    """
    program = jax.jit(_fits_each, static_argnums=(0, 1, 2, 3)).lower(
        geometry, half_size, spacing_m, blocks).compile()
    return tuple(bool(f) for f in np.asarray(program()))


def _lattice_blocks(grid, config):
    """Static block sizes to try, smallest first: ``lattice_block``, then one that
    fits whenever the offset spacing is at most the node spacing (as
    :func:`~jaxgrav.match.api.config_for` sizes it). None for maps spanning
    (nearly) all longitudes, too small maps or ``lattice_block`` 0."""
    if (config.lattice_block < 3 or min(grid.ny, grid.nx) < 4
            or (grid.nx - 1) * grid.dlon > 300.0):
        return []
    big = min(2 * config.half_size + 2, max(grid.ny, grid.nx))
    return [config.lattice_block] + ([big] if big > config.lattice_block else [])


def offset_scores(table, grid, frame, readings, w, prior, d_1d, d_n, d_e, rot, config,
                  gls=None):
    """Scores and biases of every candidate track, flattened rotation-major then (north, east).

    Parameters
    ----------
    table : Array
        Lattice table (:func:`~jaxgrav.match.dense.lattice_table`).
    grid : Grid
        The map (its geometry).
    frame : tuple
        :func:`track_frame` of the INS track.
    readings, w : Array, shape ``(N,)``
        Readings (mGal) and weights μ_i.
    prior : Array
        κ of the bias prior.
    d_1d : Array, shape ``(A,)``
        Offsets along each axis (m), ``A = 2·half_size + 1``.
    d_n, d_e : Array, shape ``(R·A²,)``
        North and east offset of every candidate (m).
    rot : Array, shape ``(R,)``
        Heading errors (rad).
    config : DenseConfig
    gls : tuple, optional
        ``(whitener, bias_sigma, scale, coupling)``: score by the GLS likelihood instead
        (:func:`~jaxgrav.match.gls.gls_score` of the track's
        :class:`~jaxgrav.match.gls.GlsWhitener`, bias prior σ_b in mGal), times
        ``scale`` (mGal²) to keep the white score's mGal² scale. The lattice values
        are whitened after the lattice evaluation, one product per candidate.
        With ``config.gap_fixes`` > 0 (survey gaps) every shifted fix is sampled on its
        own and scored by :mod:`~jaxgrav.match.gaps`. ``coupling`` ``(N, 2)`` or None:
        the residuals' expected value per metre of offset (north, east), taken off.

    Returns
    -------
    scores, biases : Array, shape ``(R·A²,)``
    """
    iy_c, ix_c, ky, kx, north, east = frame
    c, s = jnp.cos(rot)[:, None], jnp.sin(rot)[:, None]
    rn, re = c * north - s * east, s * north + c * east  # (R, N) turned fixes
    n_rot, n = rn.shape

    def separable(block):
        def run(_):
            rows = iy_c + ky * (rn.reshape(-1)[:, None] + d_1d)
            cols = ix_c + kx * (re.reshape(-1)[:, None] + d_1d)
            v, in_y, in_x = lattice_values(table, rows, cols, block, config.method)
            a = d_1d.shape[0]
            v = v.reshape(n_rot, n, a, a)
            bad = (jnp.any(~in_y.reshape(n_rot, n, a), axis=1)[:, :, None]
                   | jnp.any(~in_x.reshape(n_rot, n, a), axis=1)[:, None, :])
            if gls is None:
                sc, b = lattice_scores(readings, v, w, config.score, prior, config.half_size)
            else:
                r = jnp.moveaxis(readings[None, :, None, None] - v, 1, -1)  # (R, A, A, N)
                if gls[3] is not None:
                    k = jnp.asarray(gls[3], r.dtype)
                    r = r - (d_1d[:, None, None] * k[:, 0] + d_1d[None, :, None] * k[:, 1])
                sc, b = gls_score(gls[0], r, gls[1])
                sc = sc * gls[2]
            return jnp.where(bad, jnp.inf, sc).reshape(-1), b.reshape(-1)

        return run

    def points(_):
        r_of = jnp.repeat(jnp.arange(n_rot), d_n.shape[0] // n_rot)
        iy = iy_c + ky * (rn[r_of] + d_n[:, None])
        ix = ix_c + kx * (re[r_of] + d_e[:, None])
        v = patch_values(table, iy, ix, config.method)
        gaps = config.gap_fixes
        if gls is not None:
            r = readings - v
            if gls[3] is not None:
                k = jnp.asarray(gls[3], r.dtype)
                r = r - (d_n[:, None] * k[:, 0] + d_e[:, None] * k[:, 1])
            sc, b = (gls_gap_score(gls[0], r, gls[1], gaps) if gaps
                     else gls_score(gls[0], r, gls[1]))
            return sc * gls[2], b
        if gaps:
            unit = jnp.asarray(config.noise_mgal, v.dtype) ** 2 * jnp.sum((w / jnp.sum(w)) ** 2)
            return gap_score(readings, v, w, config.score, prior, unit, gaps)
        return score_track(readings, v, w, config.score, prior)

    blocks = [] if config.gap_fixes else _lattice_blocks(grid, config)
    if not blocks:
        return points(None)
    branches = [separable(b) for b in blocks] + [points]
    if config.spacing_bound_m is not None:
        # the blocks beyond the first that fits every spacing up to the bound, and the
        # points, are never taken: not compiled (under vmap every branch would also run)
        fit = list(_static_fits((grid.lat0, grid.dlat, grid.ny, grid.dlon, grid.nx),
                                config.half_size, float(config.spacing_bound_m), tuple(blocks)))
        if any(fit):
            branches = branches[:fit.index(True) + 1]
    index = jnp.asarray(len(branches) - 1, jnp.int32)  # the last, unless a block fits
    for k in reversed(range(len(branches) - 1)):
        index = jnp.where(_lattice_fits(grid, config.half_size, config.spacing_m, blocks[k]),
                          k, index)
    return branches[0](None) if len(branches) == 1 else jax.lax.switch(index, branches, None)


def lattice_scores(g, v, w, kind, prior, centre):
    """:func:`~jaxgrav.match.scoring.score_track` of lattice values ``v`` ``(R, N, A, B)``.

    One pass over ``v`` (weighted sums of the residuals and of their squares, one
    variadic reduction). For the bias form the residuals are taken about the bias
    at the lattice centre (zero offset) so that the one-pass form does not cancel
    badly in float32.
    """
    w = w / jnp.sum(w)
    shape = (1, -1, 1, 1)
    r = g.reshape(shape) - v
    if kind == "difference":
        wd = jnp.concatenate([w[:-1] / jnp.sum(w[:-1]), jnp.zeros((1,), w.dtype)])
        d = jnp.concatenate([r[:, 1:] - r[:, :-1], jnp.zeros_like(r[:, :1])], axis=1)
        return tuple(sums([wd.reshape(shape) * d * d, w.reshape(shape) * r], 1))
    if kind == "absolute":
        score, _ = sums([w.reshape(shape) * r * r, r], 1)
        return score, jnp.zeros_like(score)
    c = sums([w[None, :] * r[:, :, centre, centre]], 1)[0][:, None, None]  # (R, 1, 1)
    u = r - c[:, None]
    s1, s2 = sums([w.reshape(shape) * u, w.reshape(shape) * u * u], 1)
    bias = (s1 + c) / (1.0 + prior)
    e = bias - c
    return s2 - 2.0 * e * s1 + e * e + prior * bias * bias, bias


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
    lat_c, lon_c, m_c, n_c, north, east = _centroid_frame(lat, lon)
    c, s = jnp.cos(rotation_rad)[..., None], jnp.sin(rotation_rad)[..., None]
    rn = c * north - s * east + jnp.asarray(d_north)[..., None]
    re = s * north + c * east + jnp.asarray(d_east)[..., None]
    return lat_c + rn / m_c, lon_c + re / n_c
