"""Gaussian-sum filter: a bank of UKFs (or EKFs) over a grid of initial position errors.

A 2 km INS error over a smooth, weak anomaly makes the posterior multi-modal: on
paper D's mass line the field is even in the east error, so its sign cannot be
told until the track turns, and a single Gaussian filter then locks onto the mode
its linearisation happened to favour. The Gaussian sum (Alspach & Sorenson 1972)
splits the Gaussian prior of the position error into ``m × m`` narrower
components on a regular grid, runs one base filter per component (``vmap``) and
re-weights the components by the likelihood of each reading. The mixture keeps
every mode alive until the data decide; its mean and covariance are the estimate.

The split preserves the prior's mean and covariance: component means at
``k · spacing · σ`` (``k = −(m−1)/2 … (m−1)/2`` per axis) with Gaussian weights, and
component covariance ``σ² − Var(means)`` per axis.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.filters.model import (
    STATUS_FILTER,
    Filter,
    FilterState,
    StepInfo,
    predict_only,
)

__all__ = ["GaussianSumState", "gaussian_sum", "split_prior"]


class GaussianSumState(NamedTuple):
    """Mixture state: per-component :class:`FilterState` (leading axis M) and log-weights (M,)."""

    components: FilterState
    log_w: jax.Array


def split_prior(x0, p0, per_axis=5, spacing=0.8):
    """Split a Gaussian prior's position block into a grid of weighted components.

    Parameters
    ----------
    x0 : Array, shape ``(n,)``
    p0 : Array, shape ``(n, n)``
        Position block ``p0[:2, :2]`` must be diagonal.
    per_axis : int
        Components per axis ``m`` (static, odd).
    spacing : float
        Grid spacing in prior standard deviations; < 1 keeps the component
        covariance positive (``σ_c² = σ²(1 − Var_w(k) spacing²)``).

    Returns
    -------
    x : Array, shape ``(m², n)``
    p : Array, shape ``(m², n, n)``
    log_w : Array, shape ``(m²,)``
        Normalised log-weights.
    """
    k = jnp.arange(per_axis) - (per_axis - 1) / 2
    w1 = jnp.exp(-0.5 * (k * spacing) ** 2)
    w1 = w1 / w1.sum()
    var_k = jnp.sum(w1 * k**2) * spacing**2  # variance of the means, in units of σ²
    sd = jnp.sqrt(jnp.diag(p0)[:2])
    kn, ke = jnp.meshgrid(k, k, indexing="ij")
    offsets = jnp.stack([kn.ravel() * spacing * sd[0], ke.ravel() * spacing * sd[1]], -1)
    x = jnp.broadcast_to(x0, (per_axis**2, x0.shape[0])).at[:, :2].add(offsets)
    shrink = jnp.ones(x0.shape[0]).at[:2].set(jnp.sqrt(1.0 - var_k))
    p = jnp.broadcast_to(p0 * jnp.outer(shrink, shrink), (per_axis**2, *p0.shape))
    log_w = jnp.log(jnp.outer(w1, w1).ravel())
    return x, p, log_w


def gaussian_sum(base, per_axis=5, spacing=0.8):
    """A Gaussian-sum filter over a base filter.

    Parameters
    ----------
    base : Filter
        :func:`~jaxgrav.filters.kalman.ukf` or :func:`~jaxgrav.filters.kalman.ekf`.
    per_axis : int
        Components per position axis (static); ``per_axis²`` filters run.
    spacing : float
        Spacing of the component means (prior σ).

    Returns
    -------
    Filter
        ``init(x0, P0) -> GaussianSumState``; ``update`` returns the mixture's
        :class:`StepInfo` (mean, σ, position covariance, weighted innovation;
        status OR-ed over components); ``predict`` predicts every component (weights
        unchanged) for steps without a reading.
    """

    def init(x0, p0):
        x, p, log_w = split_prior(jnp.asarray(x0), jnp.asarray(p0), per_axis, spacing)
        return GaussianSumState(jax.vmap(base.init)(x, p), log_w)

    def mixture_info(comps, log_w, infos, step):
        w = jnp.exp(log_w)
        mean = w @ comps.x
        d = comps.x - mean
        cov = jnp.einsum("m,mi,mj->ij", w, d, d) + jnp.einsum("m,mij->ij", w, comps.p)
        sigma = jnp.sqrt(jnp.clip(jnp.diag(cov), 0.0, None))
        nu = infos.innovation
        return StepInfo(
            mean, sigma, cov[:2, :2], w @ jnp.where(jnp.isfinite(nu), nu, 0.0) + jnp.where(
                jnp.isfinite(step.z), 0.0, jnp.nan), w @ infos.innovation_var,
            jnp.bitwise_or.reduce(infos.status),
        )  # fmt: skip

    def update(state, step, field, dynamics):
        comps, infos = jax.vmap(base.update, in_axes=(0, None, None, None))(
            state.components, step, field, dynamics
        )
        nu, s = infos.innovation, infos.innovation_var
        skipped = STATUS_FILTER["off_map"] | STATUS_FILTER["covariance_failed"]
        skipped = skipped | STATUS_FILTER["gated"]
        used = jnp.isfinite(nu) & ((infos.status & skipped) == 0)
        loglik = jnp.where(used, -0.5 * (jnp.where(used, nu, 0.0) ** 2 / s + jnp.log(s)), 0.0)
        log_w = state.log_w + loglik
        log_w = log_w - jax.nn.logsumexp(log_w)
        return GaussianSumState(comps, log_w), mixture_info(comps, log_w, infos, step)

    base_predict = predict_only(base)

    def predict(state, step, field, dynamics):
        comps, infos = jax.vmap(base_predict, in_axes=(0, None, None, None))(
            state.components, step, field, dynamics
        )
        info = mixture_info(comps, state.log_w, infos, step)
        nan = jnp.full_like(info.innovation, jnp.nan)
        return GaussianSumState(comps, state.log_w), info._replace(innovation=nan,
                                                                   innovation_var=nan)

    return Filter(init, update, predict)
