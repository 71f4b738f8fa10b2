"""The matchers of the loosely coupled loop: their settings and one segment's match.

:func:`matcher_config` builds a matcher's settings as :func:`~jaxgrav.navigate.loose.loose_config`
uses them; :func:`match_segment` matches one corrected segment with the search spread
over the segment's reach and the Eötvös error of the filter's velocity told beside the
map's error.

The Eötvös error of the filter's velocity is not a map error: the navigation INS's
velocity error oscillates at the Schuler rate ω_s = √(g/R) (84 min), so along a track
sailed at speed v it varies over ``v/ω_s`` (4.1 km at 10 kn), not over the map error's
L (10 km). Every matcher, each of which reads one correlated error, is told the sum of
the two as one Gauss–Markov process of the same variance and the same slope variance
(:func:`told_error`): told with the map's L, the Eötvös error's faster wiggles were
explained by shifting the track, and the fixes were centred off the truth with a
covariance too small for it (``examples/voyage_loose.py --calibrate``).
"""

import dataclasses
import math

import jax.numpy as jnp

from jaxgrav._linalg import inv_2x2
from jaxgrav.constants import DEG, MGAL, WGS84_MEAN_RADIUS
from jaxgrav.fields.map_error import map_error
from jaxgrav.geodesy import (
    eotvos_jacobian,
    meridian_radius,
    normal_gravity,
    prime_vertical_radius,
)
from jaxgrav.match.combined import match_entropy_iccp
from jaxgrav.match.correlation import ChainConfig, match_chains
from jaxgrav.match.dense import DenseConfig, match_dense
from jaxgrav.match.entropy import EntropyConfig
from jaxgrav.match.sizing import FAR_FIX_RADII, chain_grid, config_for, iccp_config_for
from jaxgrav.prepared import prepare_map

__all__ = ["CHAIN_REACH_M", "LOOSE_MATCHERS", "LOOSE_MAX_EDGE_MASS", "eotvos_sigma", "loose_map",
           "match_segment", "matcher_config", "schuler_length_m", "segment_error_covariance",
           "told_error"]

LOOSE_MATCHERS = ("dense", "chains", "entropy+iccp")
"""Matchers of the loop: the dense offset grid (GLS score, Gauss–Newton), paper A's
iso-point chains on a refined map (a fixed window of nodes), or paper B's entropy coarse
search and ICCP fine match (the reading bias marginalised)."""

CHAIN_REACH_M = 8000.0
"""Reach (m) of the chain matcher's fixed window about each fix (:func:`matcher_config`):
the Rayleigh 99.9 % reach of a 2.1 km position 1-σ."""


LOOSE_MAX_EDGE_MASS = 0.2
"""A loop fix with more than this share of its posterior on the search region's edge is
rejected (status 4096): the likelihood goes on beyond the region, so the fix and its
covariance, cut there, are not what the readings say. Every matcher of the loop is
given it as ``max_edge_mass`` (:func:`matcher_config`)."""


def loose_map(grid, matcher):
    """The map the loop reads for ``matcher``.

    Parameters
    ----------
    grid : Grid or PreparedMap
        The anomaly map.
    matcher : {"dense", "chains", "entropy+iccp"}

    Returns
    -------
    Grid or PreparedMap
        ``chains``: the map refined to :data:`~jaxgrav.match.sizing.CHAIN_NODE_DEG` nodes
        (:func:`~jaxgrav.match.sizing.chain_grid`; its nodes are the candidates, no spline
        needed); the others: the map with its bicubic spline prepared once.
    """
    if matcher not in LOOSE_MATCHERS:
        raise ValueError(f"matcher must be one of {LOOSE_MATCHERS}; got {matcher!r}")
    return chain_grid(grid) if matcher == "chains" else prepare_map(grid)


def eotvos_sigma(lat, v_east, v_north, vel_cov):
    """σ (mGal) of the Eötvös correction from a velocity of covariance ``vel_cov``.

    Parameters
    ----------
    lat, v_east, v_north : Array
        Position (degrees) and velocity (m/s).
    vel_cov : Array, shape ``(2, 2)``
        Covariance of the velocity error, north then east (m²/s²).
    """
    jac = eotvos_jacobian(lat, v_east, v_north)
    return jnp.sqrt(jac @ vel_cov @ jac)


def schuler_length_m(speed, lat):
    """Along-track correlation length (m) of an error oscillating at the Schuler rate.

    A velocity error ``cos(ω_s t)`` read along a track sailed at ``speed`` and a second-order
    Gauss–Markov covariance ``(1 + d/L) e^{−d/L}`` have the same curvature at zero lag
    (the same slope variance) when ``L = speed / ω_s``, ``ω_s = √(g/R)``.

    Parameters
    ----------
    speed : Array
        Ground speed (m/s).
    lat : Array
        Latitude (degrees) of the normal gravity g.

    Returns
    -------
    Array
        ``L`` (m); 0 at rest (the error then varies in time only: white along the fixes).
    """
    rate = jnp.sqrt(normal_gravity(lat) * MGAL / WGS84_MEAN_RADIUS)  # rad/s
    return jnp.abs(speed) / rate


def told_error(map_sigma, map_length_m, eotvos_sigma, eotvos_length_m, order=2):
    """One Gauss–Markov error standing for the map's and the Eötvös error together.

    The variance is the sum; L gives the sum's slope variance: ``σ²/L² = Σ σ_k²/L_k²``
    (order 2, the curvature at zero lag) or ``σ²/L = Σ σ_k²/L_k`` (order 1, the slope
    at zero lag). An error of L = 0 (white) makes the sum white.

    Parameters
    ----------
    map_sigma, map_length_m : Array
        The map error told (mGal, m).
    eotvos_sigma, eotvos_length_m : Array
        The Eötvös error of the filter's velocity (mGal) and its length
        (:func:`schuler_length_m`; m).
    order : {1, 2}
        Gauss–Markov order of the told covariance.

    Returns
    -------
    sigma, length_m : Array
        mGal, m (``map_length_m`` when both σ are 0).
    """
    sigmas = jnp.stack([jnp.asarray(map_sigma, float), jnp.asarray(eotvos_sigma, float)])
    lengths = jnp.stack([jnp.asarray(map_length_m, float), jnp.asarray(eotvos_length_m, float)])
    var = jnp.sum(sigmas**2)
    p = 2 if order == 2 else 1
    safe = jnp.where(lengths > 0, lengths, 1.0)
    rough = jnp.sum(jnp.where(sigmas > 0, jnp.where(lengths > 0, sigmas**2 / safe**p, jnp.inf),
                              0.0))
    length = jnp.where(rough > 0, (var / jnp.where(rough > 0, rough, 1.0)) ** (1.0 / p), 0.0)
    return jnp.sqrt(var), jnp.where(var > 0, length, map_length_m)


def segment_error_covariance(grid, lat, lon, v_east, v_north, backward, h_mean, p,
                             conditional=False, cell_m=0.0):
    """Covariance (mGal²) of a corrected segment's reading error that the filter's error explains.

    Along a segment corrected with the filter's estimate, the residual INS error at fix k
    is ``e_k = B_k e`` (``B_k`` the block mean of ``F^{−j}`` over the fix's steps, ``e`` the
    residual now, of covariance ``p``). It leaves two reading errors, both linear in
    ``e``: the Eötvös error of the residual velocity, ``∂E/∂v · e_v,k``, and, once the
    matcher has taken out the segment's mean position error (the rigid offset it fits),
    the map misread by the position error's change along the segment (the stretch and
    bend of the segment), ``−∇m_k · (e_p,k − H̄ e)``. With ``G`` their rows the
    covariance is ``G p Gᵀ``, of rank at most 13: a few smooth trends along the segment,
    not a stationary error (which :func:`told_error` would tell).

    Parameters
    ----------
    grid : PreparedMap
        The map (its bicubic gradient, read at the corrected fixes).
    lat, lon, v_east, v_north : Array, shape ``(n,)``
        The corrected fixes (degrees) and their velocity (m/s).
    backward : Array, shape ``(n, 4, 13)``
        Rows north, east position and north, east velocity of ``B_k`` per fix.
    h_mean : Array, shape ``(2, 13)``
        ``H̄``, the segment's mean position error.
    p : Array, shape ``(13, 13)``
        The filter's covariance now.
    conditional : bool
        Static. True: the error given the segment's mean position error, which the
        matcher's offset ``o`` is (``H̄ e = −o``): covariance ``G P_c Gᵀ`` with
        ``P_c = P − P H̄ᵀ S⁻¹ H̄ P`` and mean ``K o``, ``K = −G P H̄ᵀ S⁻¹``
        (``S = H̄ P H̄ᵀ``).
    cell_m : float or Array
        The matcher's lattice spacing (m): the offset's place within a cell, uniform
        (``cell_m²/12`` per axis), read through the map's gradient, is added,
        ``cell_m²/12 ∇m ∇mᵀ``; 0 (default): nothing.

    Returns
    -------
    cov : Array, shape ``(n, n)``
    coupling : Array, shape ``(n, 2)`` or None
        ``K`` (mGal per m) when ``conditional``.
    """
    jac = eotvos_jacobian(lat, v_east, v_north)  # (n, 2): mGal per m/s, north then east
    _, d_lat, d_lon = grid.value_and_gradient(lat, lon)
    grad = jnp.stack([d_lat / (meridian_radius(lat) * DEG), d_lon / (
        prime_vertical_radius(lat) * jnp.cos(lat * DEG) * DEG)], -1)  # mGal per m
    grad = jnp.where(jnp.isfinite(grad), grad, 0.0)
    g = (jnp.einsum("ki,kij->kj", jac, backward[:, 2:4])
         - jnp.einsum("ki,kij->kj", grad, backward[:, :2] - h_mean[None]))
    coupling = None
    if conditional:
        ph = p @ h_mean.T
        s_inv = inv_2x2(h_mean @ ph)
        coupling = -(g @ ph) @ s_inv
        p = p - ph @ s_inv @ ph.T
    c = g @ p @ g.T + jnp.asarray(cell_m, g.dtype) ** 2 / 12.0 * (grad @ grad.T)
    return 0.5 * (c + c.T), coupling


def matcher_config(matcher, noise_mgal, map_error_mgal, map_error_length_m, grid=None,
                   step_m=None, chain_reach_m=CHAIN_REACH_M):
    """A loop matcher's settings (see :func:`~jaxgrav.navigate.loose.loose_config`).

    Parameters
    ----------
    matcher : {"dense", "chains", "entropy+iccp"}
    noise_mgal : float
        1-σ of one fix's reading (mGal; the mean of the readings it averages).
    map_error_mgal, map_error_length_m : float
        The map error told to the matcher (mGal, m); 0: the white-noise score.
    grid : Grid or PreparedMap, optional
        ``entropy+iccp``: the map (its cell sizes ICCP's window); ``chains``: the map the
        loop will be given (its nodes are the candidates: pass it refined,
        :func:`~jaxgrav.match.sizing.chain_grid`).
    step_m : float, optional
        ``chains``: the largest distance between consecutive fixes (m), which sizes the
        chain search's displacement stencil; None: the pairwise search.
    chain_reach_m : float
        ``chains``: the window's reach about each fix (m).

    Returns
    -------
    DenseConfig or ChainConfig or tuple of (EntropyConfig, IccpConfig)
    """
    if matcher not in LOOSE_MATCHERS:
        raise ValueError(f"matcher must be one of {LOOSE_MATCHERS}; got {matcher!r}")
    if matcher == "dense":
        return DenseConfig(noise_mgal=noise_mgal, map_error_mgal=map_error_mgal,
                           map_error_length_m=map_error_length_m, fix="posterior",
                           max_sigma_m=3000.0, max_edge_mass=LOOSE_MAX_EDGE_MASS, n_rotations=5,
                           max_rotation_deg=3.0, score_model="gls")
    if grid is None:
        raise ValueError(f"loose_config(matcher={matcher!r}) needs the grid (entropy+iccp: "
                         "its cell sizes ICCP's window; chains: its nodes are the candidates)")
    if matcher == "chains":
        if not chain_reach_m > 0:
            raise ValueError(f"chain_reach_m must be a positive distance (m); got "
                             f"{chain_reach_m!r}")
        told = map_error(map_error_mgal, map_error_length_m) if map_error_mgal > 0 else None
        config = config_for("chains", grid, chain_reach_m / 1.2, noise_mgal=noise_mgal,
                            step_m=step_m, map_error=told)
        return dataclasses.replace(config, map_error_length_m=map_error_length_m,
                                   fix="posterior", max_sigma_m=3000.0,
                                   max_edge_mass=LOOSE_MAX_EDGE_MASS,
                                   score_model="auto")  # the loop tells errors traced
    # sized for a nominal 1 km reach; the loop sets the spacing and window per segment
    iccp = iccp_config_for(grid, 1000.0, stage="fine", noise=noise_mgal, max_rotation_deg=3.0,
                           map_error=map_error(map_error_mgal, map_error_length_m),
                           bias_sigma=math.inf, fix="posterior", max_sigma_m=3000.0,
                           max_edge_mass=LOOSE_MAX_EDGE_MASS)
    return (EntropyConfig(half_size=20), iccp)


def match_segment(matcher, grid, lat, lon, g, reach, sigma_eotvos, spacing_bounds,
                  eotvos_length_m=None, reading_covariance=None, reading_coupling=None):
    """Match one corrected segment as the loop does.

    Parameters
    ----------
    matcher : DenseConfig or ChainConfig or tuple of (EntropyConfig, IccpConfig)
    grid : Grid or PreparedMap
    lat, lon, g : Array, shape ``(n_fixes,)``
        The corrected segment's fixes (degrees) and Eötvös-corrected readings (mGal).
    reach : Array
        The search's reach (m): the dense and entropy offset grids are spread over it
        (spacing ``reach / half_size`` within ``spacing_bounds``); the chain window is
        fixed.
    sigma_eotvos : Array
        1-σ (mGal) of the Eötvös error of the filter's velocity, told as a correlated
        error beside the map's (and, for chains, in the iso-value tolerance).
    spacing_bounds : tuple of float
        ``(min_spacing_m, max_spacing_m)``; the second static (the dense matcher compiles
        only the map reads that spacings up to it need,
        :attr:`~jaxgrav.match.dense.DenseConfig.spacing_bound_m`).
    eotvos_length_m : Array, optional
        The Eötvös error's along-track length (m, :func:`schuler_length_m`), told with
        the map error as one error (:func:`told_error`) to every matcher; None: the map
        error's L.
    reading_covariance : Array, shape ``(n_fixes, n_fixes)``, optional
        The dense matcher only: a further covariance of the readings' error
        (:func:`segment_error_covariance`), added to the GLS covariance
        (:attr:`~jaxgrav.match.dense.DenseConfig.reading_covariance`).
    reading_coupling : Array, shape ``(n_fixes, 2)``, optional
        The dense matcher only: the readings' error expected per metre of offset
        (:attr:`~jaxgrav.match.dense.DenseConfig.reading_coupling`).

    Returns
    -------
    MatchResult
    """
    chains, dense = isinstance(matcher, ChainConfig), isinstance(matcher, DenseConfig)
    # the offset grid's settings, and the settings that are told the map error
    offsets, told_to = (matcher, matcher) if chains or dense else matcher
    length_e = told_to.map_error_length_m if eotvos_length_m is None else eotvos_length_m
    told, length = told_error(told_to.map_error_mgal, told_to.map_error_length_m,
                              sigma_eotvos, length_e, told_to.map_error_order)
    if chains:  # a fixed window of map nodes
        delta = 2.0 * jnp.sqrt(matcher.noise_mgal**2 + told**2)  # as config_for's
        return match_chains(grid, lat, lon, g, dataclasses.replace(
            matcher, map_error_mgal=told, map_error_length_m=length, delta=delta))
    spacing = jnp.clip(reach / offsets.half_size, *spacing_bounds)
    if dense:
        return match_dense(grid, lat, lon, g, dataclasses.replace(
            matcher, spacing_m=spacing, map_error_mgal=told, map_error_length_m=length,
            spacing_bound_m=float(spacing_bounds[1]), reading_covariance=reading_covariance,
            reading_coupling=reading_coupling))
    entropy, iccp = matcher
    window = jnp.maximum(iccp.window_m, 1.2 * spacing * entropy.half_size)
    # a fix beyond 1.5 searched reaches is rejected (the config's own bound is for a
    # nominal 1 km reach)
    far = FAR_FIX_RADII * spacing * entropy.half_size
    return match_entropy_iccp(grid, lat, lon, g, dataclasses.replace(entropy, spacing_m=spacing),
                              dataclasses.replace(iccp, window_m=window, map_error_mgal=told,
                                                  map_error_length_m=length, max_offset_m=far))
