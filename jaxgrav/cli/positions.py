"""INS positions against the velocity columns: jumps, and velocities in other units.

:func:`check_positions` refuses an INS log (``filter``, ``navigate``) whose positions
jump between rows beyond what ``v_east``/``v_north`` explain; :func:`check_velocity_units`
(``match``, whose fixes are minutes apart) refuses only velocity columns that disagree
with the positions on most steps, in another unit (knots, km/h) or swapped, since
their Eötvös correction would be wrong (a log in knots was matched with a +42 mGal
bias, exit 0).
"""

import numpy as np

from jaxgrav.cli.log_clock import check_time_unit
from jaxgrav.geodesy import local_offsets_m_jit
from jaxgrav.tracks import csv_line

__all__ = ["POSITION_JUMP_M", "POSITION_JUMP_MS", "VELOCITY_UNITS", "check_positions",
           "check_velocity_units"]

POSITION_JUMP_MS = 1.0
"""A move between rows that departs from the velocity columns' by more than this (m/s,
or 10 % of the speed, whichever is larger; at least :data:`POSITION_JUMP_M`, plus a
quarter of the velocity change for turns) is a jump (:func:`check_positions`)."""

POSITION_JUMP_M = 25.0
"""The least departure (m) taken as a jump: rounded coordinates (1e-5° is 1.1 m) and
metre-level position noise of a fast log are not jumps."""


def check_positions(track, *, where):
    """Refuse INS positions that jump between rows (see the module notes).

    Parameters
    ----------
    track : mapping
        ``t`` (s), ``lat``, ``lon`` (degrees), ``v_east``, ``v_north`` (m/s), ``(N,)``;
        a :class:`~jaxgrav.tracks.TrackTable`'s own file lines name the rows.
    where : str
        The file, for messages.

    Raises
    ------
    ValueError
        The first row whose move from the previous one departs from the mean of the two
        rows' velocities times the step by more than :data:`POSITION_JUMP_MS` (or 10 %
        of the speed) times the step, at least :data:`POSITION_JUMP_M`, plus a quarter
        of the velocity change times the step (in a turn the mean velocity cuts the
        arc's chord short by about ``v Δt θ²/12`` for a heading change θ, which this
        covers up to θ ≈ 3 rad), with the line, the jump in metres and how many there
        are; when most steps (at least 3) depart so, the velocity columns are named
        instead, with their likely unit or a swap (:func:`_velocity_cause`).
    """
    t = np.asarray(track["t"], float)
    if t.size < 2:
        return
    check_time_unit(track, where=where)  # days, hours: moves too short to be called jumps
    line = getattr(track, "line", csv_line)  # the file's own lines (comments skipped)
    miss, jump, cause = _departures(track)
    if jump.size >= max(3, (t.size - 1) // 2):  # most steps: the velocity columns
        i = int(jump[0])
        raise ValueError(
            f"{where}: v_east/v_north disagree with the positions on {jump.size} of "
            f"{t.size - 1} steps (first between lines {line(i)} and {line(i + 1)}): {cause()}")
    if jump.size:
        i = int(jump[0])
        raise ValueError(
            f"{where}: the position jumps by {miss[i]:.4g} m between lines {line(i)} and "
            f"{line(i + 1)} (t {t[i]:g} -> {t[i + 1]:g} s) beyond what v_east/v_north "
            f"allow ({jump.size} such jump(s)); a reset or glitch of the INS position: split "
            "the log there or remove the row")


VELOCITY_UNITS = {"knots (× 0.5144 gives m/s)": 1.943844, "km/h (÷ 3.6 gives m/s)": 3.6,
                  "ft/s (× 0.3048 gives m/s)": 3.28084, "cm/s (÷ 100 gives m/s)": 100.0}
"""Velocity units a log may hold instead of m/s, by their factor over m/s."""


def _velocity_cause(pos_n, pos_e, vn, ve):
    """What the velocity columns look like against the positions' own speed (m/s per step):
    another unit (:data:`VELOCITY_UNITS`), east and north swapped, or neither."""
    mid_n, mid_e = 0.5 * (vn[1:] + vn[:-1]), 0.5 * (ve[1:] + ve[:-1])
    moving = (np.hypot(pos_n, pos_e) > 0) & (np.hypot(mid_n, mid_e) > 0.1)
    said = f"the positions move at a median {np.median(np.hypot(pos_n, pos_e)):.3g} m/s, "
    said += f"the velocity columns say {np.median(np.hypot(mid_n, mid_e)):.3g} m/s"
    if moving.sum() >= 2:
        ratio = float(np.median(np.hypot(mid_n, mid_e)[moving] / np.hypot(pos_n, pos_e)[moving]))
        for unit, factor in VELOCITY_UNITS.items():
            if abs(ratio / factor - 1.0) < 0.05:
                return f"{said} (a factor {ratio:.3g}): are they in {unit}?"
        for unit, factor in (("milliseconds", 1000.0), ("minutes", 1.0 / 60.0)):
            if abs(ratio / factor - 1.0) < 0.05:
                return f"{said} (a factor {ratio:.3g}): is column t in {unit}, not seconds?"
        swapped = np.hypot(pos_n - mid_e, pos_e - mid_n)
        if np.median(swapped[moving] / np.hypot(pos_n, pos_e)[moving]) < 0.1:
            return f"{said}, but along the other axis: are v_east and v_north swapped?"
    return (f"{said}; expected the INS velocity of these rows, east and north, in m/s "
            "(name the columns with --columns v_east=COLUMN,v_north=COLUMN)")


def check_velocity_units(track, *, where):
    """Refuse velocity columns that disagree with the positions on most steps (at least
    3), naming their likely unit or a swap (as :func:`check_positions` does); a single
    odd step passes (a match's fixes are minutes apart, its velocities instantaneous).

    Parameters
    ----------
    track : mapping
        ``t`` (s), ``lat``, ``lon``, ``v_east``, ``v_north``, ``(N,)``.
    where : str
        The file, for messages.
    """
    n_steps = len(track["t"]) - 1
    if n_steps < 3:
        return
    _, off, cause = _departures(track)
    if off.size >= max(3, (n_steps + 1) // 2):
        line = getattr(track, "line", csv_line)
        i = int(off[0])
        raise ValueError(
            f"{where}: v_east/v_north disagree with the positions on {off.size} of "
            f"{n_steps} steps (first between lines {line(i)} and {line(i + 1)}): {cause()}")


def _departures(track):
    """Each step's departure of the move from the velocities' (m), the steps beyond what
    is allowed (see :func:`check_positions`), and a callable naming the likely cause."""
    t, lat, lon = (np.asarray(track[k], float) for k in ("t", "lat", "lon"))
    ve, vn = np.asarray(track["v_east"], float), np.asarray(track["v_north"], float)
    dt = np.diff(t)
    north, east = (np.asarray(a) for a in local_offsets_m_jit(lat[1:], lon[1:], lat[:-1],
                                                               lon[:-1]))
    miss = np.hypot(north - 0.5 * (vn[1:] + vn[:-1]) * dt, east - 0.5 * (ve[1:] + ve[:-1]) * dt)
    speed = 0.5 * (np.hypot(ve[1:], vn[1:]) + np.hypot(ve[:-1], vn[:-1]))
    turn = np.hypot(np.diff(ve), np.diff(vn))
    allowed = np.maximum(np.maximum(POSITION_JUMP_MS, 0.1 * speed) * dt, POSITION_JUMP_M)
    off = np.flatnonzero(miss > allowed + 0.25 * turn * dt)
    return miss, off, lambda: _velocity_cause(north / dt, east / dt, vn, ve)
