"""Validated entry point for matching one track, by any method: :func:`match_track`.

The jitted cores (:func:`~jaxgrav.match.dense.match_dense`,
:func:`~jaxgrav.match.correlation.match_chains`, :func:`~jaxgrav.match.entropy.match_entropy`,
:func:`~jaxgrav.match.iccp.match_iccp`, :func:`~jaxgrav.match.combined.match_entropy_iccp`)
take one track and are meant to be vmapped; they cannot raise. This wrapper checks the
inputs first, sizes the search to the INS drift, applies the velocity-based Eötvös
correction when velocities are given, prepares the map once
(:class:`~jaxgrav.prepared.PreparedMap`), runs the matcher and turns its status flags
(:data:`~jaxgrav.match.result.STATUS`) into warnings.
"""

import dataclasses
import math
import warnings

import jax.numpy as jnp
import numpy as np

from jaxgrav import executables
from jaxgrav._validate import check_latitude
from jaxgrav.geodesy import eotvos_jit
from jaxgrav.match.combined import match_entropy_iccp
from jaxgrav.match.correlation import ChainConfig, chain_tolerances, match_chains
from jaxgrav.match.dense import DenseConfig, match_dense
from jaxgrav.match.entropy import EntropyConfig, entropy_config_for, match_entropy
from jaxgrav.match.iccp import IccpConfig, match_iccp
from jaxgrav.match.lattice_chains import stencil_size_for
from jaxgrav.match.result import IMPLAUSIBLE_FIT, P_IMPLAUSIBLE, fit_p_value, status_messages
from jaxgrav.match.sizing import config_for, iccp_config_for
from jaxgrav.prepared import as_grid

__all__ = ["ENTROPY_HALF_SIZE", "MAP_ERROR_METHODS", "MASKED", "METHODS", "MIN_FIXES",
           "ins_over_missing", "match_track", "max_gap_fixes", "missing_in_reach",
           "missing_reading", "track_latitude", "validate_track"]

METHODS = ("dense", "chains", "entropy", "iccp", "entropy+iccp")
"""``dense``: offset grid + Gauss–Newton (default, most accurate on real maps);
``chains``: paper A's iso-point chains with constraint elimination; ``entropy``:
difference-entropy coarse match; ``iccp``: iterative closest contour point;
``entropy+iccp``: entropy coarse then ICCP fine (paper B)."""

MAP_ERROR_METHODS = ("dense", "chains", "entropy+iccp")
"""Methods that take ``map_error`` (a GLS score, a covariance and an integrity test)."""

MIN_FIXES = 5
"""Fewest fixes a track may have (paper A uses N ≥ 10)."""

ENTROPY_HALF_SIZE = 20
"""Default cap on entropy offsets per side in :func:`match_track`."""

_CONFIG_TYPES = {"dense": DenseConfig, "chains": ChainConfig, "entropy": EntropyConfig,
                 "iccp": IccpConfig}


def validate_track(grid, lat, lon, readings):
    """Check one track against a map; return it as float NumPy arrays.

    Parameters
    ----------
    grid : Grid or PreparedMap
    lat, lon : array_like, shape ``(N,)``
        Fixes (degrees).
    readings : array_like, shape ``(N,)``
        Measured values (map units).

    Returns
    -------
    tuple of numpy.ndarray
        ``(lat, lon, readings)``.

    Raises
    ------
    ValueError
        Not 1-D, mismatched lengths, fewer than :data:`MIN_FIXES` fixes, NaN/inf
        values, a latitude outside ±90°, a track off the map.
    """
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
    grid = as_grid(grid)
    inside = np.asarray(grid.contains(lat, lon))
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        w, e, s, n = grid.extent
        raise ValueError(f"the track leaves the map: fix {i} at ({lat[i]:.5f}, {lon[i]:.5f}) is "
                         f"outside lat {s}..{n}, lon {w}..{e} ({int((~inside).sum())} fixes off)")
    return lat, lon, readings


def _check_options(method, noise, bias_sigma_mgal, max_rotation_deg, entropy_half_size,
                   config):
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    if not noise >= 0:
        raise ValueError(f"noise must be a non-negative standard deviation; got {noise!r}")
    if bias_sigma_mgal is not None and method not in ("dense", "chains"):
        raise ValueError(f"bias_sigma_mgal is the bias prior of dense and chains; method "
                         f"{method!r} estimates no bias (correct the readings instead)")
    if max_rotation_deg is not None:
        if method not in ("iccp", "entropy+iccp"):
            raise ValueError(f"max_rotation_deg bounds ICCP's rotation; it has no effect with "
                             f"method {method!r} (use iccp or entropy+iccp)")
        if not 0 <= max_rotation_deg <= 180:
            raise ValueError(f"max_rotation_deg must be the INS heading-error bound in "
                             f"degrees, between 0 and 180; got {max_rotation_deg!r}")
    if entropy_half_size is not None:
        if method not in ("entropy", "entropy+iccp"):
            raise ValueError(f"entropy_half_size sizes the entropy stage; it has no effect "
                             f"with method {method!r} (use entropy or entropy+iccp)")
        if not (isinstance(entropy_half_size, int) and entropy_half_size >= 1):
            raise ValueError(f"entropy_half_size must be an integer >= 1; "
                             f"got {entropy_half_size!r}")
    if config is None:
        return
    if method == "entropy+iccp":
        ok = (isinstance(config, tuple) and len(config) == 2
              and isinstance(config[0], (EntropyConfig, type(None)))
              and isinstance(config[1], (IccpConfig, type(None))))
        expected = "a pair (EntropyConfig or None, IccpConfig or None)"
    else:
        ok = isinstance(config, _CONFIG_TYPES[method])
        expected = f"a {_CONFIG_TYPES[method].__name__}"
    if not ok:
        raise ValueError(f"config for method {method!r} must be {expected}; "
                         f"got {type(config).__name__}")


def match_track(grid, lat, lon, readings, *, method="dense", drift_radius_m=5000.0,
                noise=1.0, v_east=None, v_north=None, bias_sigma_mgal=None,
                max_rotation_deg=None, entropy_half_size=None, config=None, warn=True,
                noise_mgal=None, map_error=None, missing="auto"):
    """Match one track against a map, with input checks (the public entry point).

    Parameters
    ----------
    grid : Grid or PreparedMap
        Map: gravity anomaly (mGal), or for ``entropy``, ``iccp``, ``entropy+iccp``
        also magnetic total intensity or anomaly (nT). For ``method="chains"`` refine
        it first to the node spacing wanted (paper A: 0.005°, ``grid.refine(100)`` of
        a 0.5° map). A Grid is prepared here (:func:`~jaxgrav.prepared.prepare_map`)
        once for the whole match.
    lat, lon : array_like, shape ``(N,)``
        INS-indicated fixes (degrees), N ≥ :data:`MIN_FIXES`.
    readings : array_like, shape ``(N,)``
        Measured values in the map's units; gravimeter readings without Eötvös
        correction if velocities are given. ``entropy`` and ``iccp`` estimate no
        bias: correct the readings for any known one.
    method : {"dense", "chains", "entropy", "iccp", "entropy+iccp"}
        See :data:`METHODS`.
    drift_radius_m : float
        Largest expected INS drift (m); sizes the search.
    noise : float
        Reading noise σ (map units: mGal or nT).
    v_east, v_north : array_like, optional
        INS velocity (m/s). When given, readings are Eötvös-corrected with it and
        (dense, chains) the bias prior defaults to 3 mGal (velocity error of about
        0.2 m/s plus gravimeter bias); otherwise the bias is estimated freely.
    bias_sigma_mgal : float, optional
        ``dense``, ``chains``: prior σ of the remaining bias (mGal), overriding the
        default above.
    max_rotation_deg : float, optional
        ``iccp``, ``entropy+iccp``: largest INS heading error (degrees, 0–180), the
        bound on ICCP's rotation; default 90.
    entropy_half_size : int, optional
        ``entropy``, ``entropy+iccp``: at most this many offsets per side (default
        :data:`ENTROPY_HALF_SIZE`; on fine maps the offset spacing grows instead).
    config : optional
        Full control, replacing the sizing from ``drift_radius_m`` and ``noise``: a
        :class:`~jaxgrav.match.dense.DenseConfig`,
        :class:`~jaxgrav.match.correlation.ChainConfig`,
        :class:`~jaxgrav.match.entropy.EntropyConfig` or
        :class:`~jaxgrav.match.iccp.IccpConfig` for the method; for ``entropy+iccp``
        a pair ``(EntropyConfig or None, IccpConfig or None)`` (None parts sized).
    warn : bool
        Emit a ``RuntimeWarning`` for each status flag raised.
    noise_mgal : float, optional
        Deprecated spelling of ``noise``.
    map_error : CorrelatedMapError, optional
        ``dense``, ``chains``, ``entropy+iccp``: the map's error model
        (:func:`~jaxgrav.fields.map_error.map_error`): GLS score, posterior fix and
        integrity test (:func:`config_for`, :func:`iccp_config_for`); None (default)
        or σ = 0: today's white-noise score. Ignored with an explicit ``config``.
    missing : {"auto", "land", "gaps"}
        What missing (NaN) map nodes are. ``"land"``: places the vehicle cannot be,
        candidates touching them are dropped. ``"gaps"`` (``dense`` only): gaps in the
        survey, each candidate is scored on its fixes over present cells (each other
        fix adds its expected χ², 1: :mod:`~jaxgrav.match.gaps`), with at most
        :func:`max_gap_fixes` of the N fixes in gaps; a fix read over gaps at more
        than half of its fixes is rejected (status 32768,
        :data:`~jaxgrav.match.result.GAPPED`, INS track kept). ``"auto"`` (default):
        ``"gaps"`` for ``dense`` when the INS-indicated track itself crosses a missing
        cell (:func:`ins_over_missing`: where the vehicle is believed to be is not
        land), ``"land"`` otherwise and for the other methods. All three are the same
        on a map without missing nodes in reach. With an explicit ``config``, its
        ``gap_fixes`` decides instead.

    Notes
    -----
    Missing (NaN) map nodes, such as land on a marine grid, are a mask: candidate
    tracks with a fix in a cell that has a missing corner are dropped, the fix is the
    best of the rest, and status bit :data:`MASKED` (8192) says the search region held
    missing nodes. ``dense`` then scores each shifted fix on its own
    (``lattice_block=0``, also with an explicit ``config``): the separable lattice
    would spread one missing node over its whole block.

    The fix's χ² is tested against its degrees of freedom (``N − 3``,
    :func:`~jaxgrav.match.result.fit_p_value`); below ``P_IMPLAUSIBLE`` (10⁻³) status
    bit 16384 (:data:`~jaxgrav.match.result.IMPLAUSIBLE_FIT`) says the readings do not
    fit the map as the stated noise and map error allow (``accepted`` is unchanged).

    Returns
    -------
    MatchResult

    Raises
    ------
    ValueError
        Unknown method, an option the method does not use, a config of the wrong
        type, mismatched lengths, too short a track, NaN readings, a track off the map,
        non-positive drift radius, a rotation bound outside 0–180°.
    """
    if noise_mgal is not None:
        warnings.warn("match_track(noise_mgal=...) is deprecated; use noise=...",
                      DeprecationWarning, stacklevel=2)
        noise = noise_mgal
    _check_options(method, noise, bias_sigma_mgal, max_rotation_deg, entropy_half_size, config)
    if map_error is not None and method not in MAP_ERROR_METHODS:
        raise ValueError(f"map_error is used by methods {MAP_ERROR_METHODS} only; got method "
                         f"{method!r}")
    if missing not in ("land", "gaps", "auto"):
        raise ValueError(f"missing must be 'land', 'gaps' or 'auto'; got {missing!r}")
    if missing == "gaps" and method != "dense":
        raise ValueError(f"missing='gaps' (survey gaps scored per fix) is built for method "
                         f"'dense' only; got method {method!r} (use missing='land' or 'auto')")
    lat, lon, readings = validate_track(grid, lat, lon, readings)
    corrected = v_east is not None and v_north is not None
    if corrected:
        ve, vn = (np.broadcast_to(np.asarray(v, float), lat.shape) for v in (v_east, v_north))
        if not (np.isfinite(ve).all() and np.isfinite(vn).all()):
            raise ValueError("v_east and v_north must be finite at every fix")
        readings = readings + np.asarray(eotvos_jit(lat, ve, vn))
    masked = missing_in_reach(grid, lat, lon, drift_radius_m) > 0
    if method in ("dense", "chains"):
        reading = missing_reading(grid, lat, lon, method, missing, drift_radius_m)
        if warn and missing == "gaps" and masked and reading == "land":
            warnings.warn(f"match_track: missing='gaps' needs more than {MIN_FIXES} fixes (at "
                          f"least {MIN_FIXES} of a candidate's fixes over present cells); with "
                          f"{lat.size} fixes missing nodes are read as land", RuntimeWarning,
                          stacklevel=2)
        result = _match_correlation(grid, lat, lon, readings, method, drift_radius_m, noise,
                                    bias_sigma_mgal, corrected, config, map_error, masked,
                                    reading == "gaps")
    else:
        result = _match_contour(grid, lat, lon, readings, method, drift_radius_m, noise,
                                max_rotation_deg, entropy_half_size, config, map_error)
    if masked:
        result = result._replace(status=result.status | MASKED)
    if fit_p_value(result.chi2_per_dof, lat.size - 3) < P_IMPLAUSIBLE:
        result = result._replace(status=result.status | IMPLAUSIBLE_FIT)
    if warn:
        for msg in status_messages(int(result.status)):
            warnings.warn(f"match_track: {msg}", RuntimeWarning, stacklevel=2)
    return result


MASKED = 8192
"""Status bit: the search region holds missing (NaN) map nodes (see :data:`STATUS`)."""


def ins_over_missing(grid, lat, lon):
    """Whether the INS-indicated track itself crosses a cell with a missing corner."""
    return bool(np.isnan(np.asarray(as_grid(grid).sample(lat, lon, "bilinear"))).any())


def missing_reading(grid, lat, lon, method, missing, reach_m):
    """How :func:`match_track` reads the missing map nodes in reach: ``"gaps"`` or ``"land"``.

    The one rule (the command line reports it): ``"land"`` when no node in reach is
    missing, for methods other than ``dense``, and for tracks of :data:`MIN_FIXES`
    fixes (no candidate may then have a fix in a gap); otherwise ``"gaps"`` when
    ``missing="gaps"``, or ``missing="auto"`` and the INS-indicated track crosses a
    missing cell (:func:`ins_over_missing`).

    Parameters
    ----------
    grid : Grid or PreparedMap
    lat, lon : array_like, shape ``(N,)``
        INS-indicated track (degrees).
    method : str
        Matcher (see :data:`METHODS`).
    missing : {"auto", "land", "gaps"}
    reach_m : float
        Search reach (m), the drift radius.

    Returns
    -------
    str
    """
    if (method != "dense" or missing == "land" or max_gap_fixes(np.size(lat)) == 0
            or missing_in_reach(grid, lat, lon, reach_m) == 0):
        return "land"
    return "gaps" if missing == "gaps" or ins_over_missing(grid, lat, lon) else "land"


def max_gap_fixes(n):
    """Most of ``n`` fixes a candidate may have over survey gaps (``missing="gaps"``).

    All but :data:`MIN_FIXES`.
    """
    return max(0, n - MIN_FIXES)


def track_latitude(lat):
    """The latitude (degrees) at which a track's search is sized: its mean, to a degree.

    The offset spacing follows the map's east–west node spacing, which shrinks with
    latitude; measured at the track, a map cropped to the track's region sizes the same
    search. To a whole degree (≤ 2.5 % within one below 75°), tracks in one band share
    the compiled program.

    Parameters
    ----------
    lat : array_like, shape ``(N,)``

    Returns
    -------
    float
    """
    return float(np.round(np.mean(np.asarray(lat, dtype=float))))


def missing_in_reach(grid, lat, lon, reach_m):
    """Number of missing (NaN) map nodes within ``reach_m`` (plus a cell) of a track's box.

    Parameters
    ----------
    grid : Grid or PreparedMap
    lat, lon : array_like, shape ``(N,)``
        The track (degrees; longitudes in the map's convention).
    reach_m : float
        How far the search reaches (m), e.g. the drift radius.

    Returns
    -------
    int
    """
    g = as_grid(grid)
    if g.n_missing == 0:
        return 0
    return int((~np.isfinite(g.values_near(lat, lon, reach_m))).sum())


def _match_correlation(grid, lat, lon, readings, method, drift_radius_m, noise,
                       bias_sigma_mgal, corrected, config, map_error=None, masked=False,
                       gaps=False):
    """``dense`` or ``chains`` on checked inputs."""
    if bias_sigma_mgal is None:
        bias_sigma_mgal = 3.0 if corrected else math.inf
    sized = config is None
    if sized:
        config = config_for(method, grid, drift_radius_m, noise_mgal=noise,
                            bias_sigma_mgal=bias_sigma_mgal, lat=track_latitude(lat),
                            **({"map_error": map_error} if map_error is not None else {}))
        if method == "chains":  # the displacement stencil, sized for this track
            tol = (float(v) for v in chain_tolerances(as_grid(grid), lat, config))
            config = dataclasses.replace(
                config, stencil_size=stencil_size_for(as_grid(grid), lat, lon, *tol))
    if sized and gaps and masked:
        config = dataclasses.replace(config, gap_fixes=max_gap_fixes(lat.size))
    if method == "dense" and config.lattice_block and masked:
        # the separable lattice spreads a missing node over its block: score each
        # shifted fix on its own (same values elsewhere), masking only what touches it
        config = dataclasses.replace(config, lattice_block=0)
    args = (jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(readings), config)
    # one program per call (the map's spline is prepared inside it), kept on disk when
    # the command line (or the caller) set a folder for executables
    if method == "dense":
        return executables.call(match_dense, grid, *args)
    return executables.call(match_chains, as_grid(grid), *args)  # reads node values only


def _match_contour(grid, lat, lon, readings, method, drift_radius_m, noise, max_rotation_deg,
                   entropy_half_size, config, map_error=None):
    """``entropy``, ``iccp`` or ``entropy+iccp`` on checked inputs."""
    entropy = iccp = None
    if method == "entropy":
        entropy = config
    elif method == "iccp":
        iccp = config
    elif config is not None:
        entropy, iccp = config
    if method != "iccp" and entropy is None:
        half = ENTROPY_HALF_SIZE if entropy_half_size is None else entropy_half_size
        entropy = entropy_config_for(grid, drift_radius_m, max_half_size=half,
                                     lat=track_latitude(lat))
    if method != "entropy" and iccp is None:
        stage = "alone" if method == "iccp" else "fine"
        iccp = iccp_config_for(grid, drift_radius_m, stage=stage, noise=noise,
                               lat=track_latitude(lat),
                               max_rotation_deg=90.0 if max_rotation_deg is None
                               else max_rotation_deg, map_error=map_error)
    args = (grid, jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(readings))
    if method == "entropy":
        return executables.call(match_entropy, *args, entropy)
    if method == "iccp":
        return executables.call(match_iccp, *args, iccp)
    return executables.call(match_entropy_iccp, *args, entropy, iccp)
