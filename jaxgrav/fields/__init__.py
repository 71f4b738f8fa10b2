"""Where maps come from: point masses, spherical harmonics, random fields, FFT
continuation, EGM2008 regional builds (and, with the ``mag`` extra, magnetic maps)."""

from jaxgrav.fields import harmonics, pointmass, random, spectral

__all__ = ["harmonics", "pointmass", "random", "spectral"]

# point-mass fitting (paper D's model by least squares)
from jaxgrav.fields import pointmass_fit
from jaxgrav.fields.pointmass_fit import (
    PointMassFit,
    PointMassSweep,
    fit_point_masses,
    sweep_point_masses,
)

__all__ += [
    "PointMassFit",
    "PointMassSweep",
    "fit_point_masses",
    "pointmass_fit",
    "sweep_point_masses",
]

# map-error models: the field the sensors see when the map is not the truth
from jaxgrav.fields import map_error  # noqa: E402  (the module; map_error.map_error builds one)
from jaxgrav.fields.map_error import (  # noqa: E402
    CorrelatedMapError,
    TruthGrid,
    along_track_covariance,
    map_error_key,
    truth_field,
    truth_grid,
)

__all__ += [
    "CorrelatedMapError",
    "TruthGrid",
    "along_track_covariance",
    "map_error",
    "map_error_key",
    "truth_field",
    "truth_grid",
]
