"""Deflection of the vertical: layered DOV grids, their interpolation (paper C) and layer studies.

:class:`LayeredGrid` (:mod:`~jaxgrav.dov.layers`) holds ξ, η on one lat/lon grid at
several heights; :func:`interpolate`, :func:`make_interpolator` (a callable
:class:`PreparedLayers` pytree) and :func:`scan_track` (:mod:`~jaxgrav.dov.interpolate`)
interpolate it with the traced kernels of
:mod:`~jaxgrav.dov.kernels`; :mod:`~jaxgrav.dov.sensitivity` differentiates the
interpolation error in the layer heights and spacing (optax studies).
"""

from jaxgrav.dov import sensitivity
from jaxgrav.dov.interpolate import (
    Interpolated,
    PreparedLayers,
    interpolate,
    make_interpolator,
    scan_track,
)
from jaxgrav.dov.kernels import DEFAULT_METHOD, HARMONIC_GAP_LIMIT, METHODS, harmonic_gap_ratio
from jaxgrav.dov.layers import PAPER_HEIGHTS, LayeredGrid, paper_c_layers
from jaxgrav.dov.sensitivity import (
    HeightStudy,
    SchulerError,
    harmonic_layers,
    optimise_heights,
    rms_error,
    schuler_error,
    spacing_error,
)

__all__ = [
    "DEFAULT_METHOD",
    "HARMONIC_GAP_LIMIT",
    "METHODS",
    "PAPER_HEIGHTS",
    "HeightStudy",
    "Interpolated",
    "LayeredGrid",
    "PreparedLayers",
    "SchulerError",
    "harmonic_gap_ratio",
    "harmonic_layers",
    "interpolate",
    "make_interpolator",
    "optimise_heights",
    "paper_c_layers",
    "rms_error",
    "scan_track",
    "schuler_error",
    "sensitivity",
    "spacing_error",
]
