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
        :class:`StepInfo` (mean, σ, position covariance; the predicted reading's
        innovation and variance, mixed with the weights before the reading, the
        components' spread included, so the NIS of the mixture is that of its
        predictive distribution's first two moments; status OR-ed over components)
        and reweights every component by its reading's likelihood (a gated one
        too; one off the map as the least likely that was not); ``predict``
        predicts every component (weights unchanged) for steps without a reading.
    """

    def init(x0, p0):
        x, p, log_w = split_prior(jnp.asarray(x0), jnp.asarray(p0), per_axis, spacing)
        return GaussianSumState(jax.vmap(base.init)(x, p), log_w)

    def mixture_info(comps, log_w, infos, step, prior_log_w):
        """The mixture's moments (weights ``log_w``) and its predicted reading: the
        components' innovations and variances mixed with the weights *before* the
        reading (``prior_log_w``), their spread included, over the components that
        predicted one (NaN when none did)."""
        w = jnp.exp(log_w)
        mean = w @ comps.x
        d = comps.x - mean
        cov = jnp.einsum("m,mi,mj->ij", w, d, d) + jnp.einsum("m,mij->ij", w, comps.p)
        sigma = jnp.sqrt(jnp.clip(jnp.diag(cov), 0.0, None))
        nu, s = infos.innovation, infos.innovation_var

        def weights(ok):
            w0 = jnp.where(ok, jnp.exp(prior_log_w), 0.0)
            total = jnp.sum(w0)
            return w0 / jnp.where(total > 0, total, 1.0), total > 0

        has_s = jnp.isfinite(s)
        has_nu = has_s & jnp.isfinite(nu)  # NaN without a reading: no spread term then
        w_nu, any_nu = weights(has_nu)
        w_s, any_s = weights(has_s)
        nu_mix = w_nu @ jnp.where(has_nu, nu, 0.0)
        s_mix = w_s @ jnp.where(has_s, s + jnp.where(has_nu, (nu - nu_mix) ** 2, 0.0), 0.0)
        return StepInfo(
            mean, sigma, cov[:2, :2],
            jnp.where(any_nu & jnp.isfinite(step.z), nu_mix, jnp.nan),
            jnp.where(any_s, s_mix, jnp.nan), jnp.bitwise_or.reduce(infos.status),
        )  # fmt: skip

    def update(state, step, field, dynamics):
        comps, infos = jax.vmap(base.update, in_axes=(0, None, None, None))(
            state.components, step, field, dynamics
        )
        nu, s = infos.innovation, infos.innovation_var
        # a gated component's reading is still scored (the gate skips its state update,
        # not its reweighting: an implausible reading must cost it weight)
        failed = STATUS_FILTER["off_map"] | STATUS_FILTER["covariance_failed"]
        scored = (jnp.isfinite(nu) & jnp.isfinite(s) & (s > 0)
                  & ((infos.status & failed) == 0))
        loglik = -0.5 * (jnp.where(scored, nu, 0.0) ** 2 / jnp.where(scored, s, 1.0)
                         + jnp.log(jnp.where(scored, s, 1.0)))
        # a component that could not predict the reading (off the map) explains it no
        # better than the worst one that could; none could: the weights stay
        worst = jnp.min(jnp.where(scored, loglik, jnp.inf))
        loglik = jnp.where(scored, loglik, jnp.where(jnp.any(scored), worst, 0.0))
        log_w = state.log_w + loglik
        log_w = log_w - jax.nn.logsumexp(log_w)
        return GaussianSumState(comps, log_w), mixture_info(comps, log_w, infos, step,
                                                            state.log_w)

    base_predict = predict_only(base)

    def predict(state, step, field, dynamics):
        comps, infos = jax.vmap(base_predict, in_axes=(0, None, None, None))(
            state.components, step, field, dynamics
        )
        info = mixture_info(comps, state.log_w, infos, step, state.log_w)
        nan = jnp.full_like(info.innovation, jnp.nan)
        return GaussianSumState(comps, state.log_w), info._replace(innovation=nan,
                                                                   innovation_var=nan)

    return Filter(init, update, predict)
