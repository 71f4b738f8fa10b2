"""Gravimeter readings along a true track, for matching scenarios.

``reading = field(true position) + white noise + bias − Eötvös``: the moving
gravimeter's output after the usual reductions (normal gravity removed), so that it
compares with an anomaly map except for noise, bias and the Eötvös effect (see
:func:`jaxgrav.eotvos`). The full sensor chain of paper D (vertical acceleration,
tilt, FIR filtering) is :mod:`jaxgrav.sim.gravimeter`.
"""

import jax

from jaxgrav.geodesy import eotvos
from jaxgrav.grid import Grid

__all__ = ["field_along", "gravity_readings"]


def field_along(field, lat, lon, method="bicubic"):
    """Evaluate a field at points: a :class:`Grid` (sampled with ``method``) or a callable.

    Parameters
    ----------
    field : Grid or callable
        Map, or function ``(lat, lon) -> values`` (e.g. a point-mass or
        spherical-harmonic model with its arguments bound).
    lat, lon : Array
        Points (degrees).
    method : {"bilinear", "bicubic"}
        Interpolation when ``field`` is a Grid.

    Returns
    -------
    Array
        Field values, NaN off a grid.
    """
    if isinstance(field, Grid):
        return field.sample(lat, lon, method)
    return field(lat, lon)


def gravity_readings(
    key, field, track, *, noise_mgal=1.0, bias_mgal=0.0, eotvos_form="full", method="bicubic"
):
    """Simulated gravimeter readings (mGal) along a true track.

    Parameters
    ----------
    key : PRNG key
        Decides the white noise.
    field : Grid or callable
        True anomaly field (mGal); may be finer than the map used for matching.
    track : Track
        True trajectory (positions and velocities).
    noise_mgal : float or Array
        Standard deviation of the white noise (mGal).
    bias_mgal : float or Array
        Constant gravimeter bias (mGal).
    eotvos_form : {"full", "simple", None}
        Eötvös effect subtracted from the reading; ``None`` for a stationary sensor
        or readings already corrected.
    method : {"bilinear", "bicubic"}
        Interpolation of a Grid field.

    Returns
    -------
    Array, shape ``(N,)``
        Readings in mGal.
    """
    truth = field_along(field, track.lat, track.lon, method)
    noise = noise_mgal * jax.random.normal(key, truth.shape, dtype=truth.dtype)
    e = (
        0.0
        if eotvos_form is None
        else eotvos(track.lat, track.v_east, track.v_north, form=eotvos_form)
    )
    return truth + noise + bias_mgal - e
