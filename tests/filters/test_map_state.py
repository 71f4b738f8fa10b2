"""Tests of the FOGM map-error state (jaxgrav.filters.map_state) and paper D's map error.

References: the closed form and SciPy's Van Loan discretisation of ``dε/dt = −ε/τ + w``;
today's filters (σ = 0 / no state, bit for bit); the generic 2n + 1-point UKF; a loop
over σ; a small Monte Carlo's NEES.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from jaxgrav import datasets
from jaxgrav import filters as fl
from jaxgrav.fields.map_error import map_error
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.filters.map_state import (
    augment,
    fogm_length,
    fogm_transition,
    map_error_measurement,
    map_error_state,
    sogm_transition,
)
from jaxgrav.montecarlo.filter_runs import ToldMapError, filter_builder, ukf_run
from jaxgrav.montecarlo.runner import run
from jaxgrav.scenarios import FilterScenario, filter_scenario, initial_state, run_steps

SCEN = FilterScenario(dt=10.0, reading_every=1, n_steps=121, geometry="random",
                      region=(28.0, 29.0, 128.0, 129.0))


@pytest.fixture(scope="module")
def grid():
    return datasets.load("ryukyu")["anomaly_2p5min"]


_TRACES = []


def _ukf_fogm(key, field, scen, truth_model, sigma, length):
    _TRACES.append(1)
    told = ToldMapError(jnp.zeros(()), map_error_state(sigma, length))
    return ukf_run(key, field, scen, truth_model, told)


ukf_fogm = jax.jit(_ukf_fogm)


@pytest.mark.parametrize("sigma, length, speed, dt", [(3.0, 10e3, 5.0, 10.0),
                                                      (1.0, 2e3, 10.0, 2.0)])
def test_fogm_discretisation_equals_closed_form_and_van_loan(sigma, length, speed, dt):
    phi, q = (float(v) for v in fogm_transition(sigma, length, speed, dt))
    tau = length / speed
    assert phi == pytest.approx(np.exp(-dt / tau), rel=1e-14)
    assert q == pytest.approx(sigma**2 * (1 - np.exp(-2 * dt / tau)), rel=1e-12)
    a, qc = np.array([[-1 / tau]]), np.array([[2 * sigma**2 / tau]])  # stationary variance σ²
    e = scipy.linalg.expm(np.block([[-a, qc], [np.zeros((1, 1)), a.T]]) * dt)
    f_vl = e[1:, 1:].T
    q_vl = f_vl @ e[:1, 1:]
    assert phi == pytest.approx(f_vl[0, 0], rel=1e-12)
    assert q == pytest.approx(q_vl[0, 0], rel=1e-10)


@pytest.mark.parametrize("sigma, length, speed, dt", [(3.0, 10e3, 5.0, 10.0),
                                                      (3.0, 10e3, 5.0, 2.0),
                                                      (3.0, 10e3, 5.0, 1.0),
                                                      (1.0, 2e3, 10.0, 60.0),
                                                      (2.0, 1e3, 10.0, 300.0)])
def test_sogm_discretisation_equals_van_loan_in_float64_and_float32(sigma, length, speed, dt):
    """Φ and Q against Van Loan (scipy's expm); Q in float32 within 1e-5 and positive
    definite (P∞ − Φ P∞ Φᵀ lost (βΔt)⁻² digits: 28 % at 10 s, indefinite at 2 s;
    review of 2026-12-06, helper-30)."""
    beta = speed / length
    a = np.array([[0.0, 1.0], [-beta**2, -2 * beta]])
    g = np.array([[0.0], [1.0]])
    qc = g @ g.T * 4 * beta**3 * sigma**2
    e = scipy.linalg.expm(np.block([[-a, qc], [np.zeros((2, 2)), a.T]]) * dt)
    f_vl = e[2:, 2:].T
    q_vl = f_vl @ e[:2, 2:]
    phi, q = (np.asarray(v) for v in sogm_transition(sigma, length, speed, dt))
    np.testing.assert_allclose(phi, f_vl, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(q, q_vl, rtol=1e-9, atol=0)
    _, q32 = (np.asarray(v, np.float64) for v in sogm_transition(
        np.float32(sigma), np.float32(length), np.float32(speed), np.float32(dt)))
    np.testing.assert_allclose(q32, q_vl, rtol=1e-5, atol=0)
    assert np.all(np.linalg.eigvalsh(q32) > 0)


def test_augment_refuses_a_bad_speed():
    scen = FilterScenario()
    x0, p0 = initial_state(scen)
    f, q = fl.Dynamics(*[jnp.eye(13)] * 2, 10.0)[:2]
    dyn = fl.Dynamics(f, q, 10.0)
    for bad in (-5.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="speed must be a finite number >= 0"):
            augment(map_error_state(3.0, 1e4, 2), dyn, x0, p0, bad)
    # at rest: the value constant (to 1 cm/s, SOGM_MIN_SPEED: tau 12 days at L = 10 km),
    # its prior positive definite (it was singular: the UKF repaired it on every row)
    d, _, p1, _ = augment(map_error_state(3.0, 1e4, 2), dyn, x0, p0, 0.0)
    np.testing.assert_allclose(np.asarray(d.q[13:, 13:]), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(d.f[13, 13]), 1.0, atol=1e-10)
    assert np.all(np.linalg.eigvalsh(np.asarray(p1[13:, 13:])) > 0)


def test_fogm_length_matches_the_integral_scale():
    assert float(fogm_length(map_error(3.0, 10e3, family="markov1"))) == 10e3
    assert float(fogm_length(map_error(3.0, 10e3))) == 20e3


@pytest.mark.long
def test_off_is_today_bit_for_bit(grid):
    key = jax.random.key(3)
    a = jax.jit(filter_scenario)(key, grid, SCEN)
    b = jax.jit(lambda k, g, s: filter_scenario(k, g, s, None))(key, grid, SCEN)
    for u, v in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(u), np.asarray(v))
    dyn, _ = run_steps(a, SCEN)
    x0, p0 = initial_state(SCEN)
    for cfg in (None, map_error_state(0.0, 10e3)):
        d2, x2, p2, m2 = augment(cfg, dyn, x0, p0, SCEN.speed)
        assert d2 is dyn and x2 is x0 and p2 is p0 and m2 is fl.gravity_measurement
    today = jax.jit(ukf_run)(key, grid, SCEN)
    off = jax.jit(ukf_run)(key, grid, SCEN, None, ToldMapError(jnp.zeros(()), None))
    for k in today:
        np.testing.assert_array_equal(np.asarray(today[k]), np.asarray(off[k]))


@pytest.mark.long
def test_map_error_changes_only_the_readings(grid):
    key = jax.random.key(4)
    a = filter_scenario(key, grid, SCEN)
    b = filter_scenario(key, grid, SCEN, map_error(3.0, 10e3))
    np.testing.assert_array_equal(np.asarray(a.errors), np.asarray(b.errors))
    np.testing.assert_array_equal(np.asarray(a.ins_lat), np.asarray(b.ins_lat))
    d = np.asarray(b.readings - a.readings)
    assert np.all(np.isfinite(d)) and 0.3 < np.std(d) + np.abs(np.mean(d)) < 15.0


def test_point_masses_refuse_map_error():
    with pytest.raises(TypeError, match="map_error needs the map"):
        filter_scenario(jax.random.key(0), paper_d(), SCEN, map_error(1.0, 1e4))
    with pytest.raises(ValueError, match="map_error needs a map"):
        filter_builder(None, kind="ukf", map_error=map_error(1.0, 1e4))


@pytest.mark.long
def test_structured_ukf_equals_generic_with_the_map_error_state(grid):
    run_ = filter_scenario(jax.random.key(5), grid, SCEN, map_error(3.0, 10e3))
    dyn, steps = run_steps(run_, SCEN)
    x0, p0 = initial_state(SCEN)
    dyn, x0, p0, meas = augment(map_error_state(3.0, 20e3), dyn, x0, p0, SCEN.speed)
    assert meas.additive == (12, 13) and x0.shape == (14,)

    def generic(field, x, lat, lon):
        return fl.map_at_error(field, x[:2], lat, lon) + x[12] + x[13]

    go = jax.jit(fl.run_filter, static_argnums=0)
    a = go(fl.ukf(meas), grid, dyn, x0, p0, steps)[1]
    b = go(fl.ukf(generic), grid, dyn, x0, p0, steps)[1]
    np.testing.assert_allclose(np.asarray(a.x), np.asarray(b.x), rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(np.asarray(a.p_pos), np.asarray(b.p_pos), rtol=1e-9, atol=1e-6)


@pytest.mark.long
def test_sweeping_sigma_and_length_does_not_retrace(grid):
    key, truth = jax.random.key(6), map_error(3.0, 10e3)
    n0 = len(_TRACES)
    out = [ukf_fogm(key, grid, SCEN, truth, s, length)
           for s, length in ((1.0, 10e3), (3.0, 20e3), (5.0, 5e3))]
    assert len(_TRACES) == n0 + 1
    assert len({float(o["err_m"]) for o in out}) == 3
    # vmap over (sigma, L) equals the loop
    sig, lens = jnp.array([1.0, 3.0, 5.0]), jnp.array([10e3, 20e3, 5e3])
    vm = jax.jit(jax.vmap(_ukf_fogm, in_axes=(None, None, None, None, 0, 0)))(
        key, grid, SCEN, truth, sig, lens)
    for i, o in enumerate(out):
        for k in ("err_m", "nees"):
            np.testing.assert_allclose(float(vm[k][i]), float(o[k]), rtol=1e-9)


def test_bad_map_error_input_names_the_option():
    for s, length, match in ((-1.0, 1e4, "sigma"), (np.nan, 1e4, "sigma"),
                             (1.0, 0.0, "length_m"), (1.0, np.inf, "length_m")):
        with pytest.raises(ValueError, match=match):
            map_error_state(s, length)
    with pytest.raises(TypeError, match="MapPlusBias"):
        map_error_measurement(lambda *a: 0.0)
    with pytest.raises(ValueError, match="map_error_told"):
        filter_builder(datasets.load("ryukyu")["anomaly_2p5min"], kind="ukf",
                       map_error=map_error(1.0, 1e4), map_error_told="loud")
    with pytest.raises(ValueError, match="point-mass filter"):
        filter_builder(datasets.load("ryukyu")["anomaly_2p5min"], kind="pmf",
                       map_error=map_error(1.0, 1e4), map_error_told="sogm")
    with pytest.raises(TypeError, match="map_error must be"):
        filter_builder(datasets.load("ryukyu")["anomaly_2p5min"], kind="ukf", map_error=3.0)


@pytest.mark.long
def test_nees_is_honest_with_the_matched_state_and_not_without(grid):
    """A small Monte Carlo (24 runs, 1 h) with a 3 mGal, 10 km markov2 map error; the
    default state is the matched second-order one."""
    truth = map_error(3.0, 10e3)
    nees = {}
    for told in ("state", "none"):
        spec = filter_builder(grid, kind="ukf", n_fixes=361, map_error=truth,
                              map_error_told=told)
        out = run(spec.fn, jax.random.key(11), 24, args=spec.args, progress=False)
        nees[told] = float(np.mean(out["nees"]))
    assert abs(nees["state"] - 2.0) <= 2.0, nees
    assert nees["none"] > 2 * nees["state"], nees
