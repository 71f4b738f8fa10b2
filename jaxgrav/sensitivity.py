"""Deprecated: moved to :mod:`jaxgrav.dov.sensitivity` (kept importable for one release)."""

import warnings

from jaxgrav.dov.sensitivity import *  # noqa: F403
from jaxgrav.dov.sensitivity import __all__  # noqa: F401

warnings.warn("jaxgrav.sensitivity is deprecated: use jaxgrav.dov.sensitivity",
              DeprecationWarning, stacklevel=2)
