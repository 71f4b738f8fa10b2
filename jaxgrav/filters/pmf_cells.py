"""The point-mass filter's cell grid: its state, moments, map values, per-cell Gaussians.

Helpers of :mod:`jaxgrav.filters.pmf`: its state, the grid's position moments, the map
values of the cells (the point-mass anomaly on a separable cell grid), and the per-cell
Gaussians (the gravimeter bias and, optionally, a map error
with its covariance with the bias) with their mixture moments.
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav import constants
from jaxgrav._fusion import computed_once
from jaxgrav._linalg import inv_2x2
from jaxgrav._validate import concrete
from jaxgrav.constants import DEG, WGS84_A, WGS84_E2
from jaxgrav.fields.pointmass import PointMasses
from jaxgrav.filters.model import gravity_measurement
from jaxgrav.geodesy import enu_basis, geodetic_to_ecef
from jaxgrav.lattice import lattice_values
from jaxgrav.prepared import PreparedMap
from jaxgrav.sim.drift import apply_drift
from jaxgrav.sim.ins import N_STATES

__all__ = [
    "MISSING",
    "PMFState",
    "cell_fields",
    "cell_summary",
    "cell_values",
    "global_moments",
    "grid_moments",
    "lattice_block",
    "mix_cells",
    "point_mass_cells",
    "sync_gaussian",
    "weigh_cells",
    "with_cells",
]

MISSING = ("gaps", "land")
"""How the point-mass filter reads a cell on a missing map node (``pmf(missing=...)``):
``"gaps"``, a survey gap (the known cells' mean likelihood: the reading moves no mass
between known and unknown cells); ``"land"``, where the vehicle cannot be (likelihood 0)
for a cell whose nearest node is missing; a cell beside one (its interpolation needs the
missing node) and a cell off the map's extent are gaps either way."""


class PMFState(NamedTuple):
    """Point-mass filter state (the last three fields None without a map-error state).

    Attributes
    ----------
    w : Array, shape ``(G, G)``
        Normalised cell weights (north index first).
    bias_mean, bias_var : Array, shape ``(G, G)``
        Per-cell Gaussian of the gravimeter bias (mGal, mGal²).
    centre : Array, shape ``(2,)``
        Position error (m, north, east) of the grid's centre cell.
    x : Array, shape ``(13,)``
        Mean of the whole error state; its position block is the grid's mean.
    p : Array, shape ``(13, 13)``
        Its covariance; the position block is the grid's covariance.
    err_mean, err_var : Array, shape ``(G, G)``, or None
        Per-cell Gaussian of the map error (mGal, mGal²).
    err_cross : Array, shape ``(G, G)``, or None
        Per-cell covariance of the bias and the map error (mGal²).
    cell : Array, shape ``(2,)``, or None
        Cell size (m, north and east) of an adaptive grid; None: the filter's fixed
        ``cell_m``.
    pending : Array, shape ``(6,)``, or None
        The prediction not yet applied to the cells
        (:func:`~jaxgrav.filters.pmf_predict.compose_pending`): spread variance north
        and east (m²), then the per-cell bias model's factor and noise variance (mGal²)
        and the map error's; None: nothing pending. ``w`` and the per-cell arrays are
        the grid as it was when last settled; ``centre`` is current, and ``x``, ``p``
        hold the predicted moments (the settled grid's position moments plus the
        pending drift and spread, without the edges' reflection).
    cell_cap : Array, shape ``(2,)``, or None
        The largest cell (m, north and east) that resolves the map where the weights
        are, from the last reading (:func:`resolving_cell`); an adaptive grid's cells
        are kept below it. None: no bound (before the first reading, a fixed grid).
    summary : Array, shape ``(3,)`` or ``(6,)``, or None
        The cells as last settled or updated (:func:`cell_summary`): their mixture
        moments and the mass in the outermost cells, which ``predict`` reports without
        a pass over the cells.
    """

    w: jax.Array
    bias_mean: jax.Array
    bias_var: jax.Array
    centre: jax.Array
    x: jax.Array
    p: jax.Array
    err_mean: jax.Array | None = None
    err_var: jax.Array | None = None
    err_cross: jax.Array | None = None
    cell: jax.Array | None = None
    pending: jax.Array | None = None
    cell_cap: jax.Array | None = None
    summary: jax.Array | None = None


def grid_moments(w, dn, de, cell_m):
    """Mean and covariance (m, m²) of the weights over the cells' position errors.

    ``dn``, ``de`` are an ``ij`` meshgrid (north constant along a row, east along a
    column), so the moments come from the weights' row and column sums and one
    matrix-vector product (three passes over the cells, not five); the covariance
    includes each cell's own ``cell_m²/12``.
    """
    north, east = dn[:, 0], de[0, :]
    rows, cols = w.sum(1), w.sum(0)
    mean = jnp.stack([rows @ north, cols @ east])
    cn, ce = north - mean[0], east - mean[1]
    cne = cn @ w @ ce
    cov = jnp.array([[rows @ cn**2, cne], [cne, cols @ ce**2]])
    return mean, cov + jnp.eye(2) * cell_m**2 / 12.0


def sync_gaussian(state, mean, cov, prior_mean=None):
    """The Gaussian part's position block set to ``mean``, ``cov`` (the grid's moments);
    the other states move by their regression on the position,
    ``m_o ← m_o + K (mean − prior_mean)``, ``K = P_op P_pp⁻¹`` (``prior_mean``
    default: the current ``x[:2]``)."""
    x, p = state.x, state.p
    prior_mean = x[:2] if prior_mean is None else prior_mean
    k = p[2:, :2] @ inv_2x2(p[:2, :2])
    x = x.at[2:].add(k @ (mean - prior_mean)).at[:2].set(mean)
    p_oo = p[2:, 2:] - k @ p[2:, :2].T + k @ cov @ k.T
    p_op = k @ cov
    p = jnp.block([[cov, p_op.T], [p_op, p_oo]])
    return state._replace(x=x, p=0.5 * (p + p.T))


def cell_fields(state):
    """The per-cell arrays: bias mean, var, then (map error mean, var, cross) if present."""
    extra = () if state.err_mean is None else (state.err_mean, state.err_var, state.err_cross)
    return (state.bias_mean, state.bias_var, *extra)


def global_moments(w, cell):
    """Mixture moments of the per-cell Gaussians (:func:`cell_fields` order)."""
    gm = jnp.sum(w * cell[0])
    out = [gm, jnp.sum(w * (cell[1] + (cell[0] - gm) ** 2))]
    if len(cell) > 2:
        em = jnp.sum(w * cell[2])
        out += [em, jnp.sum(w * (cell[3] + (cell[2] - em) ** 2)),
                jnp.sum(w * (cell[4] + (cell[0] - gm) * (cell[2] - em)))]
    return out


def cell_summary(w, cell):
    """:func:`global_moments` of the cells then the mass in the outermost cells, ``(K + 1,)``."""
    edge = w[0].sum() + w[-1].sum() + w[1:-1, 0].sum() + w[1:-1, -1].sum()
    return jnp.stack([*global_moments(w, cell), edge])


def with_cells(state, cell):
    """``state`` with the per-cell arrays of :func:`cell_fields` replaced."""
    names = ("bias_mean", "bias_var", "err_mean", "err_var", "err_cross")
    return state._replace(**dict(zip(names, cell, strict=False)))


def point_mass_cells(masses, lat, lon):
    """Anomaly (mGal) of point masses on the separable cell grid ``lat (G, 1) × lon (1, G)``.

    The same physics as :func:`~jaxgrav.fields.pointmass.gravity_anomaly`, with the
    trigonometry of the cells' latitudes and longitudes done per row and per column
    (``2G`` instead of ``G²`` evaluations). The row and column factors and the result
    are materialised (:func:`~jaxgrav._fusion.computed_once`): left to itself, XLA's CPU
    fusion recomputes the row and column sines and cosines for every cell and mass
    inside each consumer of the anomaly (the filter ran at half the speed).
    """
    dtype = jnp.result_type(float)
    # rows: distance from the axis, height above the equator, the up vector's parts
    rho, _, z = geodetic_to_ecef(lat, 0.0, 0.0)
    _, _, (c_lat, _, s_lat) = enu_basis(lat, 0.0)
    lam = jnp.deg2rad(jnp.asarray(lon, dtype))
    rho, z, c_lat, s_lat = computed_once((rho, z, c_lat, s_lat), lat)
    c_lon, s_lon = computed_once((jnp.cos(lam), jnp.sin(lam)), lon)
    xp = (rho * c_lon, rho * s_lon, z)  # z broadcasts along the row
    up = (c_lat * c_lon, c_lat * s_lon, s_lat)
    xm = geodetic_to_ecef(masses.lat, masses.lon, -jnp.asarray(masses.depth, dtype=dtype))
    d = [a[..., None] - b for a, b in zip(xp, xm, strict=True)]
    inv_l = jax.lax.rsqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    k = constants.G_NEWTON * jnp.asarray(masses.mass, dtype=dtype) * inv_l**3
    g = sum(jnp.sum(k * di, axis=-1) * u for di, u in zip(d, up, strict=True)) / constants.MGAL
    (g,) = computed_once((g,), g)
    return g


def cell_values(field, step, dn, de, measurement, span_m=None):
    """The reading each cell predicts, ``(G, G)`` (mGal): the map at the INS position
    minus the cell's position error (``dn``, ``de``: an ``ij`` meshgrid, m).

    ``measurement(field, x, lat, lon)`` with ``x`` holding the cell's offset and zero
    bias. With the library's measurement the cells' true latitudes depend on the row
    only and their longitudes on the column only, which two fast paths use: paper D's
    point masses (:func:`point_mass_cells`), and a
    :class:`~jaxgrav.prepared.PreparedMap` (a Grid as
    :func:`~jaxgrav.filters.model.run_filter` passes it) evaluated separably on the
    cells' lattice (:func:`jaxgrav.lattice.lattice_values`, a block of map nodes of
    static size from ``span_m``, the largest extent of the cells per axis in metres;
    equal to point-by-point bicubic sampling, NaN off the map and in cells with a
    missing node; tested). Otherwise, or when the block would not fit the map, the
    cells are sampled one by one.
    """
    if measurement is gravity_measurement and isinstance(field, (PointMasses, PreparedMap)):
        lat, lon = apply_drift(step.lat, step.lon, -dn[:, 0], -de[0, :])  # (G,) each
        if isinstance(field, PointMasses):
            return point_mass_cells(field, lat[:, None], lon[None, :])
        block = lattice_block(field.grid, span_m)
        if block is not None:
            # the lattice ascends (north offsets ascend, so latitudes descend); the
            # longitudes are wrapped once, at the easternmost cell, then run on linearly
            # (wrapped one by one, cells across the map's west edge would jump by 360°)
            iy, _ = field.grid.fractional_index(lat[::-1], step.lon)
            _, ix_east = field.grid.fractional_index(step.lat, lon[0])
            ix = ix_east - (lon[0] - lon[::-1]) / field.grid.dlon
            v, in_y, in_x = lattice_values(field.interleaved(), iy[None], ix[None], block,
                                           nan_cells=True)
            v = jnp.where(in_y[0][:, None] & in_x[0][None, :], v[0], jnp.nan)
            return v[::-1, ::-1]
    x = jnp.zeros(N_STATES, dn.dtype)

    def one(a, b):
        return measurement(field, x.at[0].set(a).at[1].set(b), step.lat, step.lon)

    return jax.vmap(jax.vmap(one))(dn, de)


def weigh_cells(w, lik, on_map, field, step, dn, de, missing):
    """The cells' weights times the reading's likelihood, not normalised, ``(G, G)``.

    Parameters
    ----------
    w, lik : Array, shape ``(G, G)``
        Weights, and the likelihood of the reading in each cell with a known map value.
    on_map : Array of bool, shape ``(G, G)``
        The cell's map value is known (:func:`cell_values` finite).
    field, step, dn, de
        As :func:`cell_values` (to tell a missing node from a cell off the map).
    missing : {"gaps", "land"}
        See :data:`MISSING`.
    """
    w_on = jnp.where(on_map, w, 0.0)
    lik_gap = jnp.sum(w_on * lik) / jnp.maximum(jnp.sum(w_on), jnp.finfo(w.dtype).tiny)
    land = jnp.zeros(on_map.shape, bool)
    if missing == "land" and isinstance(field, PreparedMap):
        # land where the cell's nearest node is missing: a cell beside a missing node
        # (a corner of its interpolation cell, up to a node spacing seaward) is a gap
        grid = field.grid
        lat, lon = apply_drift(step.lat, step.lon, -dn[:, 0], -de[0, :])
        iy, ix = grid.fractional_index(lat[:, None], lon[None, :])
        inside = grid.contains(lat[:, None], lon[None, :])
        iy = jnp.clip(jnp.round(iy), 0, grid.ny - 1).astype(jnp.int32)
        ix = jnp.clip(jnp.round(ix), 0, grid.nx - 1).astype(jnp.int32)
        land = ~on_map & inside & ~jnp.isfinite(jnp.asarray(grid.values)[iy, ix])
    return w * jnp.where(on_map, lik, jnp.where(land, 0.0, lik_gap))


def lattice_block(grid, span_m, largest=64):
    """Nodes per axis of a map block that holds any lattice of cells spanning ``span_m``
    metres per axis (static), or None when there is none (no ``span_m``, a map global in
    longitude, within 1° of a pole, or a block larger than ``largest`` or the map).

    Bounds: a row spans at least ``a (1 − e²) · dlat`` (the meridian radius's minimum),
    a column at least ``a cos φ_max · dlon`` at the map's highest latitude plus half the
    span. :func:`~jaxgrav.lattice.lattice_values` has no run-time check of the span: the
    caller's cells must never be wider than ``span_m`` allows (the point-mass filter's
    largest cell, fixed or adaptive, times ``G − 1``).
    """
    span_m = None if span_m is None else concrete(span_m)
    if span_m is None or span_m.dtype == object or grid.nx * grid.dlon >= 359.0:
        return None
    top = max(abs(grid.lat0), abs(grid.lat0 + (grid.ny - 1) * grid.dlat))
    # the cells' longitudes are converted at the INS latitude, which may lie up to half
    # the span beyond the map while some cells are on it
    top += float(span_m) / 2.0 / (WGS84_A * (1.0 - WGS84_E2)) / DEG
    if top >= 89.0:
        return None
    row_m = WGS84_A * (1.0 - WGS84_E2) * grid.dlat * DEG
    col_m = WGS84_A * math.cos(top * DEG) * grid.dlon * DEG
    block = math.ceil(float(span_m) / min(row_m, col_m)) + 3
    return block if block <= min(largest, grid.ny, grid.nx) else None


def mix_cells(a_n, a_e, w0, cell0, tiny=1e-13, dtype=None):
    """Weights and per-cell Gaussians carried through the separable kernels ``a_n``, ``a_e``.

    ``w = a_n w0 a_eᵀ`` and each cell's moments matched from the mixed channels
    ``w·m``, ``w·(s + m²)`` (and, with a map error, its mean, variance and covariance
    with the bias), the means taken about the mixture's (``m − m̄``: no cancellation of
    a large mean's square); a cell below ``tiny`` of the total weight (where the channels
    are rounding noise) takes the global moments. The channels are stacked along the
    middle axis, ``(G, C, G)``, so that both products are plain matrix products of the
    stack (no transposes between them).

    Parameters
    ----------
    a_n, a_e : Array, shape ``(G, G)``
        Kernels along north and east (new cell index first).
    w0 : Array, shape ``(G, G)``
        Weights.
    cell0 : list of Array
        Per-cell arrays in :func:`cell_fields` order.
    tiny : float
        See above.
    dtype : dtype, optional
        Of the two products (e.g. float32: twice the speed on a CPU); the channels are
        formed and the moments taken in ``w0``'s dtype. None: ``w0``'s.

    Returns
    -------
    w : Array, shape ``(G, G)``
        Normalised.
    cell : list of Array
    """
    glob = global_moments(w0, cell0)
    m0, s0 = cell0[0] - glob[0], cell0[1]
    chans = [w0, w0 * m0, w0 * (s0 + m0**2)]
    has_err = len(cell0) > 2
    if has_err:
        em, ev, ec = cell0[2] - glob[2], cell0[3], cell0[4]
        chans += [w0 * em, w0 * (ev + em**2), w0 * (ec + m0 * em)]
    out = w0.dtype
    dtype = out if dtype is None else dtype
    x = jnp.stack(chans, 1).astype(dtype)  # (G, C, G)
    y = jnp.einsum("ij,jck->ick", a_n.astype(dtype), x) @ a_e.T.astype(dtype)
    w, wm, wm2, *we = (y[:, c, :].astype(out) for c in range(len(chans)))
    total = w.sum()
    small = w <= tiny * total  # the channels' rounding is relative to the total mass
    safe = jnp.where(small, 1.0, w)
    dm = jnp.where(small, 0.0, wm / safe)
    m = glob[0] + dm
    s = jnp.where(small, glob[1], jnp.clip(wm2 / safe - dm**2, 1e-12, None))
    cell = [m, s]
    if has_err:
        de = jnp.where(small, 0.0, we[0] / safe)
        ev = jnp.where(small, glob[3], jnp.clip(we[1] / safe - de**2, 1e-12, None))
        ec = jnp.where(small, glob[4], we[2] / safe - dm * de)
        # keep each cell's 2 x 2 covariance positive semi-definite after round-off
        lim = jnp.sqrt(s * ev)
        cell += [glob[2] + de, ev, jnp.clip(ec, -lim, lim)]
    return w / total, cell
