"""Sampling-importance-resampling (SIR) particle filter for the gravity/INS problem.

The particles carry the whole error state (``N × n``: position, velocity, attitude,
sensor biases, gravimeter bias, and the map-error state if :func:`augment` added one).
Each step they move with the INS error model, ``xᵢ ← F xᵢ + wᵢ``, ``wᵢ ~ N(0, Q)`` (a
noise-free state, e.g. a random-constant gyro bias, gets no noise: ``Q``'s factor is
semi-definite); a reading multiplies each weight by ``N(z; h(xᵢ) + h_lin · xᵢ, r)``
(the measurement of :mod:`jaxgrav.filters.model`, any callable). When the effective
sample size falls below ``ess_threshold · N`` the particles are resampled
(:data:`~jaxgrav.filters.particles.RESAMPLERS`) and roughened
(:func:`~jaxgrav.filters.particles.roughen`). The filter is an ``init`` / ``update`` /
``predict`` triple (:class:`~jaxgrav.filters.model.Filter`) run by
:func:`~jaxgrav.filters.run_filter` like the Kalman filters; its state carries its
PRNG key, so a run is reproducible from the key given to ``init``.

Its :class:`~jaxgrav.filters.model.StepInfo` is the weighted posterior mean and
covariance; the innovation is the reading minus the predicted mean reading, its
variance the particles' spread of predicted readings plus ``r``. Status flags as the
UKF's: a missing reading, every particle off the map (``off_map``), a gated innovation
or a non-positive reading variance (``covariance_failed``) skip the weighting. A particle
off the map or on a missing node while others are on it takes their mean likelihood (it
neither gains nor loses weight against them, as the point-mass filter's unknown cells),
and the reading's moments are the others'; ``off_map`` is flagged.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._linalg import psd_sqrt
from jaxgrav.filters.model import Filter, StepInfo, gravity_measurement
from jaxgrav.filters.particle_reading import (
    particle_flags,
    prediction_flags,
    weigh_reading,
)
from jaxgrav.filters.particles import (
    check_particle_settings,
    particle_summary,
    resample_regularised,
    standard_normal,
)

__all__ = ["ParticleState", "pf"]


class ParticleState(NamedTuple):
    """SIR particle filter state.

    Attributes
    ----------
    particles : Array, shape ``(N, n)``
        Error-state particles.
    log_w : Array, shape ``(N,)``
        Normalised log-weights.
    key : PRNG key
        Consumed and replaced every step.
    """

    particles: jax.Array
    log_w: jax.Array
    key: jax.Array


def pf(n_particles=1000, measurement=gravity_measurement, *, resample="systematic",
       ess_threshold=0.5, roughening=0.5, gate=jnp.inf):
    """SIR particle filter with effective-sample-size-triggered resampling.

    Parameters
    ----------
    n_particles : int
        Particles ``N`` (static).
    measurement : callable
        ``h(field, x, lat, lon) -> ẑ`` (mGal); default
        :data:`~jaxgrav.filters.gravity_measurement`.
    resample : {"systematic", "residual"}
    ess_threshold : float
        Resample after a reading when the effective sample size is below this share
        of ``N`` (0: never, 1: every reading).
    roughening : float
        The regularisation kernel's bandwidth after each resampling
        (:func:`~jaxgrav.filters.particles.roughen`) as a share of the optimal one
        (:func:`~jaxgrav.filters.particles.kernel_bandwidth`), in ``[0, 1]``; 0: off.
        With ``N = 1000`` and 13 states the optimal bandwidth is 0.62.
    gate : float
        Skip readings whose normalised innovation squared exceeds this.

    Returns
    -------
    Filter
        ``init(x0, P0, key=None)`` (``key`` default ``PRNGKey(0)``; particles drawn
        from ``N(x0, P0)`` with equal weights), ``update`` and ``predict`` with the
        Kalman filters' signature, returning :class:`ParticleState`.

    Raises
    ------
    ValueError
        Bad settings (:func:`check_particle_settings`).
    """
    resampler = check_particle_settings(n_particles, resample, ess_threshold, roughening)

    def init(x0, p0, key=None):
        key = jax.random.PRNGKey(0) if key is None else key
        x0, p0 = jnp.asarray(x0), jnp.asarray(p0)
        key, sub = jax.random.split(key)
        eps = standard_normal(sub, (n_particles, x0.shape[0]), p0.dtype)
        log_w = jnp.full(n_particles, -jnp.log(n_particles), p0.dtype)
        return ParticleState(x0 + eps @ psd_sqrt(p0).T, log_w, key)

    def _move(state, dynamics):
        key, sub = jax.random.split(state.key)
        eps = standard_normal(sub, state.particles.shape, state.particles.dtype)
        moved = state.particles @ dynamics.f.T + eps @ psd_sqrt(dynamics.q).T
        return ParticleState(moved, state.log_w, key)

    def _info(state, nu, s, flags):
        mean, sigma, p_pos = particle_summary(state.log_w, state.particles)
        return StepInfo(mean, sigma, p_pos, nu, s, flags)

    def predict(state, step, field, dynamics):
        del field
        state = _move(state, dynamics)
        nan = jnp.full_like(step.z, jnp.nan)
        return state, _info(state, nan, nan, prediction_flags(step.z))

    def update(state, step, field, dynamics):
        state = _move(state, dynamics)
        x = state.particles
        zs = jax.vmap(lambda xi: measurement(field, xi, step.lat, step.lon))(x)
        if step.h_lin is not None:
            zs = zs + x @ step.h_lin
        wr = weigh_reading(state.log_w, zs, step.r, step.z)
        flags, skip = particle_flags(step.z, step.r, wr.s, wr.nu, gate, wr.known)
        log_w = jnp.where(skip, state.log_w, wr.log_w)
        weighted = ParticleState(x, log_w, state.key)
        nu_out = jnp.where(jnp.isfinite(step.z) & ~wr.none_known, wr.nu, jnp.nan)
        info = _info(weighted, nu_out, wr.s, flags)  # the posterior, before resampling
        return resample_if_degenerate(weighted), info

    def resample_if_degenerate(state):
        key, k_idx, k_rough = jax.random.split(state.key, 3)
        x, log_w = resample_regularised((k_idx, k_rough), state.log_w, state.particles, resampler,
                                        roughening, ess_threshold)
        return ParticleState(x, log_w, key)

    return Filter(init, update, predict)
