"""Layered deflection-of-the-vertical grids and their interpolation (paper C).

A :class:`LayeredGrid` holds DOV components (ξ, η, or any channels) on one regular
lat/lon grid at several heights. Heights and values are pytree leaves, so
interpolation is differentiable in the point, in the map values and in the layer
heights; the horizontal geometry is static.

Interpolation is horizontal in each layer, then vertical (see
:mod:`jaxgrav.dov.kernels` for the formulas). Methods ``"<horizontal>-<vertical>"``:

=====================  ==========================================================
``bilinear-linear``    the paper's (trilinear; equals SciPy's 3-D "linear")
``bilinear-lagrange``  quadratic in h through the three nearest layers
``bilinear-harmonic``  cubic in h with vertical curvature from Laplace's equation
``bicubic-*``          the same with a not-a-knot bicubic spline in each layer
=====================  ==========================================================

``bicubic-harmonic`` is the most accurate on the paper's trajectory (see
``examples/paper_c_dov.py``) and the default. Points off the map or outside the
layers' height range give NaN and ``inside=False`` (``strict=True`` raises instead);
nothing is clamped.

Heights are above the reference sphere of the model (spherical approximation, as
in :mod:`jaxgrav.fields.harmonics`); ξ, η are in arcsec, Heiskanen–Moritz signs.

The layered grid itself, its builders and NetCDF I/O are :mod:`jaxgrav.dov.layers`;
this module interpolates it.
"""

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import check_points, concrete
from jaxgrav.dov import kernels
from jaxgrav.dov.kernels import DEFAULT_METHOD
from jaxgrav.dov.layers import LayeredGrid

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "Interpolated",
    "PreparedLayers",
    "interpolate",
    "make_interpolator",
    "scan_track",
]

METHODS = kernels.METHODS


class Interpolated(NamedTuple):
    """Result of layered interpolation.

    Attributes
    ----------
    values : Array, shape ``(C, *P)``
        Interpolated channels (arcsec for DOV), NaN where ``inside`` is false.
    inside : Array of bool, shape ``P``
        Point on the map and within the layers' height range.
    """

    values: jax.Array
    inside: jax.Array


# -------------------------------------------------------------------- interpolation


def _check_layers(layers):
    if not isinstance(layers, LayeredGrid):
        raise TypeError(f"layers must be a LayeredGrid; got {type(layers).__name__}")


def _check_points(layers, lat, lon, h, strict):
    check_points(lat, lon, h)
    if not strict:
        return
    pts = [concrete(x) for x in (lat, lon, h)]
    if any(p is None for p in pts) or concrete(layers.heights) is None:
        raise ValueError("strict=True needs concrete points and heights (not traced)")
    la, lo, hh = np.broadcast_arrays(*pts)
    on_map = np.asarray(layers.layer(0).contains(la, lo))
    hs = np.asarray(layers.heights)
    in_h = (hh >= hs[0]) & (hh <= hs[-1])
    bad = ~(on_map & in_h)
    if bad.any():
        i = int(np.flatnonzero(bad.reshape(-1))[0])
        w, e, s, n = layers.extent
        raise ValueError(
            f"point (lat={float(la.reshape(-1)[i])!r}, lon={float(lo.reshape(-1)[i])!r}, "
            f"h={float(hh.reshape(-1)[i])!r} m) is outside the layered grid (lat {s}..{n}, lon "
            f"{w}..{e}, h {hs[0]}..{hs[-1]} m); {int(bad.sum())} point(s) out of range"
        )


def _checked_points(layers, lat, lon, h, method, strict):
    """Validate the layers, method and points; the points broadcast, in the float dtype."""
    _check_layers(layers)
    kernels.check_method(method, layers.values.shape[0])
    _check_points(layers, lat, lon, h, strict)
    dt = jnp.result_type(float)
    return jnp.broadcast_arrays(*(jnp.asarray(x, dt) for x in (lat, lon, h)))


def interpolate(layers, lat, lon, h, method=DEFAULT_METHOD, *, strict=False):
    """Interpolate layered DOV at points (horizontal, then vertical).

    Parameters
    ----------
    layers : LayeredGrid
        Values ``(L, C, ny, nx)``.
    lat, lon : array_like
        Points (degrees), broadcast with ``h`` to shape ``P``.
    h : array_like
        Heights (m) above the layers' reference surface.
    method : str
        One of :data:`METHODS` (static), default :data:`DEFAULT_METHOD`;
        ``"bilinear-linear"`` is the paper's.
    strict : bool
        Raise ``ValueError`` for (concrete) points off the map or outside
        ``[heights[0], heights[-1]]`` instead of returning NaN there.

    Returns
    -------
    Interpolated
        ``values (C, *P)`` and ``inside (P,)``. Differentiable in the points, in
        ``layers.values`` and in ``layers.heights``.
    """
    lat, lon, h = _checked_points(layers, lat, lon, h, method, strict)
    return interpolate_compiled(layers, lat, lon, h, method)


@functools.partial(jax.jit, static_argnames="method")
def interpolate_compiled(layers, lat, lon, h, method):
    """The compiled core of :func:`interpolate` (no validation; package-internal)."""
    return make_interpolator(layers, method)(lat, lon, h)


@pytree_dataclass
class PreparedLayers:
    """A layered grid prepared for interpolation once: a callable pytree value.

    Build with :func:`make_interpolator`. Its coefficients (spline slopes and, for
    ``harmonic``, the vertical curvatures of every layer) are array leaves and the
    method is static, so it is passed as data through ``jit``, ``vmap`` and ``scan``
    (a filter's state, a sensitivity study) without being rebuilt, and a new map of
    the same shape and geometry (``lat0``, ``dlat``, ``lon0``, ``dlon`` are static) does
    not recompile. Calling it validates only the (static) method, not the points.
    Differentiate through :func:`make_interpolator` (made inside the differentiated
    function) to get gradients in the map: the coefficients are computed from
    ``layers.values``, which the call itself reads only for its shape, so a gradient
    with respect to a prepared value's ``layers.values`` is zero.

    Attributes
    ----------
    layers : LayeredGrid
        The grid it was made from (heights and geometry are read from it).
    coefficients : Array
        ``(L, C', ny, nx)`` (bilinear) or ``(L, C', ny, nx, 4)`` (bicubic), with
        ``C' = 2C`` for ``harmonic`` (values, then curvatures).
    method : str
        One of :data:`METHODS`. Static.
    """

    layers: LayeredGrid
    coefficients: jax.Array
    method: str = static_field(DEFAULT_METHOD)

    # a function value: compared and hashed by identity, as functools.partial is, so
    # that ``jax.jit(make_interpolator(...))`` works (fields holding arrays are not
    # hashable)
    __eq__ = object.__eq__
    __hash__ = object.__hash__

    def __call__(self, lat, lon, h):
        """Interpolate at points (degrees, degrees, m), broadcast to shape ``P``.

        Returns
        -------
        Interpolated
            ``values (C, *P)`` (NaN off the map or the height range) and ``inside P``.
        """
        horiz, vert = kernels.check_method(self.method, self.layers.values.shape[0])
        return Interpolated(*kernels.evaluate(self.layers, self.coefficients, horiz, vert,
                                              lat, lon, h))


def make_interpolator(layers, method=DEFAULT_METHOD):
    """The layered grid prepared once for interpolation (spline slopes, curvatures).

    For use inside ``jit`` (filters, sensitivity studies): no validation at call.
    Traceable: made inside a jitted function, the preparation is part of it and is
    differentiable in ``layers.values`` and ``layers.heights``.

    Parameters
    ----------
    layers : LayeredGrid
    method : str
        One of :data:`METHODS`.

    Returns
    -------
    PreparedLayers
        ``f(lat, lon, h) -> Interpolated(values (C, *P), inside P)``, as
        :func:`interpolate`; a pytree, so it can be an argument of a jitted function.
    """
    horiz, vert = kernels.check_method(method, layers.values.shape[0])
    return PreparedLayers(layers, kernels.prepare(layers, horiz, vert), method)


def scan_track(layers, lat, lon, h, method=DEFAULT_METHOD):
    """Interpolate along a trajectory one fix at a time with ``lax.scan`` (on-board form).

    Same values as :func:`interpolate`; the scan carries the previous fix's cell
    (layer, row, column), as the paper's locate step does.

    Parameters
    ----------
    layers : LayeredGrid
    lat, lon, h : array_like, shape ``(T,)``
        Fixes in time order (degrees, degrees, m).
    method : str

    Returns
    -------
    values : Array, shape ``(C, T)``
    inside : Array of bool, shape ``(T,)``
    cell_changes : Array of int32, scalar
        Fixes at which the enclosing cell differs from the previous fix's.
    """
    lat, lon, h = _checked_points(layers, lat, lon, h, method, False)
    if lat.ndim != 1 or lat.shape[0] == 0:
        raise ValueError(f"lat, lon, h must be non-empty 1-D tracks; got shape {lat.shape}")
    return _scan(layers, lat, lon, h, method)


@functools.partial(jax.jit, static_argnames="method")
def _scan(layers, lat, lon, h, method):
    horiz, vert = kernels.check_method(method, layers.values.shape[0])
    coef = kernels.prepare(layers, horiz, vert)
    return kernels.scan_points(layers, coef, horiz, vert, lat, lon, h)
