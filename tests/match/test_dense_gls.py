"""Dense matcher with the GLS score of a correlated map error, and the fix's quality."""

import dataclasses
import json
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.fields.map_error import map_error, truth_field
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match import DenseConfig, match_dense, shifted_tracks
from jaxgrav.match.gls import track_covariance
from jaxgrav.match.result import STATUS
from jaxgrav.match.sizing import config_for
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import MatchingScenario, matching_scenario

GOLDEN = pathlib.Path(__file__).with_name("dense_white_golden.json")
SCEN = MatchingScenario(region=(29.6, 30.4, 129.6, 130.4), drift_deg=0.01, n_fixes=20, dt=60.0)
FIELDS = ("lat", "lon", "score", "bias", "offset_north_m", "offset_east_m", "rotation_deg",
          "status", "topk_score")


@pytest.fixture(scope="module")
def grid(smooth_grid):
    """The suite's smooth synthetic map (the golden white-path results were recorded on it)."""
    return smooth_grid


@pytest.mark.long
def test_map_error_zero_is_todays_white_score(grid):
    gold = json.loads(GOLDEN.read_text())  # written by the matcher before map errors existed
    for name, nrot in (("plain", 1), ("rot", 3)):
        # the golden runs searched the whole square (config_for's default is now the disc)
        cfg = config_for("dense", grid, 1500.0, n_rotations=nrot, region="square")
        assert cfg.map_error_mgal == 0.0
        for s in range(3):
            run = matching_scenario(jax.random.key(s), grid, SCEN)
            r = match_dense(grid, run.ins_lat, run.ins_lon, run.readings, cfg)
            for f in FIELDS:
                got, want = np.asarray(getattr(r, f)), np.asarray(gold[name][s][f])
                if nrot == 1:  # to rounding: the suite compiles with XLA's elemental
                    # emitters (conftest), the golden runs had its defaults (bit for bit
                    # then; now the scores up to 1.3e-13 relative apart)
                    np.testing.assert_allclose(got, want, rtol=1e-10, atol=0,
                                               err_msg=f"{name} {s} {f}")
                else:  # XLA fuses the refinement's sums otherwise: last-bit differences
                    # (since the missing-node fallback after the refinement changed the
                    # program around it: up to 5e-10 relative, 0.5 µm in an offset)
                    np.testing.assert_allclose(got, want, rtol=1e-8, err_msg=f"{name} {s} {f}")
            assert bool(r.accepted)


def _gls_config(grid, sigma=3.0, length=8000.0, **kw):
    cfg = config_for("dense", grid, 1500.0, map_error=map_error(sigma, length))
    return dataclasses.replace(cfg, **kw)


@pytest.mark.parametrize("region", ["square", "disc"])
@pytest.mark.long
def test_gls_dense_scores_equal_brute_force_numpy_gls(grid, region):
    cfg = _gls_config(grid, half_size=3, spacing_m=300.0, k_best=10, refine_steps=0,
                      region=region)
    run = matching_scenario(jax.random.key(5), grid, SCEN)
    r = match_dense(grid, run.ins_lat, run.ins_lon, run.readings, cfg)
    lat, lon, g = (np.asarray(a) for a in (run.ins_lat, run.ins_lon, run.readings))
    d = np.arange(-3, 4) * 300.0
    on, oe = (a.reshape(-1) for a in np.meshgrid(d, d, indexing="ij"))
    s_lat, s_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), on, oe, np.zeros_like(on))
    v = np.asarray(prepare_map(grid).sample(s_lat, s_lon))
    # the fixes' offsets from the centroid, local metres: only distances matter
    north, east = (np.asarray(a) for a in local_offsets_m(jnp.asarray(lat), jnp.asarray(lon),
                                                        jnp.mean(jnp.asarray(lat)),
                                                        jnp.mean(jnp.asarray(lon))))
    dist = np.hypot(north[:, None] - north[None, :], east[:, None] - east[None, :])
    x = dist / 8000.0
    cov = np.eye(lat.size) * 1.0 + 9.0 * (1 + x) * np.exp(-x)
    p = np.linalg.inv(cov)
    one = np.ones(lat.size)
    res = g[None, :] - v
    b = res @ p @ one / (one @ p @ one)
    e = res - b[:, None]
    chi2 = np.einsum("ci,ij,cj->c", e, p, e)
    if region == "disc":  # only the offsets within 3 × 300 m are candidates
        chi2 = chi2[on**2 + oe**2 <= 900.0**2]
    want = np.sort(chi2)[:10] / lat.size  # mGal² scale: χ² · σ_n² Σμ² (equal weights)
    np.testing.assert_allclose(np.asarray(r.topk_score), want, rtol=2e-4)


@pytest.mark.long
def test_no_retrace_when_map_error_changes_and_vmap_equals_loop(grid):
    runs = [matching_scenario(jax.random.key(s), grid, SCEN) for s in range(3)]
    lat, lon, g = (jnp.stack([getattr(r, f) for r in runs]) for f in ("ins_lat", "ins_lon",
                                                                      "readings"))
    traces = []

    @jax.jit
    def batch(grid, lat, lon, g, cfg):  # data as arguments, not executable constants
        traces.append(1)
        return jax.vmap(lambda a, b, c: match_dense(grid, a, b, c, cfg))(lat, lon, g)

    out = [batch(grid, lat, lon, g, _gls_config(grid, s, length))
           for s, length in ((3.0, 8000.0), (1.0, 12000.0))]
    assert len(traces) == 1
    for i in range(3):
        one = match_dense(grid, lat[i], lon[i], g[i], _gls_config(grid, 1.0, 12000.0))
        for f in ("lat", "lon", "score", "covariance_m2", "accepted", "n_effective"):
            np.testing.assert_allclose(np.asarray(getattr(out[1], f))[i],
                                       np.asarray(getattr(one, f)), rtol=1e-6, atol=1e-6)
    assert not np.allclose(np.asarray(out[0].score), np.asarray(out[1].score))


@pytest.mark.long
def test_covariance_95_ellipse_coverage_with_a_correlated_map_error(grid):
    """Truth = map + a drawn σ = 3 mGal, L = 8 km error; 60 runs, posterior fix, all accepted."""
    model = map_error(3.0, 8000.0)
    scen = dataclasses.replace(SCEN, drift_deg=0.008)
    cfg = dataclasses.replace(_gls_config(grid), max_sigma_m=float("inf"))
    keys = jax.random.split(jax.random.key(15), 60)

    def one(grid, key):
        truth = truth_field(jax.random.fold_in(key, 1), grid, model)
        run = matching_scenario(key, truth, scen)
        r = match_dense(grid, run.ins_lat, run.ins_lon, run.readings, cfg)
        err = jnp.stack([r.offset_north_m + jnp.mean(run.drift_north_m),
                         r.offset_east_m + jnp.mean(run.drift_east_m)])
        return err @ jnp.linalg.solve(r.covariance_m2, err), r.accepted

    maha, acc = jax.jit(lambda g, k: jax.lax.map(lambda kk: one(g, kk), k))(grid, keys)
    maha, acc = np.asarray(maha), np.asarray(acc)
    assert acc.all()
    coverage = np.mean(maha <= 5.991)
    assert 0.85 <= coverage <= 1.0, coverage


@pytest.mark.long
def test_integrity_rejection_returns_the_ins_track_with_status_bits(grid):
    run = matching_scenario(jax.random.key(1), grid, SCEN)
    cfg = _gls_config(grid, max_sigma_m=1e-3, max_second_mode=0.0)
    r = match_dense(grid, run.ins_lat, run.ins_lon, run.readings, cfg)
    assert not bool(r.accepted)
    np.testing.assert_array_equal(np.asarray(r.lat), np.asarray(run.ins_lat))
    assert int(r.status) & 512 and 512 in STATUS and 4096 in STATUS
    assert float(r.offset_north_m) == 0.0


@pytest.mark.long
def test_score_model_compiles_one_score_with_the_same_results(grid):
    """``score_model`` "gls" and "white" (what config_for sets) give what "auto" gives,
    and "white" refuses a map error it would ignore."""
    run = matching_scenario(jax.random.key(3), grid, SCEN)
    args = (grid, run.ins_lat, run.ins_lon, run.readings)
    gls = _gls_config(grid, half_size=4, spacing_m=350.0)
    white = config_for("dense", grid, 1500.0)
    white = dataclasses.replace(white, half_size=4, spacing_m=350.0)
    assert (gls.score_model, white.score_model) == ("gls", "white")
    for cfg in (gls, white):
        one, auto = (match_dense(*args, dataclasses.replace(cfg, score_model=m))
                     for m in (cfg.score_model, "auto"))
        for f in ("lat", "lon", "score", "bias", "covariance_m2", "status", "topk_score"):
            np.testing.assert_allclose(np.asarray(getattr(one, f)),
                                       np.asarray(getattr(auto, f)), rtol=1e-9, atol=1e-9)
    # "gls" told σ = 0 is the white-noise likelihood: the white fix, to rounding
    zero = match_dense(*args, dataclasses.replace(gls, map_error_mgal=0.0))
    auto0 = match_dense(*args, dataclasses.replace(gls, map_error_mgal=0.0, score_model="auto"))
    np.testing.assert_allclose(np.asarray(zero.lat), np.asarray(auto0.lat), atol=1e-9)
    with pytest.raises(ValueError, match="score_model='white' ignores the map error"):
        DenseConfig(score_model="white", map_error_mgal=3.0)
    with pytest.raises(ValueError, match="score_model must be"):
        DenseConfig(score_model="both")


def test_config_validation_and_other_matchers_neutral_quality(grid):
    with pytest.raises(ValueError, match="map_error_mgal"):
        DenseConfig(map_error_mgal=-1.0)
    with pytest.raises(ValueError, match="fix"):
        DenseConfig(fix="mean")
    told = config_for("chains", grid, 1500.0, map_error=map_error(1.0, 1e4))
    assert (float(told.map_error_mgal), float(told.map_error_length_m)) == (1.0, 1e4)
    cov = track_covariance(np.arange(3.0), np.zeros(3), 1.0, 0.0, 1e4)
    np.testing.assert_allclose(np.asarray(cov), np.eye(3))
