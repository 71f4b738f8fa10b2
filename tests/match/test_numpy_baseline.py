"""The NumPy baseline of the correlation benchmark agrees with jaxgrav (keeps it honest).

``benchmarks/_numpy_correlation.py`` re-implements ``match_dense`` and ``match_chains``
in NumPy/SciPy; ``benchmarks/match_correlation.py`` times jaxgrav against it. These
checks run both on a few tracks over a piece of the shipped ryukyu map and require
the same choices and numbers. One compile per path (single-track jit).
"""

import sys
from pathlib import Path

import numpy as np
import pytest

import jaxgrav as jg
from jaxgrav import constants, datasets
from jaxgrav.match.correlation import ChainConfig, match_chains
from jaxgrav.match.dense import DenseConfig, match_dense

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import _numpy_correlation as npc

N_FIX = 10
N_TRACKS = 3


@pytest.fixture(scope="module")
def region():
    """A 50 × 50 node (≈ 2° × 2°) piece of the 2.5′ ryukyu map, float64."""
    full = datasets.load("ryukyu")["anomaly_2p5min"]
    rows, cols = slice(120, 170), slice(130, 180)
    values = np.asarray(full.values, np.float64)[rows, cols]
    return jg.Grid.from_arrays(full.lat[rows], full.lon[cols], values, units="mGal")


@pytest.fixture(scope="module")
def tracks(region):
    """Straight tracks (10 kn E + 10 kn N, 2 min), drift 2 km, bicubic truth + 1 mGal noise."""
    rng = np.random.default_rng(42)
    m = npc.prepare_grid(region)
    w, e, s, n = region.extent
    v = 10 * constants.KNOT * 120.0
    out = []
    for _ in range(N_TRACKS):
        lat0 = rng.uniform(s + 0.4, n - 0.6)
        lon0 = rng.uniform(w + 0.4, e - 0.6)
        tlat = lat0 + np.arange(N_FIX) * v / npc.meridian_radius(lat0) / npc.DEG
        tlon = lon0 + np.arange(N_FIX) * v / (
            npc.prime_vertical_radius(lat0) * np.cos(lat0 * npc.DEG) * npc.DEG
        )
        a = rng.uniform(0, 2 * np.pi)
        ilat = tlat + 2000.0 * np.cos(a) / npc.meridian_radius(tlat) / npc.DEG
        ilon = tlon + 2000.0 * np.sin(a) / (
            npc.prime_vertical_radius(tlat) * np.cos(tlat * npc.DEG) * npc.DEG
        )
        g = npc.sample_bicubic(m, tlat, tlon) + rng.normal(size=N_FIX)
        out.append((ilat, ilon, g))
    return out


def test_constants_and_spline_match_jaxgrav(region):
    assert npc.WGS84_A == constants.WGS84_A and npc.WGS84_E2 == constants.WGS84_E2
    assert npc.DEG == constants.DEG
    m = npc.prepare_grid(region)
    rng = np.random.default_rng(0)
    w, e, s, n = region.extent
    lat, lon = rng.uniform(s, n, 500), rng.uniform(w, e, 500)
    np.testing.assert_allclose(
        npc.sample_bicubic(m, lat, lon), region.sample(lat, lon, "bicubic"), rtol=0, atol=1e-9
    )
    # NaN off the map, like jaxgrav (FITPACK alone would clamp)
    assert np.isnan(npc.sample_bicubic(m, np.array([n + 0.1]), np.array([w + 1.0])))[0]


def test_dense_grid_sampling_equals_point_sampling(region, tracks):
    m = npc.prepare_grid(region)
    cfg = DenseConfig(half_size=6)
    for lat, lon, g in tracks:
        a = npc.match_dense_np(m, lat, lon, g, cfg, sampling="grid")
        b = npc.match_dense_np(m, lat, lon, g, cfg, sampling="points")
        assert a.chosen == b.chosen
        np.testing.assert_allclose(a.topk_score, b.topk_score, rtol=1e-12)
        np.testing.assert_allclose(a.topk_lat, b.topk_lat, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.lat, b.lat, rtol=0, atol=1e-9)


@pytest.mark.long
def test_dense_agrees_with_jaxgrav(region, tracks):
    # rotations (point sampling, rotation column of the Jacobian), a bias prior,
    # decreasing weights and the nearest-to-INS rule: the least common paths
    cfg = DenseConfig(spacing_m=500.0, half_size=5, n_rotations=3, max_rotation_deg=1.0,
                      weight_decay=0.5, bias_sigma_mgal=5.0, selection="nearest",
                      refine_steps=6, score_model="white")
    m = npc.prepare_grid(region)
    for lat, lon, g in tracks:
        r = match_dense(region, lat, lon, g, cfg)
        a = npc.match_dense_np(m, lat, lon, g, cfg)
        assert int(r.chosen) == a.chosen
        np.testing.assert_allclose(r.topk_score, a.topk_score, rtol=1e-9)
        np.testing.assert_allclose(r.topk_lat, a.topk_lat, rtol=0, atol=1e-10)
        np.testing.assert_allclose(r.topk_lon, a.topk_lon, rtol=0, atol=1e-10)
        # after the Gauss-Newton refinement: same position to well below a metre
        dn, de = npc.local_offsets_m(np.asarray(r.lat), np.asarray(r.lon), a.lat, a.lon)
        assert np.max(np.hypot(dn, de)) < 0.01
        np.testing.assert_allclose(r.rotation_deg, a.rotation_deg, atol=1e-6)
        np.testing.assert_allclose(r.bias, a.bias, atol=1e-6)
        np.testing.assert_allclose(r.score, a.score, rtol=1e-6)
        assert int(r.status) == a.status


@pytest.mark.long
def test_chains_agree_with_jaxgrav(region, tracks):
    fine = region.refine(4)
    m = npc.prepare_grid(fine, spline=False)
    cfg = ChainConfig(half_size=6, capacity=48, k_dp=8)  # small capacity: overflow happens
    overflow = found = 0
    for lat, lon, g in tracks:
        r = match_chains(fine, lat, lon, g, cfg)
        a = npc.match_chains_np(m, lat, lon, g, cfg)
        assert int(r.status) == a.status
        np.testing.assert_array_equal(r.n_candidates, a.n_candidates)
        np.testing.assert_allclose(r.work_constrained, a.work_constrained, rtol=1e-12)
        assert float(r.work_pairs) == a.work_pairs
        np.testing.assert_allclose(r.work_unconstrained, a.work_unconstrained, rtol=1e-12)
        fin = np.isfinite(a.topk_score)
        np.testing.assert_array_equal(np.isfinite(r.topk_score), fin)
        np.testing.assert_allclose(np.asarray(r.topk_score)[fin], a.topk_score[fin], rtol=1e-9)
        np.testing.assert_allclose(np.asarray(r.topk_lat)[fin], a.topk_lat[fin], atol=1e-12)
        np.testing.assert_allclose(np.asarray(r.topk_lon)[fin], a.topk_lon[fin], atol=1e-12)
        assert int(r.chosen) == a.chosen
        np.testing.assert_allclose(r.lat, a.lat, rtol=0, atol=1e-12)
        np.testing.assert_allclose(r.lon, a.lon, rtol=0, atol=1e-12)
        overflow += a.status & 2 > 0
        found += not a.status & 1
    assert overflow >= 1 and found >= 1  # both the capacity cut and the search were exercised
