"""GLS scores with a correlated map error, and the posterior over an offset lattice."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.match.gls import (
    gls_dof,
    gls_log_normaliser,
    gls_score,
    gls_whitener,
    offset_posterior,
    track_covariance,
    whiten,
)
from jaxgrav.match.scoring import bias_precision, decreasing_weights, score_track

# compiled once per shape: op-by-op dispatch of the same code is several times slower
cov_j = jax.jit(track_covariance, static_argnames="order")
whitener_j = jax.jit(gls_whitener)
score_j = jax.jit(gls_score)
_posterior_j = jax.jit(offset_posterior)


def posterior_j(scores, on, oe, cell=0.0, dof=1.0, exclusion_m=0.0, edge=None):
    """One compiled posterior per shape: every argument passed, as floats."""
    return _posterior_j(scores, on, oe, float(cell), dof=float(dof),
                        exclusion_m=float(exclusion_m), edge=edge)


score_track_j = jax.jit(score_track, static_argnames=("kind", "axis"))
RNG = np.random.default_rng(15)
SEED = 2015
N, C = 30, 17


def _track(n=N):
    """A wandering track with fixes ~600 m apart (m)."""
    heading = np.cumsum(RNG.normal(0.0, 0.3, n))
    step = RNG.uniform(300.0, 900.0, n)
    return np.cumsum(step * np.cos(heading)), np.cumsum(step * np.sin(heading))


def _numpy_cov(north, east, sn, sm, length, order):
    d = np.hypot(north[:, None] - north[None, :], east[:, None] - east[None, :])
    x = d / length
    poly = 1.0 if order == 1 else 1.0 + x
    return sn**2 * np.eye(north.size) + sm**2 * poly * np.exp(-x)


def _numpy_gls(cov, r, sigma_b):
    """Brute force: explicit inverse, bias marginalised by hand."""
    p = np.linalg.inv(cov)
    one = np.ones(cov.shape[0])
    prec_b = 0.0 if np.isinf(sigma_b) else 1.0 / sigma_b**2
    b = (r @ p @ one) / (one @ p @ one + prec_b)
    e = r - b[:, None]
    score = np.einsum("ci,ij,cj->c", e, p, e) + prec_b * b**2
    if np.isfinite(sigma_b):  # also the marginal form rᵀ(Σ + σ_b² 11ᵀ)⁻¹r
        pm = np.linalg.inv(cov + sigma_b**2 * np.outer(one, one))
        np.testing.assert_allclose(score, np.einsum("ci,ij,cj->c", r, pm, r), rtol=1e-10)
    return score, b


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("sigma_b", [np.inf, 2.5])
def test_gls_equals_numpy_brute_force(order, sigma_b):
    for _ in range(3):
        north, east = _track()
        sn, sm, length = RNG.uniform(0.5, 2.0), RNG.uniform(0.5, 5.0), RNG.uniform(2e3, 2e4)
        cov = cov_j(north, east, sn, sm, length, order)
        ref_cov = _numpy_cov(north, east, sn, sm, length, order)
        np.testing.assert_allclose(cov, ref_cov, rtol=1e-13, atol=1e-13)
        r = RNG.multivariate_normal(np.full(N, 3.0), ref_cov, size=C)
        w = whitener_j(cov)
        score, bias = score_j(w, r, sigma_b)
        ref_score, ref_bias = _numpy_gls(ref_cov, r, sigma_b)
        np.testing.assert_allclose(score, ref_score, rtol=1e-10)
        np.testing.assert_allclose(bias, ref_bias, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(w.log_det, np.linalg.slogdet(ref_cov)[1], rtol=1e-12)


def test_log_normaliser_is_the_negative_log_likelihood():
    north, east = _track()
    cov = _numpy_cov(north, east, 1.0, 3.0, 1e4, 2)
    r = RNG.multivariate_normal(np.zeros(N), cov, size=C)
    w = whitener_j(jnp.asarray(cov))
    sb = 4.0
    marg = cov + sb**2
    ref = (np.einsum("ci,ij,cj->c", r, np.linalg.inv(marg), r)
           + np.linalg.slogdet(marg)[1] + N * np.log(2 * np.pi))
    np.testing.assert_allclose(score_j(w, r, sb)[0] + gls_log_normaliser(w, sb), ref,
                               rtol=1e-10)
    # flat prior: the Gaussian prior's limit, less the prior's density at the bias
    big = 1e5
    lim = score_j(w, r, big)[0] + gls_log_normaliser(w, big) - np.log(2 * np.pi * big**2)
    flat = score_j(w, r)[0] + gls_log_normaliser(w)
    np.testing.assert_allclose(lim, flat, rtol=1e-7)
    assert int(gls_dof(N)) == N - 1 and int(gls_dof(N, sb)) == N


@pytest.mark.parametrize("decay", [0.0, 1.0])
@pytest.mark.parametrize("sigma_b", [np.inf, 0.7])
def test_white_map_equals_scoring_bias_form(decay, sigma_b):
    north, east = _track()
    sn = 1.3
    mu = decreasing_weights(N, decay)
    cov = cov_j(north, east, sn, 0.0, 1e4, weights=None if decay == 0 else mu)
    if decay == 0:
        np.testing.assert_allclose(cov, sn**2 * np.eye(N), rtol=0, atol=0)
    g = RNG.normal(0.0, 20.0, N)
    m = g - RNG.normal(1.0, sn, (C, N))
    m[3, 5] = np.nan  # off the map
    ref, ref_bias = score_track_j(g, m, mu, "bias", bias_precision(mu, sn, sigma_b))
    score, bias = score_j(whitener_j(cov), g - m, sigma_b)
    scale = sn**2 * np.sum(np.asarray(mu) ** 2)  # score_track = σ_n² Σμ² · J
    assert np.isinf(score[3]) and np.isinf(ref[3])
    keep = np.arange(C) != 3
    np.testing.assert_allclose(scale * score[keep], ref[keep], rtol=1e-12)
    np.testing.assert_allclose(bias[keep], ref_bias[keep], rtol=1e-12)


def test_zero_length_is_white_and_bad_input_is_named():
    north, east = _track(5)
    np.testing.assert_allclose(track_covariance(north, east, 1.0, 2.0, 0.0), 5.0 * np.eye(5))
    for kw, name in [(dict(map_sigma=-1.0), "map_sigma"), (dict(map_length_m=np.nan),
                     "map_length_m"), (dict(noise_sigma=0.0), "noise_sigma"),
                     (dict(map_length_m=np.inf), "map_length_m")]:
        args = dict(noise_sigma=1.0, map_sigma=1.0, map_length_m=1e4) | kw
        with pytest.raises(ValueError, match=name):
            track_covariance(north, east, **args)
    with pytest.raises(ValueError, match="order"):
        track_covariance(north, east, 1.0, 1.0, 1e4, order=3)


def test_batched_equals_loop_and_solve():
    tracks = [_track() for _ in range(3)]
    covs = jnp.stack([cov_j(n, e, 1.0, 3.0, 1e4) for n, e in tracks])
    r = jnp.asarray(RNG.normal(size=(3, C, N)))
    ws = jax.jit(jax.vmap(gls_whitener))(covs)
    batched = jax.jit(jax.vmap(gls_score, in_axes=(0, 0, None)))(ws, r, 2.0)
    for t in range(3):
        w = whitener_j(covs[t])
        s_t, b_t = score_j(w, r[t], 2.0)
        np.testing.assert_allclose(batched[0][t], s_t, rtol=1e-13)
        np.testing.assert_allclose(batched[1][t], b_t, rtol=1e-13, atol=1e-14)
        for c in range(C):
            s_c, b_c = score_j(w, r[t, c], 2.0)
            np.testing.assert_allclose(s_c, s_t[c], rtol=1e-13)
            np.testing.assert_allclose(b_c, b_t[c], rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(whiten(w, r[t], solve=True), whiten(w, r[t]), atol=1e-12)
        np.testing.assert_allclose(w.chol @ whiten(w, r[t]).T, r[t].T, atol=1e-12)


def _pipeline(north, east, r, sn, sm, length, sb):
    return score_j(whitener_j(cov_j(north, east, sn, sm, length)), r, sb)[0]


def test_no_retrace_when_noise_or_map_error_change():
    traces = []

    @jax.jit
    def f(north, east, r, sn, sm, length, sb):
        traces.append(1)
        return _pipeline(north, east, r, sn, sm, length, sb)

    north, east = _track()
    r = RNG.normal(size=(C, N))
    for sn, sm, length, sb in [(1.0, 3.0, 1e4, np.inf), (0.5, 0.0, 2e4, 3.0),
                               (2.0, 5.0, 0.0, 1.0)]:
        out = f(north, east, r, sn, sm, length, sb)
        np.testing.assert_allclose(out, _pipeline(north, east, r, sn, sm, length, sb),
                                   rtol=1e-12)
    assert len(traces) == 1


def test_gradients_match_finite_differences():
    north, east = _track()
    r = jnp.asarray(RNG.normal(size=N))
    args = (1.0, 3.0, 1e4, 2.0)

    @jax.jit
    def f(r, sn, sm, length, sb):
        return _pipeline(north, east, r, sn, sm, length, sb)

    g_r, g_sm, g_length = jax.jit(jax.grad(f, argnums=(0, 2, 3)))(r, *args)
    h = 1e-6
    for i in (0, 7, N - 1):
        e = jnp.zeros(N).at[i].set(h)
        fd = (f(r + e, *args) - f(r - e, *args)) / (2 * h)
        np.testing.assert_allclose(g_r[i], fd, rtol=1e-6)
    for k, step, g in [(1, 1e-5, g_sm), (2, 1e-2, g_length)]:  # map_sigma, map_length_m
        up, dn = list(args), list(args)
        up[k] += step
        dn[k] -= step
        fd = (f(r, *up) - f(r, *dn)) / (2 * step)
        assert np.isfinite(g) and abs(g) > 0
        np.testing.assert_allclose(g, fd, rtol=1e-6)


def _lattice(h=100.0, a=61):
    d = (np.arange(a) - a // 2) * h
    on, oe = np.meshgrid(d, d, indexing="ij")
    return on.reshape(-1), oe.reshape(-1)


MEAN = np.array([230.0, -410.0])
K = np.array([[300.0**2, 0.5 * 300 * 200], [0.5 * 300 * 200, 200.0**2]])


def _quad(on, oe, mean, cov):
    d = np.stack([on - mean[0], oe - mean[1]], -1)
    return np.einsum("ci,ij,cj->c", d, np.linalg.inv(cov), d)


@pytest.mark.long
def test_posterior_of_a_gaussian_likelihood():
    on, oe = _lattice()
    j = _quad(on, oe, MEAN, K) + 25.0
    post = jax.jit(offset_posterior)(j, on, oe, dof=25)
    np.testing.assert_allclose([post.mean_north_m, post.mean_east_m], MEAN, rtol=1e-6)
    np.testing.assert_allclose(post.covariance_m2, K, rtol=1e-6)
    np.testing.assert_allclose(post.curvature_covariance_m2, K, rtol=1e-6)
    assert post.curvature_ok and post.valid and int(post.n_invalid) == 0
    np.testing.assert_allclose(post.n_effective, 4 * np.pi * np.sqrt(np.linalg.det(K)) / 1e4,
                               rtol=1e-6)
    np.testing.assert_allclose(post.chi2_per_dof, np.min(j) / 25, rtol=1e-12)
    assert post.second_mode_ratio < np.exp(-4.0)  # unimodal: nothing outside 3 σ is likely
    assert post.edge_mass < 1e-12
    near_edge = posterior_j(_quad(on, oe, np.array([2900.0, 0.0]), K), on, oe)
    assert 0.1 < near_edge.edge_mass < 0.5  # the lattice ends at 3000 m north
    cell = posterior_j(j, on, oe, 100.0)
    np.testing.assert_allclose(cell.covariance_m2, K + np.eye(2) * 100.0**2 / 12, rtol=1e-6)
    ref = np.log(np.sum(np.exp(-0.5 * j)))
    np.testing.assert_allclose(post.log_evidence, ref, rtol=1e-12)


def test_bimodal_likelihood_has_second_mode_ratio_near_one():
    on, oe = _lattice()
    other = np.array([-1800.0, 1500.0])
    lik = np.exp(-0.5 * _quad(on, oe, MEAN, K)) + 0.9 * np.exp(-0.5 * _quad(on, oe, other, K))
    j = -2.0 * np.log(lik)
    post = posterior_j(j, on, oe, 100.0)
    near_other = np.hypot(on - other[0], oe - other[1]) < 1000.0
    expected = lik[near_other].max() / lik.max()  # the lattice's own peaks, ≈ 0.9
    np.testing.assert_allclose(post.second_mode_ratio, expected, rtol=1e-9)
    assert abs(expected - 0.9) < 0.02
    for rad in (1000.0, 2000.0):
        alt = posterior_j(j, on, oe, 100.0, exclusion_m=rad)
        np.testing.assert_allclose(alt.second_mode_ratio, expected, rtol=1e-9)
    mix = (MEAN + 0.9 * other) / 1.9
    np.testing.assert_allclose([post.mean_north_m, post.mean_east_m], mix, rtol=1e-4)
    assert np.sqrt(post.covariance_m2[0, 0]) > 900.0  # the spread of both modes


@pytest.mark.long
def test_invalid_offsets_are_ignored_and_all_invalid_is_flagged():
    on, oe = _lattice()
    j = _quad(on, oe, MEAN, K)
    bad = RNG.random(j.size) < 0.3
    bad[np.argmin(j)] = False
    jb = j.copy()
    jb[bad] = np.where(RNG.random(bad.sum()) < 0.5, np.inf, np.nan)
    post = posterior_j(jb, on, oe, 100.0, dof=5)
    ref = posterior_j(j[~bad], on[~bad], oe[~bad], 100.0, dof=5)
    assert int(post.n_invalid) == bad.sum() and int(post.n_valid) == (~bad).sum()
    for name in ("mean_north_m", "mean_east_m", "covariance_m2", "n_effective",
                 "second_mode_ratio", "best_score", "log_evidence"):
        np.testing.assert_allclose(getattr(post, name), getattr(ref, name), rtol=1e-12,
                                   err_msg=name)
    none = posterior_j(np.full(j.size, np.nan), on, oe, 100.0)
    assert not none.valid and not none.curvature_ok and int(none.n_invalid) == j.size
    assert none.mean_north_m == 0 and none.mean_east_m == 0 and none.n_effective == 0
    assert np.all(np.isinf(np.diag(none.covariance_m2))) and none.second_mode_ratio == 1
    for name, v in none._asdict().items():
        assert not np.any(np.isnan(np.asarray(v))), name
    batch = jax.jit(jax.vmap(lambda s: offset_posterior(s, on, oe, 100.0, dof=5)))(
        np.stack([jb, np.full(j.size, np.nan)]))
    for name, v in post._asdict().items():
        np.testing.assert_allclose(getattr(batch, name)[0], v, rtol=1e-12, err_msg=name)
    assert not batch.valid[1]


@pytest.mark.long
def test_posterior_covers_the_truth_under_a_correlated_map_error():
    """Monte Carlo: map error drawn from the model along the true track, readings matched
    on an offset lattice fine enough to resolve the posterior (a smooth map, ~10 offsets
    share the mass). The GLS posterior's 95 % ellipse covers the true offset on about
    95 % of tracks (0.94–0.98 over seeds); the white-noise score (map error ignored) is
    overconfident (about 35 %)."""
    rng = np.random.default_rng(SEED)  # its own draws: the same whatever runs first
    n, tracks, h, cell = 30, 200, 10, 500.0
    kw = rng.uniform(2 * np.pi / 80e3, 2 * np.pi / 20e3, (tracks, 12))  # a map per track
    ang, phase = rng.uniform(0, 2 * np.pi, (2, tracks, 12))
    waves = np.stack([kw * np.cos(ang), kw * np.sin(ang), phase], 1)  # (tracks, 3, 12)
    d1 = (np.arange(-h, h + 1)) * cell
    on, oe = (jnp.asarray(a.reshape(-1)) for a in np.meshgrid(d1, d1, indexing="ij"))
    north = east = np.arange(n) * 617.0  # 2 min at 10 kn north and 10 kn east
    offsets = np.clip(rng.normal(0.0, 1500.0, (tracks, 2)), -4000.0, 4000.0)
    starts = rng.uniform(-50e3, 50e3, (tracks, 2))
    keys = jnp.asarray(rng.normal(size=(tracks, n)))

    def field(wave, pn, pe):  # analytic map (mGal), 20 mGal rms
        kn, ke, phase = wave
        return 8.2 * jnp.sum(jnp.cos(pn[..., None] * kn + pe[..., None] * ke + phase), -1)

    @jax.jit
    def run(wave, start, off, xi, map_sigma):
        tn, te = start[0] + north, start[1] + east  # the true track
        cov_true = track_covariance(north, east, 1.0, 3.0, 10e3)
        g = field(wave, tn, te) + jnp.linalg.cholesky(cov_true) @ xi
        # INS track = truth + off; candidate k = INS track + lattice offset k
        r = g - field(wave, tn + off[0] + on[:, None], te + off[1] + oe[:, None])
        w = gls_whitener(track_covariance(north, east, 1.0, map_sigma, 10e3))
        p = offset_posterior(gls_score(w, r)[0], on, oe, cell, dof=gls_dof(n))
        e = jnp.stack([p.mean_north_m, p.mean_east_m]) + off
        return e @ jnp.linalg.solve(p.covariance_m2, e)

    for map_sigma, lo, hi in [(3.0, 0.92, 0.995), (0.0, 0.0, 0.6)]:
        q = jax.vmap(run, in_axes=(0, 0, 0, 0, None))(waves, starts, offsets, keys, map_sigma)
        coverage = np.mean(np.asarray(q) < 5.991)
        assert lo <= coverage <= hi, (map_sigma, coverage)


def test_edge_mass_of_a_disc_ring_equals_numpy():
    on, oe = _lattice()
    r2 = on**2 + oe**2
    j = np.where(r2 <= 3000.0**2, _quad(on, oe, np.array([2500.0, 1200.0]), K), np.inf)
    post = posterior_j(j, on, oe, edge=r2 > 2900.0**2)
    w = np.exp(-0.5 * (j - j[np.isfinite(j)].min()))
    w = w / w.sum()
    np.testing.assert_allclose(post.edge_mass, w[r2 > 2900.0**2].sum(), rtol=1e-10)
    assert 0.05 < float(post.edge_mass) < 0.95
    square = posterior_j(j, on, oe)  # the lattice's outermost rows and columns
    assert float(square.edge_mass) < 1e-12  # only the four axis ends of the disc
