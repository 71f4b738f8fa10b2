"""Tests of the no-harm guard (jaxgrav.filters.guard).

References: SciPy's generalised symmetric eigensolver, NumPy loops for the free
covariance and the windowed NIS, Python loops over runs for vmap.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from jaxgrav.filters import Dynamics, StepInfo
from jaxgrav.filters.guard import (
    GuardConfig,
    free_covariance,
    generalized_eig_2x2,
    guard_gain,
    guard_infos,
    guard_position,
    guard_run,
    windowed_nis,
)
from jaxgrav.sim import ins

RNG = np.random.default_rng(7)
# one compiled guard for the run-level tests (same shapes: 40 steps, window 10)
guard_infos_jit = jax.jit(guard_infos, static_argnums=3)


def _spd(rng, scale=1.0):
    a = rng.normal(size=(2, 2))
    return scale * (a @ a.T + 0.1 * np.eye(2))


def _pair(rng):
    """A free covariance and a posterior that is smaller (posterior ≤ free)."""
    b = _spd(rng, 2e6)
    lb = np.linalg.cholesky(b)
    u = scipy.linalg.qr(rng.normal(size=(2, 2)))[0]
    lam = np.sort(rng.uniform(0.01, 1.0, 2))
    return lb @ u @ np.diag(lam) @ u.T @ lb.T, b


def test_generalized_eig_matches_scipy():
    eig = jax.jit(generalized_eig_2x2)
    for _ in range(50):
        a, b = _spd(RNG, 3.0), _spd(RNG, 5.0)
        a[0, 1] = a[1, 0] = a[0, 1] * RNG.choice([0.0, 1.0])  # also diagonal cases
        lam, v = map(np.asarray, eig(jnp.asarray(a), jnp.asarray(b)))
        ref = scipy.linalg.eigh(a, b, eigvals_only=True)
        np.testing.assert_allclose(lam, ref, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(v @ v.T, b, rtol=1e-10, atol=1e-12)
        vi = np.linalg.inv(v)
        np.testing.assert_allclose(vi @ a @ vi.T, np.diag(lam), rtol=1e-9, atol=1e-9)
        # b⁻¹ vᵢ are the generalised eigenvectors: a w = λ b w
        w = np.linalg.solve(b, v)
        np.testing.assert_allclose(a @ w, b @ w * lam, rtol=1e-9, atol=1e-9)


def test_gain_shape():
    lam = jnp.linspace(-0.1, 1.2, 27)
    g = np.asarray(guard_gain(lam, 0.3, 0.7))
    assert np.all(g[np.asarray(lam) <= 0.3] == 1.0)
    assert np.all(g[np.asarray(lam) >= 0.7] == 0.0)
    assert np.all(np.diff(g) <= 0.0)
    hard = np.asarray(guard_gain(lam, 0.5, 0.5))
    np.testing.assert_array_equal(hard, (np.asarray(lam) <= 0.5).astype(float))


def test_identity_when_everything_passes():
    for _ in range(10):
        a, b = _pair(RNG)
        x = RNG.normal(size=2) * 1e3
        xg, pg, gain, _ = guard_position(jnp.asarray(x), jnp.asarray(a), jnp.asarray(b), 2.0, 2.0)
        np.testing.assert_array_equal(np.asarray(gain), 1.0)
        np.testing.assert_array_equal(np.asarray(xg), x)
        np.testing.assert_array_equal(np.asarray(pg), a)


def test_nothing_observed_gives_zero_correction_and_free_covariance():
    a, b = _pair(RNG)
    x = jnp.array([900.0, -400.0])
    # posterior equal to the free covariance: λ = 1, nothing learnt
    xg, pg, gain, lam = guard_position(x, jnp.asarray(b), jnp.asarray(b), 0.5, 0.9)
    np.testing.assert_allclose(np.asarray(lam), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(xg), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(pg), b, rtol=1e-10)
    # hold: everything back, whatever was learnt
    xg, pg, gain, _ = guard_position(x, jnp.asarray(a), jnp.asarray(b), 2.0, 2.0, True)
    np.testing.assert_array_equal(np.asarray(gain), 0.0)
    np.testing.assert_allclose(np.asarray(xg), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(pg), b, rtol=1e-10)


def test_partial_guard_keeps_observed_direction():
    # free: isotropic 1.4 km; posterior: north well observed (λ = 0.04), east not (λ = 0.95)
    b = np.eye(2) * 1400.0**2
    a = np.diag([280.0**2, 0.95 * 1400.0**2])
    x = jnp.array([1200.0, -500.0])
    xg, pg, _, lam = guard_position(x, jnp.asarray(a), jnp.asarray(b), 0.5, 0.5)
    np.testing.assert_allclose(np.asarray(lam), [0.04, 0.95], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(xg), [1200.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(np.asarray(pg), np.diag([280.0**2, 1400.0**2]), rtol=1e-12,
                               atol=1e-6)


def test_reported_covariance_between_posterior_and_free():
    for _ in range(20):
        a, b = _pair(RNG)
        _, pg, _, _ = guard_position(jnp.zeros(2), jnp.asarray(a), jnp.asarray(b), 0.3, 0.7)
        pg = np.asarray(pg)
        assert np.all(np.linalg.eigvalsh(pg - a) > -1e-6 * np.trace(b))
        assert np.all(np.linalg.eigvalsh(b - pg) > -1e-6 * np.trace(b))


def test_free_covariance_matches_numpy():
    f, q = ins.transition(ins.INSErrorModel(), 24.3, 10.0)
    p0 = ins.initial_covariance(ins.INSErrorModel(), 1414.2, 0.1414)
    out = np.asarray(jax.jit(free_covariance, static_argnums=2)(Dynamics(f, q), p0, 30))
    f, q, p = map(np.asarray, (f, q, p0))
    for k in range(30):
        p = f @ p @ f.T + q
        np.testing.assert_allclose(out[k], p[:2, :2], rtol=1e-10, atol=1e-6)  # m²


def _nis_reference(nu, s, window):
    out = np.full(nu.shape, np.nan)
    seen = []
    for k in range(nu.size):
        if np.isfinite(nu[k]):
            seen.append(nu[k] ** 2 / s[k])
        if seen:
            out[k] = np.mean(seen[-window:])
    return out


def test_windowed_nis_matches_loop():
    nu = RNG.normal(size=200) * 2.0
    nu[RNG.uniform(size=200) < 0.4] = np.nan
    nu[:3] = np.nan
    s = RNG.uniform(1.0, 4.0, 200)
    for window in (1, 5, 30):
        got = np.asarray(windowed_nis(jnp.asarray(nu), jnp.asarray(s), window))
        np.testing.assert_allclose(got, _nis_reference(nu, s, window), rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="window"):
        windowed_nis(jnp.asarray(nu), jnp.asarray(s), 0)


def _infos(rng, t):
    pairs = [_pair(rng) for _ in range(t)]
    a = np.stack([p[0] for p in pairs])
    b = np.stack([p[1] for p in pairs])
    x = rng.normal(size=(t, 13)) * 500.0
    nu = rng.normal(size=t) * 1.5
    info = StepInfo(
        jnp.asarray(x), jnp.ones((t, 13)), jnp.asarray(a), jnp.asarray(nu), jnp.ones(t),
        jnp.zeros(t, jnp.int32),
    )
    return info, jnp.asarray(b)


@pytest.mark.long
def test_guard_infos_vmap_equals_loop():
    runs, t = 4, 40
    cases = [_infos(np.random.default_rng(i), t) for i in range(runs)]
    cfg = GuardConfig(0.3, 0.6, 1.8)
    looped = [guard_infos_jit(info, b, cfg, 10) for info, b in cases]
    stacked = jax.tree.map(lambda *xs: jnp.stack(xs), *[c[0] for c in cases])
    frees = jnp.stack([c[1] for c in cases])
    batched = jax.jit(jax.vmap(guard_infos, in_axes=(0, 0, None, None)), static_argnums=3)(
        stacked, frees, cfg, 10
    )
    for i in range(runs):
        for got, ref in zip(batched, looped[i], strict=True):
            np.testing.assert_allclose(np.asarray(got[i]), np.asarray(ref), rtol=1e-12,
                                       atol=1e-9)
    # states other than position are untouched, held steps have zero correction
    info, b = cases[0]
    out = looped[0]
    np.testing.assert_array_equal(np.asarray(out.x[:, 2:]), np.asarray(info.x[:, 2:]))
    hold = np.nan_to_num(np.asarray(windowed_nis(info.innovation, info.innovation_var, 10))) > 1.8
    assert hold.any() and (~hold).any()
    np.testing.assert_allclose(np.asarray(out.x[hold, :2]), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(out.p_pos[hold]), np.asarray(b)[hold], rtol=1e-10)
    np.testing.assert_allclose(np.asarray(out.sigma[:, :2]) ** 2,
                               np.asarray(out.p_pos)[:, [0, 1], [0, 1]], rtol=1e-12)


def test_guard_infos_passthrough_default_rule():
    info, b = _infos(np.random.default_rng(3), 40)
    out = guard_infos_jit(info, b, GuardConfig(2.0, 2.0), 10)  # λ < 1 < 2: everything passes
    np.testing.assert_array_equal(np.asarray(out.x), np.asarray(info.x))
    np.testing.assert_array_equal(np.asarray(out.p_pos), np.asarray(info.p_pos))


def test_guard_infos_bad_input():
    info, b = _infos(np.random.default_rng(4), 6)
    with pytest.raises(ValueError, match="p_free"):
        guard_infos(info, b[:5])
    with pytest.raises(ValueError, match="lo"):
        guard_infos(info, b, GuardConfig(0.7, 0.3))


@pytest.mark.long
def test_guard_run_uses_free_covariance():
    model = ins.INSErrorModel()
    dyn = Dynamics(*ins.transition(model, 24.3, 10.0))
    p0 = ins.initial_covariance(model, 1414.2, 0.1414)
    info, _ = _infos(np.random.default_rng(5), 12)
    free = free_covariance(dyn, p0, 12)
    # posterior = a fraction of the free covariance: λ = 0.1 north-ish, 0.6 east-ish
    info = info._replace(p_pos=free * jnp.array([[0.1, 0.0], [0.0, 0.6]]))
    got = guard_run(info, dyn, p0)  # default: λ ≤ 0.2 passes
    ref = guard_infos(info, free)
    np.testing.assert_array_equal(np.asarray(got.x), np.asarray(ref.x))
    np.testing.assert_allclose(np.asarray(got.x[:, 1]), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(got.x[:, 0]), np.asarray(info.x[:, 0]), rtol=1e-9)
