"""Chain and entropy + ICCP matchers told a correlated map error: GLS scores, covariance,
integrity, no retrace, vmap == loop, coverage on a small Monte Carlo."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.fields.map_error import map_error, truth_field
from jaxgrav.geodesy import local_offsets_m
from jaxgrav.match.combined import match_entropy_iccp
from jaxgrav.match.correlation import match_chains
from jaxgrav.match.entropy import entropy_config_for
from jaxgrav.match.gls import gls_whitener
from jaxgrav.match.sizing import config_for, iccp_config_for
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import MatchingScenario, matching_scenario
from jaxgrav.scenarios.paper_b import PaperBScenario, paper_b_scenario

REGION = (29.6, 30.4, 129.6, 130.4)
SCEN_A = MatchingScenario(region=REGION, drift_deg=0.01, n_fixes=12, dt=120.0, eotvos=None)
SCEN_B = PaperBScenario(region=REGION, n_fixes=16, offset_min_deg=0.004, offset_max_deg=0.008,
                        rotation_deg=1.0, noise=1.0)
SIGMA, LENGTH = 3.0, 8000.0


def _numpy_cov(lat, lon, noise, weights=None):
    north, east = (np.asarray(a) for a in local_offsets_m(jnp.asarray(lat), jnp.asarray(lon),
                                                        lat[0], lon[0]))
    x = np.hypot(north[:, None] - north[None, :], east[:, None] - east[None, :]) / LENGTH
    var = np.full(lat.size, noise**2)
    if weights is not None:
        mu = weights / weights.sum()
        var = var * np.sum(mu**2) / mu
    return np.diag(var) + SIGMA**2 * (1 + x) * np.exp(-x)


def _check_cov(cov):
    cov = np.asarray(cov)
    assert np.all(cov[..., 0, 1] == cov[..., 1, 0])
    assert np.all(cov[..., 0, 0] > 0) and np.all(
        cov[..., 0, 0] * cov[..., 1, 1] - cov[..., 0, 1] ** 2 > 0)


def _chain_cfg(grid, **kw):
    cfg = config_for("chains", grid, 1500.0, step_m=SCEN_A.step_m,
                     map_error=map_error(SIGMA, LENGTH))
    return dataclasses.replace(cfg, **kw)


def _iccp_cfgs(grid, sigma=SIGMA, length=LENGTH, **kw):
    drift = (SCEN_B.offset_max_deg + 0.003) * 111_320.0
    ent = entropy_config_for(grid, drift, max_half_size=6)
    fine = iccp_config_for(grid, drift, stage="fine", noise=1.0, max_rotation_deg=1.5,
                           map_error=map_error(sigma, length))
    return ent, dataclasses.replace(fine, **kw)


def test_scan_whitener_equals_the_lapack_one():
    """The plain-JAX whitener against NumPy's LAPACK factor, inverse and log-determinant."""
    m = np.random.default_rng(0).normal(size=(12, 12))
    cov = m @ m.T + 12 * np.eye(12)
    chol = np.linalg.cholesky(cov)
    inv_chol = np.linalg.inv(chol)
    want = (chol, inv_chol, inv_chol.sum(-1), (inv_chol.sum(-1) ** 2).sum(),
            np.linalg.slogdet(cov)[1])
    for got, ref in zip(gls_whitener(cov), want, strict=True):
        np.testing.assert_allclose(np.asarray(got), ref, rtol=1e-10, atol=1e-12)


@pytest.mark.long
def test_chain_gls_score_equals_brute_force_numpy_and_covariance_is_pd(smooth_grid):
    grid = smooth_grid
    cfg = _chain_cfg(grid, fix="chain", max_sigma_m=float("inf"), selection="best")
    run = matching_scenario(jax.random.key(3), grid, SCEN_A)
    r = match_chains(grid, run.ins_lat, run.ins_lon, run.readings, cfg)
    assert bool(r.accepted) and int(r.status) & ~(4 | 8) == 0
    lat, lon, g = (np.asarray(a) for a in (run.ins_lat, run.ins_lon, run.readings))
    iy, ix = (np.rint(np.asarray(a)).astype(int) for a in grid.fractional_index(r.lat, r.lon))
    v = np.asarray(grid.values)[iy, ix]  # the chosen chain sits on map nodes
    w = np.exp(-cfg.weight_decay * np.arange(lat.size) / (lat.size - 1))
    # node quantisation noise: central-difference gradient at the INS fixes' nodes
    vals = np.asarray(grid.values)
    jy, jx = (np.rint(np.asarray(a)).astype(int) for a in grid.fractional_index(lat, lon))
    dy, dx = (np.asarray(a) for a in grid.spacing_m(jnp.asarray(lat)))
    g_n = (vals[jy + 1, jx] - vals[jy - 1, jx]) / (2 * dy)
    g_e = (vals[jy, jx + 1] - vals[jy, jx - 1]) / (2 * dx)
    noise = np.sqrt(cfg.noise_mgal**2 + ((g_n * dy) ** 2 + (g_e * dx) ** 2) / 12.0)
    p = np.linalg.inv(_numpy_cov(lat, lon, noise, w))
    one, res = np.ones(lat.size), g - v
    chi2 = res @ p @ res - (one @ p @ res) ** 2 / (one @ p @ one)
    mu = w / w.sum()
    np.testing.assert_allclose(float(r.score), chi2 * np.sum(mu**2), rtol=1e-6)
    np.testing.assert_allclose(float(r.chi2_per_dof), chi2 / (lat.size - 1), rtol=1e-6)
    assert np.all(np.diff(np.asarray(r.topk_score)) >= 0)
    _check_cov(r.covariance_m2)
    white = match_chains(grid, run.ins_lat, run.ins_lon, run.readings,
                         dataclasses.replace(cfg, map_error_mgal=0.0))
    _check_cov(white.covariance_m2)
    rejected = match_chains(grid, run.ins_lat, run.ins_lon, run.readings,
                            dataclasses.replace(cfg, max_sigma_m=1.0))
    assert not bool(rejected.accepted) and int(rejected.status) & 512
    np.testing.assert_array_equal(np.asarray(rejected.lat), lat)


@pytest.mark.long
def test_iccp_gls_score_equals_brute_force_numpy_and_covariance_is_pd(smooth_grid):
    grid = smooth_grid
    ent, fine = _iccp_cfgs(grid, max_sigma_m=float("inf"))
    run = paper_b_scenario(jax.random.key(4), grid, SCEN_B)
    r = match_entropy_iccp(grid, run.ins_lat, run.ins_lon, run.readings, ent, fine)
    assert bool(r.accepted)
    lat, lon, g = (np.asarray(a) for a in (run.ins_lat, run.ins_lon, run.readings))
    v = np.asarray(prepare_map(grid).sample(r.lat, r.lon))
    res = g - v
    chi2 = res @ np.linalg.solve(_numpy_cov(lat, lon, 1.0), res)  # no bias (paper B)
    np.testing.assert_allclose(float(r.chi2_per_dof) * lat.size, chi2, rtol=1e-5)
    _check_cov(r.covariance_m2)
    rejected = match_entropy_iccp(grid, run.ins_lat, run.ins_lon, run.readings, ent,
                                  dataclasses.replace(fine, max_sigma_m=1.0))
    assert not bool(rejected.accepted) and int(rejected.status) & 512
    np.testing.assert_array_equal(np.asarray(rejected.lat), lat)


@pytest.mark.long
def test_no_retrace_when_map_error_changes_and_vmap_equals_loop(smooth_grid):
    grid = smooth_grid
    runs_a = [matching_scenario(jax.random.key(s), grid, SCEN_A) for s in (1, 2)]
    runs_b = [paper_b_scenario(jax.random.key(s), grid, SCEN_B) for s in (1, 2)]
    stack = lambda runs: tuple(jnp.stack([getattr(r, f) for r in runs])  # noqa: E731
                               for f in ("ins_lat", "ins_lon", "readings"))
    a, b = stack(runs_a), stack(runs_b)
    traces = []

    @jax.jit
    def batch(grid, a, b, cc, ent, ic):  # data as arguments, not executable constants
        traces.append(1)
        ra = jax.vmap(lambda x, y, z: match_chains(grid, x, y, z, cc))(*a)
        rb = jax.vmap(lambda x, y, z: match_entropy_iccp(grid, x, y, z, ent, ic))(*b)
        return ra, rb

    outs = []
    for s, length in ((3.0, 8000.0), (1.0, 12000.0)):
        cc = dataclasses.replace(_chain_cfg(grid), map_error_mgal=s, map_error_length_m=length)
        outs.append(batch(grid, a, b, cc, *_iccp_cfgs(grid, s, length)))
    assert len(traces) == 1
    ra, rb = outs[1]
    cc = dataclasses.replace(_chain_cfg(grid), map_error_mgal=1.0, map_error_length_m=12000.0)
    ent, ic = _iccp_cfgs(grid, 1.0, 12000.0)
    for i in range(2):
        one_a = match_chains(grid, a[0][i], a[1][i], a[2][i], cc)
        one_b = match_entropy_iccp(grid, b[0][i], b[1][i], b[2][i], ent, ic)
        for got, want in ((ra, one_a), (rb, one_b)):
            for f in ("lat", "lon", "score", "covariance_m2", "accepted", "status"):
                np.testing.assert_allclose(np.asarray(getattr(got, f))[i],
                                           np.asarray(getattr(want, f)), rtol=1e-6, atol=1e-6)
    assert not np.allclose(np.asarray(outs[0][0].score), np.asarray(ra.score))


@pytest.mark.parametrize("method", ["chains", "entropy+iccp"])
@pytest.mark.long
def test_covariance_coverage_on_a_small_monte_carlo(smooth_grid, method):
    """Truth = map + a drawn σ = 3 mGal, L = 8 km error; 32 runs; loose bounds."""
    grid = smooth_grid
    model = map_error(SIGMA, LENGTH)
    cc = _chain_cfg(grid)
    ent, ic = _iccp_cfgs(grid)

    def one(grid, key):
        truth = truth_field(jax.random.fold_in(key, 1), grid, model)
        if method == "chains":
            run = matching_scenario(key, truth, SCEN_A)
            r = match_chains(grid, run.ins_lat, run.ins_lon, run.readings, cc)
        else:
            run = paper_b_scenario(key, truth, SCEN_B)
            r = match_entropy_iccp(grid, run.ins_lat, run.ins_lon, run.readings, ent, ic)
        e_n, e_e = local_offsets_m(r.lat, r.lon, run.truth.lat, run.truth.lon)
        i_n, i_e = local_offsets_m(run.ins_lat, run.ins_lon, run.truth.lat, run.truth.lon)
        err = jnp.stack([jnp.mean(e_n), jnp.mean(e_e)])
        cov = r.covariance_m2
        det = cov[0, 0] * cov[1, 1] - cov[0, 1] ** 2
        maha = (cov[1, 1] * err[0] ** 2 - 2 * cov[0, 1] * err[0] * err[1]
                + cov[0, 0] * err[1] ** 2) / det
        return maha, r.accepted, jnp.hypot(*err), jnp.hypot(jnp.mean(i_n), jnp.mean(i_e))

    keys = jax.random.split(jax.random.key(21), 32)
    # the map is an argument: closed over, it would be a constant of the executable
    runs = jax.jit(lambda g, k: jax.lax.map(lambda kk: one(g, kk), k))(grid, keys)
    maha, acc, err, ins = (np.asarray(x) for x in runs)
    assert acc.sum() >= 8, acc.sum()
    coverage = np.mean(maha[acc] <= 5.991)
    assert 0.75 <= coverage <= 1.0, coverage
    out = np.where(acc, err, ins)
    assert np.mean(out > ins * (1 + 1e-9)) <= 0.25
