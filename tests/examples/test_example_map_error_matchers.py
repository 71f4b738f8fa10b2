"""Smoke run of examples/map_error_matchers.py (3 tracks per matcher)."""

import importlib.util
import pathlib

import numpy as np
import pytest

pytestmark = pytest.mark.long  # runs an example script end to end (a process of its own)

SCRIPT = pathlib.Path(__file__).parents[2] / "examples" / "map_error_matchers.py"


def test_map_error_matchers_smoke(capsys):
    spec = importlib.util.spec_from_file_location("map_error_matchers", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rows = mod.main(["--smoke"])
    assert set(rows) == {"chains, white", "chains, told", "entropy+iccp, white",
                         "entropy+iccp, told", "entropy+iccp, told, 3 km only"}
    for r in rows.values():
        assert 0.0 <= r["accepted"] <= 1.0 and np.isfinite(r["median"]) and r["symmetric_pd"]
    assert "median err/INS" in capsys.readouterr().out
