"""The voyage methods of ``jaxgrav montecarlo``: their options, summary lines and figure."""

import json
import math

import jax
import matplotlib.pyplot as plt
import numpy as np

from jaxgrav.cli.inputs import whole_number
from jaxgrav.cli.navigate_loose import add_dense_loop_options, reacquire_options
from jaxgrav.cli.voyage import MAX_HOURS
from jaxgrav.montecarlo.voyage_runs import SERIES_EVERY_S, TOLD, voyage_tracks
from jaxgrav.navigate import voyage_summary
from jaxgrav.plot import plot_map, plot_voyage_errors, save_figure
from jaxgrav.scenarios import INS_GRADES

__all__ = ["add_loop_options", "plot_voyage_tracks", "plot_voyages", "tracks_path",
           "voyage_attrs", "voyage_lines", "voyage_options"]


def add_loop_options(parser):
    """``--segment-error``, ``--[no-]fix-prior``, ``--first-n-fixes``,
    ``--[no-]shape-update``, ``--reacquire-after`` and ``--reacquire-inflation``:
    voyage-dense's loop settings."""
    add_dense_loop_options(parser, "voyage-dense")
    parser.add_argument("--first-n-fixes", type=whole_number, default=None,
                        help="voyage-dense: the segment ends before a whole segment match the "
                             "last N fixes (e.g. 30: the first fix after 1 h; default none)")


def voyage_options(args):
    """Builder options of a voyage method from the command line (ValueError naming the
    option for ``--fixes``, a bad ``--hours``, ``--told-map-error`` or ``--map-error-order``)."""
    if args.fixes is not None:
        raise ValueError(f"--fixes is not an option of {args.method}: a voyage runs over "
                         "--hours (default 12)")
    if args.hours is not None and not (math.isfinite(args.hours) and 1 <= args.hours <= MAX_HOURS):
        raise ValueError(f"--hours must be a patrol length from 1 h (the errors are reported "
                         f"per hour) to {MAX_HOURS:g} h; got {args.hours!r}")
    told = args.told_map_error or "state"
    if told not in TOLD:
        raise ValueError(f"--told-map-error must be one of {', '.join(TOLD)} with --method "
                         f"{args.method}; got {told!r}")
    if args.map_error_order not in (None, 1, 2):
        raise ValueError(f"--map-error-order must be 1 or 2; got {args.map_error_order}")
    loop = {k: v for k, v in (("segment_error", args.segment_error),
                              ("fix_prior", args.fix_prior),
                              ("first_n_fixes", args.first_n_fixes),
                              ("shape_update", args.shape_update)) if v is not None}
    if (loop or args.reacquire_after is not None or args.reacquire_inflation is not None) and (
            args.method != "voyage-dense"):
        raise ValueError(f"--segment-error, --fix-prior, --first-n-fixes, --shape-update and "
                         f"--reacquire-after / --reacquire-inflation are options of --method "
                         f"voyage-dense; got --method {args.method}")
    loop |= reacquire_options(args, never=0)
    return dict(map_error_told=told, map_error_order=args.map_error_order, hours=args.hours,
                ins=INS_GRADES[args.ins or "navigation"], **loop)


def _km(values):
    return " ".join(f"{v / 1000:.1f}" for v in values)


def voyage_lines(results):
    """The voyage figures of :func:`~jaxgrav.navigate.voyage_summary`, as two lines.

    Only the figures the voyage has: the last / second hour ratio needs three whole
    hours (with two the last hour is the second), the comparison with the free INS
    "from the second hour" two; a shorter voyage says which are left out and why.
    """
    vs = voyage_summary(results["hourly_err_m"], results["hourly_ins_err_m"], results["nees"])
    hours = len(vs["hourly_rms_nav_m"])
    parts = [f"last hour / free INS {vs['last_hour_ratio']:.3f}"]
    if hours >= 3:
        parts.append(f"last / second hour {vs['last_over_second_hour']:.2f}")
    if hours >= 2:
        parts.append(f"worse than the free INS in some hour from the second: "
                     f"{100 * vs['share_worse_than_free_some_hour']:.0f} % of voyages")
    if hours == 2:
        parts.append("no last / second hour ratio: the last hour is the second (it needs "
                     "--hours 3 or more)")
    elif hours == 1:
        parts.append("one whole hour, no second: the last / second hour ratio needs --hours 3 "
                     "or more, the hours from the second --hours 2")
    parts.append(f"NEES mean {vs['nees']:.2f} (median {vs['nees_median']:.2f}, 2 expected)")
    return (f"hourly RMS (km) navigation: {_km(vs['hourly_rms_nav_m'])}; free INS: "
            f"{_km(vs['hourly_rms_free_m'])}\n" + ", ".join(parts))




def voyage_attrs(results):
    """The voyage figures of :func:`~jaxgrav.navigate.voyage_summary` as NetCDF attributes
    (``summary_voyage_*``; the hourly lists as JSON text)."""
    vs = voyage_summary(results["hourly_err_m"], results["hourly_ins_err_m"], results["nees"])
    return {f"summary_voyage_{k}": json.dumps(v) if isinstance(v, list) else v
            for k, v in vs.items()}


def plot_voyages(results, title, path, force):
    """Error against time (median and 90 % band, free INS alongside, stated 1-σ; for the
    loosely coupled method the share of fixes accepted at each segment end) as a PNG."""
    series = [np.asarray(results[k]) for k in ("err_series_m", "ins_err_series_m",
                                               "sigma_series_m")]
    t_h = np.arange(series[0].shape[1]) * SERIES_EVERY_S / 3600.0
    fixes = {}
    if "fix_event" in results:  # loosely coupled: the share of fixes accepted at each end
        fixes = dict(fix_t_h=np.asarray(results["fix_time_s"])[0] / 3600.0,
                     fix_accepted=np.asarray(results["fix_event"]) == 0)
    save_figure(plot_voyage_errors(t_h, *series, title=title, **fixes), path, force=force)


def tracks_path(out):
    """The tracks figure next to ``--out``: ``V.nc`` -> ``V_tracks.png``."""
    return out.with_name(out.stem + "_tracks.png")


def plot_voyage_tracks(spec, key, runs, title, path, force):
    """The first run's voyage on the map (truth, free INS, navigation) as a PNG.

    Parameters
    ----------
    spec : MethodSpec
        The voyage method that ran (its ``args``: prepared map, map, scenario, map-error
        model, navigation settings).
    key : PRNG key
        The Monte Carlo key; run 0's key is ``split(key, runs)[0]``, as
        :func:`jaxgrav.montecarlo.run` gives it, so the figure shows that run.
    runs : int
    title : str
    path : Path
    force : bool

    Returns
    -------
    dict of str to (numpy.ndarray, numpy.ndarray)
        The tracks drawn (degrees).
    """
    run_key = jax.random.split(key, runs)[0]
    tracks = jax.tree.map(np.asarray, jax.jit(voyage_tracks)(run_key, *spec.args))
    lats = np.concatenate([lat for lat, _ in tracks.values()])
    lons = np.concatenate([lon for _, lon in tracks.values()])
    pad = 0.05
    window = (lats.min() - pad, lats.max() + pad, lons.min() - pad, lons.max() + pad)
    fig, ax = plt.subplots(figsize=(7, 6), layout="constrained")
    plot_map(spec.args[1], ax, tracks=tracks, window=window, scale_bar=True, title=title)
    save_figure(fig, path, force=force)
    return tracks
