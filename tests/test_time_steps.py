"""The regular step of a log (jaxgrav.time_steps): jitter absorbed, gaps bridged or named."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgrav.filters import filter_track
from jaxgrav.filters.api import reading_stride
from jaxgrav.time_steps import JITTER, at_rows, on_steps, time_steps


def test_jitter_within_a_tenth_of_a_step_is_absorbed():
    rng = np.random.default_rng(0)
    t = 100.0 + 10.0 * np.arange(500) + rng.uniform(-0.5, 0.5, 500)
    steps = time_steps(t, "log")
    np.testing.assert_array_equal(steps.rows, np.arange(500))
    assert steps.n_steps == 500 and steps.n_gaps == 0 and steps.n_inserted == 0
    assert steps.dt == pytest.approx((t[-1] - t[0]) / 499, rel=1e-12)  # no clock drift
    assert 0.5 < steps.jitter <= 1.0
    assert "(steps jitter by up to" in steps.describe()


def test_a_log_with_more_gaps_than_single_steps_is_read():
    # 1-row gaps between most rows: the median step is two steps, the short ones say one
    steps = time_steps(np.array([0, 10, 30, 40, 60, 70, 90.0]), "log")
    np.testing.assert_array_equal(steps.rows, [0, 1, 3, 4, 6, 7, 9])
    assert steps.dt == 10.0 and steps.n_gaps == 3
    steps = time_steps(np.array([0, 10, 30, 50, 70, 80.0]), "log")
    np.testing.assert_array_equal(steps.rows, [0, 1, 3, 5, 7, 8])
    # a regular 20 s log is not read as a 10 s log with gaps
    np.testing.assert_array_equal(time_steps(20.0 * np.arange(6), "log").rows, np.arange(6))


def test_decimal_times_have_no_jitter():
    t = np.round(0.3 + 0.1 * np.arange(2000), 1)  # 0.1 s steps as written in a CSV
    steps = time_steps(t, "log")
    assert steps.jitter == 0.0 and steps.describe() == "time step 0.1 s"


def test_a_clock_running_slow_is_followed_not_refused():
    # 10.002 s steps for a day: 0.2 % off the median would be 17 s (1.7 steps) at the end
    t = 10.002 * np.arange(8640)
    steps = time_steps(t, "log")
    assert steps.dt == pytest.approx(10.002) and steps.jitter < 1e-6


def test_gaps_are_whole_steps_and_the_rows_keep_their_place():
    t = 10.0 * np.array([0, 1, 2, 5, 6, 9, 10], float)
    t[3] += 0.4  # jitter on a gap's far side
    steps = time_steps(t, "log")
    np.testing.assert_array_equal(steps.rows, [0, 1, 2, 5, 6, 9, 10])
    assert (steps.n_steps, steps.n_gaps, steps.n_inserted) == (11, 2, 4)
    assert "2 gap(s) bridged by prediction over 4 missing row(s)" in steps.describe()
    lat = np.array([0, 1, 2, 5, 6, 9, 10], float)
    np.testing.assert_allclose(on_steps(steps, lat), np.arange(11.0))
    reading = on_steps(steps, lat + 100, fill=np.nan)
    assert np.isnan(reading[[3, 4, 7, 8]]).all() and reading[5] == 105
    back = at_rows(steps, {"x": on_steps(steps, lat)})["x"]
    np.testing.assert_array_equal(back, lat)


def test_longitudes_are_interpolated_across_the_antimeridian():
    steps = time_steps(np.array([0.0, 10.0, 20.0, 40.0]), "log")
    lon = on_steps(steps, np.array([178.9, 179.4, 179.9, -179.1]), period=360.0)
    np.testing.assert_allclose(lon, [178.9, 179.4, 179.9, 180.4, -179.1])  # rows as read


def test_a_gap_with_several_columns_is_interpolated_per_column():
    steps = time_steps(np.array([0.0, 1.0, 2.0, 4.0]), "log")
    jac = on_steps(steps, np.array([[0.0, 1.0], [1.0, 2.0], [2.0, 3.0], [4.0, 5.0]]))
    np.testing.assert_allclose(jac, [[0, 1], [1, 2], [2, 3], [3, 4], [4, 5]])
    assert on_steps(steps, np.ones((4, 2)), fill=0.0).shape == (5, 2)


@pytest.mark.parametrize(("t", "kw", "message"), [
    ([0.0], {}, "log has 1 row; the filter needs at least 2"),
    ([0, 10, 10, 20], {}, "column t must increase; it repeats on lines 3-4 (t 10 -> 10 s); 1 "
                          "such step(s)"),
    ([0, 10, 5, 20], {}, "it goes backwards on lines 3-4 (t 10 -> 5 s)"),
    ([0, 10, 13, 20, 30, 40, 50], {}, "a step of 3 s on lines 3-4 (t 10 -> 13 s) is under half the "
                              "log's step (10 s)"),
    ([0, 10, float("nan"), 30], {}, "log: column t has 1 missing or non-finite time(s), the "
                                    "first on line 4"),
    ([0, 120, 240, 360], {"max_gap": 60.0, "max_step": 60.0},
     "log: the log's step, 120 s, is longer than --max-gap 60 s: is column t in seconds?"),
    ([0, 10, 20, 1e20], {}, "steps of 10 s without a row, more than 10 x"),
    ([0, 10, 20, 32, 40, 50], {}, "column t must have a regular step; a step of 12 s on lines "
                                  "4-5 (t 20 -> 32 s) is not within 10% of the step 10 s"),
    ([0, 10, 20, 34, 40, 50], {}, "a step of 14 s on lines 4-5"),  # 1.4 steps: not a gap
    ([0, 10, 20, 50, 60], {"gaps": "pmf needs every row"},
     "log: a gap of 2 missing row(s) on lines 4-5 (t 20 -> 50 s) (step 10 s; 1 gap(s)), and "
     "pmf needs every row; split the log at the gap"),
    ([0, 10, 20, 1e6, 1e6 + 10], {},
     "log: 99997 steps of 10 s without a row, more than 10 x the log's 5 rows (the longest "
     "gap on lines 4-5 (t 20 -> 1e+06 s)); split the log"),
    ([0, 10, 20, 100, 110], {"max_gap": 60.0},
     "a gap of 80 s on lines 4-5 (t 20 -> 100 s) is longer than --max-gap 60 s"),
])
def test_bad_times_are_named_with_their_lines(t, kw, message):
    with pytest.raises(ValueError) as err:
        time_steps(np.asarray(t, float), "log", **kw)
    assert message in str(err.value)


def test_the_file_lines_come_from_the_reader():
    lines = np.array([5, 6, 9, 10])  # comments or blank lines in the file
    with pytest.raises(ValueError, match="on lines 9-10"):
        time_steps(np.array([0, 10, 20, 33.0]), "log", line=lambda i: int(lines[i]))
    assert JITTER == 0.1


def test_filter_track_refuses_a_gap_and_takes_jitter():
    t = 10.0 * np.array([0, 1, 2, 4, 5, 6], float)
    z = np.zeros(6)
    with pytest.raises(ValueError, match=r"track: filter_track needs a row on every step; 1 "
                                         r"gap\(s\) of 1 step\(s\) of 10 s"):
        filter_track(None, t, z, z, z)
    with pytest.raises(ValueError, match="a step of 14 s on lines 4-5"):
        filter_track(None, np.array([0, 10, 20, 34, 40, 50.0]), z, z, z)


def test_the_point_mass_stride_is_the_readings_common_stride():
    assert reading_stride(np.array([2, 5, 8, 14, 17])) == 3  # one missing on the stride
    assert reading_stride(np.array([2, 5, 8, 9])) == 1  # an irregular one: every row
    assert reading_stride(np.array([4])) == 1


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.05, 600.0), st.integers(8, 400),
       st.floats(0.0, 0.04), st.floats(0.0, 1.0))
def test_any_jittered_log_with_gaps_gives_back_its_steps(seed, dt, n, jitter, drop):
    # a regular clock t0 + k·dt, each stamp off by up to 4 % of a step (a step off by
    # at most 8 %), rows dropped at random among every fourth (single steps stay the
    # median, which the step's first guess is)
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    keep = k[~((k % 4 == 1) & (k < n - 1) & (rng.random(n) < drop))]
    t = 1e5 + keep * dt + rng.uniform(-jitter, jitter, keep.size) * dt
    steps = time_steps(t, "log")
    np.testing.assert_array_equal(steps.rows, keep)
    assert steps.n_steps == n and steps.n_inserted == n - keep.size
    assert abs(steps.dt - dt) <= 2 * jitter * dt / (n - 1) + 1e-9 * dt
    # each step off by two stamps' jitter, and by the estimated step's error (gaps: 2 steps)
    assert steps.jitter <= 2 * jitter * dt + 2 * abs(steps.dt - dt) + 1e-9 * dt
