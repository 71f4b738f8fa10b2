"""Matplotlib figures: maps with tracks, error summaries.

Figures are built on the non-interactive Agg backend and saved atomically.
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import LogFormatterSciNotation, MaxNLocator

from jaxgrav._io import atomic_output

__all__ = ["add_scale_bar", "plot_error_summary", "plot_map", "plot_voyage_errors", "save_figure"]


def _nice_length_km(width_km):
    """A round scale-bar length (km) of about a quarter of ``width_km``."""
    target = max(width_km / 4.0, 1e-3)
    base = 10.0 ** np.floor(np.log10(target))
    return float(max(m * base for m in (1, 2, 5) if m * base <= target))


def add_scale_bar(ax, lat_mid):
    """Draw a kilometre scale bar in the lower-left corner of a lon/lat map axes.

    Parameters
    ----------
    ax : matplotlib Axes
        Axes whose x is longitude and y latitude (degrees), limits already set.
    lat_mid : float
        Latitude (degrees) at which a degree of longitude is converted to km.

    Returns
    -------
    float
        The bar's length (km).
    """
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    km_per_deg = 111.32 * np.cos(np.radians(lat_mid))
    length = _nice_length_km((x1 - x0) * km_per_deg)
    xs = x0 + 0.05 * (x1 - x0)
    y = y0 + 0.06 * (y1 - y0)
    ax.plot([xs, xs + length / km_per_deg], [y, y], color="k", lw=3, solid_capstyle="butt")
    ax.text(xs + 0.5 * length / km_per_deg, y + 0.02 * (y1 - y0), f"{length:g} km",
            ha="center", va="bottom", fontsize=8)
    return length


def plot_map(grid, ax=None, *, tracks=None, title=None, cmap="RdBu_r", channel=None,
             window=None, scale_bar=False):
    """Draw a grid as an image with optional tracks on top.

    Parameters
    ----------
    grid : Grid
        Map to draw; for multi-channel grids pass ``channel`` (an index tuple).
    ax : matplotlib Axes, optional
        Axes to draw into; a new figure is made if omitted.
    tracks : dict of str to (lat, lon), optional
        Named tracks (degrees), drawn as lines with a legend (solid, dashed, dotted, so
        a track drawn over another stays visible); each track's first point is marked,
        and the marker has one legend entry ("start").
    title : str, optional
    cmap : str
        Colour map: symmetric about zero for the whole map, spanning the window's own
        minimum to maximum with ``window``.
    channel : tuple of int, optional
        Index into the leading axes of ``grid.values``.
    window : (south, north, west, east), optional
        Show only this window (degrees); the colour range is then the window's own,
        so the local field is not drawn flat by the whole map's extremes.
    scale_bar : bool
        Draw a kilometre scale bar.

    Returns
    -------
    matplotlib Axes
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 6), layout="constrained")
    v = np.asarray(grid.values)
    if channel is not None:
        v = v[channel]
    if v.ndim != 2:
        raise ValueError(f"channel must select a 2-D map; values have shape {v.shape}")
    shown = v
    if window is not None:
        s, n, w, e = window
        lat, lon = np.asarray(grid.lat), np.asarray(grid.lon)
        rows = (lat >= s) & (lat <= n)
        cols = (lon >= w) & (lon <= e)
        if rows.any() and cols.any():
            shown = v[np.ix_(rows, cols)]
    if not np.isfinite(shown).any():
        lo, hi = -1.0, 1.0
    elif window is None:  # the whole map: symmetric about zero
        hi = float(np.nanmax(np.abs(shown)))
        lo = -hi
    else:  # a window: its own range, so the local field is not drawn flat
        lo, hi = float(np.nanmin(shown)), float(np.nanmax(shown))
        if hi - lo < 1e-12:
            lo, hi = lo - 1.0, hi + 1.0
    im = ax.imshow(v, origin="lower", extent=grid.extent, cmap=cmap, vmin=lo, vmax=hi,
                   aspect="auto", interpolation="nearest")
    plt.colorbar(im, ax=ax, label=grid.units or None, shrink=0.85, pad=0.02)
    for i, (name, (lat_t, lon_t)) in enumerate((tracks or {}).items()):
        lat_t, lon_t = np.asarray(lat_t), np.asarray(lon_t)
        ax.plot(lon_t, lat_t, lw=2.0 if i else 1.5, ls=("-", "--", ":", "-.")[i % 4],
                label=name)
        ax.plot(lon_t[0], lat_t[0], "ko", ms=4, label="start" if i == 0 else None)
    if window is not None:
        ax.set_xlim(window[2], window[3])
        ax.set_ylim(window[0], window[1])
    if tracks:
        ax.legend(loc="upper right", fontsize=8, framealpha=0.85)
    if scale_bar:
        add_scale_bar(ax, 0.5 * sum(ax.get_ylim()))
    ax.set_xlabel("longitude (°E)")
    ax.set_ylabel("latitude (°N)")
    ax.set_title(title or grid.name, fontsize=10)
    return ax


def plot_error_summary(ins_err, err, *, title, label="matched",
                       xlabel="mean track error (m)", failure_ratio=1 / 3):
    """Two panels comparing a method's per-run errors with the free INS's.

    Left: histogram of the per-run ratio error / INS error on a log axis, with the INS
    (ratio 1) and the failure bound as vertical lines — a ratio, so a fixed-size INS
    drift (the same error in every run) does not draw one spike that squashes the
    method's histogram. Right: the cumulative distributions of both errors.

    Parameters
    ----------
    ins_err, err : array_like, shape ``(runs,)``
        Errors of the free INS and of the method (m); non-finite runs are counted in
        the title and left out of the panels.
    title : str
        The scenario (method, runs, map error...), shown above both panels.
    label : str
        Name of the method's curve.
    xlabel : str
        What the errors are (with units).
    failure_ratio : float
        Ratio above which a run counts as failed (drawn as a line).

    Returns
    -------
    matplotlib Figure
    """
    ins = np.asarray(ins_err, float)
    err = np.asarray(err, float)
    ok = np.isfinite(ins) & np.isfinite(err) & (ins > 0)
    ratio = err[ok] / ins[ok]
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(12, 4.8), layout="constrained")
    pos = ratio[ratio > 0]
    lo = min(pos.min() if pos.size else 0.1, 0.5 * failure_ratio)
    hi = max(pos.max() if pos.size else 2.0, 2.0)
    bins = np.geomspace(lo, hi * 1.001, 40)
    ax0.hist(np.clip(ratio, lo, None), bins=bins, color="C1", alpha=0.8,
             label=f"{label} (median {np.median(ratio):.3f})" if ratio.size else label)
    ax0.axvline(1.0, color="k", lw=1.5, label="free INS (= 1)")
    ax0.axvline(failure_ratio, color="C3", ls="--", lw=1.2,
                label=f"failure bound ({failure_ratio:.3g})")
    ax0.set_xscale("log")
    ax0.xaxis.set_major_formatter(LogFormatterSciNotation(labelOnlyBase=False,
                                                          minor_thresholds=(2, 0.5)))
    ax0.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax0.set_xlabel(f"error / INS error, per run ({xlabel.split(' (')[0]})")
    ax0.set_ylabel("runs")
    ax0.legend(fontsize=8)
    worse = float(np.mean(ratio > 1.0)) if ratio.size else float("nan")
    ax0.set_title(f"worse than the INS: {100 * worse:.1f} % of runs", fontsize=9)
    for name, v, c in (("INS", ins, "k"), (label, err, "C1")):
        v = np.sort(v[np.isfinite(v)])
        ax1.plot(v, np.arange(1, v.size + 1) / max(v.size, 1), color=c, label=name)
    ax1.set_xscale("log")
    ax1.set_xlabel(xlabel)
    ax1.set_ylabel("fraction of runs ≤ error")
    ax1.set_ylim(0, 1.02)
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(loc="lower right", fontsize=8)
    bad = int((~ok).sum())
    fig.suptitle(title + (f" ({bad} runs non-finite, left out)" if bad else ""), fontsize=10)
    return fig


def plot_voyage_errors(t_h, nav_err, free_err, sigma, *, title, fix_t_h=None,
                       fix_accepted=None):
    """Position error against time over many voyages: median and 90 % band.

    Parameters
    ----------
    t_h : array_like, shape ``(T,)``
        Time (h).
    nav_err, free_err : array_like, shape ``(runs, T)``
        Radial error of the navigation solution and of the free INS (m).
    sigma : array_like, shape ``(runs, T)``
        The navigation solution's stated radial 1-σ (m): ``√(σ_n² + σ_e²)``.
    title : str
    fix_t_h : array_like, shape ``(C,)``, optional
        Times of the segment ends (h).
    fix_accepted : array_like, shape ``(runs, C)``, optional
        Whether each voyage's fix there was accepted; the share is drawn on a second axis.

    Returns
    -------
    matplotlib Figure
    """
    t = np.asarray(t_h, float)
    fig, ax = plt.subplots(figsize=(10, 4.8), layout="constrained")
    for name, e, c in (("free INS", free_err, "k"), ("navigation", nav_err, "C1")):
        lo, med, hi = np.nanpercentile(np.asarray(e, float), [5, 50, 95], axis=0)
        ax.fill_between(t, lo / 1e3, hi / 1e3, color=c, alpha=0.15, lw=0)
        ax.plot(t, med / 1e3, color=c, label=f"{name}: median, 90 % band")
    ax.plot(t, np.nanmedian(np.asarray(sigma, float), axis=0) / 1e3, color="C0", ls="--",
            label="navigation: median stated 1-σ")
    ax.set_xlabel("time (h)")
    ax.set_ylabel("radial position error (km)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    if fix_t_h is not None and fix_accepted is not None:
        ax2 = ax.twinx()
        share = np.mean(np.asarray(fix_accepted, float), axis=0)
        ax2.plot(np.asarray(fix_t_h, float), share, "v", color="C2", label="fixes accepted")
        ax2.set_ylim(0, 1.05)
        ax2.set_ylabel("share of voyages whose fix was accepted", color="C2")
        ax2.legend(loc="lower right", fontsize=8)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title, fontsize=10)
    return fig


def save_figure(fig, path, *, force=False, dpi=120):
    """Save a figure to ``path`` atomically (PNG by suffix); refuses to overwrite without force."""
    with atomic_output(path, force=force) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format=str(path).rsplit(".", 1)[-1])
    plt.close(fig)
