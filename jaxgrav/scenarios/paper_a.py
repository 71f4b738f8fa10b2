"""Ready-made simulation scenarios, one PRNG key in, one run out (vmap them).

``matching_scenario`` is paper A's experiment: a ship at constant velocity, an INS
whose error is a (nearly) constant offset, gravimeter readings of a true field.
It is what the demo, the paper-A example, the benchmarks and the Monte Carlo runner
simulate, so that they all mean the same thing by "a track".
"""

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import sim
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import concrete
from jaxgrav.constants import DEG, KNOT, WGS84_A
from jaxgrav.fields import map_error as map_errors
from jaxgrav.fields.map_error import CorrelatedMapError, TruthGrid, map_error_key
from jaxgrav.geodesy import meridian_radius
from jaxgrav.grid import Grid

__all__ = ["POLE_LIMIT_DEG", "MatchingRun", "MatchingScenario", "check_region_covered",
           "check_start_tries", "first_clear_draw", "matching_scenario", "max_fixes",
           "placement_region", "scenario_truth"]


def check_start_tries(value):
    """Raise ``ValueError`` unless ``value`` (a scenario's ``start_tries``) is an int >= 1."""
    if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
        raise ValueError(f"start_tries must be an integer >= 1; got {value!r}")


@pytree_dataclass
class MatchingScenario:
    """Paper A's matching experiment.

    Attributes
    ----------
    region : tuple of float
        ``(lat_min, lat_max, lon_min, lon_max)`` where tracks may start (degrees);
        static.
    v_east, v_north : float
        Ship velocity (m/s); paper A: 10 kn each.
    dt : float
        Interval between fixes (s).
    drift_deg : float
        INS drift radius (degrees of arc): fixed size, or Rayleigh scale σ.
    drift_growth, drift_rotation_deg : float
        Growth and rotation of the drift along the track (0 = exactly parallel).
    noise_mgal, bias_mgal : float
        Reading noise σ and constant gravimeter bias (mGal).
    n_fixes : int
        Fixes per track (static).
    drift_law : {"fixed", "rayleigh"}
        Static.
    eotvos : {"full", "simple", None}
        Eötvös effect in the readings (static).
    truth_method : {"bicubic", "bilinear"}
        Interpolation of a Grid truth field (static).
    start_lat, start_lon : float
        A fixed start of the true track (degrees; traced, so a batch may give every run
        its own, e.g. the cells of a suitability map). NaN (default): uniform in
        ``region`` with the margin. A start given does not have to leave that margin;
        a track that leaves the map gives NaN readings, which the matchers flag.
    start_tries : int
        Random starts tried per run (static, default 1): the first whose true track
        reads no missing (NaN) node of the truth field is taken, the first draw being
        the one of a single try (so runs on a complete map are the same for any
        value); for maps with land masked. A run none of whose tries is clear keeps
        the first, and its NaN readings say so.
    """

    region: tuple = static_field((24.0, 36.0, 124.0, 136.0))
    v_east: float = 10 * KNOT
    v_north: float = 10 * KNOT
    dt: float = 120.0
    drift_deg: float = 0.035
    drift_growth: float = 0.0
    drift_rotation_deg: float = 0.0
    noise_mgal: float = 1.0
    bias_mgal: float = 0.0
    n_fixes: int = static_field(30)
    drift_law: str = static_field("fixed")
    eotvos: str = static_field("full")
    truth_method: str = static_field("bicubic")
    start_lat: float = float("nan")
    start_lon: float = float("nan")
    start_tries: int = static_field(1)

    def __post_init__(self):
        check_start_tries(self.start_tries)
        lat, lon = concrete(self.start_lat), concrete(self.start_lon)
        if lat is None or lon is None or lat.dtype == object or lon.dtype == object:
            return  # traced, or a pytree placeholder
        given = np.isfinite(lat), np.isfinite(lon)
        if np.any(given[0] != given[1]) or np.any(np.isinf(lat)) or np.any(np.isinf(lon)):
            raise ValueError("start_lat and start_lon must both be finite (a fixed start, "
                             f"degrees) or both NaN (a random start); got {lat}, {lon}")
        if np.any(np.abs(lat[given[0]]) > 90.0):
            raise ValueError(f"start_lat must be within -90..90 degrees; got {lat}")

    @property
    def step_m(self):
        """Distance between consecutive fixes (m)."""
        return float(np.hypot(self.v_east, self.v_north) * self.dt)


class MatchingRun(NamedTuple):
    """One simulated run: true track, INS fixes, readings and the drift."""

    truth: sim.Track
    ins_lat: jax.Array
    ins_lon: jax.Array
    readings: jax.Array
    drift_north_m: jax.Array
    drift_east_m: jax.Array


POLE_LIMIT_DEG = 89.0
"""Latitude (degrees, either hemisphere) beyond which :func:`placement_region` places no
track: a region reaching a pole is cut there."""


def placement_region(scenario):
    """``scenario.region`` narrowed so that every track :func:`matching_scenario` draws stays in it.

    :func:`matching_scenario` keeps the start its track's span plus 1.5 ``drift_deg``
    from each edge, the span counted on a sphere (mean radius; longitudes at the region's
    northern edge). The track itself is sailed on the ellipsoid, where a degree of
    latitude is up to 0.5 % shorter: a long track, or one with a small drift margin, can
    then end beyond the edge (off the map: NaN readings). The region returned is the
    scenario's less that excess at each edge where it is larger than the 1.5
    ``drift_deg`` margin, so the scenario's draws are unchanged whenever the margin
    already covers it (the usual case). A region reaching beyond ±:data:`POLE_LIMIT_DEG`
    (a global map) is first cut there: at a pole a degree of longitude has no length,
    and :func:`matching_scenario` spans longitudes at the region's northern edge.

    Parameters
    ----------
    scenario : MatchingScenario
        Concrete ``v_east``, ``v_north``, ``dt`` and ``drift_deg``.

    Returns
    -------
    tuple of float
        ``(lat_min, lat_max, lon_min, lon_max)`` (degrees); possibly empty (min > max)
        when the track cannot fit.
    """
    s = scenario
    lat_min, lat_max, lon_min, lon_max = (float(v) for v in s.region)
    # a map reaching a pole: starts kept within ±89° (east-west spans are finite there)
    lat_min, lat_max = max(lat_min, -POLE_LIMIT_DEG), min(lat_max, POLE_LIMIT_DEG)
    span = (s.n_fixes - 1) * float(s.dt)
    low = 0.0 if lat_min <= 0.0 <= lat_max else min(abs(lat_min), abs(lat_max))
    high = max(abs(lat_min), abs(lat_max))
    margin = 1.5 * float(s.drift_deg)
    north_m, east_m = abs(float(s.v_north)) * span, abs(float(s.v_east)) * span
    over_lat = north_m * (1.0 / (float(meridian_radius(low)) * DEG) - 1.0 / sim.DEG_ARC_M)
    over_lon = east_m * (1.0 / (WGS84_A * np.cos(high * DEG) * DEG)
                         - 1.0 / (sim.DEG_ARC_M * np.cos(lat_max * DEG)))
    d_lat, d_lon = max(0.0, over_lat - margin), max(0.0, float(over_lon) - margin)
    return (lat_min + d_lat, lat_max - d_lat, lon_min + d_lon, lon_max - d_lon)


def max_fixes(scenario):
    """The largest ``n_fixes`` whose tracks fit in ``scenario.region`` (see
    :func:`placement_region`): a start is left for the span and the drift margin.

    Parameters
    ----------
    scenario : MatchingScenario
        Concrete ``v_east``, ``v_north``, ``dt`` and ``drift_deg``; its ``n_fixes`` is
        not used.

    Returns
    -------
    int
        0 when not even two fixes fit; capped at 10**9 for a track that barely moves.
    """
    def fits(n):
        trial = dataclasses.replace(scenario, n_fixes=n)
        lat_min, lat_max, lon_min, lon_max = placement_region(trial)
        span = (n - 1) * float(scenario.dt)
        d_lat = abs(float(scenario.v_north)) * span / sim.DEG_ARC_M
        d_lon = abs(float(scenario.v_east)) * span / (sim.DEG_ARC_M * np.cos(lat_max * DEG))
        room = 3.0 * float(scenario.drift_deg)
        return lat_max - lat_min >= d_lat + room and lon_max - lon_min >= d_lon + room

    lo, hi = 1, 10**9
    if not fits(2):
        return 0
    while hi - lo > 1:  # fits(lo), and hi is beyond the last that fits or the cap
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return hi if fits(hi) else lo


def check_region_covered(grid, region, name="map_error.grid (the truth grid)"):
    """Raise ``ValueError`` naming ``name`` unless Grid ``grid`` covers ``region``.

    ``region`` is ``(lat_min, lat_max, lon_min, lon_max)`` (degrees); the two may use
    different longitude conventions (0–360 or ±180).
    """
    lat_min, lat_max, lon_min, lon_max = (float(v) for v in region)
    w, e, s, n = (float(v) for v in grid.extent)
    tol = 1e-6 * max(grid.dlat, grid.dlon) + 1e-9
    w0 = w + np.mod(lon_min - w, 360.0)  # region's west edge in the grid's range
    if w0 - w > 360.0 - tol:
        w0 -= 360.0
    ok = (lat_min >= s - tol and lat_max <= n + tol and w0 >= w - tol
          and w0 + (lon_max - lon_min) <= e + tol)
    if not ok:
        raise ValueError(
            f"{name} must cover the scenario's region (lat {lat_min:g}..{lat_max:g} deg, lon "
            f"{lon_min:g}..{lon_max:g} deg); got a grid over lat {s:g}..{n:g} deg, lon "
            f"{w:g}..{e:g} deg"
        )


def scenario_truth(key, truth_field, map_error, region):
    """The field a scenario's sensor sees: ``truth_field`` with the map error applied.

    Parameters
    ----------
    key : PRNG key
        The run's key; a :class:`~jaxgrav.fields.map_error.CorrelatedMapError` is drawn
        from :func:`~jaxgrav.fields.map_error.map_error_key` of it, so the run's other
        draws are unchanged.
    truth_field : Grid or callable
        The map (a Grid when ``map_error`` is a CorrelatedMapError), or the truth itself.
    map_error : CorrelatedMapError, TruthGrid or None
        None: ``truth_field`` is the truth (one field for every run, e.g. one drawn once
        per batch); CorrelatedMapError: ``truth_field`` plus an error field drawn per run
        (:func:`~jaxgrav.fields.map_error.truth_field`); TruthGrid: its grid, which must
        cover ``region``.
    region : tuple of float
        ``(lat_min, lat_max, lon_min, lon_max)`` the run stays in (degrees), static.

    Returns
    -------
    Grid or callable
        The truth to sample.

    Raises TypeError for a wrong ``map_error`` type (or a CorrelatedMapError on a
    ``truth_field`` that is not a Grid), ValueError for a TruthGrid that does not cover
    ``region``.
    """
    if map_error is None:
        return truth_field
    if isinstance(map_error, TruthGrid):
        check_region_covered(map_error.grid, region)
        return map_error.grid
    if not isinstance(map_error, CorrelatedMapError):
        raise TypeError("map_error must be a CorrelatedMapError (fields.map_error.map_error"
                        "(sigma, length_m)), a TruthGrid or None; got "
                        f"{type(map_error).__name__}")
    if not isinstance(truth_field, Grid):
        raise TypeError("a CorrelatedMapError is drawn on the map's grid: truth_field must be "
                        f"a Grid; got {type(truth_field).__name__}")
    return map_errors.truth_field(map_error_key(key), truth_field, map_error)


def first_clear_draw(key, first, draw, clear, tries):
    """The first of ``tries`` random draws (``first``, then ``draw`` of keys folded from
    ``key``) that ``clear`` accepts: the start-redraw of a scenario on a map with missing
    (NaN, land-masked) nodes.

    All tries are drawn and checked at once (``vmap``: no loop), and the first clear one
    is picked, so ``first`` is kept whenever it is clear, and runs on a complete map are
    those of a single try. With ``tries`` 1 ``first`` is returned unchanged and nothing
    more is drawn.

    Parameters
    ----------
    key : PRNG key
        The key ``first`` was drawn from; the other ``tries - 1`` draws use the keys of
        ``split(fold_in(key, 1), tries - 1)``.
    first : pytree of Array
        The single try's draw (e.g. a start ``(lat0, lon0)``, or a whole true track).
    draw : callable
        ``draw(key) -> pytree`` shaped as ``first``: one more draw.
    clear : callable
        ``clear(pytree) -> bool Array, shape ()``: the draw's true track reads no missing
        node.
    tries : int
        Draws tried (static, >= 1).

    Returns
    -------
    pytree of Array
        The first clear draw; ``first`` when none is clear (its NaN readings then say
        so).
    """
    check_start_tries(tries)
    if tries == 1:
        return first
    alt = jax.vmap(draw)(jax.random.split(jax.random.fold_in(key, 1), tries - 1))
    every = jax.tree.map(lambda a, b: jnp.concatenate([jnp.asarray(a)[None], b]), first, alt)
    pick = jnp.argmax(jax.vmap(clear)(every))  # 0 when none is clear
    return jax.tree.map(lambda c: c[pick], every)


def matching_scenario(key, truth_field, scenario=MatchingScenario(), map_error=None):  # noqa: B008
    """Simulate one matching run.

    The start point is uniform in ``scenario.region`` with a margin so that the
    whole track stays inside it (or ``scenario.start_lat, start_lon`` when given); the
    drift direction is uniform. The start's draw is made either way, so a run with a
    fixed start draws the same drift, noise and map error as the run of that key
    without it.

    Parameters
    ----------
    key : PRNG key
    truth_field : Grid or callable
        Field the gravimeter senses (mGal), or, with ``map_error``, the map it is
        drawn from.
    scenario : MatchingScenario
    map_error : CorrelatedMapError, TruthGrid or None, optional
        How the truth differs from ``truth_field`` (:func:`scenario_truth`):
        a CorrelatedMapError is drawn once per run from the run's own key
        (``map_error_key(key)``); a TruthGrid is sampled instead of ``truth_field``
        (it must cover ``scenario.region``). None (default): the readings come from
        ``truth_field`` itself, bit-identical to the scenario without this argument;
        for one map-error draw per batch, draw the truth Grid once
        (``fields.map_error.truth_field(key, grid, model)``) and pass it as
        ``truth_field`` with ``map_error=None``.

    Returns
    -------
    MatchingRun
    """
    truth_field = scenario_truth(key, truth_field, map_error, scenario.region)
    k_start, k_drift, k_noise = jax.random.split(key, 3)
    s = scenario
    span = (s.n_fixes - 1) * s.dt
    dlat = abs(s.v_north) * span / sim.DEG_ARC_M
    dlon = abs(s.v_east) * span / (sim.DEG_ARC_M * jnp.cos(jnp.deg2rad(s.region[1])))
    margin = jnp.stack([
        jnp.where(s.v_north >= 0, 0.0, dlat), jnp.where(s.v_north >= 0, dlat, 0.0),
        jnp.where(s.v_east >= 0, 0.0, dlon), jnp.where(s.v_east >= 0, dlon, 0.0),
    ]) + 1.5 * s.drift_deg
    lat0, lon0 = sim.random_start(k_start, s.region, margin)

    def clear(start):
        t = sim.straight_track(*start, s.v_east, s.v_north, s.n_fixes, s.dt)
        return jnp.all(jnp.isfinite(sim.field_along(truth_field, t.lat, t.lon, s.truth_method)))

    lat0, lon0 = first_clear_draw(k_start, (lat0, lon0),
                                  lambda k: sim.random_start(k, s.region, margin), clear,
                                  s.start_tries)
    fixed = jnp.isfinite(s.start_lat) & jnp.isfinite(s.start_lon)
    lat0 = jnp.where(fixed, s.start_lat, lat0)
    lon0 = jnp.where(fixed, s.start_lon, lon0)
    truth = sim.straight_track(lat0, lon0, s.v_east, s.v_north, s.n_fixes, s.dt)
    drift = sim.sample_drift(k_drift, s.drift_deg * sim.DEG_ARC_M, growth=s.drift_growth,
                             rotation_deg=s.drift_rotation_deg, law=s.drift_law)
    dn, de = sim.drift_offsets(drift, s.n_fixes)
    ins_lat, ins_lon = sim.apply_drift(truth.lat, truth.lon, dn, de)
    g = sim.gravity_readings(k_noise, truth_field, truth, noise_mgal=s.noise_mgal,
                             bias_mgal=s.bias_mgal, eotvos_form=s.eotvos, method=s.truth_method)
    return MatchingRun(truth, ins_lat, ins_lon, g, dn, de)
