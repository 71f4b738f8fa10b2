"""``jaxgrav dov``: layered DOV interpolation along a track CSV (paper C).

Wire into :mod:`jaxgrav.cli` with ``add_parser(sub)``; the command
function is :func:`cmd_dov`.
"""

import itertools
import math
import sys

import numpy as np

from jaxgrav import dov
from jaxgrav._io import check_outputs
from jaxgrav.cli.inputs import add_track_option, check_out_format, read_track
from jaxgrav.dov import DEFAULT_METHOD, HARMONIC_GAP_LIMIT, METHODS
from jaxgrav.grid_files import check_netcdf_file
from jaxgrav.tracks import write_track_csv

__all__ = ["add_parser", "cmd_dov"]


def add_parser(subparsers):
    """Add the ``dov`` sub-command to an ``argparse`` sub-parser set."""
    d = subparsers.add_parser("dov", help="interpolate layered DOV along a track (paper C)")
    add_track_option(d, "CSV with lat, lon (degrees) and h (m)")
    d.add_argument("--out", required=True, help="output CSV: the track columns + xi, eta (arcsec)")
    d.add_argument("--layers", default=None,
                   help="comma-separated layer heights in m, e.g. -50,0,10000,20000 for a track "
                        "below 0 m (default: the grid's; other "
                        "heights than the shipped 0,10000,20000 are synthesised from the "
                        "shipped degree-360 coefficients)")
    d.add_argument("--method", choices=METHODS, default=DEFAULT_METHOD,
                   help=f"default {DEFAULT_METHOD} (most accurate); bilinear-linear is the "
                        "paper's")
    d.add_argument("--grid", default=None,
                   help="NetCDF layers: xi, eta (arcsec) on (height, lat, lon), height in m "
                        "(default: the shipped qinling set)")
    d.add_argument("--force", action="store_true", help="overwrite an existing output")
    d.set_defaults(func=cmd_dov)
    return d


LOWEST_LAYER_M = -11000.0
"""Lowest ``--layers`` height (m): the deepest ocean floor; -1e9 ended in the harmonic
synthesis's "h must be > -radius = -6378136.3 m", naming no option."""

HIGHEST_LAYER_M = 100_000.0
"""Highest ``--layers`` height (m): the edge of space (the Kármán line), above every
aircraft and balloon the layers serve; ``--layers 0,1e12`` synthesised a layer a million
km up, warned of the gap and wrote deflections of -736964 arcsec, exit 0."""


def _parse_heights(text):
    """The heights (m) of ``--layers TEXT``: comma-separated, finite, strictly ascending,
    none below :data:`LOWEST_LAYER_M` or above :data:`HIGHEST_LAYER_M`; an empty item
    (``0,,20000``: a height lost in typing, which was dropped) is refused."""
    items = [v.strip() for v in text.split(",")]
    if not any(items):  # --layers '' ran on the default heights, silently
        raise ValueError(f"--layers {text!r} is empty; expected comma-separated heights in m, "
                         "e.g. 0,10000,20000 (or leave it out for the default)")
    if "" in items:
        raise ValueError(f"--layers {text!r}: item {items.index('') + 1} is empty; expected "
                         "comma-separated heights in m, e.g. 0,10000,20000")
    try:
        vals = [float(v) for v in items if v]
    except ValueError:
        raise ValueError(f"--layers must be comma-separated heights in m; got {text!r}") from None
    if len(vals) < 2:
        raise ValueError(f"--layers needs at least 2 heights; got {text!r}")
    got = ", ".join(f"{v:g}" for v in vals)
    if not all(math.isfinite(v) for v in vals):
        raise ValueError(f"--layers {text}: heights must be finite numbers (m); got {got}")
    if any(b <= a for a, b in itertools.pairwise(vals)):
        raise ValueError(f"--layers {text}: heights must be strictly ascending (m); got {got}")
    if vals[0] < LOWEST_LAYER_M or vals[-1] > HIGHEST_LAYER_M:
        raise ValueError(f"--layers {text}: heights must be between {LOWEST_LAYER_M:g} m (the "
                         f"deepest ocean floor) and {HIGHEST_LAYER_M:g} m (the edge of space), "
                         f"in m above the ellipsoid; got "
                         f"{vals[0] if vals[0] < LOWEST_LAYER_M else vals[-1]:g}")
    return vals


def _check_points(args, track, layers):
    """Refuse the first track point outside ``layers``, naming ``--track``, its line and the
    option that would take the track's heights in."""
    lat, lon, h = (np.asarray(track[k], float) for k in ("lat", "lon", "h"))
    hs = np.asarray(layers.heights)
    off = ~np.asarray(layers.layer(0).contains(lat, lon))
    bad = off | (h < hs[0]) | (h > hs[-1])
    if not bad.any():
        return
    i = int(np.flatnonzero(bad)[0])
    w, e, s, n = (float(v) for v in layers.extent)
    source = f"--grid {args.grid!r}" if args.grid else "the shipped qinling layers"
    raise ValueError(
        f"--track {str(args.track)!r}, line {track.line(i)}: point (lat={float(lat[i])!r}, "
        f"lon={float(lon[i])!r}, h={float(h[i])!r} m) is outside the layered grid of {source} (lat "
        f"{s:g}..{n:g}, lon {w:g}..{e:g}, h {hs[0]:g}..{hs[-1]:g} m); {int(bad.sum())} of "
        f"{bad.size} point(s) out of range{_height_fix(args, h[~off], hs)}")


def _height_fix(args, h, hs):
    """What takes the heights ``h`` (m) of the on-map points into layers at ``hs`` (m): for
    the shipped set, ``--layers`` with a layer at the lowest (highest) height rounded down
    (up) to 10 m, synthesised from the degree-360 model (no extrapolation); for a --grid, a
    layer added to the file. Empty when every height is inside; a height beyond the
    layers' range (:data:`LOWEST_LAYER_M`, :data:`HIGHEST_LAYER_M`) asks for its unit."""
    lo, hi = (float(np.min(h)), float(np.max(h))) if h.size else (hs[0], hs[-1])
    if hs[0] <= lo and hi <= hs[-1]:
        return ""
    if lo < LOWEST_LAYER_M or hi > HIGHEST_LAYER_M:  # advised --layers that were refused
        far = lo if lo < LOWEST_LAYER_M else hi
        return (f"; a height of {far:g} m is beyond any layer ({LOWEST_LAYER_M:g} to "
                f"{HIGHEST_LAYER_M:g} m above the ellipsoid, the deepest ocean floor to the "
                "edge of space): check the h column's unit (declare it in the header, e.g. "
                "'h (ft)')")
    below = math.floor(min(lo, hs[0]) / 10.0) * 10.0
    above = math.ceil(max(hi, hs[-1]) / 10.0) * 10.0
    need = " and ".join(([f"at or below {below:g} m"] if lo < hs[0] else [])
                        + ([f"at or above {above:g} m"] if hi > hs[-1] else []))
    if args.grid:
        return (f"; the track needs a layer {need}: add one to --grid (a user grid cannot be "
                f"re-layered with --layers)")
    heights = sorted({*([below] if lo < hs[0] else []), *hs.tolist(),
                      *([above] if hi > hs[-1] else [])})
    return (f"; the track needs a layer {need}: give --layers="
            f"{','.join(f'{v:g}' for v in heights)} (new heights are synthesised from the "
            f"shipped degree-360 model)")


def _gap_warning(layers, h, method, user_grid):
    """The warning for track points in layer gaps too wide for ``harmonic``, or None."""
    if not method.endswith("-harmonic"):
        return None
    ratio = np.asarray(dov.harmonic_gap_ratio(layers))
    hs = np.asarray(layers.heights)
    h = np.asarray(h, float)
    gaps, width = [], np.inf
    for k in np.flatnonzero(ratio > HARMONIC_GAP_LIMIT):
        n = int(np.count_nonzero((h > hs[k]) & (h < hs[k + 1])))
        if n:
            gaps.append(f"{n} between {hs[k]:g} and {hs[k + 1]:g} m (k*gap = {ratio[k]:.1f})")
            width = min(width, HARMONIC_GAP_LIMIT / ratio[k] * (hs[k + 1] - hs[k]))
    if not gaps:
        return None
    closer = (f"a --grid with layers at most about {width:.0f} m apart" if user_grid else
              f"--layers at most about {width:.0f} m apart")
    return (f"track points lie in layer gaps too wide for {method}'s vertical continuation "
            f"(k: the layers' effective wavenumber; k*gap trusted up to "
            f"{HARMONIC_GAP_LIMIT:g}): {'; '.join(gaps)}; it is unreliable there and can "
            f"leave the layers' range: use {closer} or --method bicubic-linear")


def cmd_dov(args):
    """Run ``jaxgrav dov`` (x64 is enabled by the CLI entry point)."""
    check_outputs([args.out], force=args.force, names=["--out"],
                  inputs={"--track": args.track, "--grid": args.grid})
    check_out_format(args.out, "CSV")
    track = read_track(args, required=("lat", "lon", "h"))
    heights = _parse_heights(args.layers) if args.layers is not None else None
    if args.grid:
        # a CSV or an empty file ended in xarray's three-line "did not find a match in any
        # of xarray's currently installed IO backends"; the layers' own errors named no option
        check_netcdf_file(args.grid, what="--grid")
        try:
            layers = dov.LayeredGrid.from_netcdf(args.grid)
        except ValueError as err:
            text = str(err)
            raise ValueError(f"--grid {text}" if text.startswith(repr(str(args.grid)))
                             else f"--grid {args.grid!r}: {text}") from None
        if layers.units != "arcsec":  # converted from any angle (jaxgrav.dov.units)
            raise ValueError(f"--grid {str(args.grid)!r}: {layers.channels[0]} declares units "
                             f"{layers.units!r}, not an angle; expected deflections of the "
                             "vertical in arcsec (or rad, urad, mrad, deg, mas)")
        own = np.asarray(layers.heights, float)
        # a count that differs was NumPy's "operands could not be broadcast together"
        if heights is not None and (len(heights) != own.size or not np.allclose(heights, own)):
            raise ValueError(
                f"--layers {args.layers} differs from the heights of --grid {args.grid!r} "
                f"({', '.join(f'{h:g}' for h in own)} m); a user grid cannot be re-layered: "
                "leave --layers out"
            )
    else:
        layers = dov.paper_c_layers(heights if heights is not None else dov.PAPER_HEIGHTS)
    _check_points(args, track, layers)
    res = dov.interpolate(layers, track["lat"], track["lon"], track["h"], args.method,
                          strict=True)
    cols = track.columns()
    vals = np.asarray(res.values)
    for i, name in enumerate(layers.channels):
        cols[name] = vals[i]
    write_track_csv(args.out, cols, force=args.force)
    print(f"wrote {args.out}: {vals.shape[1]} fixes, {', '.join(layers.channels)} (arcsec) "
          f"by {args.method} from layers at "
          f"{', '.join(f'{h:g}' for h in np.asarray(layers.heights))} m")
    warning = _gap_warning(layers, track["h"], args.method, args.grid is not None)
    if warning is not None:
        print(f"warning: {warning}", file=sys.stderr)
