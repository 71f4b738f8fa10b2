"""Moved to :mod:`jaxgrav.lattice` (the matchers and the point-mass filter share it).

This import path is kept: it re-exports the same functions.
"""

from jaxgrav._fusion import computed_once
from jaxgrav.lattice import interleave, lattice_values, patch_values

__all__ = ["computed_once", "interleave", "lattice_values", "patch_values"]
