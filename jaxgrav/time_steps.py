"""The regular time step a log is filtered on: clock jitter absorbed, gaps bridged.

``jaxgrav filter`` and ``jaxgrav navigate`` run their filters on a fixed step. A real
log's time stamps jitter (a logger stamping a 10 s record at 10.02 s, then 9.98 s) and
drop records. :func:`time_steps` reads the times as ``t0 + k·dt``: every step between
rows must be a whole number of steps within :data:`JITTER` of one step, and is refused
otherwise, naming its file lines. A step of two or more is a gap: the filters predict
through its missing rows (made by :func:`on_steps`: positions and velocities
interpolated, no reading) when the caller allows gaps, up to ``max_gap`` seconds.

Why a tenth of a step of jitter is harmless: the filters propagate the INS *error*,
whose dynamics are slow (the Schuler rate, 1/806 s⁻¹, is the fastest); a step
propagated over ``dt`` instead of ``dt ± ε`` is off by ``Φ(dt)·F·ε``, for a 10 s step
and ε = 1 s about 0.1 % of the state, and the readings are compared with the map at
their own row's position, whatever its time. ``dt`` is the log's duration over its
number of steps, so the filter's clock does not drift from the log's.
:func:`~jaxgrav.filters.filter_track` reads its times with :func:`time_steps` too.
"""

from typing import NamedTuple

import numpy as np

from jaxgrav.tracks import csv_line

__all__ = ["JITTER", "MAX_INSERTED", "TimeSteps", "at_rows", "first_step", "on_steps",
           "time_steps"]

JITTER = 0.1
"""Largest deviation of a step between rows from a whole number of steps, as a fraction
of the step."""

MAX_INSERTED = 10
"""Most steps without a row, as a multiple of the log's rows: more is refused (a time
column in the wrong unit or a stray stamp years off would otherwise allocate and
predict through millions of steps)."""


class TimeSteps(NamedTuple):
    """A log's times read as a regular grid ``t0 + k·dt``.

    Attributes
    ----------
    dt : float
        The step (s): the log's duration over its number of steps.
    rows : numpy.ndarray of int, shape ``(R,)``
        Each row's step index ``k`` (0 for the first row, ascending).
    n_steps : int
        Steps the filter runs: ``rows[-1] + 1``.
    jitter : float
        Largest deviation of a step from a whole number of steps (s).
    n_gaps : int
        Steps between rows longer than one step (each bridged by prediction).
    """

    dt: float
    rows: np.ndarray
    n_steps: int
    jitter: float
    n_gaps: int

    @property
    def n_inserted(self):
        """Steps without a row of the log (predicted through)."""
        return self.n_steps - self.rows.size

    def describe(self):
        """One phrase for a command's summary line: the step, its jitter and the gaps."""
        text = f"time step {self.dt:.6g} s"
        if self.jitter > 0:
            text += f" (steps jitter by up to {self.jitter:.3g} s)"
        if self.n_gaps:
            text += (f", {self.n_gaps} gap(s) bridged by prediction over {self.n_inserted} "
                     "missing row(s)")
        return text


def time_steps(t, where, *, max_gap=None, max_step=None, gaps=None, line=csv_line):
    """Read a log's time column as a regular step.

    Parameters
    ----------
    t : array_like, shape ``(R,)``
        Times (s), R ≥ 2.
    where : str
        How error messages name the log (e.g. ``"--track 'log.csv'"``).
    max_gap : float, optional
        Longest gap between rows (s); longer ones are refused, naming ``--max-gap``.
    max_step : float, optional
        Longest step of the log itself (s), refused naming ``--max-gap`` too (``navigate``:
        a log whose every step is longer may have its times in ms).
    gaps : str, optional
        None: gaps are bridged. Else they are refused, and this says why (e.g. ``"--method
        pmf updates on a fixed row stride"``).
    line : callable
        Row index → the file's line number, for messages.

    Returns
    -------
    TimeSteps

    Raises
    ------
    ValueError
        Missing or non-finite times, times that do not increase, a step shorter than
        half the log's step, a step not within :data:`JITTER` of a whole number of
        steps, a step longer than ``max_step``, a gap longer than ``max_gap``, a gap not
        allowed, more steps
        without a row than :data:`MAX_INSERTED` times the rows; each naming the lines,
        the times and the step.

    Notes
    -----
    The step's first guess is the median step between rows, or the median of the short
    ones (within 1.5 × the shortest) when more steps are a whole number of those (a log
    with more gaps than single steps); each step then counts as its nearest whole number
    of steps, and ``dt`` is the duration over their sum.
    """
    t = np.asarray(t, dtype=float)
    if t.size < 2:
        raise ValueError(f"{where} has {t.size} row; the filter needs at least 2 (the time "
                         "step is taken from column t)")
    nan = np.flatnonzero(~np.isfinite(t))
    if nan.size:
        raise ValueError(f"{where}: column t has {nan.size} missing or non-finite time(s), "
                         f"the first on line {line(int(nan[0]))}")
    d = np.diff(t)

    def lines(i):
        return f"lines {line(i)}-{line(i + 1)} (t {t[i]:g} -> {t[i + 1]:g} s)"

    back = np.flatnonzero(~(d > 0))
    if back.size:
        i = int(back[0])
        what = "repeats" if d[i] == 0 else "goes backwards"
        raise ValueError(f"{where}: column t must increase; it {what} on {lines(i)}; "
                         f"{back.size} such step(s)")
    guess = first_step(d)
    ratio = d / guess
    inserted = np.sum(np.rint(ratio)) + 1 - t.size  # float: 1e20 s must not overflow
    if inserted > MAX_INSERTED * t.size:
        i = int(np.argmax(d))
        raise ValueError(f"{where}: {inserted:.6g} steps of "
                         f"{guess:.6g} s without a row, more than {MAX_INSERTED} x the log's "
                         f"{t.size} rows (the longest gap on {lines(i)}); split the log, or "
                         "check the time column's unit")
    m = np.rint(ratio).astype(np.int64)
    short = np.flatnonzero(m < 1)
    if short.size:
        i = int(short[0])
        raise ValueError(f"{where}: a step of {d[i]:g} s on {lines(i)} is under half the "
                         f"log's step ({guess:g} s): rows must be one step apart or a whole "
                         f"number of steps (gaps); {short.size} such step(s)")
    rows = np.concatenate([[0], np.cumsum(m)])
    dt = float((t[-1] - t[0]) / rows[-1])
    if max_step is not None and dt > max_step:
        raise ValueError(f"{where}: the log's step, {dt:.6g} s, is longer than --max-gap "
                         f"{max_step:g} s: is column t in seconds? (raise --max-gap if the "
                         "step is right)")
    off = np.abs(d - m * dt)
    bad = np.flatnonzero(off > JITTER * dt)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{where}: column t must have a regular step; a step of {d[i]:g} s on {lines(i)} "
            f"is not within {JITTER:.0%} of the step {dt:.6g} s or a whole number of steps "
            f"(a gap); {bad.size} such step(s)")
    gap = np.flatnonzero(m > 1)
    if gap.size and gaps is not None:
        i = int(gap[0])
        raise ValueError(f"{where}: a gap of {int(m[i]) - 1} missing row(s) on {lines(i)} "
                         f"(step {dt:.6g} s; {gap.size} gap(s)), and {gaps}; split the log at "
                         "the gap")
    long = np.flatnonzero((m > 1) & (d > (np.inf if max_gap is None else max_gap)))
    if long.size:
        i = int(long[0])
        raise ValueError(f"{where}: a gap of {d[i]:g} s on {lines(i)} is longer than "
                         f"--max-gap {max_gap:g} s ({long.size} such gap(s)); split the "
                         "log at the gap, or raise --max-gap to predict through it")
    n_steps = int(rows[-1]) + 1
    jitter = float(off.max())  # below 1 ppm of a step: the decimals the times were written in
    return TimeSteps(dt=dt, rows=rows, n_steps=n_steps,
                     jitter=jitter if jitter > 1e-6 * dt else 0.0,
                     n_gaps=int(gap.size))


def first_step(d):
    """The first guess of a log's step from the steps between its rows (s).

    The median step, or the median of the short steps (within 1.5 × the shortest) when
    more steps are within :data:`JITTER` of a whole number (≥ 1) of those: a log with
    more gaps than single steps.

    Parameters
    ----------
    d : numpy.ndarray, shape ``(R − 1,)``
        Positive steps between rows (s).

    Returns
    -------
    float
    """
    def fits(step):
        k = np.rint(d / step)
        return int(np.sum((k >= 1) & (np.abs(d - k * step) <= JITTER * step)))

    median, short = float(np.median(d)), float(np.median(d[d < 1.5 * d.min()]))
    return short if fits(short) > fits(median) else median


def on_steps(steps, values, *, fill=None, period=None):
    """A per-row column on every step of :func:`time_steps`' grid.

    Parameters
    ----------
    steps : TimeSteps
        The log's steps (:func:`time_steps`).
    values : array_like, shape ``(R, ...)``
        The column at the log's rows.
    fill : float, optional
        The value of steps without a row (e.g. NaN for readings: none was taken). None:
        linear in the step index between the rows around the gap (positions,
        velocities).
    period : float, optional
        Interpolate the column unwrapped with this period (360 for longitudes across
        the antimeridian); the values between are left unwrapped.

    Returns
    -------
    numpy.ndarray, shape ``(steps.n_steps, ...)``
        ``values`` at ``steps.rows``; the rest filled or interpolated.
    """
    values = np.asarray(values)
    if steps.n_inserted == 0:
        return values
    if fill is not None:
        out = np.full((steps.n_steps, *values.shape[1:]), fill,
                      dtype=np.result_type(values, type(fill)))
        out[steps.rows] = values
        return out
    v = np.unwrap(values, period=period, axis=0) if period is not None else values
    k = np.arange(steps.n_steps)
    flat = v.reshape(v.shape[0], -1)
    out = np.stack([np.interp(k, steps.rows, c) for c in flat.T], axis=1)
    out = out.reshape((steps.n_steps, *v.shape[1:]))
    out[steps.rows] = values  # the log's own values on its rows, wrapped as read
    return out


def at_rows(steps, columns):
    """Every column of a result on the grid, at the log's rows only.

    Parameters
    ----------
    steps : TimeSteps
    columns : dict of array_like, each of shape ``(steps.n_steps, ...)``

    Returns
    -------
    dict
        The same keys, each of shape ``(R, ...)``.
    """
    return {k: np.asarray(v)[steps.rows] for k, v in columns.items()}
