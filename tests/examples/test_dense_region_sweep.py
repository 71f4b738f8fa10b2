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
    n_p = len(mod.P_WORSE) - 1
    assert {r[0] for r in rows} == {"square", "disc"}
    assert len(rows) == 2 * len(mod.RATIOS) + n_p
    for region in ("square", "disc"):
        acc = [r[5] for r in rows if r[0] == region and r[2] == np.inf]
        assert acc == sorted(acc)  # a looser ratio never accepts fewer fixes
        assert all(np.isfinite(r[3]) for r in rows if r[0] == region)
    # at ratio 0.9 a looser no-harm threshold never accepts fewer fixes
    disc = [r for r in rows if r[0] == "disc" and r[1] == 0.9]
    acc = [r[5] for r in sorted(disc, key=lambda r: r[2])]
    assert len(disc) == n_p + 1 and acc == sorted(acc)
    assert "its own 1-sigma" in capsys.readouterr().out
