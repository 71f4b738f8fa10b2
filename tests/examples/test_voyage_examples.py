"""Smoke run of examples/voyage_loose.py (2 voyages of 2 h)."""

import importlib.util
import pathlib

import numpy as np
import pytest

pytestmark = pytest.mark.long  # runs an example script end to end (a process of its own)

SCRIPT = pathlib.Path(__file__).parents[2] / "examples" / "voyage_loose.py"


def test_voyage_loose_smoke(capsys, tmp_path):
    spec = importlib.util.spec_from_file_location("voyage_loose_example", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    png = tmp_path / "errors.png"
    rows = mod.main(["--smoke", "--png", str(png)])
    assert png.stat().st_size > 10_000
    assert set(rows) == {"perfect map", "map error, told"}
    for r in rows.values():
        assert len(r["hourly_rms_nav_m"]) == 2 and np.isfinite(r["nees"])
        assert sum(r["fix_events"].values()) == 2 * 2  # 2 voyages x 2 segment ends
    assert '"setting": "perfect map"' in capsys.readouterr().out


def test_voyage_loose_calibrate_smoke():
    spec = importlib.util.spec_from_file_location("voyage_loose_example_c", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rows = mod.main(["--smoke", "--calibrate"])
    for r in rows.values():
        assert r["calibrate"] and len(r["by_edge_mass"]) == 4
        assert len(r["ideal_filter_hourly_rms_m"]) == 2 and np.isfinite(r["fix_nees_median"])


TIGHT = pathlib.Path(__file__).parents[2] / "examples" / "voyage_tight.py"


def test_voyage_tight_smoke(capsys, tmp_path):
    spec = importlib.util.spec_from_file_location("voyage_tight_example", TIGHT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    png = tmp_path / "tight.png"
    tracks = tmp_path / "tracks.png"
    rows = mod.main(["--smoke", "--settings", "map error, told", "--png", str(png),
                     "--tracks-png", str(tracks), "--bound"])
    assert png.stat().st_size > 10_000 and set(rows) == {"map error, told"}
    assert tracks.stat().st_size > 10_000
    r = rows["map error, told"]
    assert len(r["hourly_rms_nav_m"]) == 2 and np.isfinite(r["nees"])
    assert r["readings_used"] > 0.9 and r["runs"] == 2
    # the bound: one RMS per hour, below the free INS, the filter not far from it
    assert len(r["bound_hourly_rms_m"]) == 2
    assert 0 < r["bound_last_hour_ratio"] < 1 and r["nav_over_bound_last_hour"] > 0.5
    assert '"setting": "map error, told"' in capsys.readouterr().out
