"""Deprecated: the filters moved to :mod:`jaxgrav.filters`, paper D's scenario to
:mod:`jaxgrav.scenarios.paper_d`.

This shim keeps ``jaxgrav.match.filters`` and its submodules (``kalman``, ``model``,
``guard``, ``gaussian_sum``, ``pmf``, ``paper_d``) importable for one release, with a
:class:`DeprecationWarning`.
"""

import sys
import warnings

from jaxgrav import filters as _filters
from jaxgrav.filters import *  # noqa: F403
from jaxgrav.filters import gaussian_sum, guard, kalman, model, pmf
from jaxgrav.scenarios import paper_d
from jaxgrav.scenarios.paper_d import (
    FilterRun,
    FilterScenario,
    filter_scenario,
    initial_state,
    run_metrics,
    run_steps,
)

warnings.warn(
    "jaxgrav.match.filters is deprecated: import the filters from jaxgrav.filters and paper "
    "D's scenario (FilterScenario, filter_scenario, ...) from jaxgrav.scenarios",
    DeprecationWarning,
    stacklevel=2,
)

for _name, _module in (("gaussian_sum", gaussian_sum), ("guard", guard), ("kalman", kalman),
                       ("model", model), ("pmf", pmf), ("paper_d", paper_d)):
    sys.modules[f"{__name__}.{_name}"] = _module

__all__ = [*_filters.__all__, "FilterRun", "FilterScenario", "filter_scenario",
           "initial_state", "run_metrics", "run_steps"]
