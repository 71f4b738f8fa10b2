"""The example scripts run at their ``--smoke`` size and print what they promise.

Each script runs in its own process (the examples enable x64 themselves, as scripts
may). Only the examples whose smoke run takes under about a minute on 2 cores are run
here (``paper_b_entropy_iccp``: 2 × 32 tracks, 50–66 s wall / 32 s CPU on a loaded 2-core
machine, most of it compiling); ``paper_d_noharm``, ``paper_d_ukf`` and
``paper_d_pointmass_fit`` in ``test_examples_paper_d.py``; ``paper_a_table1`` (~2 min) is
exercised by the ``jaxgrav demo`` smoke test and its library functions' tests instead.
"""

import itertools
import json
import re
import subprocess
import sys

import pytest
from _examples import EXAMPLES, run_example

pytestmark = pytest.mark.long  # runs an example script end to end (a process of its own)


def test_paper_b_failures_smoke():
    out = run_example("paper_b_failures.py")
    assert "gravity, seed 0, 32 tracks, Δχ² ≥ 7.81" in out  # the library's default test
    assert re.search(r"^combined matcher: ICCP fix on \d+, entropy track on \d+, rejected "
                     r"\(INS track\) on \d+ tracks \(\d+ of them a far fix", out, flags=re.M)
    row = r"^(library decision|\+ rival).*?(\d+)\s+(\d+)\s+([\d.]+)%\s+([\d.]+)%$"
    rows = re.findall(row, out, flags=re.M)
    assert len(rows) == 6
    median_default = int(rows[0][1])
    entropy_median = float(re.search(r"entropy alone: median (\d+) m", out).group(1))
    assert median_default < entropy_median / 2  # the combined matcher's median goal


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_paper_b_failures_refuses_bad_accept_chi2(value):
    proc = subprocess.run([sys.executable, str(EXAMPLES / "paper_b_failures.py"),
                           "--accept-chi2", value], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and not proc.stdout
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "--accept-chi2" in lines[0] and value in lines[0], proc.stderr


def test_paper_b_entropy_iccp_smoke():
    out = run_example("paper_b_entropy_iccp.py")
    cases = re.split(r"^== ", out, flags=re.M)[1:]
    assert [c.split(":")[0] for c in cases] == ["gravity", "gravity-large"]
    tables = {}
    for case in cases:
        assert ": 32 tracks, noise 1.0" in case.splitlines()[0]
        rows = re.findall(r"^(INS|entropy|ICCP alone|entropy\+ICCP)\s+(\d+)\s+(\d+)\s+(\d+)"
                          r"\s+([\d.]+)%$", case, flags=re.M)
        assert [r[0] for r in rows] == ["INS", "entropy", "ICCP alone", "entropy+ICCP"]
        tables[case.split(":")[0]] = {r[0]: [float(x) for x in r[1:]] for r in rows}
    g = tables["gravity"]  # columns: RMS, median, p90 (m), share over 1 km (%)
    # the accuracy goal: median at most half the INS one, not worse than entropy alone
    assert g["entropy+ICCP"][1] <= 0.5 * g["INS"][1]
    assert g["entropy+ICCP"][1] <= g["entropy"][1]
    assert "accuracy goal (gravity): median met" in out
    big = tables["gravity-large"]  # large offsets: the coarse stage is what rescues ICCP
    assert big["entropy+ICCP"][0] < big["ICCP alone"][0]
    assert big["ICCP alone"][3] > g["ICCP alone"][3]


def test_paper_c_dov_smoke(tmp_path):
    out = run_example("paper_c_dov.py", "--out", str(tmp_path / "c"))
    table = json.loads((tmp_path / "c" / "paper_c_table.json").read_text())
    assert table
    assert (tmp_path / "c" / "paper_c_dov.png").stat().st_size > 10_000
    errors = {m: float(v) for m, v in re.findall(
        r"INS max horizontal position error, ([\w-]+): ([\d.]+) m", out)}
    # compensation must beat the uncompensated INS by orders of magnitude
    assert errors["uncompensated"] > 100 * errors["bilinear-linear"]
    assert errors["bilinear-linear"] > errors["bicubic-harmonic"]
    # both settings, labelled: the perfect model and the finer (degree-2159) truth
    assert "setting 1 (perfect model, best case): truth = the degree-60 model" in out
    assert "setting 2 (finer truth): truth = EGM2008 to degree 2159" in out
    fine = {r["case"]: r for r in table["table_truth_n2159"]}
    assert {"uncompensated", "layered bicubic-harmonic", "exact degree-60 model"} <= set(fine)
    assert len(fine) == len(table["table"]) + 1  # every method, plus the omission alone
    omission = fine["exact degree-60 model"]["rms_total"]
    # against the finer truth no method beats the exact model by more than its own error
    for case, r in fine.items():
        assert r["rms_total"] > 0.5 * omission, case
    assert table["settings"]["table_truth_n2159"].startswith("truth = EGM2008 to degree 2159")
    ins_fine = {m: float(v) for m, v in re.findall(
        r"INS max horizontal position error \(truth degree 2159\), ([\w-]+): ([\d.]+) m", out)}
    assert set(ins_fine) == {"uncompensated", "bilinear-linear", "bicubic-harmonic",
                             "exact-degree-60-model"}
    assert ins_fine["uncompensated"] > ins_fine["exact-degree-60-model"] > 0


def test_paper_d_gravimeter_smoke():
    out = run_example("paper_d_gravimeter.py")
    rows = re.findall(r"^\s+(\d+)\s+[\d.]+\s+([\d.]+)\s+\d+\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)",
                      out, flags=re.M)
    assert len(rows) >= 3
    for _, f_ratio, _, no_tilt, tilt_kf in rows:
        if float(f_ratio) <= 1.0:  # below the speed bound the tilt filter helps
            assert float(tilt_kf) < float(no_tilt)


def test_suitability_validation_smoke():
    """Two settings, each a JSON line with the CRLB's, the std descriptor's and the
    oracle's ranking (40 runs and 2 more draws each: 80, a batch of 50 beside a remainder
    of 30, which deadlocked when the GLS whitening called LAPACK)."""
    lines = [json.loads(s) for s in run_example("suitability_validation.py",
                                                "--oracle-draws", "2").splitlines()
             if s.startswith("{")]
    assert [r["setting"] for r in lines] == ["perfect map", "map error"]
    for r in lines:
        assert r["crlb"]["runs"] == 40 and (r["heading_deg"], r["n_fixes"]) == (45.0, 30)
        assert -1 <= r["crlb"]["spearman"] <= 1 and r["crlb"]["cut"] > 0
        assert r["std_descriptor"]["runs"] > 30
        assert r["oracle_draws"] == 2 and r["oracle"]["runs"] == 40
        assert r["bias_prior_sigma_mgal"] == 3.0


def test_missing_nodes_smoke():
    rows = [json.loads(s) for s in run_example("missing_nodes.py").splitlines()
            if s.startswith("{")]
    interp_rows = [r for r in rows if r["part"] == "interpolant"]
    assert [r["nodes_from_hole"] for r in interp_rows] == [1, 2, 3, 4, 5, 6]
    rms = [r["rms_mgal"] for r in interp_rows]
    assert all(a > b for a, b in itertools.pairwise(rms))  # the hole's effect decays
    assert rms[-1] < 0.01 * rms[0]
    match_rows = [r for r in rows if r["part"] == "dense matcher"]
    assert len(match_rows) == 20  # complete, three holey maps as land, as gaps and auto,
    # perfect map and map error
    for r in match_rows:
        assert r["runs"] > 0 and 0 <= r["median_ratio"] < 10
        if r["map"] == "complete":
            assert r["flagged_8192"] == 0.0
        if "hole under" in r["map"]:
            assert r["flagged_8192"] == 1.0  # a hole under the track is always in reach
