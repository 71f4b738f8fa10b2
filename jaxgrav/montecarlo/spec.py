"""What a Monte Carlo method is: :class:`MethodSpec`, the metrics of every run, checks."""

from collections.abc import Callable

import numpy as np

from jaxgrav import datasets
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.fields.map_error import CorrelatedMapError, TruthGrid
from jaxgrav.fields.map_error_estimate import estimate_map_error
from jaxgrav.scenarios.paper_a import check_region_covered
from jaxgrav.xla_options import CPU_OPTIONS, FUSION_EMITTER_OPTIONS

__all__ = ["METRICS", "MethodSpec", "check_map_error", "check_settings", "cpu_options_for",
           "default_grid",
           "map_error_settings", "region_of", "told_map_error", "told_settings"]

METRICS = ("ins_err_m", "err_m", "status")
"""Metrics every method returns per run."""


@pytree_dataclass
class MethodSpec:
    """A method ready for :func:`jaxgrav.montecarlo.run`.

    A pytree whose only data field is ``args`` (the rest is static).

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
    cpu_options : tuple of (str, value)
        XLA options to compile ``fn``'s runs with on CPU (``run(..., cpu_options=)``):
        :data:`jaxgrav.xla_options.CPU_OPTIONS`, or another set of
        :mod:`jaxgrav.xla_options` for a method measured faster with it
        (:func:`cpu_options_for`).
    """

    fn: Callable = static_field()
    args: tuple
    settings: dict = static_field()
    status_bits: dict = static_field()
    cpu_options: tuple = static_field(default=CPU_OPTIONS)


def cpu_options_for(kind):
    """XLA options on CPU of a method's runs (:attr:`MethodSpec.cpu_options`).

    :data:`~jaxgrav.xla_options.CPU_OPTIONS` (LLVM ``-O2``, XLA's elemental kernel
    emitters), except the point-mass filter's (``pmf``, ``voyage-pmf``) and the voyages'
    Rao–Blackwellised particle filter's (``voyage-rbpf``):
    :data:`~jaxgrav.xla_options.FUSION_EMITTER_OPTIONS` (``-O2``, XLA's fusion emitters),
    since their runs were 28 % (``pmf``) and 65 % (``voyage-rbpf``) slower with the
    elemental emitters (16 runs in one chunk, twice; ``python
    benchmarks/montecarlo_scaling.py --compile-only --against emitters`` measures it).
    Since ``voyage-rbpf``'s steps stopped joining positions and means into one array
    (2026-12-08) the gap is smaller: 16 patrols of 12 h, 7.68 s with the elemental
    emitters against 6.44 s with the fusion emitters, compile 8.54 against 8.94 s (load
    ~1; half-hour voyages at load ~11 had shown 0.50 against 0.54 s CPU the other way),
    so it keeps the fusion emitters. The paper-D ``rbpf`` took the fusion emitters until
    2026-12-07, when its predicted readings became one dot
    (:func:`~jaxgrav.filters.rbpf`): with the elemental emitters its 16 runs then took
    3.2 s CPU against 4.2 s before with the fusion emitters, and XLA compiled them in half
    the CPU time (5.2 against 10 s).
    """
    if kind == "voyage-rbpf" or kind.removeprefix("voyage-") == "pmf":
        return FUSION_EMITTER_OPTIONS
    return CPU_OPTIONS


def default_grid():
    """The shipped 2.5′ ``ryukyu`` gravity anomaly map (mGal), 24–36°N, 124–136°E."""
    return datasets.load("ryukyu")["anomaly_2p5min"]


def region_of(grid):
    """``(south, north, west, east)`` of a map (degrees), as scenarios take a region."""
    w, e, s, n = grid.extent
    return (float(s), float(n), float(w), float(e))


def check_settings(drift, noise, n):
    """One clear error for a non-positive drift, a negative noise or fewer than 5 fixes."""
    if not 0 < drift < float("inf"):
        raise ValueError(f"drift must be a positive angle (degrees of arc); got {drift!r}")
    if not 0 <= noise < float("inf"):
        raise ValueError(f"noise must be a non-negative standard deviation (mGal); got {noise!r}")
    if n < 5:
        raise ValueError(f"fixes must be at least 5 per track; got {n}")


def check_map_error(map_error, grid):
    """The map-error model a builder simulates with (validated), or None.

    Parameters
    ----------
    map_error : CorrelatedMapError, TruthGrid or None
        A CorrelatedMapError must have scalar σ and L; σ = 0 (a perfect map) becomes
        None, so that the runs are exactly the perfect-map runs. A TruthGrid must
        cover ``grid``'s area.
    grid : Grid
        The map the method uses.

    Returns
    -------
    CorrelatedMapError, TruthGrid or None

    Raises TypeError for another type, ValueError for a TruthGrid that does not cover
    the map or a non-scalar σ or L.
    """
    if map_error is None:
        return None
    if isinstance(map_error, TruthGrid):
        check_region_covered(map_error.grid, region_of(grid), "the truth map (map_error.grid)")
        return map_error
    _check_scalar_model(map_error, "map_error must be a CorrelatedMapError (fields.map_error."
                        "map_error(sigma, length_m)), a TruthGrid or None",
                        "map_error.sigma and map_error.length_m")
    return None if float(map_error.sigma) == 0 else map_error


def map_error_settings(map_error):
    """Settings entries describing a map-error model (for a spec's ``settings``).

    ``map_error_sigma`` (map units; 0 for a perfect map), ``map_error_length_m``,
    ``map_error_family``; for a TruthGrid ``truth_map`` (its grid's name) and, if it
    states one, its error's σ and L.
    """
    if map_error is None:
        return dict(map_error_sigma=0.0)
    out = {}
    if isinstance(map_error, TruthGrid):
        out["truth_map"] = map_error.grid.name or "explicit truth grid"
        map_error = map_error.error
        if map_error is None:
            return out
    out.update(map_error_sigma=float(map_error.sigma),
               map_error_length_m=float(map_error.length_m),
               map_error_family=map_error.family)
    return out


def told_map_error(told, map_error, grid):
    """The map-error model a matcher is told, and where it comes from.

    Parameters
    ----------
    told : "auto", CorrelatedMapError or None
        ``"auto"``: ``map_error`` itself if it is a CorrelatedMapError; for a TruthGrid
        its stated ``error``, else
        :func:`~jaxgrav.fields.map_error_estimate.estimate_map_error` of ``grid`` (the
        map alone); None for a perfect map. None or σ = 0: none (white-noise matcher).
        A CorrelatedMapError: itself (scalar σ and L, validated by
        :func:`~jaxgrav.fields.map_error.map_error`).
    map_error : CorrelatedMapError, TruthGrid or None
        The readings' map error (:func:`check_map_error`'s result).
    grid : Grid
        The map the matcher uses.

    Returns
    -------
    model : CorrelatedMapError or None
    source : str
        ``"none"``, ``"same as the readings"``, ``"truth map's stated error"``,
        ``"estimated from the map"`` or ``"given"``.
    """
    if isinstance(told, str):
        if told != "auto":
            raise ValueError(f"map_error_told must be 'auto', a CorrelatedMapError or None; "
                             f"got {told!r}")
        if map_error is None:
            return None, "none"
        if isinstance(map_error, TruthGrid):
            if map_error.error is not None and float(map_error.error.sigma) > 0:
                return map_error.error, "truth map's stated error"
            return estimate_map_error(grid).model, "estimated from the map"
        return map_error, "same as the readings"
    if told is None:
        return None, "none"
    _check_scalar_model(told, "map_error_told must be 'auto', a CorrelatedMapError "
                        "(fields.map_error.map_error(sigma, length_m)) or None",
                        "map_error_told.sigma and .length_m")
    return (None, "none") if float(told.sigma) == 0 else (told, "given")


def told_settings(told, source):
    """Settings entries of the told model: ``told_map_error_sigma`` (0: white-noise
    matcher), ``told_map_error_length_m`` (when σ > 0), ``told_map_error_source``."""
    if told is None:
        return dict(told_map_error_sigma=0.0, told_map_error_source=source)
    return dict(told_map_error_sigma=float(told.sigma),
                told_map_error_length_m=float(told.length_m),
                told_map_error_family=told.family, told_map_error_source=source)


def _check_scalar_model(model, expected, fields):
    """TypeError unless ``model`` is a CorrelatedMapError; ValueError unless σ, L scalar.

    ``expected`` is the message's "<name> must be ..." part, ``fields`` names σ and L.
    """
    if not isinstance(model, CorrelatedMapError):
        raise TypeError(f"{expected}; got {type(model).__name__}")
    if np.ndim(model.sigma) or np.ndim(model.length_m):
        raise ValueError(f"{fields} must be scalars; got shapes {np.shape(model.sigma)}, "
                         f"{np.shape(model.length_m)}")
