"""No-harm guard: hold back position corrections in weakly observed directions.

A gravity-aided filter corrects the INS by its position-error estimate ``x̂``. Where
the readings carry little information in some direction, the posterior variance
there stays close to the free INS's and ``x̂`` moves by a fraction of a large σ,
right or wrong; on average that still helps, but in single runs it can make the
position worse than the INS. The guard compares the filter's position covariance
``P`` with the free INS's ``P_f`` (the same linear error model predicted from the
same prior without any update: :func:`free_covariance`) in their generalised
eigen-directions

    ``P_f = V Vᵀ``,  ``V⁻¹ P V⁻ᵀ = diag(λ₁, λ₂)``,

where ``λᵢ`` is the posterior/free variance ratio along direction ``i`` (0: fully
observed, 1: nothing learnt). In those coordinates the correction is
``â = V⁻¹ x̂`` and the guard applies ``gᵢ âᵢ`` with a gain ``gᵢ = g(λᵢ)`` that is
1 below ``lo`` and 0 above ``hi`` (smooth in between, or a hard threshold when
``lo == hi``). The reported covariance is the filter model's own mean squared error
of the shrunk estimate, ``λᵢ + (1 − gᵢ)² (1 − λᵢ)`` per direction: ``P`` where
everything passes, ``P_f`` where nothing does (the INS and its own covariance).

A second, optional rule (:func:`windowed_nis`) checks the innovations: over the last
``window`` readings their normalised squares should average 1; when they average
far more, the filter's Gaussian no longer explains the data (typically a wrong
mode) and the whole correction is held back while that lasts.

Everything here is 2 × 2 closed form (no LAPACK: batched LAPACK under ``vmap``
deadlocks jaxlib's CPU pool, see :mod:`jaxgrav._linalg`), per step, and vmaps over
steps and runs.
"""

import jax
import jax.numpy as jnp

from jaxgrav._pytree import pytree_dataclass
from jaxgrav.filters.kalman import predict
from jaxgrav.filters.model import FilterState

__all__ = [
    "GuardConfig",
    "free_covariance",
    "generalized_eig_2x2",
    "guard_gain",
    "guard_infos",
    "guard_position",
    "guard_run",
    "windowed_nis",
]


@pytree_dataclass
class GuardConfig:
    """Thresholds of the guard (floats or arrays: pytree leaves, traced and sweepable).

    Attributes
    ----------
    lo, hi : float
        Variance ratio ``λ`` (posterior / free INS, per generalised eigen-direction)
        below which a direction's correction passes fully (``lo``) and above which it
        is held back fully (``hi``); ``lo == hi`` is a hard threshold. ``hi >= 1``
        with ``lo >= 1`` passes everything. The default 0.2 (correct a direction only
        once its variance is down to a fifth of the free INS's) was chosen on a
        selection seed of paper D's 1000-run experiment (``examples/paper_d_noharm.py``).
    nis_max : float
        Hold back the whole correction while the windowed mean NIS exceeds this
        (``inf``: never).

    All three are data fields, so ``GuardConfig(ratio, ratio)`` with a traced
    ``ratio`` works inside ``jit``, and a batch of configurations maps under ``vmap``.
    """

    lo: float = 0.2
    hi: float = 0.2
    nis_max: float = float("inf")


def free_covariance(dynamics, p0, n_steps):
    """Position covariance of the free INS: ``P ← F P Fᵀ + Q`` from ``p0``, no updates.

    Parameters
    ----------
    dynamics : Dynamics
        The filter's per-step error dynamics (``f``, ``q`` of shape ``(n, n)``).
    p0 : Array, shape ``(n, n)``
        The filter's prior covariance.
    n_steps : int
        Number of filter steps (static).

    Returns
    -------
    Array, shape ``(n_steps, 2, 2)``
        Entry ``k`` is the position block after ``k + 1`` predictions, aligned with the
        ``StepInfo`` of a filter run over the same steps (m²).
    """

    def body(p, _):
        p = predict(FilterState(jnp.zeros(p.shape[0], p.dtype), p), dynamics.f, dynamics.q).p
        return p, p[:2, :2]

    _, out = jax.lax.scan(body, jnp.asarray(p0), None, length=n_steps)
    return out


def _chol_2x2(b):
    l00 = jnp.sqrt(b[0, 0])
    l10 = b[1, 0] / l00
    l11 = jnp.sqrt(b[1, 1] - l10**2)
    return l00, l10, l11


def generalized_eig_2x2(a, b):
    """Generalised eigen-decomposition of a symmetric pair, ``b`` positive definite.

    Parameters
    ----------
    a, b : Array, shape ``(2, 2)``
        Symmetric; ``b`` positive definite.

    Returns
    -------
    lam : Array, shape ``(2,)``
        Eigenvalues of ``a v = λ b v``, ascending.
    v : Array, shape ``(2, 2)``
        Columns ``vᵢ`` scaled so that ``V Vᵀ = b`` and ``V⁻¹ a V⁻ᵀ = diag(λ)``
        (equivalently ``a b⁻¹ vᵢ = λᵢ vᵢ``; the eigenvectors of ``a v = λ b v`` are
        ``b⁻¹ vᵢ``).
    """
    l00, l10, l11 = _chol_2x2(b)
    # M = L⁻¹ a L⁻ᵀ, with L = [[l00, 0], [l10, l11]]
    m00 = a[0, 0] / l00**2
    m01 = (a[0, 1] - l10 * a[0, 0] / l00) / (l00 * l11)
    m11 = (a[1, 1] - 2.0 * l10 * a[0, 1] / l00 + l10**2 * a[0, 0] / l00**2) / l11**2
    half_tr = 0.5 * (m00 + m11)
    rad = jnp.sqrt(jnp.square(0.5 * (m00 - m11)) + m01**2)
    lam = jnp.stack([half_tr - rad, half_tr + rad])
    # eigenvector of the smaller eigenvalue: rotation by θ = ½ atan2(2 m01, m00 − m11)
    theta = 0.5 * jnp.arctan2(2.0 * m01, m00 - m11)
    c, s = jnp.cos(theta), jnp.sin(theta)
    u = jnp.array([[-s, c], [c, s]])  # column 0 ↔ smaller λ, column 1 ↔ larger
    low = jnp.array([[l00, 0.0], [l10, l11]], dtype=u.dtype)
    return lam, low @ u


def guard_gain(lam, lo, hi):
    """Gain per direction: 1 for ``λ ≤ lo``, 0 for ``λ ≥ hi``, smoothstep in between.

    Parameters
    ----------
    lam : Array
        Variance ratios.
    lo, hi : float
        ``lo <= hi``; equal values give a hard threshold (gain 1 at ``λ ≤ lo``).

    Returns
    -------
    Array, like ``lam``, in ``[0, 1]``.
    """
    width = jnp.maximum(hi - lo, 1e-300)
    t = jnp.clip((lam - lo) / width, 0.0, 1.0)
    smooth = 1.0 - t * t * (3.0 - 2.0 * t)
    return jnp.where(lam <= lo, 1.0, jnp.where(lam >= hi, 0.0, smooth))


def guard_position(x_pos, p_pos, p_free, lo, hi, hold=False):
    """Guard one step's position correction.

    Parameters
    ----------
    x_pos : Array, shape ``(2,)``
        Filter estimate of the position error (m), north/east.
    p_pos : Array, shape ``(2, 2)``
        Its covariance (m²).
    p_free : Array, shape ``(2, 2)``
        Free INS position covariance at the same step (m²).
    lo, hi : float
        See :class:`GuardConfig`.
    hold : bool or Array, shape ``()``
        Hold back everything (gains 0) at this step.

    Returns
    -------
    x : Array, shape ``(2,)``
        Guarded estimate ``V diag(g) V⁻¹ x̂``.
    p : Array, shape ``(2, 2)``
        ``V diag(λ + (1 − g)² (1 − λ)) Vᵀ``: the filter model's mean squared error
        of the guarded estimate (``p_pos`` when ``g = 1``, ``p_free`` when ``g = 0``).
    gain : Array, shape ``(2,)``
        Gains of the two directions (ascending ``λ``).
    lam : Array, shape ``(2,)``
        Variance ratios, ascending.
    """
    lam, v = generalized_eig_2x2(p_pos, p_free)
    gain = jnp.where(hold, 0.0, guard_gain(lam, lo, hi))
    det = v[0, 0] * v[1, 1] - v[0, 1] * v[1, 0]
    v_inv = jnp.array([[v[1, 1], -v[0, 1]], [-v[1, 0], v[0, 0]]]) / det
    a = v_inv @ x_pos
    x = v @ (gain * a)
    # λ can leave [0, 1] slightly by rounding or when the filter's P grew past P_f
    var = lam + jnp.square(1.0 - gain) * jnp.clip(1.0 - lam, 0.0, None)
    p = (v * var) @ v.T
    passthrough = jnp.all(gain == 1.0)  # exact identity when nothing is held back
    x = jnp.where(passthrough, x_pos, x)
    p = jnp.where(passthrough, p_pos, 0.5 * (p + p.T))
    return x, p, gain, lam


def windowed_nis(innovation, innovation_var, window):
    """Causal mean normalised innovation squared over the last ``window`` readings.

    Parameters
    ----------
    innovation, innovation_var : Array, shape ``(T,)``
        From :class:`StepInfo` (NaN innovation: no reading, not counted).
    window : int
        Number of readings averaged (static, ≥ 1).

    Returns
    -------
    Array, shape ``(T,)``
        Mean NIS of the last ``window`` readings up to and including each step; NaN
        before the first reading. Expected 1 for a consistent filter.
    """
    if int(window) < 1:
        raise ValueError(f"window must be >= 1, got {window!r}")
    used = jnp.isfinite(innovation)
    nis = jnp.where(used, jnp.square(jnp.where(used, innovation, 0.0)) / innovation_var, 0.0)
    # index each reading by its reading count; sum over counts in (c − window, c]
    count = jnp.cumsum(used)
    csum = jnp.cumsum(nis)
    # cumulative sum at the step where the count was c − window: last step with count ≤ c − w
    idx = jnp.searchsorted(count, count - window, side="right") - 1
    before = jnp.where(idx >= 0, csum[jnp.clip(idx, 0, None)], 0.0)
    n = jnp.minimum(count, window)
    return jnp.where(n > 0, (csum - before) / jnp.maximum(n, 1), jnp.nan)


def guard_infos(infos, p_free, config=None, window=30):
    """Guard a whole filter run's output.

    Parameters
    ----------
    infos : StepInfo
        Leading axis ``T`` (from :func:`~jaxgrav.filters.model.run_filter`).
    p_free : Array, shape ``(T, 2, 2)``
        From :func:`free_covariance` with the same dynamics, prior and steps.
    config : GuardConfig, optional
        Default ``GuardConfig()``.
    window : int
        Readings in the NIS window (static).

    Returns
    -------
    StepInfo
        ``x[:, :2]``, ``sigma[:, :2]`` and ``p_pos`` replaced by the guarded values;
        the other states and fields unchanged.

    Raises
    ------
    ValueError
        ``p_free`` not one 2 × 2 block per step; ``config.lo > config.hi``.
    """
    config = GuardConfig() if config is None else config
    t = infos.x.shape[0]
    if tuple(p_free.shape) != (t, 2, 2):
        raise ValueError(f"p_free must have shape {(t, 2, 2)} (one 2 x 2 block per step of "
                         f"infos), got {tuple(p_free.shape)}")
    lo, hi = config.lo, config.hi
    if isinstance(lo, int | float) and isinstance(hi, int | float) and not lo <= hi:
        raise ValueError(f"config.lo must be <= config.hi, got lo={lo!r}, hi={hi!r}")
    nis = windowed_nis(infos.innovation, infos.innovation_var, window)
    hold = jnp.nan_to_num(nis, nan=0.0) > config.nis_max  # never when nis_max = inf
    x, p, _, _ = jax.vmap(guard_position, in_axes=(0, 0, 0, None, None, 0))(
        infos.x[:, :2], infos.p_pos, p_free, config.lo, config.hi, hold
    )
    sd = jnp.sqrt(jnp.clip(jnp.stack([p[:, 0, 0], p[:, 1, 1]], -1), 0.0, None))
    return infos._replace(
        x=infos.x.at[:, :2].set(x), sigma=infos.sigma.at[:, :2].set(sd), p_pos=p
    )


def guard_run(infos, dynamics, p0, config=None, window=30):
    """Guard a filter run given its dynamics and prior (computes the free covariance).

    Parameters
    ----------
    infos : StepInfo
        Leading axis ``T``, one entry per filter step (each after one prediction with
        ``dynamics``).
    dynamics : Dynamics
        The per-step error dynamics the filter used.
    p0 : Array, shape ``(n, n)``
        The filter's prior covariance.
    config : GuardConfig, optional
    window : int
        Readings in the NIS window (static).

    Returns
    -------
    StepInfo
        As :func:`guard_infos`.
    """
    return guard_infos(infos, free_covariance(dynamics, p0, infos.x.shape[0]), config, window)
