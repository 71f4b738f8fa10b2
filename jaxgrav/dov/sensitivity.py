"""Gradient-based studies of layered DOV compensation (paper C), with optax.

* :func:`harmonic_layers` builds layers from a spherical-harmonic model as a
  differentiable function of the layer heights (values are re-synthesised, so
  d(error)/d(height) includes how the field changes with the layer's height);
  :func:`rms_error`, :func:`optimise_heights` study and tune the heights.
* :func:`schuler_error` is a horizontal INS error model driven by the DOV
  compensation error ε: per axis ``δp̈ = −ω_s² δp − g ε`` (ω_s² = g/R, Schuler),
  integrated exactly for piecewise-constant ε with ``lax.scan``. A constant ε gives
  the bounded oscillation ``δp = −R ε (1 − cos ω_s t)``.
* :func:`spacing_error` makes the grid spacing a differentiable parameter: the
  nodes of a grid of spacing Δ (a traced scalar, fixed node count, centred on the
  track) are synthesised from the model *at their positions*, then interpolated at
  the track. This is the exact "resample the truth at spacing Δ" model; the error is
  continuous and piecewise smooth in Δ (kinks where a fix crosses a node line).
"""

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxgrav import interp
from jaxgrav.constants import ARCSEC
from jaxgrav.dov import kernels
from jaxgrav.dov.interpolate import make_interpolator
from jaxgrav.dov.layers import LayeredGrid
from jaxgrav.fields.harmonics import synthesize_grid

__all__ = [
    "HeightStudy",
    "SchulerError",
    "harmonic_layers",
    "height_loss_and_grad",
    "optimise_heights",
    "rms_error",
    "schuler_error",
    "spacing_error",
]

_G = 9.80
_R = 6371000.0


def harmonic_layers(model, lat_1d, lon_1d):
    """A function ``heights -> LayeredGrid`` synthesising ξ, η from ``model`` (float64).

    Parameters
    ----------
    model : SphericalHarmonics
    lat_1d, lon_1d : array_like
        Regular grid coordinates (degrees).

    Returns
    -------
    callable
        ``build(heights (L,) in m) -> LayeredGrid``, differentiable in ``heights``.
    """
    geo = LayeredGrid.from_arrays(lat_1d, lon_1d, [0.0, 1.0],
                                  np.zeros((2, 2, np.size(lat_1d), np.size(lon_1d))))
    lat = jnp.asarray(geo.lat)
    lon = jnp.asarray(geo.lon)

    def build(heights):
        heights = jnp.asarray(heights, jnp.float64)
        vals = []
        for k in range(heights.shape[0]):  # a few layers (static count)
            f = synthesize_grid(model, lat, lon, heights[k])
            vals.append(jnp.stack([f.xi, f.eta]))
        return dataclasses.replace(geo, values=jnp.stack(vals), heights=heights)

    return build


def rms_error(layers, lat, lon, h, truth, method="bilinear-linear"):
    """RMS over points and channels of interpolated minus true values (arcsec).

    Parameters
    ----------
    layers : LayeredGrid
    lat, lon, h : Array, shape (T,)
        Track (degrees, degrees, m).
    truth : Array, shape (C, T)
        Exact values at the track.
    method : str
        Static.

    Returns
    -------
    Array, scalar
        NaN if any fix is outside the layers.
    """
    out, _ = _k_eval(layers, method, lat, lon, h)
    return jnp.sqrt(jnp.mean((out - truth) ** 2))


def _k_eval(layers, method, lat, lon, h):
    return make_interpolator(layers, method)(lat, lon, h)


class HeightStudy(NamedTuple):
    """History of :func:`optimise_heights`.

    Attributes
    ----------
    heights : ndarray, shape (steps+1, L)
        Layer heights (m) at each step.
    rms : ndarray, shape (steps+1,)
        RMS error (arcsec) at each step.
    grad : ndarray, shape (L,)
        d rms / d heights at the initial heights (arcsec/m).
    """

    heights: np.ndarray
    rms: np.ndarray
    grad: np.ndarray


def optimise_heights(build, heights, lat, lon, h, truth, *, free, method="bilinear-linear",
                     steps=25, learning_rate=300.0):
    """Tune some layer heights with optax Adam to minimise the RMS error along a track.

    Parameters
    ----------
    build : callable
        ``heights -> LayeredGrid`` (e.g. :func:`harmonic_layers`).
    heights : array_like, shape (L,)
        Initial heights (m).
    lat, lon, h : array_like, shape (T,)
        Track.
    truth : array_like, shape (C, T)
        Exact DOV at the track (arcsec).
    free : array_like of bool, shape (L,)
        Which heights move (the others stay fixed, e.g. the outer layers that
        bound the flight envelope).
    method : str
        Interpolation method.
    steps : int
        Adam iterations (Python loop outside jit; each step is one jitted call).
        ``steps=0`` evaluates the RMS and its gradient at ``heights`` only.
    learning_rate : float
        Adam step (m).

    Returns
    -------
    HeightStudy

    Notes
    -----
    The loss and gradient program is compiled once per ``build`` object, ``method``
    and array shapes: further calls with the same ``build`` (other start heights,
    tracks of the same length) reuse it.
    """
    free = jnp.asarray(free, bool)
    lat, lon, h, truth = (jnp.asarray(x, jnp.float64) for x in (lat, lon, h, truth))

    opt = optax.adam(learning_rate)
    x = jnp.asarray(heights, jnp.float64)
    state = opt.init(x)
    hist, losses, g0 = [], [], None
    for _ in range(int(steps) + 1):
        loss, g = height_loss_and_grad(x, lat, lon, h, truth, build=build, method=method)
        hist.append(np.asarray(x))
        losses.append(float(loss))
        g0 = np.asarray(g) if g0 is None else g0
        upd, state = opt.update(jnp.where(free, g, 0.0), state, x)
        x = x + jnp.where(free, upd, 0.0)
    return HeightStudy(np.stack(hist), np.asarray(losses), g0)


@functools.partial(jax.jit, static_argnames=("build", "method"))
def height_loss_and_grad(heights, lat, lon, h, truth, *, build, method="bilinear-linear"):
    """RMS error of ``build(heights)`` along a track and its gradient in the heights.

    Parameters
    ----------
    heights : Array, shape (L,)
        Layer heights (m).
    lat, lon, h : Array, shape (T,)
        Track (degrees, degrees, m).
    truth : Array, shape (C, T)
        Exact values at the track (arcsec).
    build : callable
        ``heights -> LayeredGrid`` (static: one compilation per ``build`` object).
    method : str
        Interpolation method (static).

    Returns
    -------
    rms : Array, scalar
        As :func:`rms_error` (arcsec).
    grad : Array, shape (L,)
        d rms / d heights (arcsec/m).
    """
    return jax.value_and_grad(lambda x: rms_error(build(x), lat, lon, h, truth, method))(heights)


class SchulerError(NamedTuple):
    """Horizontal INS errors driven by a DOV compensation error.

    Attributes
    ----------
    north, east : Array, shape (T,)
        Position errors (m).
    v_north, v_east : Array, shape (T,)
        Velocity errors (m/s).
    """

    north: jax.Array
    east: jax.Array
    v_north: jax.Array
    v_east: jax.Array


def schuler_error(eps_north, eps_east, dt, *, g=_G, radius=_R):
    """Integrate the Schuler loop driven by the residual deflection.

    Per axis ``δp̈ = −(g/R) δp − g ε``; ε is held constant over each step (exact
    zero-order-hold update, so any ``dt`` is stable).

    Parameters
    ----------
    eps_north, eps_east : Array, shape (T,)
        Compensation error (used minus true deflection) ξ and η (arcsec).
    dt : float
        Step (s).
    g, radius : float
        Gravity (m/s²) and Earth radius (m).

    Returns
    -------
    SchulerError
        Errors after each step (shape (T,)).
    """
    w = float(np.sqrt(g / radius))
    c, s = float(np.cos(w * dt)), float(np.sin(w * dt))
    acc = -g * ARCSEC * jnp.stack([jnp.asarray(eps_north), jnp.asarray(eps_east)], -1)

    def step(state, a):
        p, v = state
        p2 = p * c + v * (s / w) + a * (1 - c) / w**2
        v2 = -p * (w * s) + v * c + a * (s / w)
        return (p2, v2), (p2, v2)

    z = jnp.zeros(2, acc.dtype)
    _, (p, v) = jax.lax.scan(step, (z, z), acc)
    return SchulerError(p[:, 0], p[:, 1], v[:, 0], v[:, 1])


def spacing_error(model, lat, lon, h, truth, heights, spacing_deg, *, n_nodes,
                  method="bilinear-linear"):
    """Compensation error along a track for layers of spacing Δ, differentiable in Δ.

    The grid has ``n_nodes = (ny, nx)`` nodes (static) centred on the track's
    bounding box, node ``i`` at ``centre + (i − (n−1)/2) Δ``; its values are
    synthesised from ``model`` at the layer ``heights``.

    Parameters
    ----------
    model : SphericalHarmonics
    lat, lon, h : Array, shape (T,)
        Track (degrees, degrees, m).
    truth : Array, shape (2, T)
        Exact ξ, η at the track (arcsec).
    heights : Array, shape (L,)
        Layer heights (m).
    spacing_deg : float or Array
        Grid spacing Δ in latitude and longitude (degrees); traced.
    n_nodes : tuple of int
        Nodes ``(ny, nx)``; must cover the track for the Δ studied (else NaN).
    method : str
        ``bilinear-*`` or ``bicubic-*`` with ``linear`` or ``lagrange`` vertical.

    Returns
    -------
    Array, shape (2, T)
        Interpolated minus true ξ, η (arcsec).
    """
    horiz, vert = kernels.check_method(method, len(heights))
    if vert == "harmonic":
        raise ValueError("spacing_error supports the linear and lagrange vertical methods")
    d = jnp.asarray(spacing_deg, jnp.float64)
    ny, nx = n_nodes
    clat = 0.5 * (float(np.min(lat)) + float(np.max(lat)))
    clon = 0.5 * (float(np.min(lon)) + float(np.max(lon)))
    lat0 = clat - 0.5 * (ny - 1) * d
    lon0 = clon - 0.5 * (nx - 1) * d
    lat_1d = lat0 + d * jnp.arange(ny)
    lon_1d = lon0 + d * jnp.arange(nx)
    vals = []
    for hk in np.asarray(heights, float):
        f = synthesize_grid(model, lat_1d, lon_1d, float(hk))
        vals.append(jnp.stack([f.xi, f.eta]))
    vals = jnp.stack(vals)
    iy, ix = (lat - lat0) / d, (lon - lon0) / d
    if horiz == "bicubic":
        hv = interp.bicubic(interp.bicubic_coefficients(vals), iy, ix)
    else:
        hv = interp.bilinear(vals, iy, ix)
    w, w2, inside = kernels.vertical_weights(jnp.asarray(heights, jnp.float64), h, vert)
    return kernels.combine(hv, w, w2, inside, 2) - truth
