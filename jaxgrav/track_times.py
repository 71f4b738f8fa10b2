"""Times in track and log files: date-time cells, seconds since the first row, their order.

:func:`parse_datetime` reads one ISO-8601 cell (also ``2024/05/01 12:00:00``, a ``UTC``
or ``GMT`` suffix and ordinal dates ``2024-122T12:00:00``); :func:`iso_seconds` turns a
column of them into seconds since the first row, joining a separate date column to
times of day (``date,time,lat,...`` logs); :func:`check_time_steps` refuses times that
repeat or go back, naming both lines; :func:`epoch_unit` recognises Unix times written
in milliseconds, microseconds or nanoseconds; :func:`time_units` labels the times an
output writes with their unit and reference.
"""

import datetime as dt
import re

import numpy as np

__all__ = ["DATE_COLUMN", "DATE_COLUMNS", "MAX_EPOCH_SECONDS", "UNIX_SECONDS_FROM",
           "check_time_steps", "epoch_unit", "iso_seconds", "parse_datetime", "time_units"]

DATE_COLUMN = "date"
"""A column (any case) whose dates are joined to a time column holding times of day
(also :data:`DATE_COLUMNS`)."""

DATE_COLUMNS = (DATE_COLUMN, "datum", "fecha")
"""Every name of such a column: German and Spanish exports' too."""

MAX_EPOCH_SECONDS = 1e11
"""Largest plausible time in seconds: 1e11 s after 1970-01-01 is the year 5138. Larger
times are Unix times in a finer unit (:func:`epoch_unit`)."""

UNIX_SECONDS_FROM = 1e8
"""Smallest time in seconds read as a Unix time when nothing declares a reference: 1e8 s
is 3.2 years (1973-03-03 as a Unix time), longer than any survey counted from its start;
seconds of the day or of a GPS week stay far below it."""

UNIX_EPOCH = "1970-01-01T00:00:00Z"
_SINCE = re.compile(r"^.+?\s+since\s+(.+?)\s*$", re.IGNORECASE)  # CF "s since 2024-05-01"

_EPOCH_UNITS = ((1e17, 1e-9, "nanoseconds", "ns"), (1e14, 1e-6, "microseconds", "us"),
                (MAX_EPOCH_SECONDS, 1e-3, "milliseconds", "ms"))
_YEAR_S = 365.2425 * 86400.0

_SLASH_DATE = re.compile(r"^(\d{4})([/-])(\d{1,2})\2(\d{1,2})(?=$|[ T])")  # 2024/5/1, 2024-5-1
_DOTTED = re.compile(r"^(\d{1,2})\.(\d{1,2})\.(\d{4})(?=$|[ T])")  # 01.05.2024: day.month.year
_AM_PM = re.compile(r"(.*?[T ])?(\d{1,2})(:\d{2}(?::\d{2}(?:[.,]\d*)?)?)\s*([ap])\.?m\.?(\s.*)?",
                    re.IGNORECASE)  # "2024-05-01 01:30:00 PM": a 12-hour clock
_NAMED_REASONS = ("leap second", "year last", "day.month", "AM/PM")  # told in messages
_YEAR_LAST = re.compile(r"^\d{1,2}([/.-])\d{1,2}\1\d{2,4}(?=$|[ T])")  # 05/01/2024: ambiguous
_MIDNIGHT = re.compile(r"(?<=[T ])24:00(:00([.,]0*)?)?(?=$|[^\d:.,])")  # ISO's end of a day
_SPACED_OFFSET = re.compile(r"(?<=\d)\s+([+-]\d{2}(:?\d{2})?)$")  # "12:00:00.000 +0000"
_ORDINAL = re.compile(r"(\d{4})-?(\d{3})(?=$|[ T])")  # ISO 8601 ordinal date: year-day
_CLOCK = re.compile(r"\d{1,2}:\d{2}(:\d{2}(\.\d*)?)?")
_UTC = re.compile(r"\s*(UTC|GMT|Z)$", re.IGNORECASE)
_LEAP = re.compile(r"(?<=[T ]\d\d:\d\d:)60(?=$|[.,]\d|[^\d])")  # 23:59:60, a leap second


def _ordinal(m):
    day = int(m[2])
    if not 1 <= day <= 366:
        return m[0]
    date = dt.date(int(m[1]), 1, 1) + dt.timedelta(days=day - 1)
    return date.isoformat() if date.year == int(m[1]) else m[0]


def parse_datetime(cell):
    """An ISO-8601 date-time cell as a :class:`datetime.datetime`.

    Also ``2024/05/01 12:00:00`` (year first, slashes) and ``2024-5-1``, a lower-case ``z``,
    a ``UTC`` or ``GMT`` suffix (``2024-05-01 12:00:00 UTC``, as databases write), an offset
    after a space (``12:00:00.000 +0000``), ISO ordinal dates (``2024-122T12:00:00``, the
    day of the year of survey logs) and ISO's ``24:00:00``, the end of a day (the next
    day's ``00:00:00``). ValueError for anything else; its text says so for a time of day
    without a date (``12:00:00``, a log that keeps the date in another column) and for a
    date with the year last (``05/01/2024``: day/month or month/day, not guessed); a
    date with dots and a four-digit year is day.month.year (``01.05.2024``, as German,
    Russian and other European software writes it); a 12-hour time with ``AM``/``PM``
    after a year-first date (``2024-05-01 01:30:00 PM``) is read as 13:30.
    Fractions of a second finer than a microsecond are cut to microseconds.

    A leap second, ``2016-12-31T23:59:60Z`` (a UTC log across one, e.g. a GNSS receiver's),
    is the instant a POSIX clock (and pandas, NumPy) calls the next ``00:00:00``, as
    :class:`datetime.datetime` has no second 60; :func:`iso_seconds` then counts the
    leap second itself, so the times around it stay one second apart. Second 60 at any
    time other than 23:59 UTC (in the cell's own time zone) is refused.
    """
    text = _SLASH_DATE.sub(lambda m: f"{m[1]}-{int(m[3]):02d}-{int(m[4]):02d}", cell.strip())
    text = _ORDINAL.sub(_ordinal, text, count=1) if _ORDINAL.match(text) else text
    dotted = _DOTTED.match(text)
    if dotted:  # 01.05.2024, as German, Russian, ... software writes: was "ambiguous"
        day, month = int(dotted[1]), int(dotted[2])
        if not 1 <= month <= 12:
            raise ValueError(f"a date with dots is day.month.year, and {month} is no month")
        text = f"{dotted[3]}-{month:02d}-{day:02d}" + text[dotted.end():]
    am_pm = _AM_PM.fullmatch(text)
    if am_pm and not _YEAR_LAST.match(text):  # was "neither a number nor ... ISO-8601"
        hour = int(am_pm[2])
        if not 1 <= hour <= 12:
            raise ValueError(f"a 12-hour time (AM/PM) has hours 1 to 12, not {hour}")
        hour = hour % 12 + 12 * (am_pm[4].lower() == "p")
        text = f"{am_pm[1] or ''}{hour:02d}{am_pm[3]}{am_pm[5] or ''}"
    if _YEAR_LAST.match(text):
        raise ValueError("a date with the year last, day/month or month/day: ambiguous; "
                         "write it year first, e.g. 2024-05-01")
    bare = _UTC.sub("", _SPACED_OFFSET.sub(r"\1", text))
    if _CLOCK.fullmatch(bare):
        raise ValueError("a time of day without a date")
    text = bare if bare == text or not _UTC.search(text) else bare + "+00:00"
    if _MIDNIGHT.search(text):  # 2024-05-01T24:00:00: the next day's 00:00:00
        return parse_datetime(_MIDNIGHT.sub("00:00:00", text, count=1)) + dt.timedelta(days=1)
    if not _LEAP.search(text):
        return dt.datetime.fromisoformat(text)
    before = dt.datetime.fromisoformat(_LEAP.sub("59", text, count=1))
    utc = before.astimezone(dt.UTC) if before.tzinfo else before
    if (utc.hour, utc.minute) != (23, 59):
        raise ValueError("second 60 is a leap second, which only 23:59:60 UTC can be")
    return before + dt.timedelta(seconds=1)


def iso_seconds(cells, lines, label, header, dates=None):
    """Seconds since the first row of ISO-8601 cells (aware times in UTC, naive as given).

    Parameters
    ----------
    cells : sequence of str
        The time column.
    lines : sequence of int
        The file line of each cell, for messages.
    label, header : str
        The file and the column, for messages.
    dates : sequence of str, optional
        A date column joined in front of each time of day (``2024-05-01`` + ``12:00:00``).

    Returns
    -------
    seconds : numpy.ndarray
        Since the first cell; a leap second in the column (``23:59:60``) counted, so
        ``23:59:59``, ``23:59:60``, ``00:00:00`` are one second apart (a leap second that
        falls between two cells is not: UTC as POSIX clocks count it).
    origin : str
        The first time, ISO-8601.
    """
    stamps = []
    for k, (cell, line) in enumerate(zip(cells, lines, strict=True)):
        shown = cell
        try:
            try:
                stamps.append(parse_datetime(cell))
            except ValueError as err:  # a time of day, and a date column: joined
                if dates is None or "time of day" not in str(err):
                    raise
                shown = f"{dates[k]} {cell}"
                stamps.append(parse_datetime(shown))
        except ValueError as err:  # a clock time: "12:00:00 ... a time of day without a date"
            clock = (f" ({err}: join the date to it, or give it a column named "
                     f"{DATE_COLUMN!r})") if "time of day" in str(err) else (
                f" ({err})" if any(w in str(err) for w in _NAMED_REASONS) else "")
            raise ValueError(
                f"{label}, line {line}, column {header!r}: {shown!r} is neither a number "
                f"(seconds) nor an ISO-8601 date-time (e.g. 2024-05-01T12:00:00Z){clock}; "
                "times must be complete") from None
    aware = [s.tzinfo is not None for s in stamps]
    if any(aware) and not all(aware):
        i = aware.index(not aware[0])
        raise ValueError(f"{label}, line {lines[i]}, column {header!r}: {cells[i]!r} "
                         f"{'has' if aware[i] else 'lacks'} a time zone, unlike line "
                         f"{lines[0]}; give every time with or every time without one")
    seconds = np.array([(s - stamps[0]).total_seconds() for s in stamps])
    leap = np.array([bool(_LEAP.search(cell)) for cell in cells])
    posix = seconds.copy()
    while leap.any():  # 23:59:60 read as the next 00:00:00: the times after it, and not
        k = int(np.argmax(leap))  # in it, one second later
        midnight = (stamps[k].replace(microsecond=0) - stamps[0]).total_seconds()
        within = leap & (posix >= midnight) & (posix < midnight + 1)
        seconds[(np.arange(len(seconds)) > k) & ~within & (posix >= midnight)] += 1.0
        leap &= ~within  # each leap second counted once
    return seconds, stamps[0].isoformat()


def check_time_steps(t, shown, lines, label, header):
    """Refuse a time that repeats or goes back, naming both lines (ValueError); a step back
    from the end of a day (or a GPS week) to its start is named as seconds of the day (of
    the week) restarting."""
    step = np.diff(t)
    bad = np.flatnonzero(~(step > 0))
    if bad.size:
        i = int(bad[0])
        what = "repeats" if step[i] == 0 else "is earlier than"
        wrap = next((f"; seconds of the {name}, starting again at 0 after {period}? give "
                     "times that keep counting (add the date, e.g. ISO-8601 date-times)"
                     for period, name in ((86400, "day"), (604800, "GPS week"))
                     if 0 <= t[i + 1] < period / 2 < t[i] <= period), "")
        raise ValueError(
            f"{label}, line {lines[i + 1]}, column {header!r}: time {shown[i + 1]} {what} "
            f"{shown[i]} on line {lines[i]}; times must increase ({int((step == 0).sum())} "
            f"repeated, {int((step < 0).sum())} backward step(s)){wrap}")


def epoch_unit(t):
    """The unit of Unix times too large to be seconds: ``(factor, name, symbol)``, or None.

    A time column whose every value exceeds :data:`MAX_EPOCH_SECONDS` (the year 5138 in
    seconds since 1970) holds Unix times in milliseconds (1e11 to 1e14: the years 1973
    to 5138), microseconds (1e14 to 1e17) or nanoseconds (above), the units of GNSS
    receivers, phones and data loggers; ``factor`` converts them to seconds.

    Parameters
    ----------
    t : array_like
        The times as read (missing ones NaN, left aside).

    Returns
    -------
    tuple of (float, str, str) or None
        E.g. ``(1e-3, "milliseconds", "ms")``; None when the times may be seconds (any
        time at most :data:`MAX_EPOCH_SECONDS`, or none given).
    """
    t = np.asarray(t, dtype=float)
    t = t[np.isfinite(t)]  # missing times (NaN) aside
    if not t.size or t.min() <= MAX_EPOCH_SECONDS:
        return None
    return next((factor, name, symbol) for low, factor, name, symbol in _EPOCH_UNITS
                if t.min() > low or low == MAX_EPOCH_SECONDS)


def epoch_year(seconds):
    """The calendar year of ``seconds`` after 1970-01-01 (approximate, for messages)."""
    return int(1970 + seconds // _YEAR_S)


def time_units(t, *, origin=None, unit=None, unix=False):
    """The unit and reference of a track's times in seconds, as an output labels them.

    Parameters
    ----------
    t : array_like
        The times (s) as the output writes them.
    origin : str, optional
        The first ISO-8601 time when the file gave ISO times (``t`` counts from it).
    unit : str, optional
        The unit the ``t`` header declares (``"hours since 2024-05-01"``), if any.
    unix : bool
        The times were recognised as Unix times (in ms, us or ns: :func:`epoch_unit`).

    Returns
    -------
    units : str
        CF style: ``"s since 2024-05-01T12:00:00+00:00"``, ``"s since 2024-05-01"`` (a
        CF header's reference), ``"s since 1970-01-01T00:00:00Z"`` for Unix times
        (recognised, or read so because every time is at least :data:`UNIX_SECONDS_FROM`),
        else ``"s"`` (the track's own clock, no reference given).
    first : str or None
        The first time as an ISO-8601 UTC date-time for Unix times (None otherwise).
    """
    if origin is not None:
        return f"s since {origin}", None
    since = _SINCE.match(unit or "")
    if since:
        return f"s since {since.group(1)}", None
    t = np.asarray(t, dtype=float)
    t = t[np.isfinite(t)]
    if not t.size or not (unix or UNIX_SECONDS_FROM <= t.min() <= MAX_EPOCH_SECONDS):
        return "s", None
    first = dt.datetime.fromtimestamp(float(t.min()), dt.UTC).isoformat().replace("+00:00", "Z")
    return f"s since {UNIX_EPOCH}", first
