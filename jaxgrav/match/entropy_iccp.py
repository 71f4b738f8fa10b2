"""Paper B combined: entropy coarse match, then ICCP fine match; validated entry point.

:func:`match_entropy_iccp` runs both stages with the map prepared once. ICCP starts
from each of the coarse stage's best offsets and from the INS track; the fine result
of least misfit replaces the coarse one only if it fits *significantly* better (a
likelihood-ratio test against the reading noise, see :class:`IccpConfig`), otherwise
status bit 128 is raised and the coarse track is kept. Where the data cannot tell the
two apart, the combined match therefore does not move away from the coarse one.

:func:`match_track_b` is the checked public entry point for one track with
``method`` in :data:`METHODS_B`; :func:`paper_b_scenario` simulates the experiment of
SPEC §B (and the issue's accuracy goal): a straight track, an INS track offset by a
random vector and rotated about its start, readings of a field with white noise.
"""

import math
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxgrav.constants import DEG
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.grid import make_sampler
from jaxgrav.match.contour import patch_coefficients, value_grad
from jaxgrav.match.dense import shifted_tracks
from jaxgrav.match.entropy import (
    ENTROPY_STATUS,
    EntropyConfig,
    coarse_offsets,
    entropy_config_for,
    match_entropy,
)
from jaxgrav.match.iccp import (
    ICCP_STATUS,
    IccpConfig,
    _iccp_result,
    _track_frame,
    iccp_fit,
    match_iccp,
)
from jaxgrav.match.result import STATUS, MatchResult
from jaxgrav.scenarios.paper_b import PaperBScenario, paper_b_scenario
from jaxgrav.sim import track_error_m

__all__ = [
    "COMBINED_STATUS",
    "METHODS_B",
    "PaperBErrors",
    "PaperBScenario",
    "iccp_config_for",
    "match_entropy_iccp",
    "match_track_b",
    "paper_b_errors",
    "paper_b_scenario",
]

METHODS_B = ("entropy", "iccp", "entropy+iccp")

COMBINED_STATUS = {
    128: "entropy+ICCP: the ICCP result did not fit significantly better than the coarse "
         "match; coarse track kept",
}
"""Status bit of the combined matcher (with :data:`ENTROPY_STATUS` and :data:`ICCP_STATUS`)."""

ALL_STATUS_B = {**STATUS, **ENTROPY_STATUS, **ICCP_STATUS, **COMBINED_STATUS}



_DEFAULT_ENTROPY = EntropyConfig()
_DEFAULT_ICCP = IccpConfig()


@jax.jit
def match_entropy_iccp(grid, lat, lon, readings, entropy=_DEFAULT_ENTROPY, iccp=_DEFAULT_ICCP):
    """Entropy coarse match followed by ICCP fine match, for one track (jitted).

    ICCP is started from each of the coarse stage's ``entropy.k_best`` best offsets and
    from the INS track itself (the search is cheap next to a wrong start); of these
    fine results the one with the least misfit is taken. It replaces the coarse track
    only if it fits significantly better, ``N·(m_coarse − m_fine)/σ² ≥
    iccp.accept_chi2`` with ``σ = iccp.noise`` (a likelihood-ratio test: the coarse
    offset lies outside the fine transform's confidence region); otherwise the coarse
    track is kept and status bit 128 raised.

    Parameters
    ----------
    grid : Grid
        Map (nT or mGal).
    lat, lon : Array, shape ``(N,)``
        INS-indicated fixes (degrees).
    readings : Array, shape ``(N,)``
        Measured values (map units), bias-free.
    entropy : EntropyConfig
    iccp : IccpConfig
        ``window_m`` should cover the coarse stage's error (a few offset spacings
        to a map cell), not the whole INS drift.

    Returns
    -------
    MatchResult
        ``score`` is the mean squared misfit (map units²); ``topk_*`` hold the coarse
        and the fine track (in that order), ``chosen`` which one was returned.
    """
    lat, lon, readings = (jnp.asarray(x) for x in (lat, lon, readings))
    n = readings.shape[0]
    coarse, d_n, d_e, top_n, top_e = coarse_offsets(make_sampler(grid, entropy.method), lat, lon,
                                                    readings, entropy)
    p0, field = _track_frame(patch_coefficients(grid.values), grid, lat, lon)
    dtype = p0.dtype
    z = readings.astype(dtype)
    starts = jnp.stack([jnp.append(top_n, 0.0), jnp.append(top_e, 0.0)], -1).astype(dtype)
    fits = jax.vmap(lambda t0: iccp_fit(field, p0, z, iccp, t0=t0))(starts)
    misfits = jnp.where(jnp.isfinite(fits.misfit), fits.misfit, jnp.inf)
    best = jnp.argmin(misfits)
    st = jax.tree.map(lambda x: x[best], fits)
    f_c, _ = value_grad(field, p0 + jnp.stack([d_n, d_e]).astype(dtype))
    coarse_misfit = jnp.mean((z - f_c) ** 2)
    gain = n * (coarse_misfit - st.misfit)
    use_fine = jnp.isfinite(st.misfit) & ~(gain < iccp.accept_chi2 * iccp.noise**2)
    rot = jnp.arctan2(st.rotation[1, 0], st.rotation[0, 0])
    f_lat, f_lon = shifted_tracks(lat, lon, st.translation[0], st.translation[1], rot)
    f_n, f_e = local_offsets_m(f_lat, f_lon, lat, lon)
    pick = lambda a, b: jnp.where(use_fine, a, b)  # noqa: E731
    status = (
        (coarse.status & ~1)
        | jnp.where(jnp.isfinite(st.misfit) | jnp.isfinite(coarse_misfit), 0, 1)
        | jnp.where(use_fine & ~st.converged, 16, 0)
        | jnp.where(st.starved, 64, 0)
        | jnp.where(use_fine, 0, 128)
    ).astype(jnp.int32)
    iters = jnp.sum(fits.n_iter).astype(dtype)
    return MatchResult(
        lat=pick(f_lat, coarse.lat),
        lon=pick(f_lon, coarse.lon),
        offset_north_m=pick(jnp.mean(f_n), coarse.offset_north_m),
        offset_east_m=pick(jnp.mean(f_e), coarse.offset_east_m),
        rotation_deg=pick(rot / DEG, coarse.rotation_deg),
        score=pick(st.misfit, coarse_misfit),
        bias=coarse.bias,
        topk_lat=jnp.stack([coarse.lat, f_lat]),
        topk_lon=jnp.stack([coarse.lon, f_lon]),
        topk_score=jnp.stack([coarse_misfit, st.misfit]),
        chosen=use_fine.astype(jnp.int32),
        n_candidates=jnp.full((n,), st.n_used, jnp.int32),
        work_unconstrained=coarse.work_unconstrained,
        work_constrained=coarse.work_constrained + iters,
        work_pairs=coarse.work_pairs + iters * n * (iccp.newton_steps + 1),
        status=status,
    )


def iccp_config_for(grid, drift_radius_m, *, stage="alone", noise=1.0, max_rotation_deg=90.0,
                    **kw):
    """An :class:`IccpConfig` sized to the expected error.

    Parameters
    ----------
    grid : Grid
    drift_radius_m : float
        Largest expected INS error (m).
    stage : {"alone", "fine"}
        ``"alone"``: the window covers 1.2 × the drift, plain ICCP; ``"fine"`` (after
        the entropy stage, whose error can still reach the drift: entropy is a weak
        criterion): the larger of that and one map cell diagonal, and 10 least-squares
        refinement steps (``refine_steps``).
    noise : float
        Reading noise σ (map units): contour points must match their value within 3σ;
        the combined matcher's acceptance test uses it.
    max_rotation_deg : float
        Largest expected INS heading error (degrees): ICCP's rotation bound.
    **kw
        Other :class:`IccpConfig` fields.

    Returns
    -------
    IccpConfig
    """
    if not drift_radius_m > 0:
        raise ValueError(f"drift_radius_m must be positive (m); got {drift_radius_m!r}")
    if stage not in ("alone", "fine"):
        raise ValueError(f"stage must be 'alone' or 'fine'; got {stage!r}")
    dy, dx = grid.spacing_m()
    cell = math.hypot(dy, dx)
    window = 1.2 * float(drift_radius_m) if stage == "alone" else max(cell, 1.2 * drift_radius_m)
    kw.setdefault("window_m", window)
    kw.setdefault("max_step_m", max(cell / 2.0, 200.0))
    kw.setdefault("contour_tol", 3.0 * float(noise) + 1e-6)
    kw.setdefault("noise", float(noise))
    kw.setdefault("refine_steps", 10 if stage == "fine" else 0)
    return IccpConfig(max_rotation_deg=max_rotation_deg, **kw)


def match_track_b(grid, lat, lon, readings, *, method="entropy+iccp", drift_radius_m=5000.0,
                  noise=1.0, max_rotation_deg=90.0, entropy_half_size=20, entropy=None,
                  iccp=None, warn=True):
    """Match one track with paper B's methods, with input checks (public entry point).

    Parameters
    ----------
    grid : Grid
        Map: magnetic total intensity or anomaly (nT), or gravity anomaly (mGal).
    lat, lon : array_like, shape ``(N,)``
        INS-indicated fixes (degrees), N ≥ :data:`~jaxgrav.match.MIN_FIXES`.
    readings : array_like, shape ``(N,)``
        Measured values in the map's units, corrected for any known bias (Eötvös for
        gravity): neither stage estimates a bias.
    method : {"entropy", "iccp", "entropy+iccp"}
    drift_radius_m : float
        Largest expected INS error (m); sizes the entropy offsets and ICCP's window.
    noise : float
        Reading noise σ (map units).
    max_rotation_deg : float
        Largest expected INS heading error (degrees, 0–180); bounds ICCP's rotation.
    entropy_half_size : int
        At most this many entropy offsets per side (``max_half_size`` of
        :func:`~jaxgrav.match.entropy.entropy_config_for`; on fine maps the offset
        spacing grows instead).
    entropy : EntropyConfig, optional
        Replaces the sizing from ``drift_radius_m``.
    iccp : IccpConfig, optional
        Replaces the sizing from ``drift_radius_m`` and ``noise``.
    warn : bool
        Emit a ``RuntimeWarning`` per status flag raised.

    Returns
    -------
    MatchResult

    Raises
    ------
    ValueError
        Unknown method, mismatched lengths, too short a track, NaN values, a track
        off the map, non-positive drift radius, a rotation bound outside 0–180°.
    """
    from jaxgrav.match.api import _validate

    if method not in METHODS_B:
        raise ValueError(f"method must be one of {METHODS_B}; got {method!r}")
    if not noise >= 0:
        raise ValueError(f"noise must be a non-negative standard deviation; got {noise!r}")
    if not 0 <= max_rotation_deg <= 180:
        raise ValueError(f"max_rotation_deg must be the INS heading-error bound in degrees, "
                         f"between 0 and 180; got {max_rotation_deg!r}")
    if not (isinstance(entropy_half_size, int) and entropy_half_size >= 1):
        raise ValueError(f"entropy_half_size must be an integer >= 1; got {entropy_half_size!r}")
    lat, lon, readings = _validate(grid, lat, lon, readings)
    if method != "iccp" and entropy is None:
        entropy = entropy_config_for(grid, drift_radius_m, max_half_size=entropy_half_size)
    if iccp is None:
        stage = "alone" if method == "iccp" else "fine"
        iccp = iccp_config_for(grid, drift_radius_m, stage=stage, noise=noise,
                               max_rotation_deg=max_rotation_deg)
    if method == "entropy":
        result = match_entropy(grid, lat, lon, readings, entropy)
    elif method == "iccp":
        result = match_iccp(grid, lat, lon, readings, iccp)
    else:
        result = match_entropy_iccp(grid, lat, lon, readings, entropy, iccp)
    if warn:
        for bit, msg in ALL_STATUS_B.items():
            if int(result.status) & bit:
                warnings.warn(msg, RuntimeWarning, stacklevel=2)
    return result


def status_messages_b(status):
    """Messages of a paper-B status bit field (a Python int)."""
    return [msg for bit, msg in ALL_STATUS_B.items() if int(status) & bit]


__all__ += ["ALL_STATUS_B", "status_messages_b"]


# ---------------------------------------------------------------------- experiment
class PaperBErrors(NamedTuple):
    """Mean-track errors (m) of one run, rotations (degrees) and misfits (map units²).

    ``misfit_*`` are mean squared differences of the readings and the map along the
    true, the entropy and the entropy + ICCP tracks: a matched track that fits better
    than the truth is an ambiguity no data criterion can resolve.
    """

    ins_m: jax.Array
    entropy_m: jax.Array
    iccp_m: jax.Array
    combined_m: jax.Array
    true_rotation_deg: jax.Array
    iccp_rotation_deg: jax.Array
    combined_rotation_deg: jax.Array
    status_iccp: jax.Array
    status_combined: jax.Array
    misfit_truth: jax.Array
    misfit_entropy: jax.Array
    misfit_combined: jax.Array


def paper_b_errors(key, truth_field, grid, scenario, entropy, iccp_alone, iccp_fine):
    """Simulate one run and match it by entropy, ICCP and entropy + ICCP (vmap over keys).

    Parameters
    ----------
    key : PRNG key
    truth_field : Grid or callable
        Field sensed.
    grid : Grid
        Map matched against.
    scenario : PaperBScenario
    entropy : EntropyConfig
    iccp_alone, iccp_fine : IccpConfig
        ICCP configurations alone (window covering the drift) and after the coarse stage.

    Returns
    -------
    PaperBErrors
    """
    run = paper_b_scenario(key, truth_field, scenario)
    lat, lon, z = run.ins_lat, run.ins_lon, run.readings
    alone = _iccp_result(patch_coefficients(grid.values), grid, lat, lon, z, iccp_alone)
    both = match_entropy_iccp(grid, lat, lon, z, entropy, iccp_fine)
    c_lat, c_lon = both.topk_lat[0], both.topk_lon[0]  # the coarse (entropy) track
    # true rotation: of the truth relative to the INS track (what a matcher should return)
    tn, te = local_offsets_m(run.truth.lat, run.truth.lon, run.truth.lat[0], run.truth.lon[0])
    in_, ie = local_offsets_m(lat, lon, lat[0], lon[0])
    true_rot = jnp.rad2deg(jnp.arctan2(te[-1], tn[-1]) - jnp.arctan2(ie[-1], in_[-1]))
    true_rot = (true_rot + 180.0) % 360.0 - 180.0
    err = lambda la, lo: track_error_m(la, lo, run.truth)  # noqa: E731
    misfit_truth = jnp.mean((z - make_sampler(grid, "bicubic")(run.truth.lat, run.truth.lon)) ** 2)
    return PaperBErrors(
        err(lat, lon), err(c_lat, c_lon), err(alone.lat, alone.lon),
        err(both.lat, both.lon), true_rot, alone.rotation_deg, both.rotation_deg,
        alone.status, both.status, misfit_truth, both.topk_score[0], both.score,
    )
