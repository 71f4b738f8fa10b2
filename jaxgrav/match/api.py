"""Validated entry point for matching one track: :func:`match_track`.

The jitted cores (:func:`~jaxgrav.match.dense.match_dense`,
:func:`~jaxgrav.match.correlation.match_chains`) take one track and are meant to be
vmapped; they cannot raise. This wrapper checks the inputs first, sizes the search
to the INS drift, applies the velocity-based Eötvös correction when velocities are
given, runs the matcher and turns its status flags into warnings.
"""

import dataclasses
import math
import warnings

import jax.numpy as jnp
import numpy as np

from jaxgrav._validate import check_latitude
from jaxgrav.geodesy import eotvos
from jaxgrav.match.correlation import ChainConfig, chain_tolerances, match_chains
from jaxgrav.match.dense import DenseConfig, match_dense
from jaxgrav.match.lattice_chains import stencil_size_for, stencil_size_for_step
from jaxgrav.match.result import status_messages

__all__ = ["METHODS", "MIN_FIXES", "config_for", "match_track"]

METHODS = ("dense", "chains")
"""``dense``: offset grid + Gauss–Newton (default, most accurate on real maps);
``chains``: paper A's iso-point chains with constraint elimination."""

MIN_FIXES = 5
"""Fewest fixes a track may have (paper A uses N ≥ 10)."""


def config_for(method, grid, drift_radius_m, *, noise_mgal=1.0, bias_sigma_mgal=math.inf,
               n_rotations=1, score=None, step_m=None):
    """A matcher configuration whose search region covers the drift.

    Parameters
    ----------
    method : {"dense", "chains"}
    grid : Grid
        The map that will be matched (for ``chains``, the refined one).
    drift_radius_m : float
        Largest expected INS drift (m); the search reaches 1.2× this.
    noise_mgal : float
        Reading noise σ (mGal).
    bias_sigma_mgal : float
        Prior σ of the reading bias (mGal); ``inf`` estimates it freely.
    n_rotations : int
        Heading errors tried by the dense path (1 = none).
    score : str, optional
        Score form; default ``"bias"`` (dense) or ``"difference"`` (chains, the paper's).
    step_m : float, optional
        ``chains``: the distance between consecutive fixes (m). When given, the
        chain search uses the displacement stencil
        (:attr:`~jaxgrav.match.correlation.ChainConfig.stencil_size`) sized for such
        steps in any direction; otherwise the pairwise search on ``capacity`` slots.

    Returns
    -------
    DenseConfig or ChainConfig
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    if not drift_radius_m > 0:
        raise ValueError(f"drift_radius_m must be positive (m); got {drift_radius_m!r}")
    reach = 1.2 * float(drift_radius_m)
    dy, dx = grid.spacing_m()
    if method == "dense":
        spacing = min(max(min(dy, dx) / 8.0, 50.0), reach / 3.0)
        half = math.ceil(reach / spacing)
        if half > 40:
            half, spacing = 40, reach / 40
        return DenseConfig(spacing_m=spacing, half_size=half, noise_mgal=noise_mgal,
                           bias_sigma_mgal=bias_sigma_mgal, n_rotations=n_rotations,
                           score=score or "bias")
    half = math.ceil(reach / min(dy, dx))
    if 2 * half + 1 > min(grid.ny, grid.nx):
        raise ValueError(
            f"drift_radius_m={drift_radius_m!r} needs a search window of {2 * half + 1} nodes, "
            f"larger than the {grid.ny}x{grid.nx} map")
    config = ChainConfig(half_size=half, capacity=min((2 * half + 1) ** 2, 384),
                         delta=2.0 * noise_mgal, score=score or "difference")
    if step_m is None:
        return config
    if not step_m >= 0:
        raise ValueError(f"step_m must be a distance >= 0 (m); got {step_m!r}")
    # the largest tolerance on the map: the node allowance grows with the cell diagonal
    tols = [chain_tolerances(grid, la, config) for la in (grid.lat0, grid.extent[3])]
    step_tol, angle_tol = max(float(t[0]) for t in tols), float(tols[0][1])
    size = stencil_size_for_step(grid, float(step_m), step_tol, angle_tol)
    return dataclasses.replace(config, stencil_size=size)


def _validate(grid, lat, lon, readings):
    lat, lon, readings = (np.asarray(a, dtype=float) for a in (lat, lon, readings))
    for name, a in (("lat", lat), ("lon", lon), ("readings", readings)):
        if a.ndim != 1:
            raise ValueError(f"{name} must be 1-D (one value per fix); got shape {a.shape}")
    if not lat.size == lon.size == readings.size:
        raise ValueError(f"lat, lon and readings must have equal lengths; got {lat.size}, "
                         f"{lon.size}, {readings.size}")
    if lat.size < MIN_FIXES:
        raise ValueError(f"the track is too short: {lat.size} fixes, need at least {MIN_FIXES}")
    for name, a in (("lon", lon), ("readings", readings)):
        bad = ~np.isfinite(a)
        if bad.any():
            raise ValueError(f"{name} has {int(bad.sum())} NaN/inf value(s), first at fix "
                             f"{int(np.flatnonzero(bad)[0])}; matching needs a value at every fix")
    check_latitude(lat, "lat")
    inside = np.asarray(grid.contains(lat, lon))
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        w, e, s, n = grid.extent
        raise ValueError(f"the track leaves the map: fix {i} at ({lat[i]:.5f}, {lon[i]:.5f}) is "
                         f"outside lat {s}..{n}, lon {w}..{e} ({int((~inside).sum())} fixes off)")
    return lat, lon, readings


def match_track(grid, lat, lon, readings, *, method="dense", drift_radius_m=5000.0,
                v_east=None, v_north=None, noise_mgal=1.0, bias_sigma_mgal=None, config=None,
                warn=True):
    """Match one track against a map, with input checks (the public entry point).

    Parameters
    ----------
    grid : Grid
        Anomaly map (mGal). For ``method="chains"`` refine it first to the node
        spacing wanted (paper A: 0.005°, ``grid.refine(100)`` of a 0.5° map).
    lat, lon : array_like, shape ``(N,)``
        INS-indicated fixes (degrees), N ≥ :data:`MIN_FIXES`.
    readings : array_like, shape ``(N,)``
        Gravimeter anomaly readings (mGal), without Eötvös correction if velocities
        are given.
    method : {"dense", "chains"}
    drift_radius_m : float
        Largest expected INS drift (m); sizes the search.
    v_east, v_north : array_like, optional
        INS velocity (m/s). When given, readings are Eötvös-corrected with it and the
        bias prior defaults to 3 mGal (velocity error of about 0.2 m/s plus
        gravimeter bias); otherwise the bias is estimated freely.
    noise_mgal : float
        Reading noise σ (mGal).
    bias_sigma_mgal : float, optional
        Prior σ of the remaining bias (mGal), overriding the default above.
    config : DenseConfig or ChainConfig, optional
        Full control; replaces the sizing from ``drift_radius_m`` and the noise.
    warn : bool
        Emit a ``RuntimeWarning`` for each status flag raised.

    Returns
    -------
    MatchResult

    Raises
    ------
    ValueError
        Unknown method, mismatched lengths, too short a track, NaN readings, a
        track off the map.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    lat, lon, readings = _validate(grid, lat, lon, readings)
    corrected = v_east is not None and v_north is not None
    if corrected:
        ve, vn = (np.broadcast_to(np.asarray(v, float), lat.shape) for v in (v_east, v_north))
        if not (np.isfinite(ve).all() and np.isfinite(vn).all()):
            raise ValueError("v_east and v_north must be finite at every fix")
        readings = readings + np.asarray(eotvos(lat, ve, vn))
    if bias_sigma_mgal is None:
        bias_sigma_mgal = 3.0 if corrected else math.inf
    if config is None:
        config = config_for(method, grid, drift_radius_m, noise_mgal=noise_mgal,
                            bias_sigma_mgal=bias_sigma_mgal)
        if method == "chains":  # the displacement stencil, sized for this track
            tol = (float(v) for v in chain_tolerances(grid, lat, config))
            config = dataclasses.replace(config,
                                         stencil_size=stencil_size_for(grid, lat, lon, *tol))
    fn = match_dense if method == "dense" else match_chains
    result = fn(grid, jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(readings), config)
    if warn:
        for msg in status_messages(int(result.status)):
            warnings.warn(f"match_track: {msg}", RuntimeWarning, stacklevel=2)
    return result
