"""Methods the Monte Carlo runner knows by name: scenario + matcher/filter + errors per run.

Each entry of :data:`BUILDERS` maps a method name to a *builder*::

    builder(grid, *, drift_deg=None, noise=None, n_fixes=None, map_error=None) -> MethodSpec

``None`` means the method's own default; for ``grid`` that is the shipped ``ryukyu``
2.5′ map for the matchers and paper D's three point masses for the filters. The
spec's ``fn(key, *args)`` simulates and solves one run and returns a dict of per-run
metrics, at least :data:`METRICS`:

``ins_err_m``  horizontal error of the INS-indicated track (m): the mean distance from
               the truth for the matchers; the RMS over the second half of the run
               for the filters
``err_m``      the same for the method's estimated track (m)
``status``     the method's status bit field (0 = clean; int32)

Matchers: ``dense`` (paper A, dense offsets; ``correlation`` is its deprecated name,
still accepted with a :class:`DeprecationWarning`), ``chains`` (paper A's iso-point
chains on the map refined to 0.005° nodes), ``entropy``, ``iccp`` and
``entropy+iccp`` (paper B, each stage alone and combined).

The paper-D filters (``ukf``, ``ekf``, ``gsf``, ``pmf`` and the guarded ``ukf-guard``,
``gsf-guard``) also return ``nees``, the mean position NEES over the second half of the
run (expected value 2); they run over paper D's point masses, or over a map (straight
tracks in random directions).

Voyages (:mod:`~jaxgrav.montecarlo.voyage_runs`): ``voyage-dense``, ``voyage-chains``,
``voyage-entropy+iccp`` (loosely coupled, hourly fixes of that matcher) and
``voyage-ukf``, ``voyage-ekf``, ``voyage-gsf``, ``voyage-rbpf``, ``voyage-pmf`` (tightly
coupled) navigate 12 h patrols; ``ins_err_m`` and ``err_m`` are the last hour's RMS, and
they return the hourly RMS and error series too.

``fn`` must be a module-level function (not a fresh closure), so that repeated runs
reuse the compiled code; everything a user may sweep goes into ``args``.

Adding a method
---------------
One entry, ``BUILDERS["name"] = builder`` or ``register("name", builder)``;
``jaxgrav montecarlo --method`` lists the keys of :data:`BUILDERS`.
"""

import functools
import warnings

from jaxgrav.montecarlo.filter_runs import (
    FILTER_METHODS,
    ekf_run,
    filter_builder,
    gsf_guard_run,
    gsf_run,
    pmf_run,
    ukf_guard_run,
    ukf_run,
)
from jaxgrav.montecarlo.matcher_runs import (
    chains_builder,
    chains_run,
    dense_builder,
    dense_run,
    entropy_iccp_builder,
    entropy_iccp_run,
    entropy_run,
    iccp_run,
    paper_b_builder,
)
from jaxgrav.montecarlo.spec import METRICS, MethodSpec, default_grid
from jaxgrav.montecarlo.voyage_runs import BUILDERS as VOYAGE_BUILDERS
from jaxgrav.montecarlo.voyage_runs import VOYAGE_METHODS, voyage_dense_run, voyage_tight_run

__all__ = [
    "BUILDERS",
    "DEPRECATED_METHODS",
    "FILTER_METHODS",
    "METRICS",
    "VOYAGE_METHODS",
    "MethodSpec",
    "build",
    "chains_run",
    "default_grid",
    "dense_run",
    "ekf_run",
    "entropy_iccp_run",
    "entropy_run",
    "filter_builder",
    "gsf_guard_run",
    "gsf_run",
    "iccp_run",
    "pmf_run",
    "register",
    "resolve_method",
    "ukf_guard_run",
    "ukf_run",
    "voyage_dense_run",
    "voyage_tight_run",
]

BUILDERS = {
    "dense": dense_builder,
    "chains": chains_builder,
    "entropy": functools.partial(paper_b_builder, stage="entropy"),
    "iccp": functools.partial(paper_b_builder, stage="iccp"),
    "entropy+iccp": entropy_iccp_builder,
    **{k: functools.partial(filter_builder, kind=k) for k in FILTER_METHODS},
    **VOYAGE_BUILDERS,
}
"""Method name -> builder."""

DEPRECATED_METHODS = {"correlation": "dense"}
"""Old method name -> registered name; accepted for one release with a DeprecationWarning."""

WARNED_ALIASES = set()
"""Deprecated names already warned about in this process (each warns once)."""


def resolve_method(method):
    """The registered name of ``method``: itself, or the new name of a deprecated one.

    A name of :data:`DEPRECATED_METHODS` warns (:class:`DeprecationWarning`) the first
    time it is resolved in a process.

    Raises
    ------
    ValueError
        ``method`` is neither registered nor a deprecated name.
    """
    if method in DEPRECATED_METHODS:
        new = DEPRECATED_METHODS[method]
        if method not in WARNED_ALIASES:
            WARNED_ALIASES.add(method)
            warnings.warn(f"Monte Carlo method {method!r} is deprecated; use {new!r}",
                          DeprecationWarning, stacklevel=3)
        method = new
    if method not in BUILDERS:
        raise ValueError(f"method must be one of {sorted(BUILDERS)}; got {method!r}")
    return method


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
        A key of :data:`BUILDERS` (or a deprecated name, :func:`resolve_method`).
    grid : Grid, optional
        Map simulated and matched (or filtered) against; None: the method's default
        (:func:`default_grid` for the matchers, paper D's point masses for the filters).
    **options
        ``drift_deg`` (degrees of arc), ``noise`` (map units), ``n_fixes``; None
        keeps the method's default. ``map_error`` (a ``CorrelatedMapError``, a
        ``TruthGrid`` or None): the readings' map error, drawn per run (see
        :func:`~jaxgrav.montecarlo.matcher_runs.dense_builder`); passed to the builder
        only when not None, so builders without the keyword still build the
        perfect-map case. ``map_error_told`` (``dense`` only): the map error the matcher
        is told; default ``"auto"`` (the readings' model, or for a truth grid an
        estimate from the map), None for the white-noise matcher
        (:func:`~jaxgrav.montecarlo.matcher_runs.dense_builder`).

    Returns
    -------
    MethodSpec
    """
    if options.get("map_error", 0) is None:
        options = {k: v for k, v in options.items() if k != "map_error"}
    return BUILDERS[resolve_method(method)](grid, **options)


DEPRECATED_NAMES = {"correlation_run": "dense_run"}
"""Old function name -> new name (kept for one release)."""


def __getattr__(name):
    if name in DEPRECATED_NAMES:
        new = DEPRECATED_NAMES[name]
        warnings.warn(f"jaxgrav.montecarlo.methods.{name} is deprecated; use {new}",
                      DeprecationWarning, stacklevel=2)
        return globals()[new]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
