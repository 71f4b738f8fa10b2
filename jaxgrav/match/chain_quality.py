"""GLS scores, fix covariance and integrity decision of the chain matcher.

The pieces of :func:`~jaxgrav.match.correlation.match_chains` that say how good its
fix is (see that module's docstring): the chains' GLS scores with the node
quantisation counted as reading noise (:func:`chain_gls_scores`), the map gradient at
nodes (:func:`node_gradient`) and the posterior, covariance and integrity bits
(:func:`chain_quality`).
"""

import jax.numpy as jnp

from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match.fix_covariance import (
    gauss_newton_information,
    integrity_status,
    offset_covariance,
    second_mode_ratio,
    spread_about,
)
from jaxgrav.match.gls import (
    gls_dof,
    gls_score,
    gls_whitener,
    offset_posterior,
    track_covariance,
)

__all__ = ["chain_gls_scores", "chain_quality", "node_gradient"]


def chain_gls_scores(grid, lat, lon, readings, values, w, config, dtype):
    """GLS scores (χ²) and biases of chains' map values ``(K, N)``, and the whitener.

    Map values are read at nodes, up to half a cell from the positions they stand
    for: the noise of fix i gets ``node_allowance² · (g_n² dy² + g_e² dx²)/12`` more
    variance, g the map gradient at the node nearest the INS fix.
    """
    north, east = local_offsets_m(lat, lon, lat[0], lon[0])
    grad = node_gradient(grid, lat, lon)
    dy, dx = grid.spacing_m(lat)
    quant = config.node_allowance**2 * ((grad[:, 0] * dy) ** 2 + (grad[:, 1] * dx) ** 2) / 12.0
    noise = jnp.sqrt(jnp.maximum(jnp.asarray(config.noise_mgal, dtype), 1e-6) ** 2 + quant)
    cov = track_covariance(north.astype(dtype), east.astype(dtype), noise.astype(dtype),
                           config.map_error_mgal, config.map_error_length_m,
                           config.map_error_order, weights=w)
    wh = gls_whitener(cov)
    sigma_b = jnp.asarray(0.0 if config.score == "absolute" else jnp.inf, dtype)
    j, b = gls_score(wh, readings - values, sigma_b)
    mu = w / jnp.sum(w)
    scale = jnp.asarray(config.noise_mgal, dtype) ** 2 * jnp.sum(mu**2)  # mGal² per χ²
    return wh, j, b, sigma_b, scale


def node_gradient(grid, lat, lon):
    """Map gradient (mGal/m, north and east) at map nodes, by central differences."""
    iy, ix = grid.fractional_index(lat, lon)
    r, c = jnp.round(iy).astype(jnp.int32), jnp.round(ix).astype(jnp.int32)
    ny, nx = grid.values.shape
    rp, rm = jnp.clip(r + 1, 0, ny - 1), jnp.clip(r - 1, 0, ny - 1)
    cp, cm = jnp.clip(c + 1, 0, nx - 1), jnp.clip(c - 1, 0, nx - 1)
    r, c = jnp.clip(r, 0, ny - 1), jnp.clip(c, 0, nx - 1)
    dy, dx = grid.spacing_m(lat)
    v = grid.values
    g_n = (v[rp, c] - v[rm, c]) / ((rp - rm) * dy) * jnp.sign(grid.dlat)
    g_e = (v[r, cp] - v[r, cm]) / ((cp - cm) * dx) * jnp.sign(grid.dlon)
    return jnp.stack([g_n, g_e], axis=-1)


def chain_quality(grid, cands, index, best, j_gls, wh, sigma_b, readings, config):
    """Fix, covariance and integrity of the chain ``best`` among the programme's chains.

    With the displacement stencil (every window node a slot, the same slot the same node
    displacement at every fix) the posterior is taken over the window's rigid chains
    (slot j at every fix: the INS track shifted by a node displacement), which spans
    the whole search region; otherwise over the programme's ``k_posterior`` chains.
    """
    n = readings.shape[0]
    fix = jnp.arange(n)[None, :]
    dof = gls_dof(n, sigma_b)
    off_n = jnp.mean(cands.north_m[fix, index], axis=1)  # (K_dp,)
    off_e = jnp.mean(cands.east_m[fix, index], axis=1)
    chain_fix = jnp.stack([off_n[best], off_e[best]])
    lat_b, lon_b = cands.lat[jnp.arange(n), index[best]], cands.lon[jnp.arange(n), index[best]]
    info = gauss_newton_information(wh, node_gradient(grid, lat_b, lon_b), sigma_b)
    local = offset_covariance(info)
    dy, dx = grid.spacing_m(jnp.mean(lat_b))
    cell = jnp.diag(jnp.stack([dy, dx]) ** 2 / 12.0)
    if config.stencil_size > 0:  # rigid chains over the window
        j = gls_score(wh, readings[None, :] - cands.value.T, sigma_b)[0]
        on, oe = jnp.mean(cands.north_m, axis=0), jnp.mean(cands.east_m, axis=0)
        post = offset_posterior(j, on, oe, 0.0, dof=dof)
        mean = jnp.stack([post.mean_north_m, post.mean_east_m])
        second, edge, resolved = (post.second_mode_ratio, post.edge_mass,
                                  post.n_effective >= 3.0)
    else:
        j, on, oe = j_gls, off_n, off_e
        _, _, p = spread_about(j, on, oe, chain_fix[0], chain_fix[1])
        ok = jnp.isfinite(j)
        mean = jnp.stack([p @ jnp.where(ok, on, 0.0), p @ jnp.where(ok, oe, 0.0)])
        second = second_mode_ratio(j, on, oe, jnp.argmin(j), local)
        edge, resolved = jnp.asarray(jnp.nan, j.dtype), jnp.asarray(False)
    the_fix = mean if config.fix == "posterior" else chain_fix
    spread, n_eff, _ = spread_about(j, on, oe, the_fix[0], the_fix[1])
    cov = spread + cell + jnp.where(resolved, 0.0, local)
    cov = 0.5 * (cov + cov.T)  # exactly symmetric
    chi2 = j_gls[best] / dof
    status = integrity_status(cov, second, chi2, edge, config)
    return {"fix": the_fix, "covariance": cov, "n_effective": n_eff, "second_mode": second,
            "edge_mass": edge, "chi2_per_dof": chi2, "status": status}
