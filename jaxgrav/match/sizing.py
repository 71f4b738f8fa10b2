"""Matcher configurations sized to the expected INS error.

:func:`config_for` sizes the correlation matchers (``dense``, ``chains``),
:func:`iccp_config_for` ICCP, and :func:`~jaxgrav.match.entropy.entropy_config_for`
the entropy stage: each search region covers 1.2 × the drift radius.
"""

import dataclasses
import math

from jaxgrav.match.correlation import ChainConfig, chain_tolerances
from jaxgrav.match.dense import DenseConfig
from jaxgrav.match.iccp import IccpConfig
from jaxgrav.match.lattice_chains import stencil_size_for_step
from jaxgrav.prepared import as_grid

__all__ = [
    "CHAIN_MAP_ERROR_INTEGRITY",
    "CHAIN_NODE_DEG",
    "FAR_FIX_RADII",
    "ICCP_MAP_ERROR_INTEGRITY",
    "MAP_ERROR_INTEGRITY",
    "WHITE_INTEGRITY",
    "chain_grid",
    "config_for",
    "iccp_config_for",
]

MAP_ERROR_INTEGRITY = {"fix": "posterior", "max_sigma_m": 3000.0, "max_sigma_ratio": 0.9,
                       "max_p_worse": 0.3}
"""DenseConfig fields :func:`config_for` sets with a map error (σ > 0): the fix and the
integrity thresholds, ``max_sigma_m`` chosen by ``examples/map_error_dense.py``,
``max_sigma_ratio`` (a fix must narrow the searched disc's own spread by 10 %) by the
Monte Carlo sweep in ``docs/map-error.md``, and the no-harm test of the entropy+ICCP
matcher (:data:`ICCP_MAP_ERROR_INTEGRITY`'s ``max_p_worse``, the same 0.3; measured on
the dense matcher with ``examples/dense_region_sweep.py``)."""

WHITE_INTEGRITY = {"max_sigma_ratio": 0.9}
"""DenseConfig fields :func:`config_for` sets without a map error (white-noise score): the
informativeness test alone (the readings must narrow the searched disc's spread by
10 %; a fix on a flat or featureless map is rejected, not accepted with a σ as wide as
the search), the fix still the refined best offset (paper A's)."""

CHAIN_MAP_ERROR_INTEGRITY = {"fix": "posterior", "max_sigma_m": 3000.0}
"""ChainConfig fields :func:`config_for` sets with a map error (σ > 0), measured with
``examples/map_error_matchers.py`` (see the README)."""

CHAIN_NODE_DEG = 0.005
"""Node spacing the chain matcher's map is refined to (degrees): paper A's 0.005°
(its 0.5° map refined ×100; the 2.5′ map refined ×8, as ``examples/paper_a_table1.py``)."""

FAR_FIX_RADII = 1.5
""":func:`iccp_config_for` (``stage="fine"``) sets ``max_offset_m`` to this many drift
radii: the entropy stage searches 1.2 radii; a fix beyond 1.5 the INS cannot have
drifted to is rejected."""

ICCP_MAP_ERROR_INTEGRITY = {"fix": "posterior", "max_sigma_m": 3000.0, "region": "disc",
                            "max_sigma_ratio": 0.9, "max_p_worse": 0.3}
"""IccpConfig fields :func:`iccp_config_for` sets with a map error (σ > 0): the posterior
coarse fix over the searched disc, the 3 km and informativeness tests (as the dense
matcher's) and the no-harm test (a fix with more than a 30 % chance of being worse than
the INS track is rejected); the ratio and the chance chosen with
``examples/map_error_matchers.py --seed 1`` (see the README)."""


def chain_grid(grid, node_deg=CHAIN_NODE_DEG):
    """``grid`` refined (bilinear, :meth:`~jaxgrav.grid.Grid.refine`) to nodes about
    ``node_deg`` apart, the chain matcher's candidates: factor ``round(min(dlat, dlon) /
    node_deg)``, at least 1 (a map as fine already is returned as it is).

    Parameters
    ----------
    grid : Grid or PreparedMap
    node_deg : float
        Wanted node spacing (degrees).

    Returns
    -------
    Grid
    """
    if not node_deg > 0:
        raise ValueError(f"node_deg must be a positive spacing (degrees); got {node_deg!r}")
    grid = as_grid(grid)
    factor = max(1, round(min(grid.dlat, grid.dlon) / node_deg))
    return grid.refine(factor) if factor > 1 else grid


def config_for(method, grid, drift_radius_m, *, noise_mgal=1.0, bias_sigma_mgal=math.inf,
               n_rotations=1, score=None, step_m=None, map_error=None, region="disc",
               lat=None):
    """A matcher configuration whose search region covers the drift.

    Parameters
    ----------
    method : {"dense", "chains"}
    grid : Grid or PreparedMap
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
    map_error : CorrelatedMapError, optional
        The map's error model (:func:`~jaxgrav.fields.map_error.map_error`); fills
        ``map_error_mgal``, ``map_error_length_m`` and ``map_error_order``, and when
        σ > 0 the fix and integrity thresholds of :data:`MAP_ERROR_INTEGRITY`
        (``dense``, measured with ``examples/map_error_dense.py``) or
        :data:`CHAIN_MAP_ERROR_INTEGRITY` (``chains``, whose iso-value tolerance
        then grows to ``2·√(noise² + σ²)``). None: the white-noise score, with the
        informativeness test of :data:`WHITE_INTEGRITY` (``dense``). ``dense``
        compiles only the score it uses (``DenseConfig.score_model`` ``"gls"`` when
        σ > 0, else ``"white"``); ``chains`` ranks by the white score only when σ = 0
        (``ChainConfig.score_model`` ``"white"``: its programme keeps the 5 chains it
        returns, not 16, about half the time; ``"auto"`` when σ > 0). A caller that
        tells a map error later, as a traced ``map_error_mgal``, sets ``"auto"``.
    region : {"disc", "square"}
        ``dense``: the offsets searched (:attr:`~jaxgrav.match.dense.DenseConfig.region`),
        by default the disc of the search's reach about the INS track (the drift is a
        radius; the square's corners are offsets it cannot reach). ``"square"`` is
        paper A's window. ``chains`` searches the square window either way.
    lat : float, optional
        Latitude (degrees) at which the map's node spacing sizes the search; the map's
        central latitude by default. :func:`~jaxgrav.match.api.match` passes the
        track's mean latitude, so the search does not depend on how far the map
        extends (a cropped map sizes it the same).

    Returns
    -------
    DenseConfig or ChainConfig
    """
    if method not in ("dense", "chains"):
        raise ValueError(f"method must be 'dense' or 'chains'; got {method!r}")
    if region not in ("disc", "square"):
        raise ValueError(f"region must be 'disc' or 'square'; got {region!r}")
    grid = as_grid(grid)
    if not drift_radius_m > 0:
        raise ValueError(f"drift_radius_m must be positive (m); got {drift_radius_m!r}")
    reach = 1.2 * float(drift_radius_m)
    dy, dx = (float(s) for s in grid.spacing_m(lat))
    if method == "dense":
        spacing = min(max(min(dy, dx) / 8.0, 50.0), reach / 3.0)
        half = math.ceil(reach / spacing)
        if half > 40:
            half, spacing = 40, reach / 40
        told = map_error is not None and float(map_error.sigma) > 0
        config = DenseConfig(spacing_m=spacing, half_size=half, region=region,
                             noise_mgal=noise_mgal,
                             bias_sigma_mgal=bias_sigma_mgal, n_rotations=n_rotations,
                             score=score or "bias", score_model="gls" if told else "white")
        if not told:
            config = dataclasses.replace(config, **WHITE_INTEGRITY)
        return _with_map_error(config, map_error, MAP_ERROR_INTEGRITY)
    half = math.ceil(reach / min(dy, dx))
    if 2 * half + 1 > min(grid.ny, grid.nx):
        raise ValueError(
            f"drift_radius_m={drift_radius_m!r} needs a search window of {2 * half + 1} nodes, "
            f"larger than the {grid.ny}x{grid.nx} map")
    # told a map error, the iso-value tolerance covers it too (readings − map carry both)
    sigma_m = 0.0 if map_error is None else float(map_error.sigma)
    config = ChainConfig(half_size=half, capacity=min((2 * half + 1) ** 2, 384),
                         delta=2.0 * math.hypot(noise_mgal, sigma_m),
                         score=score or "difference", noise_mgal=noise_mgal,
                         score_model="auto" if sigma_m > 0 else "white")
    config = _with_map_error(config, map_error, CHAIN_MAP_ERROR_INTEGRITY)
    if step_m is None:
        return config
    if not step_m >= 0:
        raise ValueError(f"step_m must be a distance >= 0 (m); got {step_m!r}")
    # the largest tolerance on the map: the node allowance grows with the cell diagonal
    tols = [chain_tolerances(grid, la, config) for la in (grid.lat0, grid.extent[3])]
    step_tol, angle_tol = max(float(t[0]) for t in tols), float(tols[0][1])
    size = stencil_size_for_step(grid, float(step_m), step_tol, angle_tol)
    return dataclasses.replace(config, stencil_size=size)


def _with_map_error(config, map_error, integrity):
    """``config`` told the map error (None: unchanged), with ``integrity`` when σ > 0."""
    if map_error is None:
        return config
    sigma = float(map_error.sigma)
    kw = dict(integrity) if sigma > 0 else {}
    return dataclasses.replace(config, map_error_mgal=sigma,
                               map_error_length_m=float(map_error.length_m),
                               map_error_order=map_error.order, **kw)


def iccp_config_for(grid, drift_radius_m, *, stage="alone", noise=1.0, max_rotation_deg=90.0,
                    map_error=None, lat=None, **kw):
    """An :class:`IccpConfig` sized to the expected error.

    Parameters
    ----------
    grid : Grid or PreparedMap
    drift_radius_m : float
        Largest expected INS error (m).
    stage : {"alone", "fine"}
        ``"alone"``: the window covers 1.2 × the drift, plain ICCP; ``"fine"`` (after
        the entropy stage, whose error can still reach the drift: entropy is a weak
        criterion): the larger of that and one map cell diagonal, and 10 least-squares
        refinement steps (``refine_steps``).
    noise : float
        Reading noise σ (map units): contour points must match their value within 3σ;
        the combined matcher's acceptance test uses it.
    max_rotation_deg : float
        Largest expected INS heading error (degrees): ICCP's rotation bound.
    map_error : CorrelatedMapError, optional
        The map's error model, for the combined matcher's GLS score, covariance and
        integrity test (:func:`~jaxgrav.match.combined.match_entropy_iccp`): fills the
        ``map_error_*`` fields and, when σ > 0, :data:`ICCP_MAP_ERROR_INTEGRITY`.
    lat : float, optional
        Latitude (degrees) at which the map's node spacing is measured (as in
        :func:`config_for`); the map's central latitude by default.
    **kw
        Other :class:`IccpConfig` fields.

    Returns
    -------
    IccpConfig
    """
    if not drift_radius_m > 0:
        raise ValueError(f"drift_radius_m must be positive (m); got {drift_radius_m!r}")
    if stage not in ("alone", "fine"):
        raise ValueError(f"stage must be 'alone' or 'fine'; got {stage!r}")
    dy, dx = (float(s) for s in as_grid(grid).spacing_m(lat))
    cell = math.hypot(dy, dx)
    window = 1.2 * float(drift_radius_m) if stage == "alone" else max(cell, 1.2 * drift_radius_m)
    kw.setdefault("window_m", window)
    kw.setdefault("max_step_m", max(cell / 2.0, 200.0))
    kw.setdefault("contour_tol", 3.0 * float(noise) + 1e-6)
    kw.setdefault("noise", float(noise))
    kw.setdefault("refine_steps", 10 if stage == "fine" else 0)
    if stage == "fine":  # the combined matcher rejects a fix beyond the drift allowed
        kw.setdefault("max_offset_m", FAR_FIX_RADII * float(drift_radius_m))
    config = IccpConfig(max_rotation_deg=max_rotation_deg, **kw)
    return _with_map_error(config, map_error, ICCP_MAP_ERROR_INTEGRITY)
