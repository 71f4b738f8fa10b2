"""Tests of the grid point-mass filter (jaxgrav.filters.pmf).

References: the diffusion kernel against a brute-force NumPy convolution with the
exact lattice heat kernel (Skellam, e^{−v} I_n(v), reflected at the edges) and
SciPy's matrix exponential; the prediction and the Bayes update against NumPy
on a small grid; causality of ``run_filter(every > 1)``; vmap against a Python loop;
the deprecated ``run_pmf`` as the same run.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
import scipy.special

from jaxgrav import datasets
from jaxgrav import filters as fl
from jaxgrav.constants import DEG
from jaxgrav.fields.pointmass import gravity_anomaly, paper_d
from jaxgrav.filters.map_state import augment, map_error_state
from jaxgrav.filters.pmf import diffusion_kernel
from jaxgrav.filters.pmf_cells import cell_values, weigh_cells
from jaxgrav.filters.pmf_predict import shifted_kernel
from jaxgrav.geodesy import meridian_radius
from jaxgrav.grid import Grid
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios.paper_d import MASS_LON
from jaxgrav.sim import ins

FLAGS = fl.STATUS_FILTER
FIELD = paper_d()
G, CELL, Q_POS, DT = 15, 400.0, 50.0, 10.0
PMF = fl.pmf(n_cells=G, cell_m=CELL, q_pos=Q_POS)
PMF_RW = fl.pmf(n_cells=G, cell_m=CELL, q_pos=Q_POS, ins=None)
LAT = 24.25



def _run(filt, field, dt, x0, p0, steps, every):
    """The point-mass filter through the one runner, its error model at the mean latitude."""
    return fl.run_filter(filt, field, filt.dynamics(jnp.mean(steps.lat), dt), x0, p0, steps,
                         every)


init = jax.jit(lambda filt, x0, p0: filt.init(x0, p0), static_argnums=0)
# the Filter protocol's predict: (state, step, field, dynamics); a step without a reading
predict = jax.jit(lambda filt, s, dyn: filt.predict(s, _step(jnp.nan), None, dyn),
                  static_argnums=0)

@functools.partial(jax.jit, static_argnums=0)
def predict_settled(filt, s, dyn):
    """The prediction applied to the cells (``predict`` leaves it pending)."""
    s, info = filt.predict(s, _step(jnp.nan), None, dyn)
    return filt.settle(s), info


update = jax.jit(lambda filt, s, step, field, dyn: filt.update(s, step, field, dyn),
                 static_argnums=0)
run = jax.jit(_run, static_argnums=(0, 6))
run_batch = jax.jit(jax.vmap(_run, in_axes=(None, None, None, None, None, 0, None)),
                    static_argnums=(0, 6))


def _radii(lat):
    a, e2 = 6378137.0, 6.69437999014e-3
    s2 = np.sin(lat * DEG) ** 2
    return a * (1 - e2) / (1 - e2 * s2) ** 1.5, a / np.sqrt(1 - e2 * s2)


def _step(z, lat=LAT, lon=MASS_LON + 0.02, r=1.0):
    return fl.Step(*(jnp.asarray(v, dtype=jnp.float64) for v in (lat, lon, z, r)))


@pytest.fixture(scope="module")
def dyn():
    return PMF.dynamics(LAT, DT)


@pytest.fixture(scope="module")
def prior():
    """A prior with a velocity error (so the model drifts) and a correlated position block."""
    p0 = np.array(ins.initial_covariance(ins.INSErrorModel(), 1000.0, 0.15))
    p0[:2, :2] = [[900.0**2, 1.5e5], [1.5e5, 700.0**2]]
    x0 = np.zeros(ins.N_STATES)
    x0[[0, 1, 2, 3, 12]] = [150.0, -100.0, 0.3, -0.2, 0.5]
    return jnp.asarray(x0), jnp.asarray(p0)


def _steps(n, every, seed=0, n_runs=None):
    """An eastward track over the masses, readings (map + noise) on steps every−1, 2·every−1, …"""
    rng = np.random.default_rng(seed)
    shape = (n,) if n_runs is None else (n_runs, n)
    lat = np.full(shape, LAT) + (0 if n_runs is None else rng.uniform(-0.1, 0.1, (n_runs, 1)))
    lon = MASS_LON - 0.05 + 100.0 * np.arange(1, n + 1) / (111320.0 * np.cos(LAT * DEG))
    lon = np.broadcast_to(lon, shape)
    z = np.asarray(gravity_anomaly(FIELD, lat - 0.004, lon + 0.003)) + rng.standard_normal(shape)
    z[..., (np.arange(n) % every) != every - 1] = np.nan
    return fl.Step(*(jnp.asarray(a) for a in (lat, lon, z)), jnp.ones(shape))


# ----------------------------------------------------------------- diffusion kernel


def _np_kernel(n, v, images=50):
    """Continuous-time random walk of variance v (Skellam pmf e^{−v} I_k(v)), reflected at
    the cell-grid edges by the method of images: a brute-force convolution."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = np.zeros((n, n))
    for m in range(-images, images + 1):
        for d in (i - j + 2 * n * m, i + j + 1 + 2 * n * m):
            a += scipy.special.ive(np.abs(d), v)
    return a


@pytest.mark.parametrize("v", [0.05, 0.9, 3.0, 40.0, 2000.0])
def test_diffusion_kernel_is_the_brute_force_convolution(v):
    a = np.asarray(diffusion_kernel(G, jnp.asarray(v)))
    np.testing.assert_allclose(a, _np_kernel(G, v), rtol=1e-9, atol=1e-14)
    lap = np.diag(np.full(G, -2.0)) + np.diag(np.ones(G - 1), 1) + np.diag(np.ones(G - 1), -1)
    lap[0, 0] = lap[-1, -1] = -1.0
    np.testing.assert_allclose(a, scipy.linalg.expm(0.5 * v * lap), rtol=1e-9, atol=1e-14)
    assert a.min() >= 0.0  # non-negative for any v (the 3-point stencil is not for v > 1)
    np.testing.assert_allclose(a.sum(0), 1.0, rtol=1e-14)  # mass conserving at the edges


def test_diffusion_kernel_has_the_variance_v_inside():
    a = np.asarray(diffusion_kernel(61, jnp.asarray(7.3)))
    col, x = a[:, 30], np.arange(61) - 30.0
    np.testing.assert_allclose(np.sum(col * x), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(col * x**2), 7.3, rtol=1e-9)


def test_shifted_kernel_from_its_profile_is_the_moved_brute_force_kernel():
    """The kernel built from its profile (Toeplitz plus Hankel, no n³ product), shifted by
    k whole cells inside one vmapped program, is the brute-force kernel's columns moved
    (zero for the cells pushed off)."""
    vs, ks = np.array([0.0, 0.0125, 0.9, 40.0, 3.0]), np.array([0, 1, -3, G - 1, -(G - 1)])
    got = np.asarray(jax.jit(jax.vmap(lambda v, k: shifted_kernel(G, v, k)))(vs, ks))
    for a, v, k in zip(got, vs, ks, strict=True):
        want = np.eye(G) if v == 0 else _np_kernel(G, v)
        j = np.arange(G) - k
        ok = (j >= 0) & (j < G)
        want = np.where(ok[None, :], want[:, np.clip(j, 0, G - 1)], 0.0)
        np.testing.assert_allclose(a, want, rtol=1e-9, atol=1e-14)


# ----------------------------------------------------------------- prediction, update


def _np_predict(state, dyn, q_pos):
    """The prediction in NumPy: Gaussian moments, drift of the origin, conditional spread."""
    x, p, f, q = (np.asarray(a) for a in (state.x, state.p, dyn.f, dyn.q))
    p_new = f @ p @ f.T + q
    spread = np.maximum(np.diag(p_new[:2, :2] - p[:2, :2]), 0.0) + q_pos * float(dyn.dt)
    a_n, a_e = (_np_kernel(G, s / CELL**2) for s in spread)
    fb, qb = f[12, 12], q[12, 12]
    w, m, s = (np.asarray(a) for a in (state.w, state.bias_mean, state.bias_var))
    m, s = fb * m, fb**2 * s + qb
    w_new = a_n @ w @ a_e.T
    m_new = a_n @ (w * m) @ a_e.T / w_new
    s_new = a_n @ (w * (s + m**2)) @ a_e.T / w_new - m_new**2
    centre = np.asarray(state.centre) + (f @ x - x)[:2]
    return w_new, m_new, s_new, centre, f @ x, p_new


def test_prediction_translates_by_the_model_drift_and_spreads_by_its_variance_growth(
        prior, dyn):
    x0, p0 = prior
    state = init(PMF, x0, p0)
    assert float(state.w.sum()) == pytest.approx(1.0, abs=1e-14)
    new, info = predict_settled(PMF, state, dyn)
    w, m, s, centre, x, _ = _np_predict(state, dyn, Q_POS)
    np.testing.assert_allclose(np.asarray(new.centre), centre, rtol=1e-12)
    assert abs(centre[0] - 3.0) < 0.1 and abs(centre[1] + 2.0) < 0.1  # 10 s at (0.3, −0.2) m/s
    np.testing.assert_allclose(np.asarray(new.w), w, rtol=1e-8, atol=1e-15)
    big = w > 1e-10
    np.testing.assert_allclose(np.asarray(new.bias_mean)[big], m[big], rtol=1e-8)
    np.testing.assert_allclose(np.asarray(new.bias_var)[big], s[big], rtol=1e-7)
    np.testing.assert_allclose(np.asarray(new.x)[2:12], x[2:12], rtol=1e-9, atol=1e-14)
    # 15 cells: the edges hold mass
    assert int(info.status) & ~FLAGS["grid_edge"] == FLAGS["no_reading"]
    assert np.isnan(float(info.innovation))
    # the reported prediction is the grid's moments without touching the cells: the
    # weights' mean moved with the origin (exactly the model's drift), the variance grown
    # by the spread; these 15 cells hold mass at their reflecting edges, so the spread
    # grid's own mean differs by ~1 mm
    np.testing.assert_allclose(np.asarray(info.x)[:2], x[:2], rtol=1e-12)
    dn = np.asarray(new.centre)[0] + (np.arange(G) - (G - 1) / 2) * CELL
    np.testing.assert_allclose(float(info.x[0]), np.sum(w * dn[:, None]), atol=0.01)


@pytest.mark.parametrize("map_error", [False, True])
def test_pending_predictions_compose_exactly(prior, map_error):
    """Five predictions left pending then settled once are five settled predictions (the
    spreads add, the per-cell bias and map-error models and their cross term compose;
    on a grid whose edges hold no mass), and the moments reported on the way are the
    settled grid's."""
    filt = fl.pmf(n_cells=41, cell_m=400.0, q_pos=Q_POS)
    x0, p0 = prior
    dyn = filt.dynamics(LAT, DT)
    if map_error:  # a first-order map error per cell, correlated with the bias
        dyn, x0, p0, _ = augment(map_error_state(3.0, 10e3, order=1), dyn, x0, p0, 5.0)
        p0 = p0.at[12, 13].set(0.3).at[13, 12].set(0.3)
    lazy = eager = init(filt, x0, p0)
    for _ in range(5):
        lazy, info = predict(filt, lazy, dyn)
        eager, _ = predict_settled(filt, eager, dyn)
    assert float(lazy.pending[0]) > 0.0  # the cells not touched yet
    settled = jax.jit(filt.settle)(lazy)
    w = np.asarray(eager.w)
    np.testing.assert_allclose(np.asarray(settled.w), w, rtol=1e-8, atol=1e-15)
    big = w > 1e-10
    names = ("bias_mean", "bias_var") + (("err_mean", "err_var", "err_cross") if map_error
                                         else ())
    for name in names:
        np.testing.assert_allclose(np.asarray(getattr(settled, name))[big],
                                   np.asarray(getattr(eager, name))[big], rtol=1e-9, atol=1e-12)
    for name in ("centre", "x", "p"):  # settled: x, p hold the grid's position moments
        np.testing.assert_allclose(np.asarray(getattr(settled, name)),
                                   np.asarray(getattr(eager, name)), rtol=1e-9, atol=1e-9)
    # what the pending prediction reported is the settled grid's moments
    np.testing.assert_allclose(np.asarray(info.x)[:2], np.asarray(settled.x)[:2], atol=1e-6)
    np.testing.assert_allclose(np.asarray(info.p_pos), np.asarray(settled.p)[:2, :2], rtol=1e-9)
    ws = np.asarray(settled.w)  # and the per-cell Gaussians' mixture means
    np.testing.assert_allclose(float(info.x[12]), np.sum(ws * np.asarray(settled.bias_mean)),
                               rtol=1e-9)
    if map_error:
        np.testing.assert_allclose(float(info.x[13]),
                                   np.sum(ws * np.asarray(settled.err_mean)), atol=1e-12)


@pytest.mark.parametrize("dt", [10.0, 5000.0])
def test_random_walk_prediction_any_v(prior, dt):
    """No error model: pure diffusion of variance q dt, exact also for v = q dt / cell² ≫ 1."""
    x0, p0 = prior
    state = init(PMF_RW, x0, p0)
    new, _ = predict_settled(PMF_RW, state, PMF_RW.dynamics(LAT, dt))
    v = Q_POS * dt / CELL**2
    a = _np_kernel(G, v)
    w = np.asarray(new.w)
    np.testing.assert_allclose(w, a @ np.asarray(state.w) @ a.T, rtol=1e-8, atol=1e-15)
    assert w.min() >= 0.0 and w.sum() == pytest.approx(1.0, abs=1e-13)
    np.testing.assert_allclose(np.asarray(new.centre), 0.0)


def test_update_is_the_brute_force_bayes_grid(prior, dyn):
    x0, p0 = prior
    state = init(PMF, x0, p0)
    lat, lon, z, r = LAT, MASS_LON + 0.02, 4.0, 0.7
    new, info = update(PMF, state, _step(z, lat, lon, r), FIELD, dyn)
    pred, _ = predict_settled(PMF, state, dyn)

    w, m, s = (np.asarray(a) for a in (pred.w, pred.bias_mean, pred.bias_var))
    offsets = (np.arange(G) - (G - 1) / 2) * CELL
    dn, de = np.meshgrid(pred.centre[0] + offsets, pred.centre[1] + offsets, indexing="ij")
    mr, nr = _radii(lat)
    g = np.asarray(gravity_anomaly(FIELD, lat - dn / mr / DEG,
                                   lon - de / (nr * np.cos(lat * DEG)) / DEG))
    like = np.exp(-0.5 * (z - g - m) ** 2 / (s + r)) / np.sqrt(s + r)
    post = w * like / np.sum(w * like)
    mean = np.array([np.sum(post * dn), np.sum(post * de)])
    prior_mean = np.array([np.sum(w * dn), np.sum(w * de)])
    d = np.stack([dn - mean[0], de - mean[1]], -1)
    cov = np.einsum("ij,ija,ijb->ab", post, d, d) + np.eye(2) * CELL**2 / 12
    b_cell = m + s / (s + r) * (z - g - m)

    np.testing.assert_allclose(np.asarray(new.w), post, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(np.asarray(new.bias_mean), b_cell, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(info.x)[[0, 1, 12]],
                               [*mean, np.sum(post * b_cell)], rtol=1e-9)
    np.testing.assert_allclose(np.asarray(info.p_pos), cov, rtol=1e-9)
    # the velocity (and the other Gaussian states) move by their regression on the position
    xp, pp = np.asarray(pred.x), np.asarray(pred.p)
    k = pp[2:12, :2] @ np.linalg.inv(pp[:2, :2])
    np.testing.assert_allclose(np.asarray(new.x)[2:12], xp[2:12] + k @ (mean - prior_mean),
                               rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(np.asarray(new.p)[2:12, :2], k @ cov, rtol=1e-9, atol=1e-18)
    assert np.abs(post - w).max() > 1e-3  # the reading was informative
    assert int(info.status) & ~FLAGS["grid_edge"] == 0


def test_update_with_a_linear_part_is_the_brute_force_mixture(prior, dyn):
    """A reading with the Eötvös effect of the velocity error (``Step.h_lin``): each cell
    a joint Kalman update of its bias and the Gaussian states, the weights by the cells'
    innovation likelihoods, the state's moments those of the mixture (NumPy, by hand)."""
    x0, p0 = prior
    state = init(PMF, x0, p0)
    lat, lon, z, r = LAT, MASS_LON + 0.02, 4.0, 0.7
    h = np.zeros(ins.N_STATES)
    h[[2, 3]] = [0.4, 12.6]  # mGal per m/s, north and east
    step = _step(z, lat, lon, r)._replace(h_lin=jnp.asarray(h))
    new, info = update(PMF, state, step, FIELD, dyn)
    pred, _ = predict_settled(PMF, state, dyn)

    w, m, s = (np.asarray(a) for a in (pred.w, pred.bias_mean, pred.bias_var))
    xp, pp = np.asarray(pred.x), np.asarray(pred.p)
    offsets = (np.arange(G) - (G - 1) / 2) * CELL
    dn, de = np.meshgrid(pred.centre[0] + offsets, pred.centre[1] + offsets, indexing="ij")
    mr, nr = _radii(lat)
    g = np.asarray(gravity_anomaly(FIELD, lat - dn / mr / DEG,
                                   lon - de / (nr * np.cos(lat * DEG)) / DEG))
    k = pp[:, :2] @ np.linalg.inv(pp[:2, :2])
    c = pp - k @ pp[:2, :]
    post_w, z_hat = np.zeros((G, G)), 0.0
    mus, covs, b_cell = np.zeros((G, G, 13)), np.zeros((G, G, 13, 13)), np.zeros((G, G))
    for i in range(G):
        for j in range(G):
            mu = xp + k @ (np.array([dn[i, j], de[i, j]]) - xp[:2])
            s_ij = s[i, j] + h @ c @ h + r
            nu = z - g[i, j] - m[i, j] - h @ mu
            z_hat += w[i, j] * (z - nu)
            post_w[i, j] = w[i, j] * np.exp(-0.5 * nu**2 / s_ij) / np.sqrt(s_ij)
            mus[i, j] = mu + c @ h * nu / s_ij
            covs[i, j] = c - np.outer(c @ h, c @ h) / s_ij
            b_cell[i, j] = m[i, j] + s[i, j] / s_ij * nu
    post_w /= post_w.sum()
    x = np.einsum("ij,ijk->k", post_w, mus)
    dev = mus - x
    p = np.einsum("ij,ijkl->kl", post_w, covs) + np.einsum("ij,ijk,ijl->kl", post_w, dev, dev)

    np.testing.assert_allclose(np.asarray(new.w), post_w, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(np.asarray(new.bias_mean), b_cell, rtol=1e-9)
    np.testing.assert_allclose(float(info.innovation), z - z_hat, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(new.x)[:12], x[:12], rtol=1e-7, atol=1e-12)
    p[:2, :2] += np.eye(2) * CELL**2 / 12  # the position block: the grid's, quantisation in
    np.testing.assert_allclose(np.asarray(new.p)[:12, :12], p[:12, :12], rtol=1e-7, atol=1e-12)
    # the reading moved the velocity error beyond the regression on the position
    moved = np.asarray(new.x)[2:4] - xp[2:4]
    regressed = (k @ (x[:2] - xp[:2]))[2:4]
    assert np.abs(moved - regressed).max() > 1e-3


def test_nan_reading_leaves_the_prediction(prior, dyn):
    x0, p0 = prior
    state = init(PMF, x0, p0)
    new, info = update(PMF, state, _step(jnp.nan), FIELD, dyn)
    pred, pinfo = predict_settled(PMF, state, dyn)
    for name in ("w", "bias_mean", "bias_var", "centre", "pending"):
        np.testing.assert_allclose(np.asarray(getattr(new, name)), np.asarray(getattr(pred, name)),
                                   rtol=1e-12, atol=1e-15)
    assert int(info.status) & FLAGS["no_reading"] and np.isnan(float(info.innovation))
    np.testing.assert_allclose(np.asarray(info.x)[2:], np.asarray(pinfo.x)[2:], rtol=1e-12,
                               atol=1e-15)
    # the update reports the spread grid's moments, the prediction the pending ones: they
    # differ by what the 15-cell grid's reflecting edges do (~1 mm)
    np.testing.assert_allclose(np.asarray(info.x)[:2], np.asarray(pinfo.x)[:2], atol=0.01)
    np.testing.assert_allclose(np.asarray(info.p_pos), np.asarray(pinfo.p_pos), rtol=1e-4)


def test_recentres_on_the_posterior_mean():
    x0 = jnp.zeros(ins.N_STATES).at[0].set(1300.0).at[1].set(-900.0)
    p0 = jnp.asarray(ins.initial_covariance(ins.INSErrorModel(), 150.0, 0.01))
    state = init(PMF_RW, x0, p0)
    new, _ = predict_settled(PMF_RW, state, PMF_RW.dynamics(LAT, 1.0))
    np.testing.assert_allclose(np.asarray(new.centre), [1200.0, -800.0])  # whole cells
    # the settled grid keeps its mean (new.x: the settled grid's moments)
    np.testing.assert_allclose(np.asarray(new.x)[:2], np.asarray(state.x)[:2], atol=1e-3)
    offsets = (np.arange(G) - (G - 1) / 2) * CELL
    w = np.asarray(new.w)
    np.testing.assert_allclose(np.sum(w * (new.centre[0] + offsets)[:, None]),
                               float(new.x[0]), rtol=1e-12)
    assert abs(float(new.x[0]) - 1300.0) < 100.0  # σ = 150 m on 400 m cells
    assert float(new.w.sum()) == pytest.approx(1.0, abs=1e-13)
    # a wide posterior is not re-centred: the far edge would lose mass
    wide = init(PMF_RW, x0, jnp.asarray(ins.initial_covariance(ins.INSErrorModel(), 2000.0)))
    new, _ = predict_settled(PMF_RW, wide, PMF_RW.dynamics(LAT, 1.0))
    np.testing.assert_allclose(np.asarray(new.centre), 0.0)


@pytest.mark.parametrize(("old", "new"), [(400.0, 150.0), (150.0, 400.0)])
def test_regrid_matrix_keeps_a_gaussian(old, new):
    """Refined (interpolated) or coarsened (gathered), the weights keep their mean and
    their variance within the two grids' quantisation."""
    n, mu, sd = 41, 300.0, 600.0  # both grids span beyond ±5σ
    i = np.arange(n) - (n - 1) / 2
    x = 100.0 + i * old
    w = np.exp(-0.5 * ((x - mu) / sd) ** 2)
    w /= w.sum()
    r = np.asarray(fl.pmf_grid.regrid_matrix(100.0, old, 250.0, new, n))
    w2 = r @ w
    w2 /= w2.sum()
    y = 250.0 + i * new
    m2 = np.sum(w2 * y)
    v2 = np.sum(w2 * (y - m2) ** 2)
    assert abs(m2 - mu) < 0.02 * sd
    # the hat (half-width h, the coarser cell) smooths by about h²/6 at most
    h = max(old, new)
    assert 0.0 <= v2 - sd**2 < h**2 / 5, (v2 - sd**2, h**2)


def test_adaptive_grid_follows_the_spread():
    """A narrow prior: the cells shrink; a random walk then widens the
    weights: the cells grow, keeping between ±3 σ and ±4.2 σ across; the spread is the one a fixed,
    wide enough grid gives."""
    x0 = jnp.zeros(ins.N_STATES).at[0].set(250.0)
    p0 = jnp.asarray(ins.initial_covariance(ins.INSErrorModel(), 150.0, 0.01))
    walk = {"q_pos": 2000.0, "ins": None}
    filt = fl.pmf(n_cells=G, cell_m=CELL, adapt_span=3.0, **walk)
    wide = fl.pmf(n_cells=61, cell_m=150.0, **walk)
    state, fixed = init(filt, x0, p0), init(wide, x0, p0)
    before = np.asarray(state.x)[:2]  # the 400 m grid's mean (quantised: not 250)
    state, _ = predict_settled(filt, state, DT)
    # refined, as far as the cells holding mass (> KEEP_WEIGHT) allow; the moments below
    # are the settled grids' (settle sets x, p to them)
    assert np.all(np.asarray(state.cell) < 0.75 * CELL)
    np.testing.assert_allclose(np.asarray(state.x)[:2], before, atol=5.0)
    for _ in range(100):
        state, _ = predict_settled(filt, state, DT)
        fixed, _ = predict_settled(wide, fixed, DT)
    grown = np.asarray(state.cell)
    sd = np.sqrt(np.diagonal(np.asarray(state.p)[:2, :2]))
    assert np.all(grown > CELL) and np.all(sd > 1200.0)
    span = grown * (G - 1) / 2  # kept between ±3 σ and ±3 · REGRID_RATIO σ (the band)
    assert np.all(span / sd > 3.0 * 0.97) and np.all(span / sd < 3.0 * 1.4 * 1.03), span / sd
    # each re-gridding smooths by up to a cell²/6 (5.2 % wider than the fixed grid here)
    np.testing.assert_allclose(sd, np.sqrt(np.diagonal(np.asarray(fixed.p)[:2, :2])), rtol=0.06)
    np.testing.assert_allclose(np.asarray(state.x)[:2], before, atol=10.0)  # over re-griddings
    assert float(state.w.sum()) == pytest.approx(1.0, abs=1e-12)


def test_adaptive_grid_keeps_a_distant_mode():
    """A 4 % mode 3 km from the main one: refining to the main mode's spread would cut
    it off the grid, so the grid is not refined along it, and the mode keeps its mass."""
    filt = fl.pmf(n_cells=31, cell_m=250.0, q_pos=0.1, ins=None, adapt_span=3.0)
    x0 = jnp.zeros(ins.N_STATES)
    p0 = jnp.asarray(ins.initial_covariance(ins.INSErrorModel(), 300.0, 0.01))
    state = init(filt, x0, p0)
    dn, _ = np.meshgrid(np.arange(31) - 15.0, np.arange(31) - 15.0, indexing="ij")
    far = (np.abs(dn * 250.0 - 3000.0) < 300.0) & (np.abs(_ - 0.0) < 2)
    w = np.asarray(state.w) * 0.96 + 0.04 * far / far.sum()
    state = state._replace(w=jnp.asarray(w / w.sum()))
    new, _ = predict_settled(filt, state, DT)
    # refined across (east), and along the modes (north) sized to keep the far one on
    # the grid (the band's top, 1.4 × the reach, 292 m here)
    assert float(new.cell[1]) < 250.0 and 15 * float(new.cell[0]) > 3400.0
    after = np.asarray(new.w)
    offsets = np.asarray(new.centre)[0] + (np.arange(31) - 15.0) * float(new.cell[0])
    assert after[np.abs(offsets - 3000.0) < 400.0].sum() > 0.03
    with pytest.raises(ValueError, match="an adaptive grid needs adapt_span > 0"):
        fl.pmf(adapt_span=-3.0)
    with pytest.raises(ValueError, match="0 < min_cell_m <= max_cell_m"):
        fl.pmf(adapt_span=3.0, min_cell_m=0.0)
    with pytest.raises(ValueError, match="resolve must be a number > 0"):
        fl.pmf(adapt_span=3.0, resolve=0.0)


def test_resolving_cell_against_a_brute_force_gradient():
    """The largest cell over which the map changes by ``k`` reading σ: on a plane of
    gradients (a, b) per metre the neighbour differences are a·cell and b·cell, so the
    cell is k σ / a and k σ / b; the weights pick where it is measured; NaN cells and a
    flat map are handled."""
    rng = np.random.default_rng(3)
    n, cell = 9, np.array([50.0, 80.0])
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = 0.02, 0.005  # mGal per metre, north and east
    g = a * i * cell[0] + b * j * cell[1]
    w = rng.random((n, n))
    w /= w.sum()
    var = 2.0 + rng.random((n, n))  # mGal², per cell
    sigma = np.sqrt(np.sum(w * var))
    got = np.asarray(fl.pmf_grid.resolving_cell(jnp.asarray(w), jnp.asarray(g),
                                                jnp.asarray(var), jnp.asarray(cell), 0.5))
    np.testing.assert_allclose(got, [0.5 * sigma / a, 0.5 * sigma / b], rtol=1e-12)
    # a steeper half where the weights are: the cell follows the weights
    g2 = np.where(i >= n // 2, 4.0 * g, g)
    w2 = np.where(i > n // 2 + 1, 1.0, 0.0)
    w2 /= w2.sum()
    got = np.asarray(fl.pmf_grid.resolving_cell(jnp.asarray(w2), jnp.asarray(g2), 2.0,
                                                jnp.asarray(cell), 1.0))
    np.testing.assert_allclose(got, np.sqrt(2.0) / np.array([4 * a, 4 * b]), rtol=1e-12)
    # NaN cells (off the map) drop out; a flat map bounds nothing
    g3 = np.where(j == 0, np.nan, g)
    got = np.asarray(fl.pmf_grid.resolving_cell(jnp.asarray(w), jnp.asarray(g3), 2.0,
                                                jnp.asarray(cell), 1.0))
    assert np.all(np.isfinite(got)) and got[1] == pytest.approx(
        np.sqrt(2.0) / b, rel=1e-12)
    flat = fl.pmf_grid.resolving_cell(jnp.asarray(w), jnp.zeros((n, n)), 2.0,
                                      jnp.asarray(cell), 1.0)
    assert np.all(np.isinf(np.asarray(flat)))


def test_resolve_keeps_the_cells_below_the_map_resolution():
    """An adaptive grid told to resolve the map: on paper D's masses, once settled after
    readings, its cells are at most the resolving cell the last reading measured (and
    smaller than the same grid's cells without the bound, which only follow the spread)."""
    x0 = jnp.zeros(ins.N_STATES)
    p0 = jnp.asarray(ins.initial_covariance(ins.INSErrorModel(), 2000.0, 0.01))
    walk = {"q_pos": 5.0, "ins": None}
    free = fl.pmf(n_cells=G, cell_m=CELL, adapt_span=4.0, **walk)
    bound = fl.pmf(n_cells=G, cell_m=CELL, adapt_span=4.0, resolve=0.25, **walk)
    steps = _steps(6, 1)
    states = []
    for filt in (free, bound):
        s = init(filt, x0, p0)
        for k in range(6):
            s, _ = update(filt, s, jax.tree.map(lambda a, k=k: a[k], steps), FIELD, DT)
        states.append(predict_settled(filt, s, DT)[0])  # re-sized with the last reading's cap
    assert states[0].cell_cap is None and states[1].cell_cap.shape == (2,)
    cap, c = np.asarray(states[1].cell_cap), np.asarray(states[1].cell)
    assert np.all(np.isfinite(cap)) and np.all(c <= cap * (1 + 1e-9))
    assert np.all(c < np.asarray(states[0].cell))


# ----------------------------------------------------------------- runs


@pytest.mark.long
def test_every_is_causal_and_predicts_between_readings(prior):
    x0, p0 = prior
    every, n = 4, 16
    steps = _steps(n, every)
    _, infos = run(PMF, FIELD, DT, x0, p0, steps, every)
    assert infos.x.shape == (n, ins.N_STATES)
    # a different later reading (step 11) changes nothing before it
    z = np.asarray(steps.z).copy()
    z[11] += 5.0
    _, other = run(PMF, FIELD, DT, x0, p0, steps._replace(z=jnp.asarray(z)), every)
    for a, b in zip(jax.tree.leaves(infos), jax.tree.leaves(other), strict=True):
        np.testing.assert_array_equal(np.asarray(a)[:11], np.asarray(b)[:11])
    assert not np.allclose(np.asarray(infos.x)[11], np.asarray(other.x)[11])
    # steps between readings are predictions, not repeats
    status = np.asarray(infos.status)
    assert np.all(status[[0, 1, 2, 4, 5, 6]] & FLAGS["no_reading"])
    assert not np.any(status[[3, 7, 11, 15]] & FLAGS["no_reading"])
    x = np.asarray(infos.x)
    assert np.all(np.abs(np.diff(x[4:8, :2], axis=0)) > 1.0)  # drifting at ~0.3 m/s
    # ... and they are the loop of predict / update
    dyn = PMF.dynamics(jnp.mean(steps.lat), DT)
    state = init(PMF, x0, p0)
    for k in range(n):
        one = jax.tree.map(lambda a, k=k: a[k], steps)
        if k % every == every - 1:
            state, info = update(PMF, state, one, FIELD, dyn)
        else:
            state, info = predict(PMF, state, dyn)
        np.testing.assert_allclose(np.asarray(info.x), x[k], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(np.asarray(info.p_pos), np.asarray(infos.p_pos)[k],
                                   rtol=1e-9)


@pytest.mark.long
def test_vmap_equals_loop(prior):
    # the single runs share the compiled program of the causality test (16 steps, every 4)
    x0, p0 = prior
    steps = _steps(16, 4, seed=3, n_runs=3)
    final_b, infos_b = run_batch(PMF, FIELD, DT, x0, p0, steps, 4)
    assert infos_b.x.shape == (3, 16, ins.N_STATES)
    for i in range(3):
        final, infos = run(PMF, FIELD, DT, x0, p0, jax.tree.map(lambda a, i=i: a[i], steps), 4)
        one = jax.tree.map(lambda a, i=i: a[i], (final_b, infos_b))
        # a cell's bias moments are rounding noise where it holds little mass (the batched
        # and single matrix products round differently): compared weighted by the mass
        cells = {id(v) for v in (final.bias_mean, final.bias_var)}
        for a, b in zip(jax.tree.leaves((final, infos)), jax.tree.leaves(one), strict=True):
            if id(a) in cells:
                a, b = np.asarray(a) * final.w, np.asarray(b) * one[0].w
            np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-9, atol=1e-12)


def test_deprecated_run_pmf_is_run_filter(prior):
    """run_pmf traces to the very program of run_filter with the filter's own dynamics (so
    the same numbers; traced only, nothing compiled)."""
    x0, p0 = prior
    steps = _steps(16, 4)
    with pytest.warns(DeprecationWarning, match="run_pmf is deprecated: use run_filter"):
        old = jax.make_jaxpr(fl.run_pmf, static_argnums=(0, 6))(PMF, FIELD, DT, x0, p0, steps, 4)
    new = jax.make_jaxpr(_run, static_argnums=(0, 6))(PMF, FIELD, DT, x0, p0, steps, 4)
    assert str(old) == str(new)


def test_bad_arguments(prior):
    x0, p0 = prior
    with (pytest.warns(DeprecationWarning),
          pytest.raises(ValueError, match="every must be a positive int dividing the 16 steps")):
        fl.run_pmf(PMF, FIELD, DT, x0, p0, _steps(16, 5), 5)
    with pytest.raises(ValueError, match="n_cells must be an odd integer"):
        fl.pmf(n_cells=60)
    # dynamics without the step length: the random-walk spread needs it
    f, q = ins.transition(ins.INSErrorModel(), LAT, DT)
    with pytest.raises(ValueError, match="the point-mass filter needs the step length"):
        fl.run_filter(PMF, FIELD, fl.Dynamics(f, q), x0, p0, _steps(16, 4), 4)


def test_dynamics_arguments():
    d = PMF.dynamics(LAT, DT)
    f, q = ins.transition(ins.INSErrorModel(), LAT, DT)
    assert isinstance(d, fl.Dynamics)
    np.testing.assert_allclose(np.asarray(d.f), np.asarray(f))
    np.testing.assert_allclose(np.asarray(d.q), np.asarray(q))
    rw = PMF_RW.dynamics(LAT, DT)
    np.testing.assert_array_equal(np.asarray(rw.f), np.eye(ins.N_STATES))


def _through_a_hole(filt, prior, z, r):
    """One reading over the ryukyu map with a NaN hole south of the INS position: the
    settled prediction, the posterior, its info, the cells' map values and which cells'
    nearest node is missing."""
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    iy, ix = int((30.3 - grid.lat0) / grid.dlat), int((129.7 - grid.lon0) / grid.dlon)
    lat, lon = float(grid.lat0 + (iy + 1) * grid.dlat), 129.7  # on a row of nodes
    values = np.asarray(grid.values).copy()
    values[iy, ix - 4:ix + 5] = np.nan  # unknown: the two rows of cells south of the INS
    field = jax.jit(prepare_map)(Grid(jnp.asarray(values), grid.lat0, grid.dlat, grid.lon0,
                                      grid.dlon))
    x0, p0 = prior
    dyn = filt.dynamics(lat, DT)
    state = init(filt, x0, p0)
    pred, _ = predict_settled(filt, state, dyn)
    step = _step(z, lat, lon, r)
    new, info = update(filt, state, step, field, dyn)
    offsets = (np.arange(G) - (G - 1) / 2) * CELL
    dn, de = jnp.meshgrid(pred.centre[0] + offsets, pred.centre[1] + offsets, indexing="ij")
    g = np.asarray(jax.jit(cell_values, static_argnums=4)(field, step, dn, de,
                                                          fl.gravity_measurement))
    # the cells whose nearest node is in the hole (its row, south of the INS row by more
    # than half a row; the hole's ±4 columns span every cell's longitude)
    cell_lat = lat - np.asarray(dn) / float(meridian_radius(lat)) / DEG
    return pred, new, info, g, cell_lat < lat - 0.5 * grid.dlat


@pytest.mark.long
def test_cells_on_land_take_no_mass(prior):
    """missing="land": a NaN node inside the map is where the vehicle cannot be, so its
    cells get zero likelihood (Bayes by hand, the hole of the test below)."""
    land = fl.pmf(n_cells=G, cell_m=CELL, q_pos=Q_POS, missing="land")
    z, r = 12.0, 0.7
    pred, new, _, g, on_hole = _through_a_hole(land, prior, z, r)
    w, m, s = (np.asarray(a) for a in (pred.w, pred.bias_mean, pred.bias_var))
    known = np.isfinite(g)
    land_cells = ~known & on_hole  # nearest node missing: land
    assert land_cells.any() and (~known & ~on_hole).any()  # and unknown cells at sea
    like = np.where(known, np.exp(-0.5 * (z - np.where(known, g, 0) - m) ** 2 / (s + r))
                    / np.sqrt(s + r), 0.0)
    gap = np.sum(w * like) / np.sum(w[known])  # the known cells' mean likelihood
    post = w * np.where(known, like, np.where(land_cells, 0.0, gap))
    np.testing.assert_allclose(np.asarray(new.w), post / post.sum(), rtol=1e-9, atol=1e-15)
    assert np.asarray(new.w)[land_cells].sum() == 0.0 and w[land_cells].sum() > 1e-3


def test_land_cells_are_missing_nodes_inside_the_map_and_others_gaps():
    """weigh_cells with missing="land": a cell whose nearest node is missing is land
    (likelihood 0); a cell beside it, whose interpolation needs that node, and a cell off
    the map's extent are gaps (the known cells' mean likelihood). Counting every cell
    without a map value inside the map as land put land up to a node spacing out to sea
    and dropped a truth 3 km from the nearest missing node (4 σ off, NEES 20)."""
    values = np.zeros((8, 8))
    values[3, 4] = np.nan  # the node at 13° N, 24° E
    # jitted (one program each; op by op this 8 x 8 map's ops took 5 s)
    field = jax.jit(prepare_map)(Grid(jnp.asarray(values), 10.0, 1.0, 20.0, 1.0))
    step = _step(1.0, 13.0, 24.0)
    east = 0.6 * np.cos(np.radians(13.0)) * 111.3e3  # 0.6° of longitude (m)
    dn, de = jnp.meshgrid(jnp.array([389e3, 0.0, -222e3]), jnp.array([0.0, east, -east]),
                          indexing="ij")  # cell (i, j): offset north, east
    on_map = jnp.asarray(np.isfinite(np.asarray(jax.jit(cell_values, static_argnums=4)(
        field, step, dn, de, fl.gravity_measurement))))
    # (0, ·) at 9.5° N, off the map; (1, 0) on the missing node; (1, 1) at 23.4° E, whose
    # nearest node (23° E) is known but whose bicubic cell holds the missing one; (2, ·)
    # at 15° N, known
    assert not np.asarray(on_map)[:2].any() and np.asarray(on_map)[2].all()
    w = jnp.full((3, 3), 1 / 9)
    lik = jnp.arange(1.0, 10.0).reshape(3, 3)
    weigh = jax.jit(weigh_cells, static_argnums=7)
    out = {mode: np.asarray(weigh(w, lik, on_map, field, step, dn, de, mode))
           for mode in ("gaps", "land")}
    known = np.asarray(on_map)
    gap = float(np.sum(np.where(known, lik, 0.0)) / known.sum())  # known cells' mean
    np.testing.assert_allclose(out["gaps"] * 9, np.where(known, lik, gap))
    assert out["land"][1, 0] == 0.0  # the truth cannot sit on the missing node
    np.testing.assert_allclose(out["land"][1, 1] * 9, gap)  # beside it: a gap
    np.testing.assert_allclose(out["land"][0] * 9, gap)  # off the map: a gap
    with pytest.raises(ValueError, match="missing must be one of"):
        fl.pmf(missing="sea")


def test_cells_of_unknown_map_value_neither_gain_nor_lose_mass(prior):
    """A NaN hole in a real map under part of the grid: the reading reweights the known
    cells among themselves (Bayes, by hand), the unknown cells keep their prior share of
    the mass and their bias, and the predicted reading is the known cells' (zero likelihood
    for the unknown cells piled the mass on the hole's rim: 10 km off with a 450 m σ)."""
    z, r = 12.0, 0.7
    pred, new, info, g, _ = _through_a_hole(PMF, prior, z, r)
    w, m, s = (np.asarray(a) for a in (pred.w, pred.bias_mean, pred.bias_var))
    known = np.isfinite(g)
    assert 0.2 < 1 - known.mean() < 0.8
    like = np.where(known, np.exp(-0.5 * (z - np.where(known, g, 0) - m) ** 2 / (s + r))
                    / np.sqrt(s + r), 0.0)
    like_unknown = np.sum(w * like) / np.sum(w[known])
    post = w * np.where(known, like, like_unknown)
    post /= post.sum()
    np.testing.assert_allclose(np.asarray(new.w), post, rtol=1e-9, atol=1e-15)
    assert np.asarray(new.w)[~known].sum() == pytest.approx(w[~known].sum(), rel=1e-9)
    np.testing.assert_array_equal(np.asarray(new.bias_var)[~known], s[~known])
    np.testing.assert_array_equal(np.asarray(new.bias_mean)[~known], m[~known])
    assert np.all(np.asarray(new.bias_var)[known] < s[known])
    wk = w * known / np.sum(w * known)
    z_hat = np.sum(wk * np.where(known, g + m, 0.0))
    np.testing.assert_allclose(float(info.innovation), z - z_hat, rtol=1e-9)
    assert int(info.status) & FLAGS["off_map"]


def test_spread_in_float32_follows_float64(prior):
    """``spread_dtype=float32`` (the spread's two products in float32, the rest in float64)
    gives the float64 filter's estimates to a small fraction of their σ, one compile."""
    x0, p0 = prior
    steps = _steps(16, 4, seed=5)
    f32 = fl.pmf(n_cells=G, cell_m=CELL, q_pos=Q_POS, spread_dtype=jnp.float32)
    _, ref = run(PMF, FIELD, DT, x0, p0, steps, 4)
    _, got = run(f32, FIELD, DT, x0, p0, steps, 4)
    assert got.x.dtype == jnp.float64
    np.testing.assert_allclose(np.asarray(got.x), np.asarray(ref.x), rtol=1e-5,
                               atol=1e-4 * float(np.max(ref.sigma)))
    np.testing.assert_allclose(np.asarray(got.sigma), np.asarray(ref.sigma), rtol=1e-4)
    before = run._cache_size()
    run(f32, FIELD, DT, x0, p0, _steps(16, 4, seed=6), 4)  # new readings: no retrace
    assert run._cache_size() == before
