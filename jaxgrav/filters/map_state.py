"""A first-order Gauss–Markov (FOGM) map-error state for the gravity/INS filters.

When the map is not the truth, the reading is ``z = Δg_M(true position) + ε_map +
δg_a + noise``: the map error ``ε_map`` along the track is correlated over the
map error's correlation length L (a few mGal over ~10 km for a marine map). A
white-noise filter treats it as independent from reading to reading and becomes
overconfident (issue 15: NEES 77). Here it is one more error state (MagNav.jl's
"FOGM catch-all"): a first-order Gauss–Markov process over the distance travelled,
i.e. in time with the time constant ``τ = L / speed``::

    ε_{k+1} = Φ ε_k + w_k,   Φ = e^{−Δt/τ},   Var w_k = σ² (1 − e^{−2Δt/τ}),

stationary with variance σ² and correlation ``e^{−r/L}`` at a distance r along a
straight track at constant speed (exact for a ``markov1`` map error; for the
default ``markov2`` field ``σ²(1 + r/L)e^{−r/L}`` the FOGM with length ``2 L``
has the same integral scale — :func:`fogm_length` gives the filter's length).

The state is appended after the INS error states (index ``n``, 13 for
:mod:`jaxgrav.sim.ins`) and enters the reading additively like the gravimeter
bias: :func:`map_error_measurement` is a
:class:`~jaxgrav.filters.model.MapPlusBias` with one extra additive index, so the
UKF still evaluates the map at the ``2·2 + 1`` position sigma points only, and
the UKF, EKF and Gaussian sum take it unchanged. σ and L are pytree data (traced:
sweeping them never recompiles). Off by default: no :class:`MapErrorState` (or a
concrete σ = 0) leaves the dynamics, the prior and the measurement as they are —
exactly today's filters.
"""

import math

import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass
from jaxgrav._validate import concrete
from jaxgrav.filters.model import Dynamics, MapPlusBias, gravity_measurement

__all__ = [
    "MapErrorState",
    "augment",
    "fogm_length",
    "fogm_transition",
    "map_error_measurement",
    "map_error_state",
]


@pytree_dataclass
class MapErrorState:
    """The filters' map-error model: a FOGM state of σ (mGal) and length L (m).

    Build with :func:`map_error_state` (validates). Both fields are pytree data.

    Attributes
    ----------
    sigma : Array, scalar
        Stationary standard deviation of the map error (mGal), ≥ 0.
    length_m : Array, scalar
        Correlation length over distance travelled (m), > 0.
    """

    sigma: jnp.ndarray
    length_m: jnp.ndarray


def _check(x, name, unit, allow_zero):
    arr = concrete(x)
    if arr is None:
        return
    if arr.dtype.kind not in "iuf" or arr.ndim != 0:
        raise TypeError(f"{name} must be a real scalar ({unit}); got {x!r}")
    v = float(arr)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        rule = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {rule} ({unit}); got {v!r}")


def map_error_state(sigma, length_m):
    """A validated :class:`MapErrorState`.

    Parameters
    ----------
    sigma : float
        Map-error σ (mGal), finite, ≥ 0 (0: no map-error state, today's filters).
    length_m : float
        Correlation length L (m), finite, > 0.

    Returns
    -------
    MapErrorState

    Raises TypeError for a non-real or non-scalar value, ValueError for a negative σ,
    a non-positive L, NaN or inf (concrete values; traced ones pass).
    """
    _check(sigma, "map-error sigma", "mGal", True)
    _check(length_m, "map-error length_m", "m", False)
    dtype = jnp.result_type(float)
    return MapErrorState(jnp.asarray(sigma, dtype), jnp.asarray(length_m, dtype))


def fogm_length(model):
    """The FOGM length (m) matching a map-error model's correlation.

    ``markov1`` (``σ² e^{−r/L}``): L itself (the FOGM is exact along a straight
    track); ``markov2`` (``σ² (1 + r/L) e^{−r/L}``): ``2 L``, the same integral
    scale ``∫ C(r) dr / σ²`` (same low-frequency power).

    Parameters
    ----------
    model : CorrelatedMapError
    """
    return model.length_m * (1.0 if model.family == "markov1" else 2.0)


def fogm_transition(sigma, length_m, speed, dt):
    """Exact discretisation of the FOGM over one step.

    Parameters
    ----------
    sigma : float or Array
        Stationary σ (mGal).
    length_m : float or Array
        Correlation length over distance (m), > 0.
    speed : float or Array
        Speed over ground (m/s), > 0: time constant ``τ = length_m / speed``.
    dt : float or Array
        Step (s).

    Returns
    -------
    phi : Array
        ``e^{−Δt/τ}``.
    q : Array
        ``σ² (1 − e^{−2Δt/τ})`` (mGal²).
    """
    a = jnp.asarray(dt) * jnp.asarray(speed) / jnp.asarray(length_m)
    phi = jnp.exp(-a)
    return phi, jnp.square(sigma) * -jnp.expm1(-2.0 * a)


def map_error_measurement(base=gravity_measurement, index=None):
    """``base`` with one more additive state: the map error (index ``index``).

    Parameters
    ----------
    base : MapPlusBias
        Default :data:`~jaxgrav.filters.model.gravity_measurement` (13 INS states).
    index : int, optional
        Index of the map-error state; default ``base.bias_index + 1`` (13).

    Returns
    -------
    MapPlusBias
    """
    if not isinstance(base, MapPlusBias):
        raise TypeError(f"base must be a MapPlusBias measurement; got {type(base).__name__}")
    index = base.bias_index + 1 if index is None else int(index)
    return MapPlusBias(base.map_part, base.bias_index, base.n_position,
                       (*base.extra_indices, index))


def _is_off(config):
    if config is None:
        return True
    s = concrete(config.sigma)
    return s is not None and np.all(s == 0)


def augment(config, dynamics, x0, p0, speed, measurement=gravity_measurement):
    """Append the FOGM map-error state to a filter's dynamics, prior and measurement.

    Parameters
    ----------
    config : MapErrorState or None
        None or a concrete σ = 0: everything returned unchanged (today's filter).
    dynamics : Dynamics
        ``f``, ``q`` of shape ``(n, n)``; ``dt`` (s) must be set.
    x0 : Array, shape ``(n,)``
    p0 : Array, shape ``(n, n)``
    speed : float or Array
        Speed over ground (m/s) for ``τ = L / speed``.
    measurement : MapPlusBias
        The measurement to extend.

    Returns
    -------
    dynamics : Dynamics
        ``(n + 1, n + 1)`` block-diagonal with ``Φ`` and ``Q_m`` (:func:`fogm_transition`).
    x0 : Array, shape ``(n + 1,)``
        The map error's prior mean 0.
    p0 : Array, shape ``(n + 1, n + 1)``
        Its prior variance σ² (the stationary one).
    measurement : MapPlusBias
        ``measurement`` plus the new state (:func:`map_error_measurement`).
    """
    if _is_off(config):
        return dynamics, x0, p0, measurement
    if not isinstance(config, MapErrorState):
        raise TypeError(f"config must be a MapErrorState (map_error_state(...)) or None; got "
                        f"{type(config).__name__}")
    if dynamics.dt is None:
        raise ValueError("augment needs dynamics.dt (the step, s) to discretise the FOGM")
    n = dynamics.f.shape[0]
    phi, qm = fogm_transition(config.sigma, config.length_m, speed, dynamics.dt)
    dtype = dynamics.f.dtype
    f = jnp.zeros((n + 1, n + 1), dtype).at[:n, :n].set(dynamics.f).at[n, n].set(phi)
    q = jnp.zeros((n + 1, n + 1), dtype).at[:n, :n].set(dynamics.q).at[n, n].set(qm)
    x0 = jnp.concatenate([jnp.asarray(x0, dtype), jnp.zeros(1, dtype)])
    p0 = (jnp.zeros((n + 1, n + 1), dtype).at[:n, :n].set(p0)
          .at[n, n].set(jnp.square(config.sigma)))
    return Dynamics(f, q, dynamics.dt), x0, p0, map_error_measurement(measurement, n)
