"""The voyage figures over many voyages (:func:`jaxgrav.navigate.voyage_summary`): a
voyage without an error to show is counted, and is not dropped unannounced."""

import numpy as np
import pytest

from jaxgrav.navigate import voyage_summary


def test_a_voyage_without_a_finite_error_counts_as_worse_and_is_reported():
    nav = np.array([[500.0, 600.0, 700.0], [400.0, np.nan, 500.0], [300.0, 300.0, 300.0]])
    free = np.full((3, 3), 1000.0)
    nees = np.array([2.0, 2.5, np.inf])
    vs = voyage_summary(nav, free, nees)
    assert vs["nonfinite_voyages"] == 2  # a NaN hour, and an infinite NEES
    assert vs["share_worse_than_free_some_hour"] == pytest.approx(1 / 3)  # the NaN voyage
    assert np.isnan(vs["hourly_rms_nav_m"][1]) and not np.isfinite(vs["nees"])
    finite = voyage_summary(nav[[0, 2]], free[[0, 2]], nees[:2])
    assert finite["nonfinite_voyages"] == 0
    assert finite["share_worse_than_free_some_hour"] == 0.0
    assert finite["last_hour_ratio"] == pytest.approx(np.sqrt((700**2 + 300**2) / 2) / 1000)
