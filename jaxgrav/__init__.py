"""jaxgrav: geophysical map-matching aided inertial navigation in JAX.

The public API is re-exported here; see the README for a tour. Packages, bottom to
top: ``constants``, ``geodesy``, ``interp`` → ``grid``, ``prepared`` → ``fields``, ``sim`` →
``datasets`` → ``match``, ``filters``, ``dov`` → ``scenarios`` → ``montecarlo`` →
``cli`` (the command, not imported here).
"""

import importlib
import os
import sys

if os.path.basename((sys.argv or [""])[0]) == "jaxgrav" and "jax" not in sys.modules:
    # The ``jaxgrav`` command only (a library user's program is left alone): jaxlib
    # 0.10.1 logs one C++ ERROR line, ~1 kB, for every compiled program it loads from
    # the persistent compilation cache ("Target machine feature +prefer-no-gather is
    # not supported": a tuning flag taken for a CPU feature, openxla/xla#44565; the
    # program loads and runs), hundreds per warm command. The level is read when jaxlib
    # loads, so it is set here, before JAX is imported, unless the user set it.
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")

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
