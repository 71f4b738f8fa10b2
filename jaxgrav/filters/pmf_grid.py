"""The point-mass filter's adaptive grid: how it is re-sized and carried to new cells.

An adaptive grid (:func:`~jaxgrav.filters.pmf.pmf` with ``adapt_span``) keeps each axis
spanning between ``±adapt_span`` σ and ``±REGRID_RATIO · adapt_span`` σ of its weights
(and every cell weighing more than a threshold, so that a distant mode stays on it);
off that band it is re-sized to the band's top (:data:`BAND`). Its cells are also kept
small enough to resolve the map where the weights are (:func:`resolving_cell`): a cell
over which the map changes by more than a fraction of a reading's 1-σ samples the
likelihood too coarsely. Re-sizing carries the weights and the per-cell Gaussians to the
new cells by a hat kernel (:func:`regrid_matrix`, :func:`regrid_cells`).
"""

import jax
import jax.numpy as jnp

from jaxgrav._validate import concrete
from jaxgrav.filters.pmf_cells import cell_fields, grid_moments, mix_cells, with_cells

__all__ = ["BAND", "REGRID_RATIO", "check_adaptive", "regrid_cells", "regrid_matrix",
           "resize_cells", "resolving_cell", "wanted_cell"]

REGRID_RATIO = 1.4
"""The width of an adaptive grid's band: it spans between ``±adapt_span`` σ and
``±REGRID_RATIO · adapt_span`` σ of its weights per axis."""

BAND = (1.0, REGRID_RATIO, REGRID_RATIO)
"""An adaptive grid's band (lower edge, upper edge, target), in units of the cell that
spans ``±adapt_span`` σ: off the band, the cell is re-sized to the target, the band's
top, so that a grid that grows with the spread starts at the top and a spread of
``REGRID_RATIO`` in σ passes before it is re-sized again. (Until 2026-12-07 the band was
``(1/1.4, 1.4, 1)``: a grid meant to span ±4 σ spanned as little as ±2.9 σ before it
grew, and the spread had already reflected mass off its edges: every voyage was flagged
``grid_edge``.)"""


def regrid_matrix(old_centre, old_cell, new_centre, new_cell, n):
    """Weights of ``n`` new nodes from ``n`` old ones along one axis, ``(n, n)``.

    A hat of half-width ``max(old_cell, new_cell)``: linear interpolation when the
    grid is refined, each new cell gathering the mass about it when coarsened (rows
    not normalised: the caller renormalises the weights).
    """
    i = jnp.arange(n) - (n - 1) / 2
    old = old_centre + i * old_cell
    new = new_centre + i * new_cell
    h = jnp.maximum(old_cell, new_cell)
    return jnp.maximum(0.0, 1.0 - jnp.abs(new[:, None] - old[None, :]) / h)


def regrid_cells(state, mean, target, tiny=1e-13):
    """``state`` on the grid of cell ``target`` centred at ``mean``.

    Parameters
    ----------
    state : PMFState
        With its ``cell`` (m, north and east) set.
    mean, target : Array, shape ``(2,)``
        The new grid's centre (m) and cell size (m), north and east.
    tiny : float
        As in :func:`mix_cells`.

    Returns
    -------
    new : PMFState
        Weights and per-cell Gaussians carried by :func:`regrid_matrix` (normalised),
        the grid shifted so that the weights' mean stays ``mean``. Old cells outside
        the new grid are dropped: size it with :func:`wanted_cell` to keep the mass.
    """
    n = state.w.shape[0]
    i = jnp.arange(n) - (n - 1) / 2
    r_n, r_e = (regrid_matrix(state.centre[k], state.cell[k], mean[k], target[k], n)
                for k in (0, 1))
    w, cell = mix_cells(r_n, r_e, state.w, cell_fields(state), tiny)
    # the interpolated weights' mean, off by a fraction of a cell, put back where it was
    moved = jnp.stack([jnp.sum(w.sum(1) * i), jnp.sum(w.sum(0) * i)]) * target
    centre = mean - moved
    return with_cells(state._replace(w=w, centre=centre, cell=target), cell)


def resize_cells(state, where, span, bounds, keep, ratio=REGRID_RATIO, tiny=1e-13, band=BAND):
    """An adaptive grid re-sized to span ``±span`` σ of its weights (and every cell
    weighing more than ``keep``), cells clipped to ``bounds`` (m) and kept below
    ``state.cell_cap`` (the map's resolution) where there is one.

    The cell is re-sized when it leaves the band ``band[:2]`` of the wanted cell (in
    units of the cell that spans ``±span`` σ; below the cap divided by ``ratio`` or above
    the cap when the cap is the smaller), to ``band[2]`` times it (or the cap).
    ``where``: the cells' position errors ``(dn, de)`` (:func:`regrid_cells`,
    :func:`wanted_cell`).
    """
    c = state.cell
    mean, cov = grid_moments(state.w, *where, c)
    wanted = jnp.clip(wanted_cell(state.w, where, mean, cov, span, keep), *bounds)
    cap = jnp.full_like(c, jnp.inf) if state.cell_cap is None else state.cell_cap
    lo, hi = jnp.minimum(band[0] * wanted, cap / ratio), jnp.minimum(band[1] * wanted, cap)
    target = jnp.clip(jnp.minimum(band[2] * wanted, cap), *bounds)
    new = regrid_cells(state, mean, target, tiny)
    go = jnp.any((c < lo * (1.0 - 1e-9)) | (c > hi * (1.0 + 1e-9))) & jnp.any(
        jnp.abs(target - c) > 1e-9 * c)
    return jax.tree.map(lambda a, b: jnp.where(go, a, b), new, state)


def resolving_cell(w, g, var, cell, per_sigma=1.0):
    """The largest cell (m, north and east) over which the map changes by at most
    ``per_sigma`` of a reading's predictive 1-σ, where the weights are.

    ``g``: the cells' map values ``(G, G)`` (NaN off the map); ``var``: the reading's
    predictive variance per cell (mGal²); ``cell``: the current cell size (m, north and
    east). The change per cell is the weighted RMS of the differences between
    neighbouring cells along each axis; a flat map (no change) gives ``inf``.
    """
    var = jnp.broadcast_to(var, g.shape)
    sigma = jnp.sqrt(jnp.sum(w * jnp.where(jnp.isfinite(var), var, 0.0)))
    caps = []
    for axis in (0, 1):
        d = jnp.diff(g, axis=axis)
        n = d.shape[axis]
        pair = 0.5 * (jax.lax.slice_in_dim(w, 0, n, axis=axis)
                      + jax.lax.slice_in_dim(w, 1, n + 1, axis=axis))
        ok = jnp.isfinite(d)
        ms = jnp.sum(jnp.where(ok, pair * d**2, 0.0)) / jnp.maximum(
            jnp.sum(jnp.where(ok, pair, 0.0)), jnp.finfo(w.dtype).tiny)
        caps.append(jnp.where(ms > 0, cell[axis] * per_sigma * sigma
                              / jnp.sqrt(jnp.where(ms > 0, ms, 1.0)), jnp.inf))
    return jnp.stack(caps)


def wanted_cell(w, where, mean, cov, span, keep):
    """Cell size (m, north and east) for the grid to span ``±span`` σ of the weights and
    every cell weighing more than ``keep`` (a distant mode stays on the grid).

    ``where`` are the cells' position errors ``(dn, de)``, ``(G, G)`` each; ``mean``,
    ``cov`` the weights' moments (:func:`grid_moments`).
    """
    reach = [jnp.max(jnp.where(w > keep, jnp.abs(a - mean[k]), 0.0))
             for k, a in enumerate(where)]
    return (jnp.maximum(2.0 * span * jnp.sqrt(jnp.diagonal(cov)), 2.0 * jnp.stack(reach))
            / (w.shape[0] - 1))


def check_adaptive(span, min_cell_m, max_cell_m, resolve=None):
    """ValueError unless ``span > 0``, ``0 < min_cell_m <= max_cell_m`` and ``resolve``
    None or > 0 (where concrete)."""
    if resolve is not None:
        r = concrete(resolve)
        if r is not None and r.dtype != object and not (r.size == 1 and float(r) > 0):
            raise ValueError(f"resolve must be a number > 0 (reading 1-sigma per cell) or "
                             f"None; got {resolve!r}")
    vals = [concrete(v) for v in (span, min_cell_m, max_cell_m)]
    if any(v is None or v.dtype == object for v in vals):
        return  # traced: checked where the numbers are made
    span, lo, hi = (float(v) for v in vals)
    if not (span > 0 and 0 < lo <= hi):
        raise ValueError("an adaptive grid needs adapt_span > 0 and 0 < min_cell_m <= "
                         f"max_cell_m (m); got {span:g}, {lo:g}, {hi:g}")
