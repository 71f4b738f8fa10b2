"""Rao–Blackwellised (marginalised) particle filter: particles in position, Kalman elsewhere.

The gravity reading is non-linear only in the horizontal position error; it is linear
in every other state (the gravimeter bias, the map-error state, the Eötvös error of the
velocity through :attr:`~jaxgrav.filters.model.Step.h_lin`), and the INS error model is
linear. So the marginalised particle filter (Schön, Gustafsson & Nordlund 2005; the
filter of MagNav.jl and of terrain-aided navigation) carries particles ``ξᵢ`` over the
position error (north, east; ``N × 2``) and, per particle, the Gaussian of the other
``n − 2`` states given that particle's position history: a mean ``mᵢ`` and a
covariance ``P``.

Both the reading's linear part ``C`` (the bias and map-error rows, plus ``h_lin``)
and the dynamics ``F``, ``Q`` are the same for every particle, so the Riccati recursion
of ``P`` does not depend on the particle: ``P`` is **one** ``(n − 2) × (n − 2)`` matrix
shared by all particles, and a particle costs a mean update only. Per step:

* **time update** — for each particle the next state is Gaussian,
  ``μᵢ = F[:, pos] ξᵢ + F[:, lin] mᵢ``, ``Σ = F[:, lin] P F[:, lin]ᵀ + Q``; the new
  position is drawn from its position block, ``ξᵢ' ~ N(μᵢ[pos], Σ_pp)``, and the
  linear states are conditioned on it: ``mᵢ' = μᵢ[lin] + G (ξᵢ' − μᵢ[pos])``,
  ``P' = Σ_ll − G Σ_pl`` with ``G = Σ_lp Σ_pp⁻¹`` (the "measurement" of the linear
  states by the sampled position step);
* **reading** — ``ẑᵢ = map(ξᵢ) + h_lin[pos] · ξᵢ + C · mᵢ``, ``s = C P Cᵀ + r``;
  weights ``× N(z; ẑᵢ, s)``, means ``mᵢ += K (z − ẑᵢ)`` with one gain ``K = P Cᵀ / s``,
  ``P −= s K Kᵀ``;
* **resampling** when the effective sample size is low, positions and means together,
  then a moment-preserving regularisation of both (:mod:`jaxgrav.filters.particles`):
  the position noise of the INS model is tiny, so each particle's velocity is pinned by
  its own trajectory and resampled copies must be spread in it too.

The measurement must be a :class:`~jaxgrav.filters.model.MapPlusBias` with two
position states (the default :data:`~jaxgrav.filters.gravity_measurement`, with or
without :func:`~jaxgrav.filters.augment`'s map-error state). The reported state is the
mixture's mean and covariance (``P`` plus the spread of the means); flags as
:func:`~jaxgrav.filters.pf`'s. A particle off the map or on a missing node while others
are on it takes their mean likelihood and keeps its mean (the reading says nothing about
its linear states without a map value); the shared ``P`` then shrinks by the posterior
weight share of the particles that have one. The reading is skipped (``off_map``) only
when no particle has a map value.
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav._linalg import inv_2x2, psd_sqrt
from jaxgrav._validate import concrete
from jaxgrav.filters.model import (
    Filter,
    MapPlusBias,
    StepInfo,
    gravity_measurement,
)
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

__all__ = ["RBPFState", "rbpf"]

_POS = 2  # position states, first in the error state


class RBPFState(NamedTuple):
    """Marginalised particle filter state.

    Attributes
    ----------
    position : Array, shape ``(N, 2)``
        Position-error particles (m, north/east).
    mean : Array, shape ``(N, n − 2)``
        Each particle's mean of the other states.
    p : Array, shape ``(n − 2, n − 2)``
        Their covariance, shared by all particles.
    log_w : Array, shape ``(N,)``
        Normalised log-weights.
    key : PRNG key
    """

    position: jax.Array
    mean: jax.Array
    p: jax.Array
    log_w: jax.Array
    key: jax.Array


def _condition(mean, cov, pos):
    """Gaussian ``N(mean, cov)`` over ``n`` states conditioned on its first two at ``pos``.

    ``mean`` (N, n) or (n,), ``pos`` (N, 2); returns the linear states' means
    ``(N, n − 2)`` and their covariance.

    The position block is regularised by a relative ``1e-9`` of its trace before it is
    inverted: the INS model's position noise is tiny (``Q_pp`` ~ 1e-7 m² per 10 s), so
    after a few steps each particle's velocity is pinned by its own trajectory and the
    block is near singular; rounding then must not flip its sign.
    """
    s_pp, s_lp = _position_block(cov), cov[_POS:, :_POS]
    gain = s_lp @ inv_2x2(s_pp)
    m = mean[..., _POS:] + (pos - mean[..., :_POS]) @ gain.T
    p = cov[_POS:, _POS:] - gain @ s_lp.T
    return m, 0.5 * (p + p.T)


def _position_block(cov):
    """The symmetrised, ridge-regularised position block of a covariance (m²)."""
    s_pp = 0.5 * (cov[:_POS, :_POS] + cov[:_POS, :_POS].T)
    ridge = 1e-9 * jnp.trace(s_pp) + jnp.finfo(cov.dtype).tiny
    return s_pp + ridge * jnp.eye(_POS, dtype=cov.dtype)


def rbpf(n_particles=500, measurement=gravity_measurement, *, resample="systematic",
         ess_threshold=0.5, roughening=1.0, gate=jnp.inf, q_pos=0.0):
    """Rao–Blackwellised particle filter over the position error.

    Parameters
    ----------
    n_particles : int
        Particles ``N`` (static).
    measurement : MapPlusBias
        With ``n_position = 2``; default :data:`~jaxgrav.filters.gravity_measurement`.
    resample : {"systematic", "residual"}
    ess_threshold : float
        Resample after a reading when the effective sample size is below this share
        of ``N``.
    roughening : float
        The regularisation kernel's bandwidth after each resampling
        (:func:`~jaxgrav.filters.particles.roughen`, applied to the positions and the
        per-particle means together) as a share of the optimal one
        (:func:`~jaxgrav.filters.particles.kernel_bandwidth` with ``d = n``), in
        ``[0, 1]``; 0: off. Default 1 (on paper D's scenario, 200 runs: mean ratio
        0.464 against 0.468 at 0.5 and 0.483 with the positions alone roughened at 0.5).
    gate : float
        Skip readings whose normalised innovation squared exceeds this.
    q_pos : float or Array
        An extra random walk of each particle's position error (m²/s per axis), added to
        the step's position noise before the draw, as the point-mass filter's ``q_pos``:
        the INS model's own position noise is tiny, so a particle's velocity is pinned
        by its own trajectory and a cloud that lost the truth on a flat stretch may not
        find it again. Default 0 (none); needs :attr:`Dynamics.dt` when not 0.

    Returns
    -------
    Filter
        ``init(x0, P0, key=None)`` (``key`` default ``PRNGKey(0)``: positions drawn from
        the prior's position block, each particle's other states conditioned on it),
        ``update`` and ``predict`` as the Kalman filters', returning
        :class:`RBPFState`.

    Raises
    ------
    ValueError
        Bad settings; a measurement that is not a MapPlusBias with two position states.
    """
    resampler = check_particle_settings(n_particles, resample, ess_threshold, roughening)
    q_value = concrete(q_pos)
    if q_value is not None and not (math.isfinite(float(q_value)) and float(q_value) >= 0.0):
        raise ValueError(f"q_pos must be a finite number >= 0 (m^2/s); got {q_pos!r}")
    no_walk = q_value is not None and float(q_value) == 0.0
    if not isinstance(measurement, MapPlusBias) or measurement.n_position != _POS:
        raise ValueError("rbpf needs a MapPlusBias measurement with n_position=2 (the map part "
                         "non-linear in the position error only, the rest additive); got "
                         f"{measurement!r}")

    def init(x0, p0, key=None):
        key = jax.random.PRNGKey(0) if key is None else key
        x0, p0 = jnp.asarray(x0), jnp.asarray(p0)
        key, sub = jax.random.split(key)
        eps = standard_normal(sub, (n_particles, _POS), p0.dtype)
        pos = x0[:_POS] + eps @ psd_sqrt(_position_block(p0)).T
        m, p = _condition(x0, p0, pos)
        log_w = jnp.full(n_particles, -jnp.log(n_particles), p0.dtype)
        return RBPFState(pos, m, p, log_w, key)

    def _move(state, dynamics):
        f, q = dynamics.f, dynamics.q
        f_pos, f_lin = f[:, :_POS], f[:, _POS:]
        mu = state.position @ f_pos.T + state.mean @ f_lin.T  # (N, n)
        cov = f_lin @ state.p @ f_lin.T + q
        cov = 0.5 * (cov + cov.T)
        if not no_walk:
            if dynamics.dt is None:
                raise ValueError("rbpf's q_pos needs the step length: Dynamics(f, q, dt)")
            cov = cov.at[:_POS, :_POS].add(q_pos * dynamics.dt * jnp.eye(_POS, dtype=cov.dtype))
        key, sub = jax.random.split(state.key)
        eps = standard_normal(sub, state.position.shape, state.position.dtype)
        pos = mu[:, :_POS] + eps @ psd_sqrt(_position_block(cov)).T
        m, p = _condition(mu, cov, pos)
        return RBPFState(pos, m, p, state.log_w, key)

    def _linear_row(step, mean):
        """``C`` over the linear states and the position part of ``h_lin``."""
        additive = [i - _POS for i in measurement.additive]
        c = jnp.zeros(mean.shape[1], mean.dtype).at[jnp.asarray(additive)].set(1.0)
        if step.h_lin is None:
            return c, jnp.zeros(_POS, c.dtype)
        return c + step.h_lin[_POS:], step.h_lin[:_POS]

    def _info(state, nu, s, flags):
        extra = jnp.concatenate([jnp.zeros(_POS, state.p.dtype), jnp.diag(state.p)])
        mean, sigma, p_pos = particle_summary(state.log_w, (state.position, state.mean), extra)
        return StepInfo(mean, sigma, p_pos, nu, s, flags)

    def predict(state, step, field, dynamics):
        del field
        state = _move(state, dynamics)
        nan = jnp.full_like(step.z, jnp.nan)
        return state, _info(state, nan, nan, prediction_flags(step.z))

    def update(state, step, field, dynamics):
        state = _move(state, dynamics)
        c, c_pos = _linear_row(step, state.mean)
        g = jax.vmap(lambda d: measurement.map_part(field, d, step.lat, step.lon))(state.position)
        # the map reading and the linear part as one dot of two columns, so the map
        # reading is a dot operand, computed once: summed element-wise, XLA fused its
        # trigonometry into each consumer (19 times per step; with the elemental emitters
        # once per element of the (N, n) means update). Not one (N, n + 1) row per
        # particle: XLA's elemental emitters join such a concatenation element by
        # element, several times slower than the fusion emitters
        lin = state.position @ c_pos + state.mean @ c
        zs = jnp.stack([g, lin], axis=1) @ jnp.ones(2, c.dtype)
        pc = state.p @ c
        s_lin = c @ pc + step.r  # each particle's innovation variance
        wr = weigh_reading(state.log_w, zs, s_lin, step.z)
        flags, skip = particle_flags(step.z, s_lin, wr.s, wr.nu, gate, wr.known)
        s_safe = jnp.where(s_lin > 0.0, s_lin, 1.0)
        gain = pc / s_safe
        # a particle without a map value learns nothing from the reading: its mean stays;
        # the shared covariance shrinks by the posterior share of those that learn (the
        # mixture's mean conditional covariance). A skipped reading moves no mean: zero
        # innovations and gain (one select per particle and per state, not per element)
        innovation = jnp.where(wr.known & ~skip, wr.z - wr.zs, 0.0)
        mean = state.mean + innovation[:, None] * jnp.where(skip, 0.0, gain)
        share = jnp.where(jnp.all(wr.known), 1.0, jnp.exp(wr.log_w) @ wr.known)
        p = state.p - share * s_safe * jnp.outer(gain, gain)
        new = RBPFState(state.position, mean,
                        jnp.where(skip, state.p, 0.5 * (p + p.T)),
                        jnp.where(skip, state.log_w, wr.log_w), state.key)
        nu_out = jnp.where(jnp.isfinite(step.z) & ~wr.none_known, wr.nu, jnp.nan)
        info = _info(new, nu_out, wr.s, flags)  # the posterior, before resampling
        return resample_if_degenerate(new), info

    def resample_if_degenerate(state):
        key, k_idx, k_rough = jax.random.split(state.key, 3)
        # the positions and the means together: each particle's velocity (and tilt …) is
        # pinned by its own trajectory (the position noise is tiny), so copies must be
        # spread in those too, or the cloud loses its velocity diversity
        (pos, mean), log_w = resample_regularised((k_idx, k_rough), state.log_w,
                                                  (state.position, state.mean), resampler,
                                                  roughening, ess_threshold)
        return RBPFState(pos, mean, state.p, log_w, key)

    return Filter(init, update, predict)
