"""A map prepared for interpolation: a pytree value holding the spline coefficients.

:class:`PreparedMap` is a :class:`~jaxgrav.grid.Grid` together with its not-a-knot
bicubic node coefficients (:func:`jaxgrav.interp.bicubic_coefficients`), computed once
by :func:`prepare_map`. It is a frozen dataclass registered as a pytree (the grid's
geometry static, the values and coefficients array leaves), so it is passed as data
through ``jit``, ``vmap`` and ``scan``: preparing it outside a hot loop and passing it
in computes the spline slopes once, not at every call.

Every form of the map a matcher reads is derived from the stored coefficients:

- :meth:`PreparedMap.sample`: values at points (NaN off the grid), bicubic or bilinear;
- :meth:`PreparedMap.value_and_gradient`: bicubic value and gradient per degree;
- :meth:`PreparedMap.patches`: 16 power-basis coefficients per cell (contour points);
- :meth:`PreparedMap.interleaved`: the ``(2·ny, 2·nx)`` lattice table (dense offsets).
"""

import jax

from jaxgrav import interp
from jaxgrav._pytree import pytree_dataclass

__all__ = ["PreparedMap", "as_grid", "prepare_map"]


@pytree_dataclass
class PreparedMap:
    """A grid with its bicubic node coefficients (build with :func:`prepare_map`).

    Attributes
    ----------
    grid : Grid
        The map: values ``(ny, nx)`` (array leaf) and static geometry.
    coefficients : Array, shape ``(ny, nx, 4)``
        ``[f, ∂f/∂ix, ∂f/∂iy, ∂²f/∂iy∂ix]`` at each node (per index step).
    """

    grid: object
    coefficients: object

    # ------------------------------------------------------------------ geometry
    @property
    def values(self):
        """Node values ``(ny, nx)`` (map units)."""
        return self.grid.values

    @property
    def ny(self):
        """Number of latitude rows."""
        return self.grid.ny

    @property
    def nx(self):
        """Number of longitude columns."""
        return self.grid.nx

    def fractional_index(self, lat, lon):
        """Fractional ``(iy, ix)`` of points; see :meth:`Grid.fractional_index`."""
        return self.grid.fractional_index(lat, lon)

    # ------------------------------------------------------------------ sampling
    def sample(self, lat, lon, method="bicubic"):
        """Interpolated values at points (no validation; for use inside ``jit``).

        Parameters
        ----------
        lat, lon : Array
            Points (degrees), broadcast together to shape ``P``.
        method : {"bicubic", "bilinear"}

        Returns
        -------
        Array, shape ``P``
            Map values; NaN off the grid.
        """
        interp.check_method(method)
        iy, ix = self.grid.fractional_index(lat, lon)
        if method == "bilinear":
            return interp.bilinear(self.grid.values, iy, ix)
        return interp.bicubic(self.coefficients, iy, ix)

    def sampler(self, method="bicubic"):
        """``f(lat, lon) -> values``: :meth:`sample` with ``method`` bound."""
        interp.check_method(method)
        return lambda lat, lon: self.sample(lat, lon, method)

    def value_and_gradient(self, lat, lon):
        """Bicubic value and its analytic gradient at points.

        Parameters
        ----------
        lat, lon : Array
            Points (degrees), broadcast together to shape ``P``.

        Returns
        -------
        value, d_lat, d_lon : Array, shape ``P``
            Value (map units; NaN off the grid) and derivatives per degree of latitude
            and longitude (0 off the grid).
        """
        iy, ix = self.grid.fractional_index(lat, lon)
        v, d_iy, d_ix = interp.bicubic_value_and_gradient(self.coefficients, iy, ix)
        return v, d_iy / self.grid.dlat, d_ix / self.grid.dlon

    # ------------------------------------------------------------------ derived forms
    def patches(self):
        """Power-basis coefficients per cell, ``(ny−1, nx−1, 16)``.

        :func:`jaxgrav.interp.bicubic_patches` of the stored coefficients.
        """
        return interp.bicubic_patches(self.coefficients)

    def interleaved(self):
        """Interleaved ``(2·ny, 2·nx)`` table (:func:`jaxgrav.interp.interleave_coefficients`)."""
        return interp.interleave_coefficients(self.coefficients)

    def lattice_table(self, method="bicubic"):
        """The table the lattice evaluators read: :meth:`interleaved` (bicubic) or the values."""
        interp.check_method(method)
        return self.grid.values if method == "bilinear" else self.interleaved()


def prepare_map(grid):
    """A :class:`PreparedMap` of ``grid`` (returned unchanged if already prepared).

    Parameters
    ----------
    grid : Grid or PreparedMap
        Map with at least 4 nodes per axis.

    Returns
    -------
    PreparedMap
    """
    if isinstance(grid, PreparedMap):
        return grid
    return PreparedMap(grid, _coefficients(grid.values))


_coefficients = jax.jit(interp.bicubic_coefficients)
"""The node coefficients as one compiled program: called outside ``jit`` (a command or
a Monte Carlo builder preparing its map) op by op they were ~40 programs compiled one
by one, 1.5–1.6 s CPU for the 2.5′ map against 0.75–0.8 s (2.2–3.0 against 1.0–1.1 s
wall, fresh processes, load ~4); inside a caller's ``jit`` it is inlined as before."""


def as_grid(grid):
    """The :class:`~jaxgrav.grid.Grid` of a Grid or a :class:`PreparedMap`."""
    return grid.grid if isinstance(grid, PreparedMap) else grid
