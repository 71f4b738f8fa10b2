"""``jaxgrav suitability``: where on a map does a segment of readings support a good fix?

Writes, for every node of ``--map``, the predicted matching precision of a straight
segment of ``--fixes`` readings ``--spacing`` m apart on ``--heading`` starting there
(:func:`jaxgrav.match.suitability.suitability`: the Cramér–Rao bound of the mean-track
offset with the reading bias marginalised and the map error correlated along the track),
and the window descriptors (standard deviation, slope standard deviation, roughness,
entropy, correlation length)::

    SUIT.nc   precision_m, sigma_north_m, sigma_east_m, corr, std, slope_std,
              roughness, entropy, correlation_length_m on the map's lat/lon nodes
    SUIT.png  the precision map (log colour scale) next to the map's own std

Both files are checked before anything is written; ``--force`` replaces them.

Nodes without a bound are missing values (NaN, the variables' ``_FillValue``), never
``inf``, and the variable ``status`` says why (CF ``flag_values``/``flag_meanings``):
0 ``ok``; 1 ``off_map``, the segment leaves the map; 2 ``missing_map``, it crosses a
cell with a missing (NaN) node, such as land on a marine grid (such maps are read
whole: their missing nodes only blank the nodes whose segments or windows touch them);
3 ``no_information``, the map does not place the segment: its CRLB exceeds the map's
own size, the diagonal of its extent (infinite where the map is flat, as a constant
map is everywhere; huge where the segment sees a single gradient direction), so the
bound says "anywhere on the map" (``precision_m``, ``corr`` and the axis whose 1-σ
exceeds that size are blanked; the summary says how many).
"""

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from matplotlib.colors import LogNorm

from jaxgrav._io import atomic_output, check_outputs
from jaxgrav.cli.inputs import check_out_format, fill_map_error_length, whole_number
from jaxgrav.cli.match_search import unresolved
from jaxgrav.cli.simulate import MAX_BIAS_MGAL
from jaxgrav.constants import DEG
from jaxgrav.datasets import load_map
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.match.suitability import DESCRIPTORS, suitability
from jaxgrav.plot import save_figure
from jaxgrav.sim import DEG_ARC_M

__all__ = ["STATUS", "add_parser", "cmd_suitability"]

_UNITS = dict(precision_m="m", sigma_north_m="m", sigma_east_m="m", corr="1", std="{u}",
              slope_std="{u}/km", roughness="{u}", entropy="nat", correlation_length_m="m")
"""The variables' units, ``{u}`` the map's (mGal; nT on a magnetic map: they were
labelled mGal)."""
_LONG = dict(
    precision_m="predicted RMS radial error of the fix of a segment starting here (CRLB)",
    sigma_north_m="CRLB 1-sigma of the offset, north", sigma_east_m="CRLB 1-sigma, east",
    corr="correlation of the CRLB's north and east errors",
    std="standard deviation of the map over the window",
    slope_std="standard deviation of the gradient magnitude over the window",
    roughness="mean absolute difference of neighbouring nodes over the window",
    entropy="Shannon entropy of the values over the window (16 bins of the map's range)",
    correlation_length_m="correlation length from the lag-one autocorrelation in the window")


def add_parser(subparsers):
    """Add the ``suitability`` sub-command to an ``argparse`` sub-parser set."""
    s = subparsers.add_parser("suitability",
                              help="predicted matching precision from every node of a map")
    s.add_argument("--map", required=True, help="anomaly map: NetCDF grid (mGal) or a shipped "
                                                "map (ryukyu)")
    s.add_argument("--var", default=None, help="variable to read when the file has several")
    s.add_argument("--out", required=True, help="output NetCDF; the PNG is written next to it")
    s.add_argument("--heading", type=float, default=45.0,
                   help="segment heading, degrees clockwise from north, -360 to 360 "
                        "(default 45; -90 is 270)")
    s.add_argument("--fixes", type=whole_number, default=30,
                   help="readings per segment (at least 3; default 30)")
    s.add_argument("--spacing", type=float, default=1200.0,
                   help="distance between readings (m, default 1200)")
    s.add_argument("--noise", type=float, default=1.0,
                   help="reading noise 1-sigma (mGal; nT on a magnetic map)")
    s.add_argument("--map-error", type=float, default=0.0, metavar="SIGMA",
                   help="the map's error 1-sigma (mGal, nT on a magnetic map; default 0: "
                        "the map is the truth)")
    s.add_argument("--map-error-length", type=float, default=None, metavar="L",
                   help="its correlation length along the track (m, default 10000)")
    s.add_argument("--window", type=whole_number, default=None, metavar="NODES",
                   help="side of the descriptors' window (odd; default the segment length)")
    s.add_argument("--force", action="store_true", help="overwrite existing outputs")
    s.set_defaults(func=cmd_suitability)


STATUS = {0: "ok", 1: "off_map", 2: "missing_map", 3: "no_information"}
"""The ``status`` values of the output (module notes)."""


def cmd_suitability(args):
    """Run ``jaxgrav suitability`` (x64 is enabled by the CLI entry point)."""
    png = Path(args.out).with_suffix(".png")
    _check_args(args)
    if Path(args.out).suffix.lower() == ".png":
        raise ValueError(f"--out {str(args.out)!r} is the NetCDF output; the PNG is written "
                         f"next to it with suffix .png: give --out {str(png.with_suffix('.nc'))!r}")
    check_outputs([args.out, png], force=args.force, names=["--out", "its PNG"],
                  inputs={"--map": args.map})
    check_out_format(args.out, "NetCDF")
    grid = load_map(args.map, args.var, allow_nan=True)
    unit = "nT" if grid.units == "nT" else "mGal"  # a map without units: gravity
    if grid.n_missing == np.asarray(grid.values).size:
        raise ValueError(f"--map {args.map} has no value: every node is missing (NaN)")
    side = min(np.asarray(grid.values).shape[-2:])
    if args.window is not None and args.window > side:
        raise ValueError(f"--window must be at most the map's shorter side ({side} nodes); "
                         f"got {args.window}")
    cell_m = grid.spacing_m()[0]  # north-south node spacing at the map's centre (m)
    nodes = (args.fixes - 1) * args.spacing / cell_m  # the segment, in the map's nodes
    if nodes >= side:  # every segment leaves the map (and the default window is too wide)
        count = f"{nodes:.0f}" if nodes < 1e9 else f"{nodes:.3g}"  # 1e300: was 297 digits
        raise ValueError(f"--fixes {args.fixes} readings --spacing {args.spacing:g} m apart make "
                         f"a segment of {(args.fixes - 1) * args.spacing / 1e3:.4g} km, "
                         f"{count} nodes of the map, longer than its shorter side ({side} "
                         "nodes): every segment would leave the map; give fewer --fixes or a "
                         "shorter --spacing")
    _check_segment_resolved(grid, args)
    with np.errstate(invalid="ignore"):  # NaN nodes: the descriptors' bins of missing values
        suit = suitability(grid, heading_deg=args.heading, n_fixes=args.fixes,
                           spacing_m=args.spacing, noise_mgal=args.noise,
                           map_error_mgal=args.map_error,
                           map_error_length_m=args.map_error_length, window_cells=args.window)
    size_m = _map_size_m(grid)
    status = _status(grid, suit, args, size_m)
    blank = status != 0
    suit = suit._replace(
        precision_m=np.where(blank, np.nan, suit.precision_m),
        sigma_north_m=np.where(blank & ~(suit.sigma_north_m <= size_m), np.nan,
                               suit.sigma_north_m),
        sigma_east_m=np.where(blank & ~(suit.sigma_east_m <= size_m), np.nan, suit.sigma_east_m),
        corr=np.where(blank, np.nan, suit.corr))
    fields = dict(precision_m=suit.precision_m, sigma_north_m=suit.sigma_north_m,
                  sigma_east_m=suit.sigma_east_m, corr=suit.corr, **suit.descriptors)
    coords = dict(lat=("lat", np.asarray(grid.lat), {"units": "degrees_north"}),
                  lon=("lon", np.asarray(grid.lon), {"units": "degrees_east"}))
    ds = xr.Dataset({k: (("lat", "lon"), np.asarray(v, np.float64),
                         {"units": _UNITS[k].format(u=unit), "long_name": _LONG[k]})
                     for k, v in fields.items()}, coords=coords)
    ds["status"] = (("lat", "lon"), status.astype(np.int8), {
        "long_name": "why a node has no bound (0: it has one)",
        "flag_values": np.array(sorted(STATUS), np.int8),
        "flag_meanings": " ".join(STATUS[k] for k in sorted(STATUS))})
    ds.attrs.update(command="jaxgrav " + " ".join(sys.argv[1:]), map=str(args.map),
                    heading_deg=args.heading, n_fixes=args.fixes, spacing_m=args.spacing,
                    **{f"noise_{unit.lower()}": args.noise,
                       f"map_error_{unit.lower()}": args.map_error},
                    map_error_length_m=args.map_error_length,
                    no_information_above_m=round(size_m),
                    comment="nodes without a bound are missing values; status says why")
    with atomic_output(args.out, force=args.force) as tmp:
        ds.to_netcdf(tmp)
    _plot(grid, suit, args, png, unit)
    print(_summary(args, png, suit, status, size_m))


def _map_size_m(grid):
    """The diagonal of the map's extent (m), east-west at its widest latitude."""
    w, e, s, n = (float(v) for v in grid.extent)
    widest = 0.0 if s <= 0.0 <= n else min(abs(s), abs(n))
    return float(np.hypot((n - s) * DEG_ARC_M, (e - w) * DEG_ARC_M * np.cos(np.radians(widest))))


def _status(grid, suit, args, size_m):
    """:data:`STATUS` of every node: why its segment has no bound (0: it has one)."""
    p = suit.precision_m
    status = np.zeros(p.shape, np.int8)
    status[np.isnan(p)] = 1
    if grid.n_missing:  # a NaN bound on a segment inside the map: missing nodes on it
        lat0, lon0 = np.meshgrid(np.asarray(grid.lat), np.asarray(grid.lon), indexing="ij")
        length = (args.fixes - 1) * args.spacing
        h = np.radians(args.heading)
        lat1 = lat0 + length * np.cos(h) / np.asarray(meridian_radius(lat0)) / DEG
        lon1 = lon0 + length * np.sin(h) / (np.asarray(prime_vertical_radius(lat0))
                                             * np.cos(np.radians(lat0))) / DEG
        inside = np.asarray(grid.contains(lat1, lon1))
        status[np.isnan(p) & inside] = 2
    status[~np.isnan(p) & ~(p <= size_m)] = 3
    return status


def _summary(args, png, suit, status, size_m):
    """The command's closing lines."""
    counts = {k: int((status == k).sum()) for k in STATUS}
    p = suit.precision_m[status == 0]
    head = (f"wrote {args.out} and {png}: {counts[0]} of {status.size} nodes have a bound "
            f"({counts[1]} segments leave the map, {counts[2]} cross missing map nodes, "
            f"{counts[3]} see no information)")
    if p.size:
        q = np.percentile(p, [10, 50, 90])
        head += (f"; predicted precision (m) best tenth <= {q[0]:.0f}, median {q[1]:.0f}, "
                 f"worst tenth >= {q[2]:.0f}")
    head += f"; descriptors {', '.join(DESCRIPTORS)}"
    if counts[3]:
        head += (f"\nno information: at {counts[3]} nodes the map does not place the segment "
                 f"(its bound exceeds the map's own {size_m / 1e3:.0f} km: infinite where the "
                 "map is flat); they are missing values with status 3 (no_information)")
    return head


def _check_segment_resolved(grid, args):
    """ValueError for a segment along which the map, at its steepest, changes by less than
    ``--fixes`` readings of ``--noise`` can tell: "no information" at every node
    (``--spacing 1e-6`` ran and wrote such a map, exit 0)."""
    length = (args.fixes - 1) * args.spacing
    text, least_m = unresolved(grid, length, args.fixes, args.noise)
    if text is not None:
        raise ValueError(f"--spacing {args.spacing:g} m makes a segment of {length:.3g} m, "
                         f"along which {text}: no node could be told from its neighbours; "
                         f"expected a --spacing of at least {least_m / (args.fixes - 1):.2g} m")


def _check_args(args):
    """One-line errors naming the option, before any work."""
    if args.fixes < 2:
        raise ValueError(f"--fixes must be an integer >= 2 (readings per segment); got "
                         f"{args.fixes}")
    if args.fixes == 2:  # wrote a map of "no information" at every node, exit 0
        raise ValueError("--fixes 2 places no segment: two readings cannot give the position "
                         "(north, east) and the free gravimeter bias; give at least 3")
    fill_map_error_length(args, args.map_error != 0)
    for name, value, zero_ok, unit in (("--spacing", args.spacing, False, "m"),
                                       ("--noise", args.noise, False, "mGal"),
                                       ("--map-error", args.map_error, True, "mGal"),
                                       ("--map-error-length", args.map_error_length, False, "m")):
        if not (np.isfinite(value) and (value >= 0 if zero_ok else value > 0)):
            bound = ">= 0" if zero_ok else "> 0"
            raise ValueError(f"{name} must be a finite number {bound} ({unit}); got {value!r}")
        if unit == "mGal" and value > MAX_BIAS_MGAL:  # 1e300: squared to inf, ran (exit 0)
            typical = ("a marine gravimeter's noise is about 1" if name == "--noise"
                       else "a marine map's error is a few mGal")
            raise ValueError(f"{name} must be at most {MAX_BIAS_MGAL:g} mGal ({typical}); got "
                             f"{value:g}")
    if not (np.isfinite(args.heading) and abs(args.heading) <= 360.0):
        raise ValueError(f"--heading must be an angle from -360 to 360 (degrees clockwise from "
                         f"north); got {args.heading!r}")
    if args.window is not None and (args.window < 3 or args.window % 2 == 0):
        raise ValueError(f"--window must be an odd number of nodes >= 3; got {args.window}")


def _plot(grid, suit, args, png, unit):
    lon, lat = np.asarray(grid.lon), np.asarray(grid.lat)
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    p = suit.precision_m
    finite = p[np.isfinite(p) & (p > 0)]
    norm = LogNorm(*np.percentile(finite, [2, 98])) if finite.size else None
    extent = (lon[0] - grid.dlon / 2, lon[-1] + grid.dlon / 2, lat[0] - grid.dlat / 2,
              lat[-1] + grid.dlat / 2)
    im = axes[0].imshow(p, origin="lower", extent=extent, norm=norm, cmap="viridis_r",
                        interpolation="nearest")
    fig.colorbar(im, ax=axes[0], label="predicted precision (m, CRLB)")
    axes[0].set_title(f"{args.fixes} fixes {args.spacing:g} m apart, heading {args.heading:g}°,"
                      f"\nnoise {args.noise:g} {unit}, map error {args.map_error:g} {unit}")
    im = axes[1].imshow(suit.descriptors["std"], origin="lower", extent=extent, cmap="magma",
                        interpolation="nearest")
    fig.colorbar(im, ax=axes[1], label=f"window std ({unit})")
    axes[1].set_title("map standard deviation over the window")
    for ax in axes:
        ax.set_xlabel("longitude (°)")
        ax.set_ylabel("latitude (°)")
        ax.set_aspect(1.0 / np.cos(np.radians(lat.mean())))
    save_figure(fig, png, force=args.force)
    plt.close(fig)
