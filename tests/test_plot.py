"""Figures: the error summary and the map panel (layout, ranges, legends)."""

import matplotlib.pyplot as plt
import numpy as np

import jaxgrav as jg
from jaxgrav.plot import add_scale_bar, plot_error_summary, plot_map


def test_error_summary_histogram_is_of_ratios_with_integer_counts():
    ins = np.full(50, 3892.0)  # a fixed-size drift: one value, no spike drawn
    err = np.geomspace(100, 8000, 50)
    err[3] = np.nan
    fig = plot_error_summary(ins, err, title="dense: 50 runs, map error 3 mGal")
    ax0 = fig.axes[0]
    assert "1 runs non-finite" in fig.get_suptitle()
    heights = [p.get_height() for p in ax0.patches]
    assert sum(heights) == 49 and all(float(h).is_integer() for h in heights)
    assert all(float(t).is_integer() for t in ax0.get_yticks())
    worse = np.mean(err[np.isfinite(err)] > ins[0])  # 9 of the 49 finite runs
    assert ax0.get_xscale() == "log"
    assert f"worse than the INS: {100 * worse:.1f} %" in ax0.get_title()
    plt.close(fig)


def test_plot_map_window_uses_the_windows_colour_range():
    lat = np.linspace(0, 1, 11)
    lon = np.linspace(10, 11, 11)
    v = np.add.outer(100 * lat, 10 * lon)
    g = jg.Grid.from_arrays(lat, lon, v, units="mGal")
    fig, (a, b) = plt.subplots(1, 2)
    plot_map(g, a, tracks={"t": ([0.2, 0.3], [10.2, 10.3]), "u": ([0.2, 0.4], [10.2, 10.4])})
    plot_map(g, b, window=(0.2, 0.4, 10.2, 10.4), scale_bar=True)
    lo, hi = a.images[0].get_clim()
    assert lo == -hi == -float(np.abs(v).max())
    lo, hi = b.images[0].get_clim()
    assert (lo, hi) == (v[2, 2], v[4, 4])
    labels = [t.get_text() for t in a.get_legend().get_texts()]
    assert labels == ["t", "start", "u"]  # one start entry for all tracks
    assert b.get_xlim() == (10.2, 10.4)
    plt.close(fig)


def test_scale_bar_length_is_round():
    fig, ax = plt.subplots()
    ax.set_xlim(126.0, 126.2)
    ax.set_ylim(30.0, 30.2)
    assert add_scale_bar(ax, 30.1) == 2.0  # 0.2° of longitude at 30° ≈ 19 km: a quarter, 2 km
    plt.close(fig)
