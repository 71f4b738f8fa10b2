"""The unit of an INS log's times, told by its own positions and velocities.

A log whose ``t`` column holds days (Excel serial dates, MATLAB ``datenum``, Julian or
modified Julian days), hours or minutes was read as seconds: ``filter`` ran on a step
of 2.3e-5 s, exit 0, with a 1-sigma that meant nothing, as the moves between rows
(10 m every 2 s) stayed below the least position jump checked (25 m). Over the whole
log the distance the velocity columns explain, ``Σ |v| Δt``, and the distance the
positions move, ``Σ |Δp|``, then differ by the unit's factor; :func:`check_time_unit`
names it.
"""

import numpy as np

from jaxgrav.geodesy import local_offsets_m_jit

__all__ = ["MIN_SPEED", "MIN_TRAVEL_M", "TIME_UNITS", "check_time_unit"]

TIME_UNITS = {"days": 86400.0, "hours": 3600.0, "minutes": 60.0}
"""Units a log's ``t`` may hold instead of seconds, by their length in seconds, with the
header that declares them (``t (d)``, ``t (h)``, ``t (min)``). Not milliseconds: the
positions would then move 1000 times less than the velocities say, as they do with
velocities in mm/s; :func:`jaxgrav.cli.sanity.check_positions` tells those apart by the
jumps they make."""

_DECLARE = {"days": "d", "hours": "h", "minutes": "min"}
_TOLERANCE = 0.2  # the units are a factor 16 or more apart

MIN_TRAVEL_M = 100.0
"""Least distance (m) the positions must move over the log to compare it with the
velocities (a log at rest tells no time unit)."""

MIN_SPEED = 0.5
"""Least median speed (m/s) of the velocity columns for the comparison: at rest, an INS
position drifting over an hour could make any ratio."""


def check_time_unit(track, *, where):
    """ValueError when the log's times are in another unit than seconds.

    Parameters
    ----------
    track : mapping
        ``t`` (as read, taken as s), ``lat``, ``lon`` (degrees), ``v_east``, ``v_north``
        (m/s), ``(N,)``; its ``renamed`` (a :class:`~jaxgrav.tracks.TrackTable`'s) names
        the ``t`` header.
    where : str
        The file, for messages.

    Raises
    ------
    ValueError
        When ``Σ |Δp| / Σ |v| Δt``, and the median of the steps' own ratios, are within
        20 % of the length in seconds of one of :data:`TIME_UNITS` (the positions move
        86 400 times farther than the velocities allow in "seconds" that are days), for a
        log moving at a median :data:`MIN_SPEED` or more; names the unit and the header
        declaring it.
    """
    t, lat, lon = (np.asarray(track[k], float) for k in ("t", "lat", "lon"))
    ve, vn = np.asarray(track["v_east"], float), np.asarray(track["v_north"], float)
    if t.size < 3:
        return
    north, east = (np.asarray(a) for a in local_offsets_m_jit(lat[1:], lon[1:], lat[:-1],
                                                              lon[:-1]))
    steps = np.hypot(north, east)
    moved = float(np.nansum(steps))
    speed = 0.5 * (np.hypot(ve[1:], vn[1:]) + np.hypot(ve[:-1], vn[:-1]))
    said = float(np.nansum(speed * np.diff(t)))
    # at rest (a moored ship's INS drifting) the ratio means nothing: the log must move
    if moved < MIN_TRAVEL_M or not said > 0 or not np.nanmedian(speed) >= MIN_SPEED:
        return
    ratio = moved / said
    each = steps / (speed * np.diff(t))  # and the steps themselves must agree
    each = float(np.nanmedian(each[np.isfinite(each) & (speed >= MIN_SPEED)]))
    for unit, seconds in TIME_UNITS.items():
        if abs(ratio / seconds - 1.0) < _TOLERANCE and abs(each / seconds - 1.0) < _TOLERANCE:
            header = (getattr(track, "renamed", None) or {}).get("t", "t")
            raise ValueError(
                f"{where}: column {header!r} looks like {unit}, not seconds: the positions move "
                f"{moved:.4g} m over the log, {ratio:.3g} times what v_east/v_north allow over "
                f"its times read as seconds ({said:.3g} m); declare the unit in the header, "
                f"e.g. '{header} ({_DECLARE[unit]})'")
