"""``jaxgrav demo`` and :mod:`jaxgrav.montecarlo.paper_a_table1` end to end, at the smoke size."""

import json
import math

import jax
import matplotlib.image
import numpy as np
import pytest

from jaxgrav.cli import main
from jaxgrav.cli.demo import OUTPUTS, run_demo
from jaxgrav.montecarlo.paper_a_table1 import TABLE1_DRIFTS_DEG
from jaxgrav.sim import DEG_ARC_M

TRACE_EVENT = "/jax/core/compile/jaxpr_trace_duration"
TRACED = []  # functions traced while the demo ran
_RECORDING = [False]


def _record_trace(name, secs, fun_name="", **kw):
    if _RECORDING[0] and name == TRACE_EVENT:
        TRACED.append(fun_name)


pytestmark = pytest.mark.long  # every test reads the demo's output (one run, minutes)


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "out"
    jax.monitoring.register_event_duration_secs_listener(_record_trace)
    _RECORDING[0] = True
    try:
        run_demo(out, runs=5, seed=0, smoke=True)
    finally:
        _RECORDING[0] = False
    return out


def test_demo_batches_reuse_the_compiled_code(demo_dir):
    """Eight batches (five table groups, three realistic settings) through the runner's
    one jitted chunk function: traced once per distinct shape, here the chain search's
    two window sizes (the four smaller drifts share one) and the dense matcher's three
    settings (perfect map, map error with the white matcher, map error told)."""
    assert 1 <= TRACED.count("chunk_fn") <= 5  # fewer if a test compiled them already


def test_demo_table_has_the_five_drift_groups(demo_dir):
    lines = (demo_dir / "table1.md").read_text().splitlines()
    assert "refined ×10" in lines[0]  # the smoke size says so
    rows = [line.split("|")[1:-1] for line in lines if line.startswith("| 0.")]
    assert len(rows) == 5
    np.testing.assert_allclose([float(r[0]) for r in rows], TABLE1_DRIFTS_DEG)
    # a fixed-size drift: the INS error of each group is its drift level
    np.testing.assert_allclose([float(r[1]) for r in rows], TABLE1_DRIFTS_DEG, atol=5e-5)
    assert all(int(r[-1]) == 2 for r in rows)  # max(5 // 5, 2) tracks per group


def test_demo_summary_json(demo_dir):
    s = json.loads((demo_dir / "summary.json").read_text())
    assert s["smoke"] is True and s["seed"] == 0
    assert [r["drift_deg"] for r in s["paper_setting"]] == list(TABLE1_DRIFTS_DEG)
    for r in s["paper_setting"]:
        np.testing.assert_allclose(r["ins_error_deg_mean"], r["drift_deg"], rtol=1e-9)
        assert r["runs"] == 2 and 0.0 <= r["success_rate"] <= 1.0
        assert math.isfinite(r["error_m_median"]) and r["error_m_median"] >= 0.0
        assert r["work_unconstrained_median"] >= r["work_constrained_median"] >= 0.0
    real = s["realistic_setting"]
    assert real["runs"] == 5
    keys = ("ins_error_m_median", "error_m_median", "median_ratio", "success_rate",
            "improved_rate", "failure_rate", "flagged_rate")
    assert all(math.isfinite(real[k]) for k in keys)
    # 0.035° of fixed drift, in metres on the mean sphere
    np.testing.assert_allclose(real["ins_error_m_median"], 0.035 * DEG_ARC_M, rtol=1e-9)
    np.testing.assert_allclose(real["median_ratio"],
                               real["error_m_median"] / real["ins_error_m_median"])
    assert all(0.0 <= real[k] <= 1.0 for k in ("success_rate", "improved_rate"))
    rows = s["realistic_settings"]
    assert len(rows) == 3 and s["realistic_setting"] == rows[-1]
    assert s["headline"] == rows[-1]["setting"] and "told the map error" in s["headline"]
    assert "perfect map" in rows[0]["setting"] and "white-noise" in rows[1]["setting"]
    for r in rows:  # the same tracks in every row: the INS errors are the same
        assert r["ins_error_m_median"] == rows[0]["ins_error_m_median"]
        assert 0.0 <= r["worse_rate"] <= 1.0 and 0.0 <= r["accepted_rate"] <= 1.0
    # the white rows run the informativeness test too (a fix as wide as the search is
    # rejected), so their accepted share is below 1 at the smoke size's short tracks
    assert 0.0 < rows[0]["accepted_rate"] <= 1.0
    cfg = s["realistic_config"]
    assert cfg["half_size"] >= 1 and cfg["spacing_m"] > 0 and math.isfinite(cfg["noise_mgal"])


def test_demo_realistic_table_reports_what_the_summary_says(demo_dir):
    text = (demo_dir / "table1.md").read_text()
    s = json.loads((demo_dir / "summary.json").read_text())
    rows = [line.split("|")[1:-1] for line in text.splitlines()
            if line.startswith(("| perfect", "| map error"))]
    assert len(rows) == 3
    for cells, r in zip(rows, s["realistic_settings"], strict=True):
        assert cells[0].strip() == r["setting"]
        assert float(cells[2]) == pytest.approx(r["median_ratio"], abs=0.006)
        assert cells[3].strip() == f"{100 * r['worse_rate']:.0f} %"
    # the paper-setting table shows the ratio and the share worse than the INS beside
    # "error < 0.01°", so a drift below 0.01° cannot read as a success on its own
    head = next(line for line in text.splitlines() if line.startswith("| INS drift"))
    assert "worse than INS" in head and "error < 0.01°" in head


def test_demo_png(demo_dir):
    path = demo_dir / "tracks.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = matplotlib.image.imread(path)
    assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 400
    assert np.ptp(img[..., :3]) > 0.5  # not a blank canvas


def test_demo_refuses_to_overwrite(demo_dir, capsys):
    before = {f: (demo_dir / f).read_bytes() for f in OUTPUTS}
    assert main(["demo", "--out", str(demo_dir), "--runs", "5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("jaxgrav demo: error: ") and "--force" in err
    assert {f: (demo_dir / f).read_bytes() for f in OUTPUTS} == before
    with pytest.raises(ValueError, match="runs must be at least 5"):
        run_demo(demo_dir / "other", runs=4)
