"""Smoke run of examples/dense_region_sweep.py (8 tracks per region)."""

import importlib.util
import pathlib

import numpy as np
import pytest

SCRIPT = pathlib.Path(__file__).parents[2] / "examples" / "dense_region_sweep.py"


@pytest.mark.long
def test_dense_region_sweep_smoke(capsys):
    spec = importlib.util.spec_from_file_location("dense_region_sweep", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rows = mod.main(["--smoke"])
    assert {r[0] for r in rows} == {"square", "disc"} and len(rows) == 2 * len(mod.RATIOS)
    for region in ("square", "disc"):
        acc = [r[4] for r in rows if r[0] == region]
        assert acc == sorted(acc)  # a looser ratio never accepts fewer fixes
        assert all(np.isfinite(r[2]) for r in rows if r[0] == region)
    assert "its own 1-sigma" in capsys.readouterr().out
