"""Matplotlib figures: maps with tracks, error summaries.

Figures are built on the non-interactive Agg backend and saved atomically.
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from jaxgrav._io import atomic_output

__all__ = ["plot_map", "save_figure"]


def plot_map(grid, ax=None, *, tracks=None, title=None, cmap="RdBu_r", channel=None):
    """Draw a grid as an image with optional tracks on top.

    Parameters
    ----------
    grid : Grid
        Map to draw; for multi-channel grids pass ``channel`` (an index tuple).
    ax : matplotlib Axes, optional
        Axes to draw into; a new figure is made if omitted.
    tracks : dict of str to (lat, lon), optional
        Named tracks (degrees), drawn as lines with a legend.
    title : str, optional
    cmap : str
        Colour map, symmetric about zero.
    channel : tuple of int, optional
        Index into the leading axes of ``grid.values``.

    Returns
    -------
    matplotlib Axes
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 6))
    v = np.asarray(grid.values)
    if channel is not None:
        v = v[channel]
    if v.ndim != 2:
        raise ValueError(f"channel must select a 2-D map; values have shape {v.shape}")
    lim = float(np.nanmax(np.abs(v)))
    im = ax.imshow(
        v,
        origin="lower",
        extent=grid.extent,
        cmap=cmap,
        vmin=-lim,
        vmax=lim,
        aspect="auto",
        interpolation="nearest",
    )
    plt.colorbar(im, ax=ax, label=grid.units or None, shrink=0.85)
    for name, (lat, lon) in (tracks or {}).items():
        ax.plot(np.asarray(lon), np.asarray(lat), lw=1.5, label=name)
    if tracks:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("longitude (°E)")
    ax.set_ylabel("latitude (°N)")
    ax.set_title(title or grid.name)
    return ax


def save_figure(fig, path, *, force=False, dpi=120):
    """Save a figure to ``path`` atomically (PNG by suffix); refuses to overwrite without force."""
    with atomic_output(path, force=force) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format=str(path).rsplit(".", 1)[-1])
    plt.close(fig)
