"""The gravity-aided INS measurement and the types every filter shares.

A filter run is a sequence of steps. At step ``k`` the INS indicates ``(lat, lon)``
and the gravimeter may give a reading ``z`` (mGal; NaN when there is none). With
the error state of :mod:`jaxgrav.sim.ins` (position error = INS − true, in metres
north/east, and the gravimeter's systematic error δg_a) the predicted reading is

    h(x) = Δg_M(lat − d_n / M, lon − d_e / (N cos lat)) + δg_a,

the map anomaly at the position the INS would be at without error, plus the bias
(paper D: ``z = Δg_s − Δg_M``, written here as ``z − h(x)``). The map is a
:class:`~jaxgrav.grid.Grid` (bicubic) or :class:`~jaxgrav.fields.pointmass.PointMasses`.

Filters follow optax: a :class:`Filter` is a pair of pure functions ``init(x0, P0) ->
FilterState`` and ``update(state, step, field, dynamics) -> (FilterState, StepInfo)`` (and
an optional, cheap ``predict`` for steps without a reading); :func:`run_filter` scans
``update`` over a run with ``lax.scan`` (a batch of runs is a ``jax.vmap`` of it); with
readings on a stride, ``run_filter(..., every=k)`` updates on them and predicts between.

The measurement is structured: :data:`gravity_measurement` is a :class:`MapPlusBias` (a map
part of the position states only, plus an additive bias state), which the UKF evaluates at
the ``2·2 + 1`` distinct sigma-point positions instead of all ``2n + 1``; any callable
``h(field, x, lat, lon)`` also works (the generic path).
"""

import inspect
import operator
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.constants import DEG
from jaxgrav.fields.pointmass import PointMasses
from jaxgrav.fields.pointmass import anomaly_kernel as _anomaly_kernel
from jaxgrav.filters.precision import in_update_precision
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.grid import Grid
from jaxgrav.prepared import PreparedMap, prepare_map
from jaxgrav.sim.ins import GRAV

__all__ = [
    "STATUS_FILTER",
    "Dynamics",
    "Filter",
    "FilterState",
    "MapPlusBias",
    "Step",
    "StepInfo",
    "gravity_measurement",
    "map_anomaly",
    "map_at_error",
    "predict_only",
    "prepare_field",
    "run_filter",
    "status_messages_filter",
]

STATUS_FILTER = {
    "ok": 0,
    "no_reading": 1,  # reading NaN: prediction only
    "off_map": 2,  # left the map / met a missing (NaN) cell (skipped; pf, pmf: see each)
    "covariance_repaired": 4,  # P was not positive definite; jitter was added
    "covariance_failed": 8,  # even the jittered P failed; update skipped
    "gated": 16,  # innovation outside the gate: update skipped
    "grid_edge": 32,  # point-mass filter: posterior mass at the grid boundary
    "reading_ignored": 64,  # run_filter(every=k): a reading off the update stride, not used
    "implausible_fit": 128,  # jaxgrav filter: the row's block of innovations fails χ² (p<1e-3)
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
    h_lin : Array, shape ``(n,)``, or None
        A part of the measurement that is linear in the state and known at this step:
        the predicted reading is ``h(x) + h_lin · x`` (mGal). Used for the Eötvös
        error of readings corrected with the INS velocity, ``∂E/∂v · δv``
        (:mod:`jaxgrav.navigate.tight`). None (default): no linear part. The Kalman,
        Gaussian-sum and particle filters take all of it; the point-mass filter its
        position and INS columns but not the gravimeter-bias and map-error ones (those
        states are per cell there; :mod:`jaxgrav.filters.pmf_linear`).
    """

    lat: jax.Array
    lon: jax.Array
    z: jax.Array
    r: jax.Array
    h_lin: jax.Array | None = None


class Dynamics(NamedTuple):
    """Linear error dynamics of one step: ``x ← F x + w``, ``w ~ N(0, Q)``.

    Attributes
    ----------
    f, q : Array, shape ``(n, n)``
        From :func:`jaxgrav.sim.ins.transition` (constant over a run).
    dt : Array, shape ``()``, or None
        Step length (s). The Gaussian filters do not use it; the point-mass filter
        needs it for its random-walk spread (``q_pos · dt``), and its
        ``dynamics(lat, dt)`` fills it in.
    """

    f: jax.Array
    q: jax.Array
    dt: jax.Array | None = None


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
    """A filter as an ``init`` / ``update`` pair of pure functions (optax style).

    Attributes
    ----------
    init : callable
        ``init(x0, P0) -> state``.
    update : callable
        ``update(state, step, field, dynamics) -> (state, StepInfo)``: predict one
        step, then use the reading if there is one.
    predict : callable or None
        ``predict(state, step, field, dynamics) -> (state, StepInfo)``: the prediction
        alone, for steps known to carry no reading (``run_filter(..., every=k)``);
        its info has NaN innovation and innovation variance and the ``no_reading``
        flag (plus ``reading_ignored`` if ``step.z`` is finite). ``None``: ``update``
        with the reading set to NaN (:func:`predict_only`).
    """

    init: Callable
    update: Callable
    predict: Callable | None = None


def prepare_field(field):
    """A map made ready to be evaluated many times: a Grid's bicubic coefficients, once.

    :func:`run_filter` calls it before its scan, so the spline solve over the whole
    map is not part of the step (XLA would usually hoist it out of the loop; this
    does not rely on that).

    Parameters
    ----------
    field : Grid, PointMasses or callable

    Returns
    -------
    PreparedMap, PointMasses or callable
        For a Grid, its :class:`~jaxgrav.prepared.PreparedMap` (a pytree value, passed
        through the scan as data; sampled bicubic, NaN off the grid, no validation);
        anything else unchanged.
    """
    if isinstance(field, Grid):
        return prepare_map(field)
    return field


def map_anomaly(field, lat, lon):
    """Map anomaly (mGal) at points: bicubic Grid sampling, a point-mass model or a callable.

    Parameters
    ----------
    field : Grid, PreparedMap, PointMasses or callable
    lat, lon : Array
        Points (degrees), broadcast together.

    Returns
    -------
    Array
        NaN off a Grid.
    """
    if isinstance(field, PreparedMap):
        return field.sample(lat, lon, "bicubic")
    if isinstance(field, Grid):
        return field.sample(lat, lon, "bicubic")
    if isinstance(field, PointMasses):
        return _anomaly_kernel(field, lat, lon, 0.0)
    return field(lat, lon)


def map_at_error(field, d, lat, lon):
    """Map anomaly (mGal) where the INS would be without the position error ``d``.

    Parameters
    ----------
    field : Grid, PointMasses or callable
    d : Array, shape ``(2,)``
        Position error north, east (m; INS − true).
    lat, lon : Array, shape ``()``
        INS-indicated position (degrees).

    Returns
    -------
    Array, shape ``()``
        ``Δg_M(lat − d_n / M, lon − d_e / (N cos lat))``; NaN off a Grid.
    """
    true_lat = lat - d[0] / meridian_radius(lat) / DEG
    true_lon = lon - d[1] / (prime_vertical_radius(lat) * jnp.cos(lat * DEG)) / DEG
    return map_anomaly(field, true_lat, true_lon)


@pytree_dataclass
class MapPlusBias:
    """A measurement ``h(x) = map_part(field, x[:n_position], lat, lon) + x[bias_index]``.

    Callable as any measurement, ``h(field, x, lat, lon) -> ẑ``, so every filter
    accepts it. The structure tells the UKF that only the first ``n_position``
    states enter the nonlinear part and the bias enters linearly: with the
    position states first and a lower Cholesky factor ``L`` of ``P``, the sigma
    points ``x ± √(n+λ) L[:, j]`` for ``j ≥ n_position`` sit at the mean position,
    so the map is evaluated at ``2 n_position + 1`` points instead of ``2n + 1``
    with the same numbers.

    Attributes
    ----------
    map_part : callable
        ``map_part(field, d, lat, lon) -> ẑ`` with ``d = x[:n_position]``
        (e.g. :func:`map_at_error`).
    bias_index : int
        Index of the additive bias state (``≥ n_position``).
    n_position : int
        Number of leading states the map part depends on.
    extra_indices : tuple of int
        Further additive states (e.g. the map-error state of
        :mod:`jaxgrav.filters.map_state`); default none.

    All fields are static (a pytree without leaves): they decide the code, not data.
    """

    map_part: Callable = static_field()
    bias_index: int = static_field(GRAV)
    n_position: int = static_field(2)
    extra_indices: tuple = static_field(())

    def __post_init__(self):
        if not 0 < self.n_position <= self.bias_index:
            raise ValueError(
                f"MapPlusBias needs 0 < n_position <= bias_index (the bias after the position "
                f"states); got n_position={self.n_position!r}, bias_index={self.bias_index!r}"
            )
        if any(not isinstance(i, int) or i < self.n_position or i == self.bias_index
               for i in self.extra_indices):
            raise ValueError(
                "MapPlusBias extra_indices must be ints after the position states, other than "
                f"bias_index; got {self.extra_indices!r}")

    @property
    def additive(self):
        """Indices of all additive states: ``(bias_index, *extra_indices)``."""
        return (self.bias_index, *self.extra_indices)

    def __call__(self, field, x, lat, lon):
        z = self.map_part(field, x[: self.n_position], lat, lon) + x[self.bias_index]
        for i in self.extra_indices:
            z = z + x[i]
        return z


gravity_measurement = MapPlusBias(map_at_error)
"""Predicted reading ``h(x)`` (mGal) for error state ``x`` at INS position ``(lat, lon)``.

``gravity_measurement(field, x, lat, lon) = map_at_error(field, x[:2], lat, lon) + x[12]``:
the map anomaly where the INS would be without its position error (``x[0], x[1]``
north/east, m) plus the gravimeter's systematic error δg_a (``x[12]``, mGal). A
:class:`MapPlusBias`, so the UKF evaluates the map at 5 sigma positions.
"""


def predict_only(filt):
    """A filter's prediction-only step: ``filt.predict``, or ``update`` with no reading.

    Returns
    -------
    callable
        ``(state, step, field, dynamics) -> (state, StepInfo)``; the fallback sets
        ``step.z`` to NaN and adds the ``reading_ignored`` flag if it was finite.
    """
    if filt.predict is not None:
        return filt.predict

    def predict(state, step, field, dynamics):
        state, info = filt.update(state, step._replace(z=jnp.full_like(step.z, jnp.nan)), field,
                                  dynamics)
        ignored = jnp.where(jnp.isfinite(step.z), STATUS_FILTER["reading_ignored"], 0)
        return state, info._replace(status=info.status | ignored.astype(info.status.dtype))

    return predict


def run_filter(filt, field, dynamics, x0, p0, steps, every=1, key=None):
    """Run a filter over one track with ``lax.scan``.

    Parameters
    ----------
    filt : Filter
    field : Grid, PointMasses or callable
        Map; pass it here (a traced argument), not closed over, so large grids are
        not baked into the compiled code. Prepared once (:func:`prepare_field`) for
        all steps.
    dynamics : Dynamics
        Error dynamics per step.
    x0 : Array, shape ``(n,)``
    p0 : Array, shape ``(n, n)``
    steps : Step
        Fields with a leading time axis ``(T, ...)``.
    every : int
        Readings sit on a fixed stride (static): only steps ``every − 1, 2·every − 1,
        …`` (indices into ``steps``) may carry one, as in
        :func:`~jaxgrav.scenarios.paper_d.filter_scenario`
        (:func:`~jaxgrav.filters.api.pad_to_stride` shifts other runs onto that
        stride). Those steps run
        ``update`` (a NaN reading there is still a masked update); the others run the
        filter's ``predict`` only — no sigma points, no factorisation — and a finite
        reading on them is not used (flag ``reading_ignored``). Every step still
        gets its :class:`StepInfo`, causally: a step before a reading shows the
        prediction, never the coming update; its innovation and innovation
        variance are NaN. Default 1: ``update`` on every step.
    key : PRNG key, optional
        For the particle filters (:func:`~jaxgrav.filters.pf`,
        :func:`~jaxgrav.filters.rbpf`): passed to their ``init`` (default there:
        ``PRNGKey(0)``). The Kalman filters take none.

    Returns
    -------
    final : FilterState
    infos : StepInfo
        Leading axis ``T``.

    Raises
    ------
    ValueError
        A bad ``every``; a ``key`` for a filter whose ``init`` takes none.
    """
    if key is not None and "key" not in inspect.signature(filt.init).parameters:
        raise ValueError("key is for the particle filters (pf, rbpf); this filter's init takes "
                         "no key: leave key=None")
    try:
        k = operator.index(every)
    except TypeError:
        k = 0
    if isinstance(every, bool) or k < 1:
        raise ValueError(f"every must be a positive int (steps per reading); got {every!r}")
    every = k
    field = prepare_field(field)
    state = filt.init(x0, p0) if key is None else filt.init(x0, p0, key)
    state = in_update_precision(filt, state, jax.tree.map(lambda a: a[0], steps), field,
                                dynamics)

    def body(state, step):
        return filt.update(state, step, field, dynamics)

    if every == 1:
        return jax.lax.scan(body, state, steps)

    predict = predict_only(filt)

    def pbody(state, step):
        return predict(state, step, field, dynamics)

    def block(state, bs):
        state, head = jax.lax.scan(pbody, state, jax.tree.map(lambda a: a[:-1], bs),
                                   unroll=min(every - 1, 8))
        state, last = body(state, jax.tree.map(lambda a: a[-1], bs))
        return state, jax.tree.map(lambda a, b: jnp.concatenate([a, b[None]]), head, last)

    t = steps.z.shape[0]
    nb, rem = divmod(t, every)
    blocks = jax.tree.map(lambda a: a[: nb * every].reshape(nb, every, *a.shape[1:]), steps)
    state, infos = jax.lax.scan(block, state, blocks)
    infos = jax.tree.map(lambda a: a.reshape(nb * every, *a.shape[2:]), infos)
    if rem:
        state, tail = jax.lax.scan(pbody, state, jax.tree.map(lambda a: a[nb * every :], steps))
        infos = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), infos, tail)
    return state, infos


def status_messages_filter(status):
    """Names of the flags set in a status word (int)."""
    return [name for name, bit in STATUS_FILTER.items() if bit and int(status) & bit]
