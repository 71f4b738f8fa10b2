"""Smoke run of examples/map_error_dense.py (4 tracks)."""

import importlib.util
import pathlib

import numpy as np
import pytest

pytestmark = pytest.mark.long  # runs an example script end to end (a process of its own)

SCRIPT = pathlib.Path(__file__).parents[2] / "examples" / "map_error_dense.py"


def test_map_error_dense_smoke(capsys):
    spec = importlib.util.spec_from_file_location("map_error_dense", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rows = mod.main(["--smoke"])
    assert set(rows) >= {"white", "gls-best", "gls-posterior"}
    for r in rows.values():
        assert 0.0 <= r["accepted"] <= 1.0 and np.isfinite(r["median"])
    assert "median err/INS" in capsys.readouterr().out
