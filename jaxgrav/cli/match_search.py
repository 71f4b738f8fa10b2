"""The search region of ``jaxgrav match``: the drift radius and ``--refine``.

:func:`check_search` refuses a search region wider than the map and a ``--refine`` that
makes the fix worse or cannot fit in memory; :func:`check_radius_resolved` one too small
for the readings to tell any position in it from the INS's (``--drift-radius 1e-9`` ran
and reported "INS kept").
"""

import math
import sys

import numpy as np

from jaxgrav.sim import DEG_ARC_M

__all__ = ["check_radius_resolved", "check_search", "check_track_moves", "steepest_slope",
           "unresolved"]

_MAX_REFINED_NODES = 2e7
"""Nodes of a refined map above which ``--refine`` is refused (160 MB in float64)."""


def steepest_slope(grid):
    """The largest change of a map between neighbouring nodes per metre (map units per
    m; 0 for a map without two neighbouring values)."""
    values = np.asarray(grid.values)
    dy, dx = (float(s) for s in grid.spacing_m())
    steepest = 0.0
    for a in range(0, values.shape[-2], _ROWS):  # in blocks: a global map is 37 M nodes
        block = values[..., a:a + _ROWS + 1, :].astype(float)
        for step in (np.diff(block, axis=-2) / dy, np.diff(block, axis=-1) / dx):
            step = np.abs(step[np.isfinite(step)])
            steepest = max(steepest, float(step.max()) if step.size else 0.0)
    return steepest


_ROWS = 256


def unresolved(grid, span_m, n_fixes, noise, noise_option="--noise", *, slope=None):
    """Whether ``n_fixes`` readings of ``noise`` can tell the map's values ``span_m`` apart.

    They can when the map's steepest slope (:func:`steepest_slope`) changes it across
    the span by at least a tenth of their mean's 1-sigma, ``0.1 noise / sqrt(n_fixes)``
    (below it, the χ² of any two positions in the span differ by less than 0.01: only a
    meaningless value falls there, e.g. ``--drift-radius 1e-9``; a smooth map with a
    short span still runs, and says that the readings tell little).

    ``noise_option`` is the option that set ``noise``, named in the text (``filter``'s
    ``--sigma-gravity``). ``slope`` (map units per m) replaces the grid's steepest one
    for a field without nodes (a point-mass model: its steepest gradient along the
    track); ``grid`` then only gives the units (``None``: mGal).

    Returns
    -------
    text : str or None
        None when they can; else the reason, ``"the map changes by at most ... can
        tell (...)"``, for a message.
    least_m : float
        The shortest span they can tell (m; 0 for a flat map or noiseless readings).
    """
    given = slope
    slope = steepest_slope(grid) if given is None else float(given)
    tell = 0.1 * noise / math.sqrt(n_fixes)
    least_m = tell / slope if slope > 0 else 0.0
    if span_m >= least_m:
        return None, least_m
    unit = getattr(grid, "units", None) or ("map units" if grid is not None else "mGal")
    what = "the map" if given is None else "the field"
    steepest = "steepest slope" if given is None else "steepest gradient along the track"
    return (f"{what} changes by at most {span_m * slope:.3g} {unit} (its {steepest} is "
            f"{slope:.3g} {unit}/m), below a tenth of what {n_fixes} readings of {noise_option} "
            f"{noise:g} {unit} can tell ({tell:.3g} {unit})"), least_m


def check_radius_resolved(grid, radius_deg, n_fixes, noise, source):
    """ValueError for a search disc across which the map, at its steepest, changes by
    less than ``n_fixes`` readings of ``noise`` can tell (:func:`unresolved`): every
    candidate in it fits as the INS track does."""
    text, least_m = unresolved(grid, 2.0 * radius_deg * DEG_ARC_M, n_fixes, noise)
    if text is None:
        return
    said = (f"{source} {radius_deg:g} degrees of arc" if source == "--drift-radius"
            else f"{source} ({radius_deg:g} degrees of arc at most)")
    raise ValueError(f"{said} ({radius_deg * DEG_ARC_M:.3g} m) searches a region across which "
                     f"{text}: every position in it would fit as the INS track does; expected "
                     f"a drift radius of at least {least_m / 2 / DEG_ARC_M:.2g} degrees of arc "
                     f"({least_m / 2:.2g} m)")


def check_track_moves(grid, lat, lon, noise, where):
    """ValueError for a track whose fixes all lie closer together than ``len(lat)``
    readings of ``noise`` can tell apart on the map (a vessel at anchor reads one map
    value: the match ran and kept the INS)."""
    north = (np.max(lat) - np.min(lat)) * DEG_ARC_M
    east = ((np.max(lon) - np.min(lon)) * DEG_ARC_M * math.cos(math.radians(float(np.mean(lat)))))
    extent = float(math.hypot(north, east))
    text, least_m = unresolved(grid, extent, len(lat), noise)
    if text is not None:
        raise ValueError(f"{where}: its {len(lat)} fixes lie within {extent:.3g} m of each "
                         f"other, across which {text}: a track that does not move reads one "
                         "value of the map and tells no position; matching needs a track "
                         f"at least {least_m:.2g} m long")


def check_search(args, grid, radius_deg, lat, source="--drift-radius"):
    """The search region and ``--refine``: a region larger than the map, a refinement that
    makes the result worse or cannot fit in memory are refused (``source``: where the
    radius came from, for the message); chains on coarse cells without ``--refine`` are
    warned."""
    ny, nx = np.asarray(grid.values).shape[-2:]
    height = (ny - 1) * grid.dlat
    width = (nx - 1) * grid.dlon * math.cos(math.radians(float(np.mean(lat))))
    if 2 * radius_deg > min(height, width):
        column = source != "--drift-radius"  # the column's 4000 (m) was blamed on the option
        said = (f"{source} holds up to {radius_deg:g} degrees, searching" if column
                else f"{source} {radius_deg:g} degrees searches")
        raise ValueError(f"{said} a region {2 * radius_deg:g} degrees across, larger than the "
                         f"map around the track ({height:.3g} x {width:.3g} degrees of arc); "
                         "expected a drift radius well inside the map" + (
                             "; in other units? declare them in the header, e.g. "
                             "'drift_radius (m)'" if column else ""))
    if args.refine <= 1:
        if args.method == "chains" and min(grid.spacing_m()) > 1000.0:
            print(f"warning: --method chains on a map of {min(grid.spacing_m()) / 1e3:.1f} km "
                  "cells without --refine: the chains move from node to node, so the fix is "
                  "no finer than a cell (paper A refines x8 to x100; try --refine 8)",
                  file=sys.stderr)
        return
    if args.method != "chains":
        raise ValueError(f"--refine {args.refine} is for --method chains (paper A's node "
                         f"lattice); --method {args.method} samples the map continuously, and "
                         "a refined (bilinear) map only smooths away its curvature and makes "
                         "the fix worse")
    nodes = ((ny - 1) * args.refine + 1) * ((nx - 1) * args.refine + 1)
    if nodes > _MAX_REFINED_NODES:
        raise ValueError(f"--refine {args.refine} would make a {ny} x {nx} map region "
                         f"{nodes:.3g} nodes ({nodes * 8 / 1e9:.2g} GB), more than the "
                         f"{_MAX_REFINED_NODES:.0e} allowed; use a smaller factor")
