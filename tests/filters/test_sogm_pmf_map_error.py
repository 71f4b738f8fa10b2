"""Tests of the second-order map-error state and the point-mass filter's per-cell map error.

References: SciPy's matrix exponential (Van Loan) and discrete Lyapunov solver; the
map-error field's own covariance along a straight track; a brute-force NumPy
point-mass filter (bias + FOGM map error per cell) on a 9 × 9 grid; vmap against a
loop; the trace count when σ and L change; the command-line options.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from jaxgrav import datasets
from jaxgrav import filters as fl
from jaxgrav.cli import main
from jaxgrav.constants import DEG
from jaxgrav.fields.map_error import map_error
from jaxgrav.fields.pointmass import gravity_anomaly, paper_d
from jaxgrav.filters.map_state import augment, map_error_state, matched_state, sogm_transition
from jaxgrav.montecarlo.filter_runs import filter_builder
from jaxgrav.scenarios.paper_d import MASS_LON
from jaxgrav.sim import ins

FIELD = paper_d()
G, CELL, Q_POS, DT, SPEED, LAT = 9, 500.0, 50.0, 10.0, 5.0, 24.25
PMF = fl.pmf(n_cells=G, cell_m=CELL, q_pos=Q_POS)


# ----------------------------------------------------------------- SOGM


@pytest.mark.parametrize("sigma, length, speed, dt", [(3.0, 10e3, 5.0, 10.0),
                                                      (1.0, 2e3, 10.0, 2.0)])
def test_sogm_discretisation_is_van_loan_and_stationary(sigma, length, speed, dt):
    phi, q = (np.asarray(v) for v in sogm_transition(sigma, length, speed, dt))
    b = speed / length
    a = np.array([[0.0, 1.0], [-b * b, -2.0 * b]])
    qc = np.array([[0.0, 0.0], [0.0, 4.0 * b**3 * sigma**2]])
    e = scipy.linalg.expm(np.block([[-a, qc], [np.zeros((2, 2)), a.T]]) * dt)
    f_vl = e[2:, 2:].T
    np.testing.assert_allclose(phi, f_vl, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(phi, scipy.linalg.expm(a * dt), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(q, f_vl @ e[:2, 2:], rtol=1e-8, atol=1e-14 * sigma**2)
    p_inf = scipy.linalg.solve_discrete_lyapunov(phi, q)
    np.testing.assert_allclose(p_inf, np.diag([sigma**2, b * b * sigma**2]), rtol=1e-8,
                               atol=1e-12 * sigma**2)


def test_sogm_autocorrelation_is_the_fields_covariance_along_a_track():
    model = map_error(3.0, 10e3)  # markov2
    cfg = matched_state(model)
    assert cfg.order == 2 and float(cfg.length_m) == 10e3
    phi, _ = (np.asarray(v) for v in sogm_transition(cfg.sigma, cfg.length_m, SPEED, DT))
    p_inf = np.diag([9.0, 9.0 * (SPEED / 10e3) ** 2])
    for lag in (1, 10, 100, 400):
        c = (np.linalg.matrix_power(phi, lag) @ p_inf)[0, 0]
        assert c == pytest.approx(float(model.covariance(SPEED * DT * lag)), rel=1e-9)
    assert matched_state(map_error(3.0, 10e3, family="markov1")).order == 1
    assert float(matched_state(model, 1).length_m) == 20e3


def test_augment_order_2_adds_value_and_rate_with_only_the_value_read():
    dyn = PMF.dynamics(LAT, DT)
    x0, p0 = jnp.zeros(13), jnp.eye(13)
    d2, x2, p2, meas = augment(map_error_state(3.0, 10e3, order=2), dyn, x0, p0, SPEED)
    assert d2.f.shape == (15, 15) and x2.shape == (15,) and meas.additive == (12, 13)
    np.testing.assert_allclose(np.asarray(p2)[13:, 13:], np.diag([9.0, 9.0 * (5e-4) ** 2]))
    x = jnp.zeros(15).at[13].set(2.0).at[14].set(100.0)
    assert float(meas(FIELD, x, LAT, MASS_LON)) == pytest.approx(
        float(meas(FIELD, jnp.zeros(15), LAT, MASS_LON)) + 2.0)


# ----------------------------------------------------------------- PMF with a map error


P0 = np.array(ins.initial_covariance(ins.INSErrorModel(), 800.0, 0.15))
X0 = np.zeros(ins.N_STATES)
X0[[2, 3, 12]] = [0.3, -0.2, 0.5]


def _prior(sigma=3.0, length=10e3):
    dyn, x0, p0, _ = augment(map_error_state(sigma, length), PMF.dynamics(LAT, DT),
                             jnp.asarray(X0), jnp.asarray(P0), SPEED)
    return dyn, x0, p0


def _steps(n, seed=0, n_runs=None):
    rng = np.random.default_rng(seed)
    shape = (n,) if n_runs is None else (n_runs, n)
    lat = np.full(shape, LAT)
    lon = MASS_LON - 0.03 + 50.0 * np.arange(1, n + 1) / (111320.0 * np.cos(LAT * DEG))
    lon = np.broadcast_to(lon, shape)
    z = (np.asarray(gravity_anomaly(FIELD, lat - 0.002, lon + 0.002)) + 2.0
         + rng.standard_normal(shape))
    return fl.Step(*(jnp.asarray(a) for a in (lat, lon, z)), jnp.ones(shape))


def _lap(n):
    lap = np.diag(np.full(n, -2.0)) + np.diag(np.ones(n - 1), 1) + np.diag(np.ones(n - 1), -1)
    lap[0, 0] = lap[-1, -1] = -1.0
    return lap


def _np_step(state, step, dyn):
    """One prediction + update of the per-cell (bias, map error) PMF in NumPy."""
    f, q = np.asarray(dyn.f), np.asarray(dyn.q)
    x, p = np.asarray(state.x), np.asarray(state.p)
    p_new = f[:13, :13] @ p @ f[:13, :13].T + q[:13, :13]
    spread = np.maximum(np.diag(p_new[:2, :2] - p[:2, :2]), 0.0) + Q_POS * DT
    a_n, a_e = (scipy.linalg.expm(0.5 * s / CELL**2 * _lap(G)) for s in spread)
    centre = np.asarray(state.centre) + (f[:13, :13] @ x - x)[:2]
    fb, qb, fe, qe = f[12, 12], q[12, 12], f[13, 13], q[13, 13]
    w, mb, sb, me, se, c = (np.asarray(a) for a in (state.w, state.bias_mean, state.bias_var,
                                                     state.err_mean, state.err_var,
                                                     state.err_cross))
    mb, sb, me, se, c = fb * mb, fb**2 * sb + qb, fe * me, fe**2 * se + qe, fb * fe * c
    conv = lambda a: a_n @ a @ a_e.T  # noqa: E731
    w1 = conv(w)
    mb1, me1 = conv(w * mb) / w1, conv(w * me) / w1
    sb1 = conv(w * (sb + mb**2)) / w1 - mb1**2
    se1 = conv(w * (se + me**2)) / w1 - me1**2
    c1 = conv(w * (c + mb * me)) / w1 - mb1 * me1
    w1 = w1 / w1.sum()
    offsets = (np.arange(G) - (G - 1) / 2) * CELL
    dn, de = np.meshgrid(centre[0] + offsets, centre[1] + offsets, indexing="ij")
    lat, lon, z, r = (float(v) for v in (step.lat, step.lon, step.z, step.r))
    rm = 6378137.0 * (1 - 6.69437999014e-3) / (1 - 6.69437999014e-3 * np.sin(lat * DEG)**2)**1.5
    rn = 6378137.0 / np.sqrt(1 - 6.69437999014e-3 * np.sin(lat * DEG) ** 2)
    g = np.asarray(gravity_anomaly(FIELD, lat - dn / rm / DEG,
                                   lon - de / (rn * np.cos(lat * DEG)) / DEG))
    nu = z - g - mb1 - me1
    s = sb1 + se1 + 2 * c1 + r
    post = w1 * np.exp(-0.5 * nu**2 / s) / np.sqrt(s)
    post /= post.sum()
    kb, ke = (sb1 + c1) / s, (c1 + se1) / s
    return dict(w=post, bias_mean=mb1 + kb * nu, err_mean=me1 + ke * nu,
                err_var=se1 - ke**2 * s, err_cross=c1 - kb * ke * s), centre


@pytest.mark.long
def test_pmf_map_error_equals_a_brute_force_numpy_filter():
    dyn, x0, p0 = _prior()
    init = jax.jit(PMF.init)
    update = jax.jit(lambda s, st, d: PMF.update(s, st, FIELD, d))
    state = init(x0, p0)
    assert state.err_mean.shape == (G, G) and float(state.err_var[0, 0]) == pytest.approx(9.0)
    steps = _steps(4)
    for k in range(4):
        step = jax.tree.map(lambda a, k=k: a[k], steps)
        # no whole-cell re-centring in these steps (the reference does not shift)
        assert np.all(np.abs(np.asarray(state.x[:2] - state.centre)) < CELL / 2)
        ref, centre = _np_step(state, step, dyn)
        state, info = update(state, step, dyn)
        np.testing.assert_allclose(np.asarray(state.centre), centre, rtol=1e-12)
        big = ref["w"] > 1e-10 * ref["w"].max()
        for name, want in ref.items():
            got = np.asarray(getattr(state, name))
            np.testing.assert_allclose(got[big], want[big], rtol=1e-6, atol=1e-9, err_msg=name)
        assert info.x.shape == (14,)
        assert float(info.x[13]) == pytest.approx(float(np.sum(ref["w"] * ref["err_mean"])))


_TRACES = []


def _pmf_run(sigma, length, steps):
    _TRACES.append(1)
    dyn, x0, p0 = _prior(sigma, length)
    return fl.run_filter(PMF, FIELD, dyn, x0, p0, steps)[1]


@pytest.mark.long
def test_pmf_map_error_vmap_equals_loop_and_sigma_length_do_not_retrace():
    steps = _steps(6, seed=1, n_runs=2)
    one = jax.jit(_pmf_run)
    n0 = len(_TRACES)
    loop = [one(s, length, jax.tree.map(lambda a, i=i: a[i], steps))
            for i, (s, length) in enumerate(((3.0, 10e3), (1.0, 20e3)))]
    assert len(_TRACES) == n0 + 1
    vm = jax.jit(jax.vmap(_pmf_run))(jnp.array([3.0, 1.0]), jnp.array([10e3, 20e3]), steps)
    for i, out in enumerate(loop):
        np.testing.assert_allclose(np.asarray(vm.x[i]), np.asarray(out.x), rtol=1e-9,
                                   atol=1e-9)
        np.testing.assert_allclose(np.asarray(vm.p_pos[i]), np.asarray(out.p_pos), rtol=1e-9)
    assert not np.allclose(np.asarray(loop[0].x), np.asarray(loop[1].x))


def test_pmf_refuses_a_second_order_state():
    _, x0, p0, _ = augment(map_error_state(3.0, 10e3, order=2), PMF.dynamics(LAT, DT),
                           jnp.zeros(13), jnp.eye(13), SPEED)
    with pytest.raises(ValueError, match="second-order map-error state"):
        PMF.init(x0, p0)


# ----------------------------------------------------------------- bad input


def test_bad_order_is_refused_everywhere(tmp_path, capsys):
    with pytest.raises(ValueError, match="order must be 1"):
        map_error_state(3.0, 1e4, order=3)
    grid_error = map_error(3.0, 1e4)
    with pytest.raises(ValueError, match="map_error_order"):
        filter_builder(None, kind="ukf", map_error=None, map_error_order=0)
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    with pytest.raises(ValueError, match="point-mass filter"):
        filter_builder(grid, kind="pmf", map_error=grid_error, map_error_order=2)
    with pytest.raises(ValueError, match="contradicts"):
        filter_builder(grid, kind="ukf", map_error=grid_error, map_error_told="fogm",
                       map_error_order=2)
    spec = filter_builder(grid, kind="ukf", map_error=grid_error)
    assert spec.settings["map_error_told"] == "state order 2"
    assert spec.args[3].state.order == 2
    spec = filter_builder(grid, kind="pmf", map_error=grid_error)
    assert spec.settings["map_error_told"] == "state order 1"
    out = str(tmp_path / "x.nc")
    for argv, match in (
            (["montecarlo", "--method", "ukf", "--map", "ryukyu", "--map-error", "3",
              "--map-error-order", "3", "--runs", "2", "--out", out], "--map-error-order"),
            (["montecarlo", "--method", "dense", "--map-error", "3", "--map-error-order", "2",
              "--runs", "2", "--out", out], "is a filter option"),
            (["montecarlo", "--method", "ukf", "--map", "ryukyu", "--map-error", "-3",
              "--runs", "2", "--out", out], "--map-error")):
        assert main(argv) != 0
        assert match in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        main(["filter", "--track", "t.csv", "--map", "ryukyu", "--out", out, "--map-error", "3",
              "--map-error-order", "3"])
    assert exit_info.value.code == 2
    assert "--map-error-order" in capsys.readouterr().err
