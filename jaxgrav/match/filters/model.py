"""The gravity-aided INS measurement and the types every filter shares.

A filter run is a sequence of steps. At step ``k`` the INS indicates ``(lat, lon)``
and the gravimeter may give a reading ``z`` (mGal; NaN when there is none). With
the error state of :mod:`jaxgrav.sim.ins` (position error = INS − true, in metres
north/east, and the gravimeter's systematic error δg_a) the predicted reading is

    h(x) = Δg_M(lat − d_n / M, lon − d_e / (N cos lat)) + δg_a,

the map anomaly at the position the INS would be at without error, plus the bias
(paper D: ``z = Δg_s − Δg_M``, written here as ``z − h(x)``). The map is a
:class:`~jaxgrav.grid.Grid` (bicubic) or :class:`~jaxgrav.fields.pointmass.PointMasses`.

Filters follow optax: a :class:`Filter` is a pair of pure functions
``init(x0, P0) -> FilterState`` and ``update(state, step, field, dynamics) ->
(FilterState, StepInfo)``; :func:`run_filter` scans ``update`` over a run with ``lax.scan``, and a
batch of runs is a ``jax.vmap`` of it.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.constants import DEG
from jaxgrav.fields.pointmass import PointMasses, _anomaly_kernel
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.grid import Grid
from jaxgrav.sim.ins import GRAV

__all__ = [
    "STATUS_FILTER",
    "Dynamics",
    "Filter",
    "FilterState",
    "Step",
    "StepInfo",
    "gravity_measurement",
    "map_anomaly",
    "run_filter",
    "status_messages_filter",
]

STATUS_FILTER = {
    "ok": 0,
    "no_reading": 1,  # reading NaN: prediction only
    "off_map": 2,  # a sigma point / the estimate left the map: update skipped
    "covariance_repaired": 4,  # P was not positive definite; jitter was added
    "covariance_failed": 8,  # even the jittered P failed; update skipped
    "gated": 16,  # innovation outside the gate: update skipped
    "grid_edge": 32,  # point-mass filter: posterior mass at the grid boundary
}
"""Bit flags in :attr:`StepInfo.status` (and, OR-ed over a run, in the summary)."""


class Step(NamedTuple):
    """Inputs of one filter step.

    Attributes
    ----------
    lat, lon : Array, shape ``()``
        INS-indicated position (degrees).
    z : Array, shape ``()``
        Gravimeter reading (mGal), NaN if none.
    r : Array, shape ``()``
        Reading noise variance (mGal²).
    """

    lat: jax.Array
    lon: jax.Array
    z: jax.Array
    r: jax.Array


class Dynamics(NamedTuple):
    """Linear error dynamics of one step: ``x ← F x + w``, ``w ~ N(0, Q)``.

    Attributes
    ----------
    f, q : Array, shape ``(n, n)``
        From :func:`jaxgrav.sim.ins.transition` (constant over a run).
    """

    f: jax.Array
    q: jax.Array


class FilterState(NamedTuple):
    """Gaussian filter state: error estimate ``x`` (n,) and covariance ``p`` (n, n)."""

    x: jax.Array
    p: jax.Array


class StepInfo(NamedTuple):
    """Per-step diagnostics.

    Attributes
    ----------
    x : Array, shape ``(n,)``
        Posterior error estimate.
    sigma : Array, shape ``(n,)``
        Posterior 1-σ of each state.
    p_pos : Array, shape ``(2, 2)``
        Posterior covariance of the position error (m²), for NEES.
    innovation, innovation_var : Array, shape ``()``
        ``z − ẑ`` (mGal) and its predicted variance (mGal²); NaN without a reading.
    status : Array, shape ``()``, int32
        Bit flags of :data:`STATUS_FILTER`.
    """

    x: jax.Array
    sigma: jax.Array
    p_pos: jax.Array
    innovation: jax.Array
    innovation_var: jax.Array
    status: jax.Array


class Filter(NamedTuple):
    """A filter as an ``init`` / ``update`` pair of pure functions (optax style)."""

    init: Callable
    update: Callable


def map_anomaly(field, lat, lon):
    """Map anomaly (mGal) at points: bicubic Grid sampling, a point-mass model or a callable.

    Parameters
    ----------
    field : Grid, PointMasses or callable
    lat, lon : Array
        Points (degrees), broadcast together.

    Returns
    -------
    Array
        NaN off a Grid.
    """
    if isinstance(field, Grid):
        return field.sample(lat, lon, "bicubic")
    if isinstance(field, PointMasses):
        return _anomaly_kernel(field, lat, lon, 0.0)
    return field(lat, lon)


def gravity_measurement(field, x, lat, lon):
    """Predicted reading ``h(x)`` (mGal) for error state ``x`` at INS position ``(lat, lon)``.

    Parameters
    ----------
    field : Grid, PointMasses or callable
    x : Array, shape ``(n,)``
        Error state; ``x[0], x[1]`` position error north/east (m), ``x[12]`` δg_a (mGal).
    lat, lon : Array, shape ``()``
        INS-indicated position (degrees).

    Returns
    -------
    Array, shape ``()``
    """
    true_lat = lat - x[0] / meridian_radius(lat) / DEG
    true_lon = lon - x[1] / (prime_vertical_radius(lat) * jnp.cos(lat * DEG)) / DEG
    return map_anomaly(field, true_lat, true_lon) + x[GRAV]


def run_filter(filt, field, dynamics, x0, p0, steps):
    """Run a filter over one track with ``lax.scan``.

    Parameters
    ----------
    filt : Filter
    field : Grid, PointMasses or callable
        Map; pass it here (a traced argument), not closed over, so large grids are
        not baked into the compiled code.
    dynamics : Dynamics
        Error dynamics per step.
    x0 : Array, shape ``(n,)``
    p0 : Array, shape ``(n, n)``
    steps : Step
        Fields with a leading time axis ``(T, ...)``.

    Returns
    -------
    final : FilterState
    infos : StepInfo
        Leading axis ``T``.
    """
    state = filt.init(x0, p0)

    def body(state, step):
        return filt.update(state, step, field, dynamics)

    return jax.lax.scan(body, state, steps)


def status_messages_filter(status):
    """Names of the flags set in a status word (int)."""
    return [name for name, bit in STATUS_FILTER.items() if bit and int(status) & bit]
