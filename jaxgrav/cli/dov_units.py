"""The units of a ``jaxgrav dov --grid`` file: deflections to arcsec, heights to metres.

The layers' reader took every file as arcsec on heights in m: deflections in radians,
µrad or degrees came out under the ``xi``/``eta`` columns the summary called arcsec,
and heights in km were read as metres (a track at 5000 m "outside 0..20 m"). The
units the file declares (CF ``units`` of the first channel and of ``height``) are now
converted; units of neither kind are refused naming ``--grid``.
"""

import dataclasses

import numpy as np
import xarray as xr

from jaxgrav.grid_values import units_attr

__all__ = ["ARCSEC_PER", "METRES_PER", "in_arcsec_and_metres"]

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


def in_arcsec_and_metres(layers, path):
    """``layers`` read from ``path`` with deflections in arcsec and heights in m.

    Parameters
    ----------
    layers : jaxgrav.dov.LayeredGrid
        As :meth:`~jaxgrav.dov.LayeredGrid.from_netcdf` read them (its ``units``: the
        first channel's, ``arcsec`` when the file declares none).
    path : str
        The ``--grid`` file (its ``height`` units are read from it; none: metres).

    Returns
    -------
    jaxgrav.dov.LayeredGrid
        Converted (the same object when already in arcsec and m).

    Raises
    ------
    ValueError
        Naming ``--grid``: deflection units that are no angle, height units that are no
        length this module knows.
    """
    with xr.open_dataset(path, decode_times=False) as ds:  # "Units", "unit" were ignored
        h_units = units_attr(ds["height"].attrs) or "m"
        declared = units_attr(ds[layers.channels[0]].attrs) or str(layers.units)
    angle = ARCSEC_PER.get(declared.strip().lower())
    if angle is None:
        raise ValueError(f"--grid {str(path)!r}: {layers.channels[0]} declares units "
                         f"{declared!r}, not an angle; expected deflections of the vertical "
                         "in arcsec (or rad, urad, mrad, deg, mas)")
    metres = METRES_PER.get(h_units.strip().lower())
    if metres is None:
        raise ValueError(f"--grid {str(path)!r}: height declares units {h_units!r}; expected "
                         "layer heights in m (or km, ft) above the ellipsoid")
    if angle == 1.0 and metres == 1.0:
        return layers
    return dataclasses.replace(layers, values=layers.values * angle,
                               heights=layers.heights * metres, units="arcsec")
