"""The point-mass filter's cell grid: diffusion kernel, moments, per-cell Gaussians.

Helpers of :mod:`jaxgrav.filters.pmf`: the zero-flux diffusion kernel of its prediction,
the grid's position moments, whole-cell shifts, the point-mass anomaly on a separable
cell grid, and the per-cell Gaussians (the gravimeter bias and, optionally, a map error
with its covariance with the bias) with their mixture moments.
"""

import jax
import jax.numpy as jnp

from jaxgrav import constants
from jaxgrav.geodesy import enu_basis, geodetic_to_ecef

__all__ = ["cell_fields", "diffusion_kernel", "global_moments", "grid_moments",
           "point_mass_cells", "shift_axis", "with_cells"]


def _neumann_basis(n):
    """Orthonormal cosine basis and eigenvalues of the zero-flux second difference on n cells."""
    i = jnp.arange(n)[:, None] + 0.5
    k = jnp.arange(n)[None, :]
    v = jnp.cos(jnp.pi * k * i / n) * jnp.where(k == 0, jnp.sqrt(1.0 / n), jnp.sqrt(2.0 / n))
    lam = -4.0 * jnp.sin(jnp.pi * jnp.arange(n) / (2 * n)) ** 2
    return v, lam


def diffusion_kernel(n, v):
    """Diffusion kernel ``exp(v/2 · L)`` on ``n`` cells with zero-flux edges.

    Parameters
    ----------
    n : int
        Cells (static).
    v : Array, shape ``()``
        Variance of the spread in cells² (any ``v ≥ 0``).

    Returns
    -------
    Array, shape ``(n, n)``
        ``A[i, j]``: share of cell ``j``'s mass that moves to cell ``i``. Entries
        are ``≥ 0`` (round-off negatives clipped) and each column sums to 1.
    """
    basis, lam = _neumann_basis(n)
    a = (basis * jnp.exp(0.5 * jnp.maximum(v, 0.0) * lam)) @ basis.T
    a = jnp.maximum(a, 0.0)
    return a / a.sum(0, keepdims=True)


def grid_moments(w, dn, de, cell_m):
    mean = jnp.array([jnp.sum(w * dn), jnp.sum(w * de)])
    cn, ce = dn - mean[0], de - mean[1]
    cne = jnp.sum(w * cn * ce)
    cov = jnp.array([[jnp.sum(w * cn * cn), cne], [cne, jnp.sum(w * ce * ce)]])
    return mean, cov + jnp.eye(2) * cell_m**2 / 12.0


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


def with_cells(state, cell):
    """``state`` with the per-cell arrays of :func:`cell_fields` replaced."""
    names = ("bias_mean", "bias_var", "err_mean", "err_var", "err_cross")
    return state._replace(**dict(zip(names, cell, strict=False)))


def shift_axis(a, k, fill, axis):
    """``a`` shifted by ``k`` cells along ``axis`` (``out[i] = a[i + k]``), ``fill`` outside."""
    n = a.shape[axis]
    idx = jnp.arange(n) + k
    ok = (idx >= 0) & (idx < n)
    out = jnp.take(a, jnp.clip(idx, 0, n - 1), axis=axis)
    ok = ok[:, None] if axis == 0 else ok[None, :]
    return jnp.where(ok, out, fill)


def point_mass_cells(masses, lat, lon):
    """Anomaly (mGal) of point masses on the separable cell grid ``lat (G, 1) × lon (1, G)``.

    The same physics as :func:`~jaxgrav.fields.pointmass.gravity_anomaly`, with the
    trigonometry of the cells' latitudes and longitudes done per row and per column
    (``2G`` instead of ``G²`` evaluations).
    """
    dtype = jnp.result_type(float)
    xp = geodetic_to_ecef(lat, lon, 0.0)
    xm = geodetic_to_ecef(masses.lat, masses.lon, -jnp.asarray(masses.depth, dtype=dtype))
    d = [a[..., None] - b for a, b in zip(xp, xm, strict=True)]
    inv_l = jax.lax.rsqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    k = constants.G_NEWTON * jnp.asarray(masses.mass, dtype=dtype) * inv_l**3
    _, _, up = enu_basis(lat, lon)
    return sum(jnp.sum(k * di, axis=-1) * u for di, u in zip(d, up, strict=True)) / constants.MGAL
