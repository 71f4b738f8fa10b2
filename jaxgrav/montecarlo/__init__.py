"""Monte Carlo: one function of a PRNG key, run over many keys on every device.

:func:`run` (:mod:`~jaxgrav.montecarlo.runner`) vmaps, shards and chunks a per-run
function; :mod:`~jaxgrav.montecarlo.methods` is the registry of named methods
(scenario + matcher or filter + per-run errors) that ``jaxgrav montecarlo`` runs;
:mod:`~jaxgrav.montecarlo.paper_a_table1` builds paper A's Table 1 groups on them.
"""

from jaxgrav.montecarlo import methods, paper_a_table1
from jaxgrav.montecarlo.methods import (
    BUILDERS,
    FILTER_METHODS,
    METRICS,
    VOYAGE_METHODS,
    MethodSpec,
    build,
    register,
)
from jaxgrav.montecarlo.runner import DEFAULT_CHUNK, RUN_AXIS, run, to_dataset, write_netcdf

__all__ = [
    "BUILDERS",
    "DEFAULT_CHUNK",
    "FILTER_METHODS",
    "METRICS",
    "RUN_AXIS",
    "VOYAGE_METHODS",
    "MethodSpec",
    "build",
    "methods",
    "paper_a_table1",
    "register",
    "run",
    "to_dataset",
    "write_netcdf",
]
