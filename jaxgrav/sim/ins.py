"""INS error model: Schuler-coupled error states, exact discretisation, simulation.

One linear error model serves both the simulator and the filters of paper D
(:mod:`jaxgrav.filters`). The state is the psi-angle error model of a
local-level (north–east–down) strapdown INS, linearised about a slow vehicle
(transport-rate terms of the vehicle speed are dropped: at 5 m/s they are 1e-6
rad/s against Ω = 7.3e-5 rad/s), plus Gauss–Markov sensor errors and the
gravimeter's systematic error δg_a:

====  =========  ======================================================  ======
index name       meaning                                                  unit
====  =========  ======================================================  ======
0, 1  d_n, d_e   position error north, east (INS − true)                  m
2, 3  dv_n, dv_e velocity error north, east                               m/s
4-6   phi        attitude error north, east (tilt), down (heading)        rad
7-9   gyro       gyro bias north, east, down                              rad/s
10-11 accel      accelerometer bias north, east                           m/s²
12    grav       gravimeter systematic error δg_a                         mGal
====  =========  ======================================================  ======

Continuous dynamics ``ẋ = A x + w`` (Titterton & Weston, ch. 12, stationary form):

    ḋ_n = dv_n,  ḋ_e = dv_e
    dv̇_n = g φ_e − 2Ω sinφ dv_e + ∇_n,   dv̇_e = −g φ_n + 2Ω sinφ dv_n + ∇_e
    φ̇_n =  dv_e / R − Ω sinφ φ_e − ε_n
    φ̇_e = −dv_n / R + Ω sinφ φ_n + Ω cosφ φ_d − ε_e
    φ̇_d = −Ω cosφ φ_e − ε_d
    ε̇ = −ε/τ_g + w_g,  ∇̇ = −∇/τ_a + w_a,  δġ_a = −δg_a/τ_b + w_b

so that position and velocity oscillate at the Schuler period 2π√(R/g) ≈ 84 min.
It is discretised exactly (Van Loan's matrix exponential), which gives each
Gauss–Markov state the exact variance growth ``σ²(1 − e^{−2Δt/τ})`` rather than the
Euler shortcut ``2σ²Δt/τ``; ``τ = inf`` makes a random constant.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._linalg import expm, psd_sqrt
from jaxgrav.constants import DEG, EARTH_RATE, MGAL, WGS84_MEAN_RADIUS
from jaxgrav.geodesy import normal_gravity

__all__ = [
    "ACCEL",
    "ATT",
    "GRAV",
    "GYRO",
    "N_STATES",
    "POS",
    "VEL",
    "INSErrorModel",
    "continuous_model",
    "initial_covariance",
    "sample_initial_error",
    "simulate_errors",
    "transition",
]

N_STATES = 13
POS = slice(0, 2)
VEL = slice(2, 4)
ATT = slice(4, 7)
GYRO = slice(7, 10)
ACCEL = slice(10, 12)
GRAV = 12

_DEG_PER_HOUR = DEG / 3600.0
_MICRO_G = 9.80665e-6


class INSErrorModel(NamedTuple):
    """Sensor error parameters of the INS and the gravimeter (all scalars, sweepable).

    The defaults are a navigation-grade marine INS (0.001 °/h gyros, 10 µg
    accelerometers, 1 h correlation time) and a marine gravimeter whose
    systematic error is a 1 mGal random constant (paper D's setting).

    Attributes
    ----------
    gyro_sigma : float
        Steady-state σ of each gyro bias (rad/s).
    gyro_tau : float
        Gyro-bias correlation time (s); ``inf`` for a random constant.
    accel_sigma : float
        Steady-state σ of each accelerometer bias (m/s²).
    accel_tau : float
        Accelerometer-bias correlation time (s).
    gravimeter_sigma : float
        σ of the gravimeter systematic error δg_a (mGal).
    gravimeter_tau : float
        Its correlation time (s); ``inf`` for a random constant.
    velocity_noise : float
        Velocity random walk of the accelerometers (m/s/√s).
    angle_noise : float
        Angle random walk of the gyros (rad/√s).
    """

    gyro_sigma: float = 0.001 * _DEG_PER_HOUR
    gyro_tau: float = 3600.0
    accel_sigma: float = 10.0 * _MICRO_G
    accel_tau: float = 3600.0
    gravimeter_sigma: float = 1.0
    gravimeter_tau: float = float("inf")
    velocity_noise: float = 1.0e-5
    angle_noise: float = 1.0e-4 * DEG / 60.0


def _gm_rate_and_density(sigma, tau):
    """Continuous decay rate 1/τ and white-noise density 2σ²/τ (0 for τ = inf)."""
    tau = jnp.asarray(tau, dtype=float)
    finite = jnp.isfinite(tau)
    safe_tau = jnp.where(finite, tau, 1.0)
    rate = jnp.where(finite, 1.0 / safe_tau, 0.0)
    density = jnp.where(finite, 2.0 * jnp.square(sigma) / safe_tau, 0.0)
    return rate, density


def continuous_model(model, lat_deg):
    """Continuous-time error dynamics ``ẋ = A x + w``, ``E[w wᵀ] = Q_c δ(t)``.

    Parameters
    ----------
    model : INSErrorModel
    lat_deg : float
        Latitude of the coupling terms (degrees).

    Returns
    -------
    A, Q_c : Array, shape ``(13, 13)``
        Dynamics matrix (1/s) and white-noise spectral density (state units²/s).
    """
    phi = jnp.asarray(lat_deg, dtype=float) * DEG
    g = normal_gravity(lat_deg) * MGAL  # m/s²
    r = WGS84_MEAN_RADIUS
    ws, wc = EARTH_RATE * jnp.sin(phi), EARTH_RATE * jnp.cos(phi)
    a = jnp.zeros((N_STATES, N_STATES))
    entries = [
        (0, 2, 1.0), (1, 3, 1.0),
        (2, 5, g), (2, 3, -2.0 * ws), (2, 10, 1.0),
        (3, 4, -g), (3, 2, 2.0 * ws), (3, 11, 1.0),
        (4, 3, 1.0 / r), (4, 5, -ws), (4, 7, -1.0),
        (5, 2, -1.0 / r), (5, 4, ws), (5, 6, wc), (5, 8, -1.0),
        (6, 5, -wc), (6, 9, -1.0),
    ]  # fmt: skip
    rows, cols, vals = zip(*entries, strict=True)
    a = a.at[jnp.array(rows), jnp.array(cols)].set(jnp.stack([jnp.asarray(v, float) for v in vals]))
    g_rate, g_q = _gm_rate_and_density(model.gyro_sigma, model.gyro_tau)
    a_rate, a_q = _gm_rate_and_density(model.accel_sigma, model.accel_tau)
    b_rate, b_q = _gm_rate_and_density(model.gravimeter_sigma, model.gravimeter_tau)
    decay = jnp.concatenate([jnp.zeros(7), jnp.full(3, g_rate), jnp.full(2, a_rate), b_rate[None]])
    a = a - jnp.diag(decay)
    qc = jnp.concatenate([
        jnp.zeros(2),
        jnp.full(2, jnp.square(model.velocity_noise)),
        jnp.full(3, jnp.square(model.angle_noise)),
        jnp.full(3, g_q), jnp.full(2, a_q), b_q[None],
    ])  # fmt: skip
    return a, jnp.diag(qc)


def transition(model, lat_deg, dt):
    """Exact discrete transition ``x_{k+1} = F x_k + w_k``, ``w_k ~ N(0, Q)``.

    Van Loan's method: the exponential of ``[[−A, Q_c], [0, Aᵀ]] Δt``.

    Parameters
    ----------
    model : INSErrorModel
    lat_deg : float
        Latitude of the coupling terms (degrees).
    dt : float
        Step (s).

    Returns
    -------
    F, Q : Array, shape ``(13, 13)``
        ``Q`` is symmetrised.
    """
    a, qc = continuous_model(model, lat_deg)
    n = N_STATES
    block = jnp.block([[-a, qc], [jnp.zeros((n, n)), a.T]]) * dt
    e = expm(block)
    f = e[n:, n:].T
    q = f @ e[:n, n:]
    return f, 0.5 * (q + q.T)


def initial_covariance(model, sigma_pos=1414.2, sigma_vel=0.1414,
                       sigma_tilt=2.0 / 3600.0 * DEG, sigma_heading=0.004 * DEG):
    """Diagonal initial error covariance.

    Parameters
    ----------
    model : INSErrorModel
        Sensor biases start at their steady-state σ.
    sigma_pos : float
        1-σ position error per axis (m); default gives 2 km RMS radial error.
    sigma_vel : float
        1-σ velocity error per axis (m/s); default 0.2 m/s RMS.
    sigma_tilt, sigma_heading : float
        1-σ attitude errors (rad).

    Returns
    -------
    Array, shape ``(13, 13)``
    """
    sd = jnp.concatenate([
        jnp.full(2, sigma_pos), jnp.full(2, sigma_vel), jnp.full(2, sigma_tilt),
        jnp.atleast_1d(sigma_heading), jnp.full(3, model.gyro_sigma),
        jnp.full(2, model.accel_sigma), jnp.atleast_1d(model.gravimeter_sigma),
    ]).astype(float)  # fmt: skip
    return jnp.diag(jnp.square(sd))


def sample_initial_error(key, model, pos_error=2000.0, vel_error=0.2, sigma_tilt=2.0 / 3600.0 * DEG,
                         sigma_heading=0.004 * DEG):
    """One initial error state: position and velocity errors of fixed size, random direction.

    Paper D's "2 km initial position error and 0.2 m/s velocity error" read as sizes:
    each run's errors have exactly these magnitudes in a uniformly random direction,
    so that every run starts equally far from the truth. Attitude and sensor errors
    are Gaussian with the model's σ.

    Parameters
    ----------
    key : PRNG key
    model : INSErrorModel
    pos_error : float
        Size of the horizontal position error (m).
    vel_error : float
        Size of the horizontal velocity error (m/s).
    sigma_tilt, sigma_heading : float
        1-σ attitude errors (rad).

    Returns
    -------
    Array, shape ``(13,)``
    """
    k_pos, k_vel, k_rest = jax.random.split(key, 3)
    a_pos = jax.random.uniform(k_pos, (), minval=0.0, maxval=2.0 * jnp.pi)
    a_vel = jax.random.uniform(k_vel, (), minval=0.0, maxval=2.0 * jnp.pi)
    p0 = initial_covariance(model, 0.0, 0.0, sigma_tilt, sigma_heading)
    rest = jax.random.normal(k_rest, (N_STATES,)) * jnp.sqrt(jnp.diag(p0))
    x0 = rest.at[0].set(pos_error * jnp.cos(a_pos)).at[1].set(pos_error * jnp.sin(a_pos))
    return x0.at[2].set(vel_error * jnp.cos(a_vel)).at[3].set(vel_error * jnp.sin(a_vel))


def simulate_errors(key, f, q, x0, n_steps):
    """Propagate the error state through ``n_steps`` steps with process noise.

    Parameters
    ----------
    key : PRNG key
    f, q : Array, shape ``(13, 13)``
        From :func:`transition`.
    x0 : Array, shape ``(13,)``
        Initial error.
    n_steps : int
        Number of states returned (static), including ``x0``.

    Returns
    -------
    Array, shape ``(n_steps, 13)``
        Error states at each step; the INS indicates truth + error.
    """
    root = psd_sqrt(q)  # Q is only semi-definite (no noise enters position directly)
    noise = jax.random.normal(key, (n_steps - 1, N_STATES)) @ root.T

    def step(x, w):
        x = f @ x + w
        return x, x

    _, xs = jax.lax.scan(step, x0, noise)
    return jnp.concatenate([x0[None], xs])
