"""The old import paths of the filters keep working for one release, with a warning.

(The deprecated ``run_pmf`` is tested in ``test_pmf.py``.)
"""

import importlib
import sys

import pytest

import jaxgrav.filters as fl
import jaxgrav.scenarios as sc
from jaxgrav.filters import gaussian_sum, guard, kalman, model, pmf
from jaxgrav.scenarios import paper_d


def test_match_filters_shim_warns_and_gives_the_same_objects(monkeypatch):
    for name in [m for m in sys.modules if m.startswith("jaxgrav.match.filters")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.warns(DeprecationWarning, match="jaxgrav.match.filters is deprecated"):
        old = importlib.import_module("jaxgrav.match.filters")
    for name in fl.__all__:
        assert getattr(old, name) is getattr(fl, name), name
    for name in ("FilterRun", "FilterScenario", "filter_scenario", "initial_state",
                 "run_metrics", "run_steps"):
        assert getattr(old, name) is getattr(sc, name), name
    for name, module in (("gaussian_sum", gaussian_sum), ("guard", guard), ("kalman", kalman),
                         ("model", model), ("pmf", pmf), ("paper_d", paper_d)):
        assert importlib.import_module(f"jaxgrav.match.filters.{name}") is module, name
    from jaxgrav.match.filters.kalman import ukf

    assert ukf is fl.ukf

