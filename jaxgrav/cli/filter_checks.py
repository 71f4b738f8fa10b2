"""Checks of ``jaxgrav filter``'s inputs and of what its readings can tell.

The one-line errors of :mod:`jaxgrav.cli.filter` (particle count, standard
deviations, the track on the map, a pmf grid the map cannot resolve), the map as the
filters evaluate it at the INS positions, and two warnings that a run cannot give a
trustworthy answer: a map too flat to tell the position (:func:`information_warning` from
:func:`gradient_at_ins`) and readings offset from the map by more than the filter's
gravimeter bias allows (:func:`offset_warning`).
"""

import math
import os

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav.cli.match_search import unresolved
from jaxgrav.constants import DEG
from jaxgrav.filters import map_anomaly
from jaxgrav.filters.api import PMF_SPAN_SIGMA
from jaxgrav.scenarios import INS_GRADES
from jaxgrav.track_units import unit_of
from jaxgrav.tracks import csv_line

__all__ = [
    "BYTES_PER_PARTICLE",
    "MAX_SIGMA_POS_M",
    "MAX_SIGMA_VEL",
    "MEMORY_SHARE",
    "MIN_PARTICLES",
    "OFFSET_FLOOR",
    "OFFSET_SIGMAS",
    "check_on_map",
    "check_particles",
    "check_pmf_span",
    "check_positive",
    "check_sigma",
    "check_sigma_pos",
    "check_sigma_vel",
    "check_velocity_columns",
    "extent_text",
    "gradient_at_ins",
    "information_warning",
    "ins_label",
    "map_at_ins",
    "memory_budget",
    "memory_bytes",
    "offset_warning",
    "speed_course_warning",
]

MIN_PARTICLES = 100
"""Fewest particles ``--particles`` takes (``filter`` and ``navigate``): with fewer, the
particles cannot represent the position's posterior and the filter degenerates with no
flag (paper D's track, rbpf: 2 to 30 particles ended 1.5-1.9 km off with a 1-sigma of
12-44 m; 100 particles 0.3 km with 0.6 km). The SIR pf needs more for a 1-sigma to
trust (NEES 15 at 300, 2.2 at 1000, 2 expected); its default is 2000."""

OFFSET_SIGMAS = 5.0
"""Readings whose median offset from the map exceeds this many 1-σ of what the filter
allows for it (gravimeter bias, map error, the noise of the median) are warned of."""
OFFSET_FLOOR = 25.0
"""... and at least this offset (mGal): the map at a wrong INS position differs too (paper
D's track, INS 2 km off: a median of 2.5 mGal; along a slope of 5 mGal/km, 3 km off: 15)."""


BYTES_PER_PARTICLE = 700.0
"""Memory a particle takes in a run of ``pf`` or ``rbpf`` (bytes): the growth of the
process's peak resident memory from 1000 to 1.6 million particles (filter pf 620-660 B,
rbpf 550-570 B, navigate rbpf 450 B a particle, 13-15 states in float64: the state and
its moved, drawn, weighed and resampled copies), rounded up."""

_BASELINE_BYTES = 0.5e9  # a filter run with few particles (JAX, the map, the program)


MEMORY_SHARE = 0.8
"""Share of the machine's physical memory a command's run may need; beyond it the
command refuses before any work (``--particles``, ``match``'s fixes, ``montecarlo``'s
``--fixes`` and ``--chunk``)."""


def memory_bytes():
    """The machine's physical memory (bytes), or None where it cannot be read."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def memory_budget():
    """``(budget, total)``: :data:`MEMORY_SHARE` of the machine's memory and the memory
    itself (bytes), or ``(None, None)`` where it cannot be read (nothing is refused)."""
    total = memory_bytes()
    return (MEMORY_SHARE * total, total) if total else (None, None)


def check_particles(n):
    """ValueError naming ``--particles`` for a count below :data:`MIN_PARTICLES`, or one
    whose particles (:data:`BYTES_PER_PARTICLE`) need more than 80 % of the machine's
    memory: refused before the filter is compiled (1e8 particles ran out of memory
    after compiling, exit 1)."""
    if n < MIN_PARTICLES:
        raise ValueError(f"--particles must be an integer >= {MIN_PARTICLES} (fewer cannot "
                         f"represent the position's posterior); got {n}")
    (budget, total), need = memory_budget(), _BASELINE_BYTES + BYTES_PER_PARTICLE * n
    if budget and need > budget:
        fit = int((budget - _BASELINE_BYTES) // BYTES_PER_PARTICLE)
        raise ValueError(f"--particles {n} needs about {need / 1e9:.3g} GB "
                         f"({BYTES_PER_PARTICLE:g} bytes a particle), more than 80 % of this "
                         f"machine's {total / 1e9:.3g} GB of memory; expected at most "
                         f"{fit:d} particles (the defaults are 500 to 2000)")


def ins_label(name):
    """How ``--ins`` and the summary line name an INS grade.

    Parameters
    ----------
    name : str
        A key of :data:`jaxgrav.scenarios.INS_GRADES`.

    Returns
    -------
    str
        E.g. ``"strategic INS (0.001 deg/h gyro, 10 ug accelerometer biases)"``, from
        the model's own values.
    """
    model = INS_GRADES[name]  # rad/s and m/s² (1 ug = 9.80665e-6 m/s²)
    return (f"{name} INS ({model.gyro_sigma / DEG * 3600.0:.3g} deg/h gyro, "
            f"{model.accel_sigma / 9.80665e-6:.3g} ug accelerometer biases)")


def check_positive(name, value, unit, allow_zero=False):
    """ValueError naming the option ``name`` unless ``value`` is finite and > 0 (``>= 0``
    with ``allow_zero``); ``unit`` is said in the message."""
    if not (math.isfinite(value) and (value >= 0 if allow_zero else value > 0)):
        sign = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite value {sign} ({unit}); got {value!r}")


MAX_SIGMA_POS_M = 200e3
"""Largest ``--sigma-pos`` (m) of ``filter`` and ``navigate``: an INS unaided for days
drifts tens of km; 1e9 m (and 1e6 m on a map) ran with every sigma point off the map,
exit 0 with a 1-sigma of 1e9 m."""


def check_sigma_pos(value):
    """ValueError naming ``--sigma-pos`` above :data:`MAX_SIGMA_POS_M` (checked positive
    and finite first by the command)."""
    if value > MAX_SIGMA_POS_M:
        raise ValueError(f"--sigma-pos must be at most {MAX_SIGMA_POS_M:.0f} m (200 km: a "
                         "prior wider than that puts the filter's sigma points, particles or "
                         "cells hundreds of km away, off any regional map; an INS unaided "
                         f"for days drifts tens of km); got {value:g}")


MAX_SIGMA_VEL = 50.0
"""Largest ``--sigma-vel`` (m/s) of ``filter`` and ``navigate``: 50 m/s (97 knots), above
the speed of the ships and submarines the filters follow; 1e9 m/s ran, exit 0, with the
covariance failing on 596 of 601 rows and a 1-sigma of 17 600 km."""


def check_sigma_vel(value):
    """ValueError naming ``--sigma-vel`` above :data:`MAX_SIGMA_VEL` (checked positive and
    finite first by the command)."""
    if value > MAX_SIGMA_VEL:
        raise ValueError(f"--sigma-vel must be at most {MAX_SIGMA_VEL:g} m/s (97 knots, "
                         "above the speed of the vessels the filters follow; an INS starts "
                         f"within about 0.01-1 m/s); got {value:g}")


def check_velocity_columns(track, where):
    """ValueError when a track holds one INS velocity column without the other (it was
    taken as having none: raw readings matched or filtered as Eötvös-corrected, the
    column dropped) or a velocity column with empty cells (``filter`` skipped the
    readings there, without a word)."""
    given = [k for k in ("v_east", "v_north") if k in track]
    if len(given) == 1:
        other = "v_north" if given == ["v_east"] else "v_east"
        raise ValueError(f"{where} has a {given[0]} column but no {other}; give both INS "
                         f"velocity columns (m/s; name them with --columns {other}=COLUMN) or "
                         "neither (readings then taken as Eötvös-corrected)")
    for k in given:
        bad = np.flatnonzero(~np.isfinite(np.asarray(track[k], float)))
        if bad.size:
            raise ValueError(f"{where}, line {track.line(int(bad[0]))}, column "
                             f"{(track.renamed or {}).get(k, k)!r}: no velocity ({bad.size} "
                             "such row(s)); the INS velocity columns must be complete")


_SPEEDS = ("speed", "sog", "speed_over_ground", "spd", "ground_speed")
_COURSES = ("course", "cog", "course_over_ground", "heading", "hdg", "true_heading")


def speed_course_warning(track, where):
    """A warning when a track without ``v_east``/``v_north`` has a speed and a course column
    (``sog``, ``cog``: a ship's log): its readings are taken as Eötvös-corrected, which
    raw ones are not (75 mGal off at 10 kn east on the equator, in silence); else None."""
    if "v_east" in track or "v_north" in track:
        return None
    names = {unit_of(k)[0].strip().lower(): k for k in (track.order or ())}
    speed = next((names[k] for k in _SPEEDS if k in names), None)
    course = next((names[k] for k in _COURSES if k in names), None)
    if speed is None or course is None:
        return None
    return (f"{where} has speed ({speed!r}) and course ({course!r}) columns but no v_east, "
            "v_north: its readings are taken as Eötvös-corrected; if they are raw, add "
            "v_east = speed x sin(course) and v_north = speed x cos(course) in m/s")


def check_sigma(name, value):
    """ValueError naming the option ``name`` unless ``value`` is a positive, finite σ."""
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive, finite standard deviation; got {value!r}")


_map_anomaly = jax.jit(map_anomaly)  # the filters' own map evaluation, one compile per field


def map_at_ins(field, lat, lon):
    """The map (or point-mass model) at the INS positions, as the filters evaluate it
    (:func:`~jaxgrav.filters.map_anomaly`; mGal, NaN off a map or in a cell with a missing
    node), shape of ``lat``."""
    return np.asarray(_map_anomaly(field, jnp.asarray(lat), jnp.asarray(lon)))


def check_pmf_span(field, sigma_pos, lat, lon, g, sigma_gravity):
    """ValueError for a pmf grid (±``PMF_SPAN_SIGMA`` ``--sigma-pos``, the region it
    searches, fixed) across which the map cannot tell positions apart (``--sigma-pos
    1e-9`` wrote a 1-sigma of 0 m, every row at the grid's edge), by the rule of
    ``match --drift-radius`` (:func:`~jaxgrav.cli.match_search.unresolved`): a map's
    steepest slope, a point-mass model's steepest gradient at the readings' INS
    positions (``lat``, ``lon``, ``g``: the log's columns, degrees and mGal)."""
    span = 2.0 * PMF_SPAN_SIGMA * sigma_pos
    read = np.isfinite(g)
    slope = None
    if not hasattr(field, "values"):  # point masses: no nodes to difference
        north, east = gradient_at_ins(field, lat[read], lon[read])
        slope = float(np.nanmax(np.hypot(north, east), initial=0.0))
    text, least_m = unresolved(field if slope is None else None, span, int(read.sum()),
                               sigma_gravity, "--sigma-gravity", slope=slope)
    if text is not None:
        raise ValueError(f"--sigma-pos {sigma_pos:g} m makes pmf's grid {span:.3g} m across "
                         f"(±{PMF_SPAN_SIGMA:g} sigma, the region it searches), across which "
                         f"{text}: no cell could be told from another; expected a --sigma-pos "
                         f"of at least {least_m / (2.0 * PMF_SPAN_SIGMA):.2g} m (the other "
                         "methods grow their 1-sigma from any start)")


def gradient_at_ins(field, lat, lon, step_m=500.0):
    """The map's north and east gradient at the INS positions (mGal/m, each the shape of
    ``lat``), central differences over ``step_m`` (m) each way."""
    dlat = step_m / 111195.0
    dlon = dlat / np.cos(np.radians(lat))
    return ((map_at_ins(field, lat + dlat, lon) - map_at_ins(field, lat - dlat, lon))
            / (2 * step_m),
            (map_at_ins(field, lat, lon + dlon) - map_at_ins(field, lat, lon - dlon))
            / (2 * step_m))


def information_warning(grad_north, grad_east, noise, sigma_ref):
    """A warning when the readings cannot tell the position better than the filter's own
    1-σ, or None (``filter`` and ``navigate``, tightly coupled, after the run).

    The bound is optimistic: the position's Fisher information from every reading of the
    map's gradient, as if the readings' errors were independent (a correlated map error
    is not), the bias known and the position the same for the whole track,
    ``σ = noise / sqrt(λ_min(Σ ∇g ∇gᵀ))`` in the weakest direction. When even that
    exceeds ``sigma_ref`` (the largest 1-σ of the run, or the prior) the readings cannot
    correct the INS: a point-mass model hundreds of km away, a map flat against its
    error, or a map that varies across one bearing only.

    Parameters
    ----------
    grad_north, grad_east : array_like, shape ``(N,)``
        The map's gradient at the readings' INS positions (mGal/m; NaN: left out).
    noise : float
        A reading's error, 1-σ (mGal): its noise and the map's error together.
    sigma_ref : float
        The 1-σ (m) the readings would have to beat.
    """
    gn, ge = np.asarray(grad_north, float), np.asarray(grad_east, float)
    ok = np.isfinite(gn) & np.isfinite(ge)
    n = int(ok.sum())
    if n == 0:
        return None
    info = np.array([[np.sum(gn[ok] ** 2), np.sum(gn[ok] * ge[ok])],
                     [np.sum(gn[ok] * ge[ok]), np.sum(ge[ok] ** 2)]])
    lam, vec = np.linalg.eigh(info)
    sigma = noise / math.sqrt(lam[0]) if lam[0] > 0 else math.inf
    if sigma <= sigma_ref:
        return None
    bearing = math.degrees(math.atan2(vec[1, 0], vec[0, 0])) % 180.0
    steepest = float(np.sqrt(np.max(gn[ok] ** 2 + ge[ok] ** 2))) * 1e3
    return (f"the map along the track cannot tell the position: even {n} independent "
            f"readings of {noise:.3g} mGal on its gradients (steepest "
            f"{steepest:.3g} mGal/km) would fix it only to {sigma:.3g} m along bearing "
            f"{bearing:.0f}°, more than the filter's own 1-sigma ({sigma_ref:.0f} m): "
            "there its track is the INS's")


def offset_warning(readings, expected, bias_sigma, map_error_sigma, noise):
    """A warning when the readings sit further from the map than the filter allows, or None.

    The filter explains a constant offset of the readings by its gravimeter-bias state,
    whose prior is ``bias_sigma``; an offset far beyond it (an untied gravimeter, another
    datum) is explained by moving the position instead (paper D's track with +250 mGal
    ended 36 km off). Warned when the median of ``readings − expected`` exceeds
    :data:`OFFSET_SIGMAS` × ``sqrt(bias² + map_error² + (1.25 noise)² / K)`` and
    :data:`OFFSET_FLOOR`.

    Parameters
    ----------
    readings, expected : array_like, shape ``(N,)``
        Eötvös-corrected readings and the map at the INS positions (mGal; NaN: left out).
    bias_sigma, map_error_sigma, noise : float
        1-σ of the gravimeter-bias prior, of the map error told and of a reading (mGal).
    """
    d = np.asarray(readings, float) - np.asarray(expected, float)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return None
    offset = float(np.median(d))
    allowed = math.sqrt(bias_sigma**2 + map_error_sigma**2 + (1.25 * noise) ** 2 / d.size)
    if abs(offset) <= max(OFFSET_SIGMAS * allowed, OFFSET_FLOOR):
        return None
    return (f"the readings sit {offset:+.4g} mGal from the map along the INS track (median "
            f"of {d.size}), {abs(offset) / allowed:.0f} × the 1-sigma the filter allows for "
            f"a constant offset ({allowed:.3g} mGal: gravimeter bias {bias_sigma:g}, map "
            f"error {map_error_sigma:g}); a datum or an untied gravimeter? subtract the "
            "offset from the gravity column, or the filter moves the position to explain it")


def check_on_map(grid, lat, lon, where, name, line=csv_line):
    """ValueError naming the first of the INS positions off the map ``--map name``
    (``line``: row index → the file's line, e.g. a reader's ``TrackTable.line``)."""
    inside = np.asarray(grid.contains(lat, lon))
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        raise ValueError(
            f"{where}: {int((~inside).sum())} of {lat.size} positions are off the map --map "
            f"{name} ({extent_text(grid)}), first on line {line(i)} "
            f"(lat {lat[i]:g}, lon {lon[i]:g}){_off_map_hint(grid, lat, lon, inside)}")


def _off_map_hint(grid, lat, lon, inside):
    """Why a whole track is off the map when it is plain: in radians (``lat (rad)`` not
    declared), or its latitudes and longitudes swapped; else ``""``."""
    if inside.any():
        return ""
    if np.asarray(grid.contains(np.degrees(lat), np.degrees(lon))).all():
        return ("; in degrees these numbers would lie on the map: are they radians? declare "
                "the unit in the header, e.g. 'lat (rad)' and 'lon (rad)'")
    if np.asarray(grid.contains(lon, lat)).all():
        return ("; with latitude and longitude swapped they would lie on the map: are the "
                "columns swapped? name them with --columns lat=COLUMN,lon=COLUMN")
    return ""


def extent_text(grid):
    """A map's extent as a message says it, e.g. ``"lat 24..36, lon 124..136"`` (degrees)."""
    w, e, s, n = (float(v) for v in grid.extent)
    return f"lat {s:g}..{n:g}, lon {w:g}..{e:g}"
