"""Matplotlib figures: maps with tracks, error summaries.

Figures are built on the non-interactive Agg backend and saved atomically.
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from jaxgrav._io import atomic_output

__all__ = ["add_scale_bar", "plot_map", "save_figure"]


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


def save_figure(fig, path, *, force=False, dpi=120):
    """Save a figure to ``path`` atomically (PNG by suffix); refuses to overwrite without force."""
    with atomic_output(path, force=force) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format=str(path).rsplit(".", 1)[-1])
    plt.close(fig)
