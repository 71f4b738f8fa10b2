"""Methods the Monte Carlo runner knows by name: scenario + matcher/filter + errors per run.

Each entry of :data:`BUILDERS` maps a method name to a *builder*::

    builder(grid, *, drift_deg=None, noise=None, n_fixes=None) -> MethodSpec

``None`` means the method's own default. The spec's ``fn(key, *args)`` simulates and
solves one run and returns a dict of per-run metrics, at least :data:`METRICS`:

``ins_err_m``  mean horizontal distance of the INS-indicated track from the truth (m)
``err_m``      the same for the method's estimated track (m)
``status``     the method's status bit field (0 = clean; int32)

``fn`` must be a module-level function (not a fresh closure), so that repeated runs
reuse the compiled code; everything a user may sweep goes into ``args``.

Adding a method
---------------
One entry, e.g. for the paper-D filters once :mod:`jaxgrav.match.filters` exists::

    BUILDERS["ukf"] = functools.partial(filters_builder, kind="ukf")

or ``register("ukf", builder)``; ``jaxgrav montecarlo --method`` lists the keys of
:data:`BUILDERS`.
"""

import dataclasses
from collections.abc import Callable

import jax.numpy as jnp

from jaxgrav.sim import DEG_ARC_M

__all__ = ["BUILDERS", "METRICS", "MethodSpec", "build", "default_grid", "register"]

METRICS = ("ins_err_m", "err_m", "status")
"""Metrics every method returns per run."""


@dataclasses.dataclass(frozen=True)
class MethodSpec:
    """A method ready for :func:`jaxgrav.montecarlo.run`.

    Attributes
    ----------
    fn : callable
        ``fn(key, *args) -> dict`` of per-run metrics (at least :data:`METRICS`).
    args : tuple
        Extra arguments of ``fn`` (map, scenario, configurations).
    settings : dict
        The resolved scenario settings and a one-line description (for file attributes).
    status_bits : dict of int to str
        Meaning of the ``status`` bits.
    """

    fn: Callable
    args: tuple
    settings: dict
    status_bits: dict


def default_grid():
    """The shipped 2.5′ ``ryukyu`` gravity anomaly map (mGal), 24–36°N, 124–136°E."""
    from jaxgrav import datasets

    return datasets.load("ryukyu")["anomaly_2p5min"]


def _region(grid):
    w, e, s, n = grid.extent
    return (float(s), float(n), float(w), float(e))


# ------------------------------------------------------------------- correlation (A)
def correlation_run(key, grid, scenario, config):
    """One paper-A run: simulate (:func:`~jaxgrav.scenarios.matching_scenario`), match dense.

    Readings are Eötvös-corrected with the true velocity (as a user with an INS
    velocity would) and matched by :func:`~jaxgrav.match.dense.match_dense`.

    Returns
    -------
    dict
        ``ins_err_m``, ``err_m`` (m), ``status`` (int32), ``score`` (the matcher's),
        ``offset_north_m``, ``offset_east_m`` (estimated correction, m).
    """
    from jaxgrav.geodesy import eotvos
    from jaxgrav.match.dense import match_dense
    from jaxgrav.scenarios import matching_scenario, track_error_m

    run = matching_scenario(key, grid, scenario)
    g = run.readings + eotvos(run.ins_lat, run.truth.v_east, run.truth.v_north)
    r = match_dense(grid, run.ins_lat, run.ins_lon, g, config)
    return dict(
        ins_err_m=track_error_m(run.ins_lat, run.ins_lon, run.truth),
        err_m=track_error_m(r.lat, r.lon, run.truth),
        status=jnp.asarray(r.status, jnp.int32),
        score=r.score,
        offset_north_m=r.offset_north_m,
        offset_east_m=r.offset_east_m,
    )


def correlation_builder(grid, *, drift_deg=None, noise=None, n_fixes=None):
    """Paper A, dense correlation matcher (the ``jaxgrav demo`` realistic setting).

    Defaults: INS drift 0.035° (fixed radius, random direction), 1 mGal noise, 30
    fixes 2 min apart at 10 kn east + 10 kn north; search radius 1.2 × the drift,
    bias prior σ 3 mGal.
    """
    from jaxgrav.match.api import config_for
    from jaxgrav.match.result import STATUS
    from jaxgrav.scenarios import MatchingScenario

    drift = 0.035 if drift_deg is None else float(drift_deg)
    noise = 1.0 if noise is None else float(noise)
    n = 30 if n_fixes is None else int(n_fixes)
    _check(drift, noise, n)
    scen = MatchingScenario(region=_region(grid), drift_deg=drift, noise_mgal=noise, n_fixes=n)
    cfg = config_for("dense", grid, 1.2 * drift * DEG_ARC_M, noise_mgal=max(noise, 0.1),
                     bias_sigma_mgal=3.0)
    settings = dict(description="paper A: dense correlation matcher, fixed INS drift",
                    drift_deg=drift, noise_mgal=noise, n_fixes=n, dt_s=scen.dt,
                    search_half_size=cfg.half_size, search_spacing_m=cfg.spacing_m)
    return MethodSpec(correlation_run, (grid, scen, cfg), settings, dict(STATUS))


# ----------------------------------------------------------------- entropy + ICCP (B)
def entropy_iccp_run(key, grid, scenario, entropy, iccp):
    """One paper-B run: simulate (:func:`~jaxgrav.match.entropy_iccp.paper_b_scenario`), match.

    Returns
    -------
    dict
        ``ins_err_m``, ``err_m`` (m), ``status`` (int32), ``score`` (mean squared
        misfit), ``rotation_deg`` (estimated heading correction).
    """
    from jaxgrav.match.entropy_iccp import match_entropy_iccp, paper_b_scenario
    from jaxgrav.scenarios import track_error_m

    run = paper_b_scenario(key, grid, scenario)
    r = match_entropy_iccp(grid, run.ins_lat, run.ins_lon, run.readings, entropy, iccp)
    return dict(
        ins_err_m=track_error_m(run.ins_lat, run.ins_lon, run.truth),
        err_m=track_error_m(r.lat, r.lon, run.truth),
        status=jnp.asarray(r.status, jnp.int32),
        score=r.score,
        rotation_deg=r.rotation_deg,
    )


def entropy_iccp_builder(grid, *, drift_deg=None, noise=None, n_fixes=None):
    """Paper B, entropy coarse + ICCP fine matching.

    Defaults (SPEC §B, the example's ``gravity`` case): INS offset uniform in
    [⅔·drift, drift] with drift 0.03°, rotated ±1.5° about the start, 1 mGal noise,
    60 fixes a minute apart at 10 m/s in a random direction.
    """
    from jaxgrav.match.entropy import entropy_config_for
    from jaxgrav.match.entropy_iccp import ALL_STATUS_B, PaperBScenario, iccp_config_for

    drift = 0.03 if drift_deg is None else float(drift_deg)
    noise = 1.0 if noise is None else float(noise)
    n = 60 if n_fixes is None else int(n_fixes)
    _check(drift, noise, n)
    scen = PaperBScenario(region=_region(grid), offset_min_deg=2.0 * drift / 3.0,
                          offset_max_deg=drift, noise=noise, n_fixes=n)
    reach_m = (drift + 0.005) * DEG_ARC_M
    ent = entropy_config_for(grid, reach_m, max_half_size=20)
    icp = iccp_config_for(grid, reach_m, stage="fine", noise=max(noise, 0.1))
    settings = dict(description="paper B: entropy coarse + ICCP fine matching, offset and "
                                "rotated INS track",
                    drift_deg=drift, offset_min_deg=scen.offset_min_deg, noise_mgal=noise,
                    n_fixes=n, dt_s=scen.dt, rotation_deg=scen.rotation_deg,
                    entropy_half_size=ent.half_size)
    return MethodSpec(entropy_iccp_run, (grid, scen, ent, icp), settings, dict(ALL_STATUS_B))


def _check(drift, noise, n):
    if not drift > 0:
        raise ValueError(f"drift must be a positive angle (degrees of arc); got {drift!r}")
    if not noise >= 0:
        raise ValueError(f"noise must be a non-negative standard deviation (mGal); got {noise!r}")
    if n < 5:
        raise ValueError(f"fixes must be at least 5 per track; got {n}")


BUILDERS = {
    "correlation": correlation_builder,
    "entropy+iccp": entropy_iccp_builder,
}
"""Method name -> builder; add the paper-D filters (``ukf``, ``ekf``, ``pmf``) here."""


def register(name, builder, *, replace=False):
    """Add a method builder under ``name`` (see the module docstring for the contract)."""
    if name in BUILDERS and not replace:
        raise ValueError(f"method {name!r} is already registered; pass replace=True")
    BUILDERS[name] = builder


def build(method, grid=None, **options):
    """The :class:`MethodSpec` of a registered method.

    Parameters
    ----------
    method : str
        A key of :data:`BUILDERS`.
    grid : Grid, optional
        Map simulated and matched against; default :func:`default_grid`.
    **options
        ``drift_deg`` (degrees of arc), ``noise`` (map units), ``n_fixes``; None
        keeps the method's default.

    Returns
    -------
    MethodSpec
    """
    if method not in BUILDERS:
        raise ValueError(f"method must be one of {sorted(BUILDERS)}; got {method!r}")
    return BUILDERS[method](default_grid() if grid is None else grid, **options)
