"""Entropy coarse matching (paper B, first stage).

Two entropies of a sequence ``h_1..h_N`` of field values (paper B):

- information entropy ``H_XX = −Σ p_i log p_i`` with ``p_i = h_i / Σ_j h_j``, defined
  for positive values only;
- difference entropy ``H_CY = −Σ q_i log q_i`` with ``q_i = C_i / Σ_j C_j`` and
  ``C_i = |h_i − h̄|``; it is unchanged by a constant bias (and by a scale factor).

Negative values and H_XX. Anomaly maps go negative (the paper's magnetic anomaly
spans −1296.8 … +1620.0 nT), so ``p_i`` would not be a distribution.
:func:`information_entropy` does not clip: it returns NaN for a sequence with any
value ≤ 0. The coarse matcher instead takes H_XX of ``h + shift``, the same constant
added to the measured and to every candidate sequence; :func:`entropy_config_for`
picks ``shift = (max − min) − min`` of the map when the map has values ≤ 0 (the map is
then mapped into ``[range, 2·range]``, strictly positive with margin for noise) and 0
otherwise, e.g. for total intensity. ``shift`` is an array field, so it can be swept.
The default entropy is H_CY, which needs no shift.

Coarse match. Candidate tracks are the INS track shifted by every offset of a square
grid of offsets (the same pattern as :func:`~jaxgrav.match.dense.match_dense`); the
map is sampled along all of them in one tensor operation and each candidate's
entropy compared with the measured sequence's. The paper's acceptance test: a
candidate is accepted only if the RMS of ``readings − map`` along it is below the
same RMS along the INS track (times ``accept_ratio``); among accepted candidates the
smallest ``|ΔH|`` wins ("else keep searching" is the walk down the |ΔH| ranking,
done here by masking). With ``k_best > 1`` and ``selection="rms"`` the least-RMS of
the ``k_best`` smallest-|ΔH| accepted candidates is taken instead (a variant, not the
paper's rule). When no candidate beats the INS RMS the INS track is kept and status
bit 32 is raised.
"""


import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match.offsets import shifted_tracks
from jaxgrav.match.result import STATUS, MatchResult
from jaxgrav.prepared import as_grid, prepare_map

__all__ = [
    "ENTROPIES",
    "ENTROPY_STATUS",
    "EntropyConfig",
    "coarse_offsets",
    "coarse_search",
    "coarse_stage",
    "difference_entropy",
    "entropy_config_for",
    "information_entropy",
    "match_entropy",
    "offset_grid",
    "sequence_entropy",
]

ENTROPIES = ("difference", "information")
"""``difference``: H_CY (default); ``information``: H_XX of ``h + shift``."""

ENTROPY_STATUS = {bit: STATUS[bit] for bit in (32,)}
"""The status bit raised by the entropy matcher only (an excerpt of
:data:`~jaxgrav.match.result.STATUS`); it also raises bits 1 (no finite candidate) and 8
(best candidate on the edge of the search region)."""


def _neg_plogp(p, valid):
    """``−p log p`` with 0 log 0 = 0, NaN-free gradients (double where)."""
    pos = valid & (p > 0)
    safe = jnp.where(pos, p, 1.0)
    return jnp.where(pos, -safe * jnp.log(safe), 0.0)


def information_entropy(h, axis=-1):
    """Information entropy ``H_XX = −Σ p_i ln p_i``, ``p_i = h_i / Σ h_j``.

    Parameters
    ----------
    h : Array, shape ``(..., N)``
        Positive field values along a track (any unit; the entropy is unit-free).
    axis : int
        Axis of the sequence.

    Returns
    -------
    Array, shape ``(...)``
        Entropy in nats, in ``[0, ln N]``; NaN where any value is ≤ 0 or not finite
        (never clipped: shift anomalies first, see the module docstring).
    """
    h = jnp.moveaxis(jnp.asarray(h), axis, -1)
    ok = jnp.all(jnp.isfinite(h) & (h > 0), axis=-1, keepdims=True)
    h_safe = jnp.where(ok, h, 1.0)
    p = h_safe / jnp.sum(h_safe, axis=-1, keepdims=True)
    out = jnp.sum(_neg_plogp(p, ok), axis=-1)
    return jnp.where(ok[..., 0], out, jnp.nan)


def difference_entropy(h, axis=-1):
    """Difference entropy ``H_CY = −Σ q_i ln q_i``, ``q_i = |h_i − h̄| / Σ_j |h_j − h̄|``.

    Parameters
    ----------
    h : Array, shape ``(..., N)``
        Field values along a track (any sign, any unit).
    axis : int
        Axis of the sequence.

    Returns
    -------
    Array, shape ``(...)``
        Entropy in nats, in ``[0, ln N]``; NaN for a constant sequence (all ``C_i = 0``,
        no distribution) or one with a non-finite value.
    """
    return _difference_entropy(jnp.moveaxis(jnp.asarray(h), axis, -1))[0]


def _difference_entropy(h, *extra):
    """:func:`difference_entropy` along the last axis, and the sums of ``extra``.

    Two sums, each over stacked terms, not four sums: XLA's CPU backend compiles each
    sum over more than 32 values as two kernels of its own. The first sums the finite
    values, counts them and sums ``extra`` (arrays of ``h``'s shape); the second sums
    ``C_i`` and ``C_i ln C_i``, and ``H = ln ΣC − Σ C ln C / ΣC`` (= ``−Σ q ln q``).
    """
    n = h.shape[-1]
    is_finite = jnp.isfinite(h)
    total_h, n_finite, *rest = jnp.sum(jnp.stack(
        [jnp.where(is_finite, h, 0.0), is_finite.astype(h.dtype), *extra]), axis=-1)
    finite = (n_finite == n)[..., None]
    h_f = jnp.where(finite, h, 0.0)
    c = jnp.abs(h_f - jnp.where(finite, total_h[..., None] / n, 0.0))
    pos = c > 0
    safe = jnp.where(pos, c, 1.0)  # 0 ln 0 = 0, NaN-free gradients (double where)
    total, c_log_c = jnp.sum(jnp.stack([c, jnp.where(pos, safe * jnp.log(safe), 0.0)]), axis=-1)
    ok = finite[..., 0] & (total > 0)
    total = jnp.where(ok, total, 1.0)
    return jnp.where(ok, jnp.log(total) - c_log_c / total, jnp.nan), rest


def sequence_entropy(h, kind="difference", shift=0.0):
    """Entropy of sequences along the last axis: H_CY, or H_XX of ``h + shift``.

    Parameters
    ----------
    h : Array, shape ``(..., N)``
    kind : {"difference", "information"}
    shift : float or Array
        Constant added before H_XX (same unit as ``h``); ignored by H_CY.

    Returns
    -------
    Array, shape ``(...)``
    """
    if kind == "difference":
        return difference_entropy(h)
    if kind == "information":
        return information_entropy(jnp.asarray(h) + shift)
    raise ValueError(f"kind must be one of {ENTROPIES}; got {kind!r}")


@pytree_dataclass
class EntropyConfig:
    """Settings of the entropy coarse matcher.

    Attributes
    ----------
    spacing_m : float
        Spacing of the offset grid (m).
    shift : float
        Constant added to every sequence before H_XX (map units); unused by H_CY.
    accept_ratio : float
        A candidate is accepted when its RMS misfit is below ``accept_ratio`` × the INS
        track's (paper: 1).
    half_size : int
        Offsets per side (static): ``(2·half_size + 1)²`` candidate tracks covering
        ±half_size·spacing_m north and east.
    kind : {"difference", "information"}
        H_CY or H_XX (static).
    k_best : int
        Candidates reported in the result's top-k (static).
    selection : {"entropy", "rms"}
        ``"entropy"``: smallest |ΔH| among accepted candidates (the paper);
        ``"rms"``: least RMS misfit among the ``k_best`` smallest-|ΔH| accepted ones (static).
    method : {"bicubic", "bilinear"}
        Map interpolation (static).
    """

    spacing_m: float = 500.0
    shift: float = 0.0
    accept_ratio: float = 1.0
    half_size: int = static_field(10)
    kind: str = static_field("difference")
    k_best: int = static_field(5)
    selection: str = static_field("entropy")
    method: str = static_field("bicubic")

    def __post_init__(self):
        if isinstance(self.kind, str) and self.kind not in ENTROPIES:
            raise ValueError(f"kind must be one of {ENTROPIES}; got {self.kind!r}")
        if isinstance(self.selection, str) and self.selection not in ("entropy", "rms"):
            raise ValueError(f"selection must be 'entropy' or 'rms'; got {self.selection!r}")
        if isinstance(self.half_size, int) and self.half_size < 0:
            raise ValueError(f"half_size must be >= 0; got {self.half_size!r}")
        if isinstance(self.k_best, int) and self.k_best < 1:
            raise ValueError(f"k_best must be >= 1; got {self.k_best!r}")


def entropy_config_for(grid, drift_radius_m, *, kind="difference", max_half_size=40,
                       lat=None, **kw):
    """An :class:`EntropyConfig` whose offset grid covers 1.2 × the INS drift.

    Parameters
    ----------
    grid : Grid or PreparedMap
        The map (its node spacing sets the offset spacing: 1/8 of a cell, at least
        50 m, at most a third of the reach).
    drift_radius_m : float
        Largest expected INS error (m).
    kind : {"difference", "information"}
    max_half_size : int
        Cap on offsets per side; the spacing grows instead.
    lat : float, optional
        Latitude (degrees) at which the node spacing is measured; the map's central
        latitude by default (:func:`~jaxgrav.match.api.match` passes the track's).
    **kw
        Other :class:`EntropyConfig` fields.

    Returns
    -------
    EntropyConfig
        For ``kind="information"`` on a map with values ≤ 0, ``shift`` is set as
        described in the module docstring unless given.
    """
    if not drift_radius_m > 0:
        raise ValueError(f"drift_radius_m must be positive (m); got {drift_radius_m!r}")
    reach = 1.2 * float(drift_radius_m)
    grid = as_grid(grid)
    dy, dx = (float(s) for s in grid.spacing_m(lat))
    spacing = min(max(min(dy, dx) / 8.0, 50.0), reach / 3.0)
    half = math.ceil(reach / spacing)
    if half > max_half_size:
        half, spacing = max_half_size, reach / max_half_size
    if kind == "information" and "shift" not in kw:
        v = np.asarray(grid.values)
        lo, hi = float(v.min()), float(v.max())
        kw["shift"] = (hi - lo) - lo if lo <= 0 else 0.0
    return EntropyConfig(spacing_m=spacing, half_size=half, kind=kind, **kw)


def offset_grid(config, dtype=float):
    """The coarse stage's offsets ``(north, east)``, each ``((2h+1)²,)`` (m), row-major."""
    h = config.half_size
    g = jnp.arange(-h, h + 1, dtype=dtype) * config.spacing_m
    on, oe = jnp.meshgrid(g, g, indexing="ij")
    return on.reshape(-1), oe.reshape(-1)


def coarse_search(sample, lat, lon, readings, config):
    """Entropy coarse search with a prepared sampler (the jit-free core).

    See :func:`coarse_offsets`; this returns its result only.
    """
    return coarse_offsets(sample, lat, lon, readings, config)[0]


def coarse_offsets(sample, lat, lon, readings, config):
    """Entropy coarse search with a prepared sampler, also returning the offsets found.

    Parameters
    ----------
    sample : callable
        ``f(lat, lon) -> values`` (NaN off the map), e.g.
        :meth:`~jaxgrav.prepared.PreparedMap.sampler`.
    lat, lon : Array, shape ``(N,)``
        INS fixes (degrees).
    readings : Array, shape ``(N,)``
        Measured field values (map units).
    config : EntropyConfig

    Returns
    -------
    tuple
        ``(result, d_north, d_east, topk_north, topk_east)``: the :class:`MatchResult`,
        the chosen offset (m) in the frame of :func:`~jaxgrav.match.offsets.shifted_tracks`
        and the offsets ``(k_best,)`` of the top-k candidates (the chosen offset where
        fewer were accepted). In the result, ``score`` is the chosen |ΔH| (nats),
        ``bias`` is 0, ``topk_score`` the |ΔH| of the ``k_best`` best accepted
        candidates (``inf`` for missing ones).
    """
    return coarse_stage(sample, lat, lon, readings, config)[:5]


def coarse_stage(sample, lat, lon, readings, config):
    """:func:`coarse_offsets` and what a later stage reads again (the jit-free core).

    Parameters
    ----------
    sample, lat, lon, readings, config
        As :func:`coarse_offsets`.

    Returns
    -------
    tuple
        :func:`coarse_offsets`' five values, then ``values`` ``(S, N)``: the map along
        the offset grid's tracks (:func:`offset_grid`'s order), and ``index`` ``(k_best +
        2,)``: the grid indices of the top-k offsets (as returned), of the zero offset
        (the INS track) and of the chosen offset, in that order.
    """
    lat, lon, readings = (jnp.asarray(a) for a in (lat, lon, readings))
    n = lat.shape[0]
    dtype = jnp.result_type(lat.dtype, float)
    d_n, d_e = offset_grid(config, dtype)
    la, lo = shifted_tracks(lat, lon, d_n, d_e, jnp.zeros_like(d_n))  # (S, N)
    vals = sample(la, lo)
    h_meas = sequence_entropy(readings, config.kind, config.shift)
    if config.kind == "difference":  # the misfit summed in the entropy's first pass
        h_cand, (sq,) = _difference_entropy(vals, (readings - vals) ** 2)
        rms = jnp.sqrt(sq / n)
    else:
        h_cand = sequence_entropy(vals, config.kind, config.shift)
        rms = jnp.sqrt(jnp.mean((readings - vals) ** 2, axis=-1))
    d_h = jnp.abs(h_cand - h_meas)
    # the INS track is the centre offset (exactly 0): the same arithmetic, so that the
    # zero offset is never "accepted" for beating itself by a rounding error
    rms_ins = rms[d_n.shape[0] // 2]
    finite = jnp.isfinite(d_h) & jnp.isfinite(rms)
    accepted = finite & (rms < config.accept_ratio * rms_ins)
    key = jnp.where(accepted, d_h, jnp.inf)
    k = min(config.k_best, key.shape[0])
    _, top = jax.lax.top_k(-key, k)
    if config.selection == "rms":
        chosen = jnp.argmin(jnp.where(jnp.isfinite(key[top]), rms[top], jnp.inf))
    else:
        chosen = jnp.asarray(0)
    i = top[chosen]
    any_ok = jnp.any(accepted)
    zero = jnp.zeros((), dtype)
    p_n = jnp.where(any_ok, d_n[i], zero)
    p_e = jnp.where(any_ok, d_e[i], zero)
    m_lat, m_lon = shifted_tracks(lat, lon, p_n, p_e, zero)
    off_n, off_e = jnp.mean(jnp.stack(local_offsets_m(m_lat, m_lon, lat, lon)), -1)
    reach = config.half_size * config.spacing_m
    edge = any_ok & ((jnp.abs(p_n) >= reach) | (jnp.abs(p_e) >= reach)) & (config.half_size > 0)
    n_off = jnp.asarray(d_n.shape[0], dtype)
    status = (
        jnp.where(jnp.any(finite), 0, 1)
        | jnp.where(edge, 8, 0)
        | jnp.where(any_ok | ~jnp.any(finite), 0, 32)
    )
    result = MatchResult(
        lat=m_lat,
        lon=m_lon,
        offset_north_m=off_n,
        offset_east_m=off_e,
        rotation_deg=zero,
        score=jnp.where(any_ok, d_h[i], jnp.abs(sequence_entropy(sample(lat, lon), config.kind,
                                                                   config.shift) - h_meas)),
        bias=zero,
        topk_lat=la[top],
        topk_lon=lo[top],
        topk_score=key[top],
        chosen=chosen,
        n_candidates=jnp.full((n,), d_n.shape[0], jnp.int32),
        work_unconstrained=n_off,
        work_constrained=n_off,
        work_pairs=n_off * n,
        status=status.astype(jnp.int32),
    )
    have = jnp.isfinite(key[top])
    centre = d_n.shape[0] // 2  # the zero offset, exactly
    chosen_i = jnp.where(any_ok, i, centre).astype(top.dtype)  # p_n = d_n[chosen_i]
    index = jnp.concatenate([jnp.where(have, top, chosen_i), jnp.stack([centre, chosen_i])])
    return (result, p_n, p_e, jnp.where(have, d_n[top], p_n), jnp.where(have, d_e[top], p_e),
            vals, index)


@jax.jit
def match_entropy(grid, lat, lon, readings, config=EntropyConfig()):  # noqa: B008
    """Entropy coarse match of one track (jitted; vmap it over tracks).

    Parameters
    ----------
    grid : Grid or PreparedMap
        Map (nT for magnetic total intensity or anomaly, mGal for gravity).
    lat, lon : Array, shape ``(N,)``
        INS-indicated fixes (degrees).
    readings : Array, shape ``(N,)``
        Measured values (map units).
    config : EntropyConfig

    Returns
    -------
    MatchResult
        The INS track shifted by the chosen offset (no rotation); see
        :func:`coarse_search` and :data:`ENTROPY_STATUS`.
    """
    return coarse_search(prepare_map(grid).sampler(config.method), lat, lon, readings, config)
