"""Moved to :mod:`jaxgrav.lattice` (the matchers and the point-mass filter share it).

This import path is kept: it re-exports the same functions.
"""

from jaxgrav.lattice import computed_once, interleave, lattice_values, patch_values

__all__ = ["computed_once", "interleave", "lattice_values", "patch_values"]
