"""The trajectory of paper C's DOV study (climbing flight over the Qinling region)."""

from typing import NamedTuple

import numpy as np

__all__ = ["PaperTrajectory", "paper_c_trajectory"]

_R = 6371000.0  # mean Earth radius for dead reckoning the track (m)
_HEADING_END = 20.56515251  # final heading (deg): with the length, spans 5° lat x 4° lon
_LENGTH = 666336.968  # path length (m)


class PaperTrajectory(NamedTuple):
    """A trajectory sampled uniformly in time.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Time (s).
    lat, lon : ndarray, shape (T,)
        Position (degrees).
    h : ndarray, shape (T,)
        Height (m).
    heading : ndarray, shape (T,)
        Heading (degrees from north).
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    heading: np.ndarray


def paper_c_trajectory(n=3333, speed=200.0):
    """Paper C's scenario: start 34.23°N 108.33°E at 1000 m, heading 45°, climb to 13 km.

    The heading turns linearly from 45° to 20.6° so that the track spans 5° of
    latitude and 4° of longitude (a straight 45° track cannot: equal north and east
    distances give 5° × 6.2°); it ends at 39.23°N 112.33°E, inside the shipped
    ``qinling`` region. The height rises smoothly (half cosine) from 1000 m to
    13 000 m over the first 60 % of the flight, then stays level.

    Parameters
    ----------
    n : int
        Number of fixes (≥ 2).
    speed : float
        Ground speed (m/s); the flight lasts 666.3 km / speed (3332 s at 200 m/s).

    Returns
    -------
    PaperTrajectory
    """
    if int(n) < 2 or not speed > 0:
        raise ValueError(f"n must be >= 2 and speed > 0; got n={n!r}, speed={speed!r}")
    s = np.linspace(0.0, 1.0, int(n))
    psi = np.deg2rad(45.0 + (_HEADING_END - 45.0) * s)
    ds = _LENGTH / (n - 1)
    pm = 0.5 * (psi[1:] + psi[:-1])
    lat = 34.23 + np.r_[0.0, np.cumsum(np.rad2deg(ds * np.cos(pm) / _R))]
    lat_m = np.deg2rad(0.5 * (lat[1:] + lat[:-1]))
    lon = 108.33 + np.r_[0.0, np.cumsum(np.rad2deg(ds * np.sin(pm) / (_R * np.cos(lat_m))))]
    h = 1000.0 + 12000.0 * np.where(s < 0.6, 0.5 - 0.5 * np.cos(np.pi * s / 0.6), 1.0)
    return PaperTrajectory(s * _LENGTH / speed, lat, lon, h, np.rad2deg(psi))
