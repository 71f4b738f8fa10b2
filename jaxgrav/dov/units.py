"""Units of a layers file: deflections to arcsec, heights to metres (one rule for
:meth:`~jaxgrav.dov.LayeredGrid.from_netcdf` and ``jaxgrav dov --grid``).

The layers' reader took every file as arcsec on heights in m: deflections in radians,
µrad or degrees came out under the ``xi``/``eta`` columns the summary called arcsec,
and heights in km were read as metres (a track at 5000 m "outside 0..20 m"). The
units the file declares (CF ``units``, or ``Units``, ``UNITS``, ``unit``:
:func:`~jaxgrav.grid_values.units_attr`, of the first channel and of ``height``) are
converted; heights in units of no length are refused, channels in units of no angle
kept as declared (a layered field of another kind; ``jaxgrav dov`` refuses them).
"""

import numpy as np

from jaxgrav.grid_values import units_attr

__all__ = ["ARCSEC_PER", "METRES_PER", "declared_units", "in_arcsec_and_metres"]

_RAD = 180.0 / np.pi * 3600.0
ARCSEC_PER = {
    **dict.fromkeys(("arcsec", "arcsecond", "arcseconds", "arc_second", "arc_seconds",
                     "arc-second", "arc-seconds", "arc second", "arc seconds", "\"", "″",
                     "seconds of arc", "asec"), 1.0),
    **dict.fromkeys(("mas", "milliarcsec", "milliarcsecond", "milliarcseconds"), 1e-3),
    **dict.fromkeys(("arcmin", "arcminute", "arcminutes", "'", "′"), 60.0),
    **dict.fromkeys(("deg", "degree", "degrees", "°"), 3600.0),
    **dict.fromkeys(("rad", "radian", "radians"), _RAD),
    **dict.fromkeys(("mrad", "milliradian", "milliradians"), 1e-3 * _RAD),
    **dict.fromkeys(("urad", "µrad", "μrad", "microradian", "microradians"), 1e-6 * _RAD),
}
"""Arcseconds per unit of deflection a layers file may declare (lower case)."""

METRES_PER = {**dict.fromkeys(("m", "meter", "meters", "metre", "metres"), 1.0),
              **dict.fromkeys(("km", "kilometer", "kilometers", "kilometre", "kilometres"),
                              1e3),
              **dict.fromkeys(("ft", "foot", "feet"), 0.3048)}
"""Metres per unit of layer height a layers file may declare (lower case)."""


def declared_units(ds, channel):
    """The units a layers dataset declares: ``(channel's, height's)``, ``"arcsec"`` and
    ``"m"`` where it declares none (any spelling of the attribute)."""
    return (units_attr(ds[channel].attrs) or "arcsec",
            units_attr(ds["height"].attrs) if "height" in ds.variables else "") or "m"


def in_arcsec_and_metres(values, heights, units, h_units, label):
    """Values in arcsec and heights in metres from those declared.

    Parameters
    ----------
    values : numpy.ndarray, shape ``(L, C, ny, nx)``
        The channels as stored.
    heights : numpy.ndarray, shape ``(L,)``
        The layer heights as stored.
    units, h_units : str
        The channels' and the heights' declared units (:func:`declared_units`).
    label : str
        The file, for the message.

    Returns
    -------
    values, heights : numpy.ndarray
        Converted; ``values`` unchanged when ``units`` is no angle.
    units : str
        ``"arcsec"`` for an angle, else ``units`` as declared.

    Raises
    ------
    ValueError
        Naming ``label``: height units that are no length this module knows.
    """
    metres = METRES_PER.get(h_units.strip().lower())
    if metres is None:
        raise ValueError(f"{label}: height declares units {h_units!r}; expected layer heights "
                         "in m (or km, ft) above the ellipsoid")
    angle = ARCSEC_PER.get(units.strip().lower())
    if angle is None:
        return values, heights * metres, units
    return values * angle, heights * metres, "arcsec"
