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
"""

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from matplotlib.colors import LogNorm

from jaxgrav._io import atomic_output, check_outputs
from jaxgrav.datasets import load_map
from jaxgrav.match.suitability import DESCRIPTORS, suitability
from jaxgrav.plot import save_figure

__all__ = ["add_parser", "cmd_suitability"]

_UNITS = dict(precision_m="m", sigma_north_m="m", sigma_east_m="m", corr="1", std="mGal",
              slope_std="mGal/km", roughness="mGal", entropy="nat", correlation_length_m="m")
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
                   help="segment heading, degrees clockwise from north (default 45)")
    s.add_argument("--fixes", type=int, default=30, help="readings per segment (default 30)")
    s.add_argument("--spacing", type=float, default=1200.0,
                   help="distance between readings (m, default 1200)")
    s.add_argument("--noise", type=float, default=1.0, help="reading noise 1-sigma (mGal)")
    s.add_argument("--map-error", type=float, default=0.0, metavar="SIGMA",
                   help="the map's error 1-sigma (mGal, default 0: the map is the truth)")
    s.add_argument("--map-error-length", type=float, default=10e3, metavar="L",
                   help="its correlation length along the track (m, default 10000)")
    s.add_argument("--window", type=int, default=None, metavar="NODES",
                   help="side of the descriptors' window (odd; default the segment length)")
    s.add_argument("--force", action="store_true", help="overwrite existing outputs")
    s.set_defaults(func=cmd_suitability)


def cmd_suitability(args):
    """Run ``jaxgrav suitability`` (x64 is enabled by the CLI entry point)."""
    png = Path(args.out).with_suffix(".png")
    _check_args(args)
    check_outputs([args.out, png], force=args.force, names=["--out", "its PNG"])
    grid = load_map(args.map, args.var)
    suit = suitability(grid, heading_deg=args.heading, n_fixes=args.fixes,
                       spacing_m=args.spacing, noise_mgal=args.noise,
                       map_error_mgal=args.map_error, map_error_length_m=args.map_error_length,
                       window_cells=args.window)
    fields = dict(precision_m=suit.precision_m, sigma_north_m=suit.sigma_north_m,
                  sigma_east_m=suit.sigma_east_m, corr=suit.corr, **suit.descriptors)
    coords = dict(lat=("lat", np.asarray(grid.lat), {"units": "degrees_north"}),
                  lon=("lon", np.asarray(grid.lon), {"units": "degrees_east"}))
    ds = xr.Dataset({k: (("lat", "lon"), np.asarray(v, np.float64),
                         {"units": _UNITS[k], "long_name": _LONG[k]})
                     for k, v in fields.items()}, coords=coords)
    ds.attrs.update(command="jaxgrav " + " ".join(sys.argv[1:]), map=str(args.map),
                    heading_deg=args.heading, n_fixes=args.fixes, spacing_m=args.spacing,
                    noise_mgal=args.noise, map_error_mgal=args.map_error,
                    map_error_length_m=args.map_error_length)
    with atomic_output(args.out, force=args.force) as tmp:
        ds.to_netcdf(tmp)
    _plot(grid, suit, args, png)
    p = suit.precision_m[np.isfinite(suit.precision_m)]
    q = np.percentile(p, [10, 50, 90]) if p.size else [np.nan] * 3
    print(f"wrote {args.out} and {png}: {p.size} of {suit.precision_m.size} nodes start a "
          f"segment inside the map; predicted precision (m) best tenth <= {q[0]:.0f}, median "
          f"{q[1]:.0f}, worst tenth >= {q[2]:.0f}; descriptors {', '.join(DESCRIPTORS)}")


def _check_args(args):
    """One-line errors naming the option, before any work."""
    if args.fixes < 2:
        raise ValueError(f"--fixes must be an integer >= 2 (readings per segment); got "
                         f"{args.fixes}")
    for name, value, zero_ok, unit in (("--spacing", args.spacing, False, "m"),
                                       ("--noise", args.noise, False, "mGal"),
                                       ("--map-error", args.map_error, True, "mGal"),
                                       ("--map-error-length", args.map_error_length, False, "m")):
        if not (np.isfinite(value) and (value >= 0 if zero_ok else value > 0)):
            bound = ">= 0" if zero_ok else "> 0"
            raise ValueError(f"{name} must be a finite number {bound} ({unit}); got {value!r}")
    if not np.isfinite(args.heading):
        raise ValueError(f"--heading must be finite (degrees from north); got {args.heading!r}")
    if args.window is not None and (args.window < 3 or args.window % 2 == 0):
        raise ValueError(f"--window must be an odd number of nodes >= 3; got {args.window}")


def _plot(grid, suit, args, png):
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
                      f"\nnoise {args.noise:g} mGal, map error {args.map_error:g} mGal")
    im = axes[1].imshow(suit.descriptors["std"], origin="lower", extent=extent, cmap="magma",
                        interpolation="nearest")
    fig.colorbar(im, ax=axes[1], label="window std (mGal)")
    axes[1].set_title("map standard deviation over the window")
    for ax in axes:
        ax.set_xlabel("longitude (°)")
        ax.set_ylabel("latitude (°)")
        ax.set_aspect(1.0 / np.cos(np.radians(lat.mean())))
    save_figure(fig, png, force=args.force)
    plt.close(fig)
