"""jaxgrav: geophysical map-matching aided inertial navigation in JAX.

The public API is re-exported here; see the README for a tour. Packages, bottom to
top: ``constants``, ``geodesy``, ``interp`` → ``grid``, ``prepared`` → ``fields``, ``sim`` →
``datasets`` → ``match``, ``filters``, ``dov`` → ``scenarios`` → ``montecarlo`` →
``cli`` (the command, not imported here).
"""

import importlib

from jaxgrav import (
    constants,
    datasets,
    dov,
    fields,
    filters,
    geodesy,
    interp,
    match,
    montecarlo,
    scenarios,
    sim,
)
from jaxgrav.dov import LayeredGrid
from jaxgrav.geodesy import (
    ecef_to_geodetic,
    enu_to_geodetic,
    eotvos,
    geodetic_to_ecef,
    geodetic_to_enu,
    meridian_radius,
    normal_gravity,
    prime_vertical_radius,
)
from jaxgrav.grid import Grid, Window, sample
from jaxgrav.prepared import PreparedMap, prepare_map

__version__ = "0.1.0"

__all__ = [
    "Grid",
    "LayeredGrid",
    "PreparedMap",
    "Window",
    "__version__",
    "constants",
    "datasets",
    "dov",
    "ecef_to_geodetic",
    "enu_to_geodetic",
    "eotvos",
    "fields",
    "filters",
    "geodesy",
    "geodetic_to_ecef",
    "geodetic_to_enu",
    "interp",
    "match",
    "meridian_radius",
    "montecarlo",
    "normal_gravity",
    "prepare_map",
    "prime_vertical_radius",
    "sample",
    "scenarios",
    "sim",
]


def __getattr__(name):
    # deprecated module paths, kept for one release
    if name == "sensitivity":
        return importlib.import_module("jaxgrav.sensitivity")
    raise AttributeError(f"module 'jaxgrav' has no attribute {name!r}")
