"""A reading's weighting of particles, and the status it leaves.

Shared by the particle filters (:mod:`~jaxgrav.filters.pf`, :mod:`~jaxgrav.filters.rbpf`):
the predicted reading's moments over the particles, the log-weights after a reading when
some particles have no map value (off the map, or on a missing node), and the step's
status bits and skip decision (:data:`~jaxgrav.filters.model.STATUS_FILTER`).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.filters.model import STATUS_FILTER
from jaxgrav.filters.particles import normalise_log_weights

__all__ = [
    "Weighing",
    "particle_flags",
    "prediction_flags",
    "reading_moments",
    "weigh_reading",
]


def prediction_flags(z):
    """Status of a prediction-only step: ``no_reading``, plus ``reading_ignored`` if ``z``
    is finite (a reading off the update stride); int32."""
    flags = STATUS_FILTER["no_reading"] | jnp.where(
        jnp.isfinite(z), STATUS_FILTER["reading_ignored"], 0)
    return flags.astype(jnp.int32)


def reading_moments(log_w, zs, var, z):
    """The predicted reading of weighted particles and the innovation.

    Parameters
    ----------
    log_w : Array, shape ``(N,)``
    zs : Array, shape ``(N,)``
        Each particle's predicted reading (mGal; finite).
    var : Array, shape ``()``
        The reading variance about a particle's prediction (mGal²).
    z : Array, shape ``()``
        The reading (NaN: none).

    Returns
    -------
    s : Array, shape ``()``
        Innovation variance: the particles' spread of predictions plus ``var``.
    nu : Array, shape ``()``
        ``z − Σ wᵢ zsᵢ`` (0 without a reading).
    z_used : Array, shape ``()``
        ``z``, or the predicted mean where there is no reading.
    """
    w = jnp.exp(log_w)
    z_hat = w @ zs
    s = w @ (zs - z_hat) ** 2 + var
    z_used = jnp.where(jnp.isfinite(z), z, z_hat)
    return s, z_used - z_hat, z_used


class Weighing(NamedTuple):
    """A reading's weighting of particles, some of which may have no predicted reading.

    Attributes
    ----------
    log_w : Array, shape ``(N,)``
        Normalised log-weights after the reading.
    known : Array, shape ``(N,)``, bool
        The particle's predicted reading is finite (it has a map value).
    none_known : Array, shape ``()``, bool
        No particle has one: the reading cannot be used.
    zs : Array, shape ``(N,)``
        The predicted readings, 0 where not known.
    s, nu, z : Array, shape ``()``
        :func:`reading_moments` over the particles with a map value.
    """

    log_w: jax.Array
    known: jax.Array
    none_known: jax.Array
    zs: jax.Array
    s: jax.Array
    nu: jax.Array
    z: jax.Array


def weigh_reading(log_w, zs, var, z):
    """Weigh particles by a reading, those without a map value at the others' mean likelihood.

    A particle whose predicted reading is not finite (off the map, or on a missing
    node) takes the mean likelihood of the particles that have one, so the reading
    moves no weight between the two groups (as the point-mass filter's unknown cells);
    the reading's moments are those of the particles with a value (renormalised).

    Parameters
    ----------
    log_w : Array, shape ``(N,)``
        Normalised log-weights before the reading.
    zs : Array, shape ``(N,)``
        Each particle's predicted reading (mGal; NaN or inf: unknown).
    var : Array, shape ``()``
        The reading variance about a particle's prediction (mGal²); not positive: the
        weights are computed with 1 (the caller flags and skips the reading).
    z : Array, shape ``()``
        The reading (NaN: none).

    Returns
    -------
    Weighing
    """
    known = jnp.isfinite(zs)
    none_known = ~jnp.any(known)
    zs = jnp.where(known, zs, 0.0)  # double-where: no NaN into the weights
    lw_known = normalise_log_weights(jnp.where(known | none_known, log_w, -jnp.inf))
    s, nu, z_used = reading_moments(lw_known, zs, var, z)
    loglik = -0.5 * (z_used - zs) ** 2 / jnp.where(var > 0.0, var, 1.0)
    gap = jax.nn.logsumexp(jnp.where(known, lw_known + loglik, -jnp.inf))
    new = normalise_log_weights(log_w + jnp.where(known, loglik, gap))
    return Weighing(new, known, none_known, zs, s, nu, z_used)


def particle_flags(z, r, s, nu, gate, known):
    """Status bits and the skip decision of a particle filter's weighting.

    Parameters
    ----------
    z : Array, shape ``()``
        The reading (NaN: none).
    r : Array, shape ``()``
        Reading variance (mGal²); not positive: ``covariance_failed``.
    s, nu : Array, shape ``()``
        Predicted innovation variance and innovation, for the gate.
    gate : float
        Skip a reading whose ``ν² / s`` exceeds it.
    known : Array, shape ``(N,)``, bool
        The particle's predicted reading is finite (:attr:`Weighing.known`); ``off_map``
        is flagged when any is not, and the reading skipped when none is.

    Returns
    -------
    flags : Array, shape ``()``, int32
    skip : Array, shape ``()``, bool
    """
    no_reading = ~jnp.isfinite(z)
    off_map = ~jnp.any(known)
    failed = (~no_reading) & (~off_map) & ~(r > 0.0)
    gated = (~no_reading) & (~off_map) & (~failed) & (nu**2 > gate * s)
    flags = (
        jnp.where(no_reading, STATUS_FILTER["no_reading"], 0)
        | jnp.where(~jnp.all(known) & ~no_reading, STATUS_FILTER["off_map"], 0)
        | jnp.where(gated, STATUS_FILTER["gated"], 0)
        | jnp.where(failed, STATUS_FILTER["covariance_failed"], 0)
    )
    return flags.astype(jnp.int32), no_reading | off_map | gated | failed
