"""A Gauss–Markov map-error state (first or second order) for the gravity/INS filters.

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

``order=2`` is the second-order Gauss–Markov (SOGM) state matched exactly to a
``markov2`` map error: two states, the error ``ε`` and its rate ``ε̇`` (mGal/s),
``dε̇/dt = −β² ε − 2β ε̇ + w`` with ``β = speed / L`` and white ``w`` of density
``4 β³ σ²``, whose autocovariance along a straight track at constant speed is the
field's own ``σ² (1 + r/L) e^{−r/L}``. It is discretised exactly
(:func:`sogm_transition`: the matrix exponential in closed form, the process noise
``P∞ − Φ P∞ Φᵀ`` from the stationary covariance ``P∞ = diag(σ², β² σ²)``, equal to Van
Loan's). Only ``ε`` enters the reading.

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

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import concrete
from jaxgrav.filters.model import Dynamics, MapPlusBias, gravity_measurement

__all__ = [
    "ORDERS",
    "SOGM_MIN_SPEED",
    "MapErrorState",
    "augment",
    "fogm_length",
    "fogm_transition",
    "map_error_measurement",
    "map_error_state",
    "matched_state",
    "sogm_transition",
]

ORDERS = (1, 2)
"""Gauss–Markov orders of the map-error state."""
SOGM_MIN_SPEED = 0.01
"""Least speed (m/s) of a second-order state's ``β = speed / L``: at rest its rate's
prior ``β² σ²`` and noise were zero, a singular covariance that the UKF repaired (and
flagged) on every row; at 1 cm/s ``τ = L / speed`` is 12 days for L = 10 km."""


@pytree_dataclass
class MapErrorState:
    """The filters' map-error model: a Gauss–Markov state of σ (mGal) and length L (m).

    Build with :func:`map_error_state` (validates). ``sigma`` and ``length_m`` are
    pytree data; ``order`` is static.

    Attributes
    ----------
    sigma : Array, scalar
        Stationary standard deviation of the map error (mGal), ≥ 0.
    length_m : Array, scalar
        Correlation length over distance travelled (m), > 0.
    order : {1, 2}
        1: FOGM, one state, correlation ``e^{−r/L}``; 2: SOGM, two states (value,
        rate), correlation ``(1 + r/L) e^{−r/L}`` (static).
    """

    sigma: jnp.ndarray
    length_m: jnp.ndarray
    order: int = static_field(1)

    @property
    def n_states(self):
        """Number of filter states the map error adds (= ``order``)."""
        return self.order


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


def map_error_state(sigma, length_m, order=1):
    """A validated :class:`MapErrorState`.

    Parameters
    ----------
    sigma : float
        Map-error σ (mGal), finite, ≥ 0 (0: no map-error state, today's filters).
    length_m : float
        Correlation length L (m), finite, > 0.
    order : {1, 2}
        Gauss–Markov order: 1 FOGM (one state), 2 SOGM (value and rate).

    Returns
    -------
    MapErrorState

    Raises TypeError for a non-real or non-scalar value, ValueError for a negative σ,
    a non-positive L, NaN or inf (concrete values; traced ones pass), or an order
    other than 1 or 2.
    """
    _check(sigma, "map-error sigma", "mGal", True)
    _check(length_m, "map-error length_m", "m", False)
    if isinstance(order, bool) or order not in ORDERS:
        raise ValueError(f"map-error order must be 1 (FOGM) or 2 (SOGM); got {order!r}")
    dtype = jnp.result_type(float)
    return MapErrorState(jnp.asarray(sigma, dtype), jnp.asarray(length_m, dtype), int(order))


def matched_state(model, order=None):
    """The filter's map-error state matched to a map-error model.

    Parameters
    ----------
    model : CorrelatedMapError
        The map error's σ, L and family.
    order : {1, 2}, optional
        Default: the family's own order (``markov1`` → 1, ``markov2`` → 2), the
        exact match. Order 1 on a ``markov2`` model takes :func:`fogm_length`
        (2 L); order 2 always takes L.

    Returns
    -------
    MapErrorState
    """
    order = model.order if order is None else order
    length = fogm_length(model) if order == 1 else model.length_m
    return map_error_state(model.sigma, length, order)


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


def sogm_transition(sigma, length_m, speed, dt):
    """Exact discretisation of the SOGM (value, rate) over one step.

    Continuous model ``ẋ = A x + (0, 1)ᵀ w``, ``A = [[0, 1], [−β², −2β]]``,
    ``β = speed / length_m``, ``E w w = 4 β³ σ²``: stationary covariance
    ``P∞ = diag(σ², β² σ²)`` and autocorrelation ``(1 + β|t|) e^{−β|t|}`` of the value.

    Parameters
    ----------
    sigma : float or Array
        Stationary σ of the value (mGal).
    length_m : float or Array
        Correlation length over distance (m), > 0.
    speed : float or Array
        Speed over ground (m/s), > 0.
    dt : float or Array
        Step (s).

    Returns
    -------
    phi : Array, shape ``(2, 2)``
        ``exp(A Δt) = e^{−βΔt} [[1 + βΔt, Δt], [−β²Δt, 1 − βΔt]]``.
    q : Array, shape ``(2, 2)``
        ``P∞ − Φ P∞ Φᵀ`` (mGal², mGal²/s, mGal²/s²), the exact process noise, in
        closed form with ``a = βΔt``: ``σ² (1 − e^{−2a}(1 + 2a + 2a²))`` (a series
        below ``a = 0.1``: the difference loses ``(βΔt)⁻²`` digits, 28 % of ``Q₀₀``
        in float32 at 10 s steps and an indefinite ``Q`` at 2 s),
        ``2σ²β a² e^{−2a}`` and ``β²σ² (1 − e^{−2a}(1 − 2a + 2a²))``.
    """
    beta = jnp.asarray(speed) / jnp.asarray(length_m)
    dt = jnp.asarray(dt)
    bt = beta * dt
    e = jnp.exp(-bt)
    phi = e * jnp.stack([jnp.stack([1.0 + bt, dt]),
                         jnp.stack([-beta * bt, 1.0 - bt])])
    s2 = jnp.square(sigma)
    e2 = jnp.square(e)
    small = bt < 0.1
    a = jnp.where(small, bt, 0.0)  # the series' argument (the other branch's is unused)
    series = a**3 * jnp.polyval(jnp.asarray(_Q00_SERIES[::-1], a.dtype), a)
    q00 = s2 * jnp.where(small, series, 1.0 - e2 * (1.0 + 2.0 * bt + 2.0 * bt**2))
    q01 = 2.0 * s2 * beta * bt**2 * e2
    q11 = jnp.square(beta) * s2 * (-jnp.expm1(-2.0 * bt) + 2.0 * bt * (1.0 - bt) * e2)
    return phi, jnp.stack([jnp.stack([q00, q01]), jnp.stack([q01, q11])])


_Q00_SERIES = (4 / 3, -2.0, 8 / 5, -8 / 9, 8 / 21, -2 / 15, 16 / 405, -16 / 1575, 8 / 3465,
               -4 / 8505, 16 / 184275)
"""``(1 − e^{−2a}(1 + 2a + 2a²)) / a³ = Σ cₖ aᵏ``, k = 0 … 10 (exact to 1e-16 below
a = 0.1)."""


def _transition(config, speed, dt):
    """``(Φ, Q, P∞)`` of the map-error block, shapes ``(m, m)`` with ``m = config.order``."""
    s2 = jnp.square(config.sigma)
    if config.order == 1:
        phi, q = fogm_transition(config.sigma, config.length_m, speed, dt)
        return phi[None, None], q[None, None], s2[None, None]
    speed = jnp.maximum(speed, SOGM_MIN_SPEED)  # at rest the rate's prior was singular
    phi, q = sogm_transition(config.sigma, config.length_m, speed, dt)
    beta = jnp.asarray(speed) / jnp.asarray(config.length_m)
    return phi, q, jnp.diag(jnp.stack([s2, jnp.square(beta) * s2]))


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
    """Append the map-error state(s) to a filter's dynamics, prior and measurement.

    Parameters
    ----------
    config : MapErrorState or None
        None or a concrete σ = 0: everything returned unchanged (today's filter).
    dynamics : Dynamics
        ``f``, ``q`` of shape ``(n, n)``; ``dt`` (s) must be set.
    x0 : Array, shape ``(n,)``
    p0 : Array, shape ``(n, n)``
    speed : float or Array
        Speed over ground (m/s) for ``τ = L / speed``; finite and ≥ 0 (0: a platform at
        rest, whose map error stays what it is; order 2 takes at least
        :data:`SOGM_MIN_SPEED`). A concrete bad value is a ValueError.
    measurement : MapPlusBias
        The measurement to extend.

    Returns
    -------
    dynamics : Dynamics
        ``(n + m, n + m)`` (``m = config.order``) block-diagonal with ``Φ`` and ``Q_m``
        (:func:`fogm_transition` or :func:`sogm_transition`).
    x0 : Array, shape ``(n + m,)``
        The map error's prior mean 0.
    p0 : Array, shape ``(n + m, n + m)``
        Its prior covariance, the stationary one (σ²; SOGM ``diag(σ², β² σ²)``).
    measurement : MapPlusBias
        ``measurement`` plus the value state, index ``n`` (:func:`map_error_measurement`);
        the SOGM's rate (index ``n + 1``) does not enter the reading.
    """
    if _is_off(config):
        return dynamics, x0, p0, measurement
    if not isinstance(config, MapErrorState):
        raise TypeError(f"config must be a MapErrorState (map_error_state(...)) or None; got "
                        f"{type(config).__name__}")
    if dynamics.dt is None:
        raise ValueError("augment needs dynamics.dt (the step, s) to discretise the FOGM")
    v = concrete(speed)
    if v is not None and v.dtype != object and not np.all(np.isfinite(v) & (v >= 0)):
        raise ValueError(f"speed must be a finite number >= 0 (m/s, the map error's time "
                         f"constant is L / speed); got {v.tolist()}")
    n = dynamics.f.shape[0]
    m = config.order
    phi, qm, p_inf = _transition(config, speed, dynamics.dt)
    dtype = dynamics.f.dtype
    z = jnp.zeros((n + m, n + m), dtype)
    f = z.at[:n, :n].set(dynamics.f).at[n:, n:].set(phi)
    q = z.at[:n, :n].set(dynamics.q).at[n:, n:].set(qm)
    x0 = jnp.concatenate([jnp.asarray(x0, dtype), jnp.zeros(m, dtype)])
    p0 = z.at[:n, :n].set(p0).at[n:, n:].set(p_inf)
    return Dynamics(f, q, dynamics.dt), x0, p0, map_error_measurement(measurement, n)
