"""Survey gaps (``missing="gaps"``): candidates scored on their fixes over present cells.

The gap scores against their gap-free forms and brute-force NumPy versions, the
truth's expected score whatever its gaps, jit/vmap/grad, the refinement's masked
residuals, and the dense matcher with a gap across the true track.
"""

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrav.match as jm
from jaxgrav.match.api import MASKED, MIN_FIXES, max_gap_fixes, missing_reading
from jaxgrav.match.gaps import gap_score, gap_whitener, gls_gap_score
from jaxgrav.match.gls import gls_score, gls_whitener, track_covariance
from jaxgrav.match.lattice import patch_values
from jaxgrav.match.offsets import track_frame
from jaxgrav.match.refine import (
    gauss_newton,
    gls_residual_function,
    laplace_covariance,
    residual_function,
)
from jaxgrav.match.result import GAPPED
from jaxgrav.match.scoring import score_track
from jaxgrav.prepared import prepare_map

N = 12
RNG = np.random.default_rng(3)
G = RNG.normal(size=N)
M = RNG.normal(size=(7, N))
W = np.exp(-0.5 * np.linspace(0.0, 1.0, N))
W = W / W.sum()
UNIT = 0.7**2 * np.sum(W**2)  # σ_n² Σμ²
# jitted: op by op (at every collection, in each pytest-xdist worker) it took 1.1 s
COV = np.asarray(jax.jit(track_covariance)(1000.0 * np.arange(N), np.zeros(N), 0.7, 2.0,
                                           5000.0, weights=W))


def _holey():
    m = M.copy()
    m[0, [2, 5]] = np.nan
    m[1, :5] = np.nan  # more gaps than the cap below
    m[2, 11] = np.nan
    return m


@pytest.mark.parametrize("kind", ["bias", "absolute", "difference"])
def test_gap_score_without_gaps_is_score_track(kind):
    a = gap_score(G, M, W, kind, 0.1, UNIT, 3)
    b = score_track(G, M, W, kind, 0.1)
    np.testing.assert_allclose(np.asarray(a[0]), np.asarray(b[0]), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(a[1]), np.asarray(b[1]), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("kind", ["bias", "absolute", "difference"])
def test_gap_score_against_a_numpy_loop(kind):
    m = _holey()
    score, bias = (np.asarray(x) for x in gap_score(G, m, W, kind, 0.1, UNIT, 3))
    for k in range(m.shape[0]):
        ok = np.isfinite(m[k])
        if (~ok).sum() > 3:
            assert score[k] == np.inf
            continue
        r = G - np.where(ok, m[k], 0.0)
        if kind == "difference":
            wd = W[:-1] / W[:-1].sum()
            s = 0.0
            for i in range(N - 1):
                if ok[i] and ok[i + 1]:
                    s += wd[i] * (r[i + 1] - r[i]) ** 2
                else:  # a difference's expected square: the sum of the two variances
                    s += wd[i] * (UNIT / W[i] + UNIT / W[i + 1])
            b = np.sum(W[ok] * r[ok]) / np.sum(W[ok])
        else:
            b = 0.0 if kind == "absolute" else np.sum(W[ok] * r[ok]) / (np.sum(W[ok]) + 0.1)
            s = np.sum(W[ok] * (r[ok] - b) ** 2) + (0.1 * b * b if kind == "bias" else 0.0)
            s += UNIT * (~ok).sum()
        np.testing.assert_allclose(score[k], s, rtol=1e-12)
        np.testing.assert_allclose(bias[k], b, rtol=1e-12, atol=1e-15)


GLS_GAP = jax.jit(gls_gap_score, static_argnums=3)
GLS = jax.jit(gls_score)
WHITENER = jax.jit(gls_whitener)  # op by op its Cholesky scan compiled again at every call


@pytest.mark.parametrize("sigma_b", [np.inf, 2.0, 0.0])
def test_gls_gap_score_is_the_restricted_covariance_score_plus_one_per_gap(sigma_b):
    wh = WHITENER(COV)
    a = GLS_GAP(wh, G - M, sigma_b, 3)
    b = GLS(wh, G - M, sigma_b)
    np.testing.assert_allclose(np.asarray(a[0]), np.asarray(b[0]), rtol=1e-10)
    np.testing.assert_allclose(np.asarray(a[1]), np.asarray(b[1]), rtol=1e-10, atol=1e-13)
    m = _holey()
    score, bias = (np.asarray(x) for x in GLS_GAP(wh, G - m, sigma_b, 3))
    for k in range(m.shape[0]):
        ok = np.isfinite(m[k])
        if (~ok).sum() > 3:
            assert score[k] == np.inf
            continue
        ref, ref_b = GLS(WHITENER(COV[np.ix_(ok, ok)]), (G - m[k])[ok], sigma_b)
        np.testing.assert_allclose(score[k], float(ref) + (~ok).sum(), rtol=1e-10)
        np.testing.assert_allclose(bias[k], float(ref_b), rtol=1e-10, atol=1e-13)


def test_the_truths_expected_score_does_not_depend_on_its_gaps():
    """Candidates with and without gaps compare on one scale: E[J] = N − 1 (flat bias)."""
    wh = WHITENER(COV)
    chol = np.linalg.cholesky(COV)
    draws = 4000
    r = (chol @ RNG.standard_normal((N, draws))).T + 5.0  # any bias
    for gaps in ([], [3], [0, 1, 2, 7, 8, 11]):
        rr = r.copy()
        rr[:, gaps] = np.nan
        j = np.asarray(GLS_GAP(wh, rr, np.inf, 6)[0])
        assert abs(j.mean() - (N - 1)) < 4 * np.sqrt(2 * (N - 1) / draws), (gaps, j.mean())


def test_gap_scores_jit_vmap_and_grad():
    wh = WHITENER(COV)
    m = jnp.asarray(_holey())
    f = jax.jit(lambda r: gls_gap_score(wh, r, 2.0, 3)[0])
    np.testing.assert_allclose(np.asarray(f(G - m)),
                               np.asarray(jax.vmap(lambda r: f(r[None])[0])(G - m)), rtol=1e-12)
    g = jax.jit(lambda mm: gap_score(G, mm, W, "bias", 0.1, UNIT, 3)[0])
    np.testing.assert_allclose(np.asarray(g(m)), np.asarray(jax.vmap(g)(m[:, None])[:, 0]),
                               rtol=1e-12)
    # grad with respect to the readings, against central differences, on a candidate with gaps
    k = 2

    def loss(gg):
        return gls_gap_score(wh, gg - m[k], 2.0, 3)[0] + gap_score(gg, m[k], W, "bias", 0.1,
                                                                   UNIT, 3)[0]

    grad = np.asarray(jax.jit(jax.grad(loss))(jnp.asarray(G)))
    h = 1e-6
    steps = h * np.eye(N)
    losses = jax.jit(jax.vmap(loss))  # one program for both sides
    fd = (losses(G + steps) - losses(G - steps)) / (2 * h)
    np.testing.assert_allclose(grad, np.asarray(fd), rtol=1e-6, atol=1e-8)
    assert grad[11] == 0.0  # a fix over a gap does not move the score


def test_refinement_residuals_are_the_gap_score(smooth_grid):
    """‖r(p)‖² plus the gaps' expectation is the gap score at p (white and GLS)."""
    lat = 29.95 + 0.003 * np.arange(N)
    lon = 129.9 + 0.004 * np.arange(N)
    pm = prepare_map(smooth_grid)
    table = pm.interleaved()
    frame = track_frame(smooth_grid, jnp.asarray(lat), jnp.asarray(lon))
    v = np.asarray(smooth_grid.sample(lat, lon, "bicubic"))
    g = v + RNG.normal(0.0, 0.7, N) + 1.5
    present = jnp.asarray(np.arange(N) % 4 != 1)
    v_gap = np.where(np.asarray(present), v, np.nan)
    p = jnp.zeros(4)

    @jax.jit
    def both(g, v_gap):
        """(cost at the best bias, score): white, then GLS (one program, one compile)."""
        res = residual_function(table, frame, g, jnp.asarray(W), "bias", 0.1, "bicubic",
                                present)
        score, bias = gap_score(g, v_gap, W, "bias", 0.1, UNIT, 6)
        # the score minimises over the bias: equal at the optimal bias
        r, _, (r_k, _) = res(p.at[3].set(bias))
        white = (jnp.sum(r * r) + r_k**2 + UNIT * 3, score)
        cov = track_covariance(frame[4], frame[5], 0.7, 2.0, 5000.0, weights=W)
        wh = gls_whitener(cov)
        inv, ones = gap_whitener(wh, present)
        j, b = gls_gap_score(wh, (g - v_gap)[None], 2.0, 6)
        res = gls_residual_function(table, frame, g, inv, ones, UNIT, 2.0, "bicubic", present)
        r, _, (r_k, _) = res(p.at[3].set(b[0]))
        return white, ((jnp.sum(r * r) + r_k**2) / UNIT + 3, j[0])

    for cost, score in both(jnp.asarray(g), jnp.asarray(v_gap)):
        np.testing.assert_allclose(float(cost), float(score), rtol=1e-9)


def _banded(grid, lon0, half_width):
    """``grid`` with a north-south band of missing nodes (a survey gap) about ``lon0``."""
    v = np.array(grid.values)
    lo = np.asarray(grid.lon)
    v[:, (lo > lon0 - half_width) & (lo < lon0 + half_width)] = np.nan
    return dataclasses.replace(grid, values=jnp.asarray(v))


@pytest.mark.long
def test_refinement_moves_from_a_start_with_gaps(smooth_grid):
    """Gauss–Newton from a start whose fixes cross a gap: finite Jacobian, steps taken.

    The truth is 300 m south of the INS track; the readings come from the complete
    field, the matcher sees it with a band of missing nodes across the track.
    """
    n = 16
    lat = 29.9 + 0.002 * np.arange(n)
    lon = 129.85 + 0.003 * np.arange(n)
    grid = _banded(smooth_grid, lon[n // 2], 0.006)
    t_lat, t_lon = (np.asarray(a) for a in jm.shifted_tracks(
        jnp.asarray(lat), jnp.asarray(lon), -300.0, 0.0, 0.0))
    z = jnp.asarray(np.asarray(smooth_grid.sample(t_lat, t_lon, "bicubic")) + 1.5)
    table = prepare_map(grid).interleaved()
    frame = track_frame(grid, jnp.asarray(lat), jnp.asarray(lon))
    iy_c, ix_c, ky, kx, north, east = frame
    v, v_y, v_x = patch_values(table, iy_c + ky * north, ix_c + kx * east, gradient=True)
    present = ~jnp.isnan(v)
    assert 3 <= int((~present).sum()) <= n // 2
    # in a cell with a missing node the value is NaN and its derivatives 0, never NaN
    assert np.all(np.asarray(v_y)[~np.asarray(present)] == 0.0)
    assert np.all(np.asarray(v_x)[~np.asarray(present)] == 0.0)
    free = (True, True, False, True)
    step_max = jnp.array([1000.0, 1000.0, 1.0, np.inf])
    cov = track_covariance(north, east, 0.7, 2.0, 5000.0)
    inv, ones = gap_whitener(gls_whitener(cov), present)
    for res in (residual_function(table, frame, z, jnp.full(n, 1.0 / n), "bias", 0.0,
                                  "bicubic", present),
                gls_residual_function(table, frame, z, inv, ones, 1.0, np.inf, "bicubic",
                                      present)):
        def cost(p, res=res):
            r, _, (r_k, _) = res(jnp.asarray(p, float))
            return float(jnp.sum(r * r) + r_k**2)

        r, cols, _ = res(jnp.zeros(4))
        assert all(np.isfinite(np.asarray(c)).all() for c in (r, *cols))
        p = np.asarray(gauss_newton(res, jnp.zeros(4), free, step_max, 1e-3, 8))
        assert np.hypot(p[0] + 300.0, p[1]) < 100.0, p
        # the minimum of the gapped map is near the truth (its spline differs by the band)
        assert cost(p) <= cost([-300.0, 0.0, 0.0, 1.5]) < 0.1 * cost(np.zeros(4))
        assert np.isfinite(np.asarray(laplace_covariance(res, jnp.asarray(p), free))).all()


def test_how_missing_nodes_are_read(smooth_grid):
    """The one rule (:func:`missing_reading`), and a warning when gaps cannot apply."""
    n = 12
    lat = 29.9 + 0.002 * np.arange(n)
    lon = 129.85 + 0.003 * np.arange(n)
    grid = _banded(smooth_grid, lon[n // 2], 0.006)
    far = _banded(smooth_grid, 130.4, 0.006)  # missing nodes out of reach
    reach = 3000.0
    assert missing_reading(grid, lat, lon, "dense", "auto", reach) == "gaps"  # INS crosses
    assert missing_reading(grid, lat, lon, "dense", "land", reach) == "land"
    assert missing_reading(grid, lat, lon, "chains", "auto", reach) == "land"
    assert missing_reading(far, lat, lon, "dense", "gaps", reach) == "land"
    assert missing_reading(grid, lat[:MIN_FIXES], lon[:MIN_FIXES], "dense", "gaps",
                           reach) == "land"
    z = np.asarray(smooth_grid.sample(lat, lon, "bicubic"))[:MIN_FIXES]
    with (pytest.warns(RuntimeWarning, match="needs more than 5 fixes"),
          pytest.warns(RuntimeWarning, match="the search region holds missing")):
        jm.match_track(grid, lat[:MIN_FIXES], lon[:MIN_FIXES], z, drift_radius_m=reach,
                       noise=0.5, missing="gaps")


def test_gaps_options_are_checked(smooth_grid):
    lat = 29.95 + 0.003 * np.arange(N)
    lon = 129.9 + 0.004 * np.arange(N)
    z = np.asarray(smooth_grid.sample(lat, lon, "bicubic"))
    with pytest.raises(ValueError, match="missing must be 'land', 'gaps' or 'auto'; got 'sea'"):
        jm.match_track(smooth_grid, lat, lon, z, missing="sea")
    with pytest.raises(ValueError, match="built for method 'dense' only; got method 'chains'"):
        jm.match_track(smooth_grid, lat, lon, z, method="chains", missing="gaps")
    with pytest.raises(ValueError, match="gap_fixes must be >= 0"):
        jm.DenseConfig(gap_fixes=-1)
    assert max_gap_fixes(30) == 30 - MIN_FIXES and max_gap_fixes(MIN_FIXES) == 0


@pytest.mark.long
def test_dense_matches_across_a_survey_gap_that_land_mode_cannot(smooth_grid):
    """A gap across the true track: as land the truth is dropped; as gaps it is found."""
    n = 24
    lat = 29.9 + 0.002 * np.arange(n)
    lon = 129.85 + 0.003 * np.arange(n)
    t_lat, t_lon = (np.asarray(a) for a in jm.shifted_tracks(
        jnp.asarray(lat), jnp.asarray(lon), -1500.0, 1000.0, 0.0))
    z = np.asarray(smooth_grid.sample(t_lat, t_lon, "bicubic")) + RNG.normal(0, 0.5, n)
    v = np.array(smooth_grid.values)
    lo = np.asarray(smooth_grid.lon)
    mid = t_lon[n // 2]
    v[:, (lo > mid - 0.012) & (lo < mid + 0.012)] = np.nan  # a north-south band, ~2.3 km
    grid = dataclasses.replace(smooth_grid, values=jnp.asarray(v))
    gap = ~np.isfinite(np.asarray(grid.sample(t_lat, t_lon, "bicubic")))
    assert 3 <= gap.sum() <= n // 2
    out = {}
    for missing, g in (("land", grid), ("gaps", grid), ("auto", grid), ("complete", smooth_grid)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            r = jm.match_track(g, lat, lon, z, drift_radius_m=3000.0, noise=0.5,
                               missing="land" if missing == "complete" else missing)
        err = np.hypot((np.asarray(r.lat) - t_lat) * 111.2e3,
                       (np.asarray(r.lon) - t_lon) * 111.2e3 * np.cos(np.radians(30.0)))
        out[missing] = (float(err.max()), r)
    err, r = out["gaps"]
    assert int(r.status) & MASKED and bool(r.accepted) and np.isfinite(float(r.score))
    assert err < max(2.0 * out["complete"][0], 300.0), out  # as good as without the gap
    assert out["land"][0] > 3 * err, out
    # the INS track crosses the gap, so the default reads it as one
    np.testing.assert_array_equal(np.asarray(out["auto"][1].lat), np.asarray(r.lat))
    assert 0.3 < float(r.chi2_per_dof) < 3.0  # the gaps count at their expectation
    # a gap over most of the track: the fix would be a guess, so it is rejected
    v[:, (lo > mid - 0.03) & (lo < mid + 0.03)] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        r = jm.match_track(dataclasses.replace(smooth_grid, values=jnp.asarray(v)), lat, lon, z,
                           drift_radius_m=3000.0, noise=0.5, missing="gaps")
    assert int(r.status) & GAPPED and not bool(r.accepted)
    np.testing.assert_array_equal(np.asarray(r.lat), lat)  # the INS track kept
