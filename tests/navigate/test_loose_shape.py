"""The segment's shape update (navigate.loose_shape.shape_update): the readings' information
on the INS error beyond the fix's offset, used given the offset."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrav as jg
from jaxgrav.geodesy import eotvos_jacobian
from jaxgrav.match.dense import DenseConfig
from jaxgrav.navigate import LooseConfig, error_kf_tables, fix_update
from jaxgrav.navigate.loose_shape import shape_update
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import NAVIGATION_GRADE
from jaxgrav.sim.drift import apply_drift
from jaxgrav.sim.ins import initial_covariance

N_FIX, EVERY, DT = 20, 12, 10.0


def _plane():
    """A map linear in lat/lon (~1 mGal/km north, 0.6 mGal/km east): its bicubic
    spline is the plane, so the readings are exactly linear in the position error."""
    lat, lon = np.linspace(29.0, 31.0, 41), np.linspace(129.0, 131.0, 41)
    values = 111.0 * (lat[:, None] - 30.0) + 58.0 * (lon[None, :] - 130.0)
    return prepare_map(jg.Grid.from_arrays(lat, lon, values, units="mGal"))


def _setting():
    tables = error_kf_tables(NAVIGATION_GRADE, 30.0, DT, N_FIX * EVERY, N_FIX * EVERY)
    b = tables.backward[:, :4].reshape(N_FIX, EVERY, 4, -1).mean(1)
    p0 = initial_covariance(NAVIGATION_GRADE, 1000.0, 0.3)
    p = tables.step_f @ p0 @ tables.step_f.T + tables.step_q
    v_e = jnp.full(N_FIX, 5.0)
    lat = jnp.full(N_FIX, 30.0)
    lat, lon = apply_drift(lat, jnp.full(N_FIX, 130.0), jnp.zeros(N_FIX),
                           5.0 * EVERY * DT * jnp.arange(N_FIX))
    return tables.h_mean, b, 0.5 * (p + p.T), lat, lon, v_e, jnp.zeros(N_FIX)


def test_the_shape_update_is_honest_and_leaves_the_fixed_mean_where_the_fix_put_it():
    """Linear map, readings drawn from the model: the update keeps H̄ x (the fix's
    answer, counted once), its covariance matches the errors it leaves (NEES ≈ 13 over
    draws), and the velocity, which a mean-position fix tells little, is better known."""
    grid = _plane()
    h_mean, b, p, lat, lon, v_e, v_n = _setting()
    matcher = DenseConfig(noise_mgal=0.3, map_error_mgal=0.0)
    jac = eotvos_jacobian(lat, v_e, v_n)
    r_fix = 150.0**2 * jnp.eye(2)
    chol = jnp.linalg.cholesky(p)

    def one(key):
        k1, k2, k3 = jax.random.split(key, 3)
        delta = chol @ jax.random.normal(k1, (13,))  # the residual error, x_ref = 0
        z = h_mean @ delta + 150.0 * jax.random.normal(k2, (2,))
        x1, p1, _ = fix_update(jnp.zeros(13), p, z, r_fix, h_mean, True)
        offset = -(h_mean @ x1)
        # the readings at the true positions (corrected − the position error)
        d = jnp.einsum("kij,j->ki", b, delta)
        t_lat, t_lon = apply_drift(lat, lon, -d[:, 0], -d[:, 1])
        g = (grid.sample(t_lat, t_lon) + jnp.einsum("ki,ki->k", jac, d[:, 2:4])
             + delta[12] + 0.3 * jax.random.normal(k3, (N_FIX,)))
        x2, p2, nis = shape_update(grid, matcher, lat, lon, g, v_e, v_n, b, h_mean,
                                   jnp.zeros(13), x1, p1, offset, 1.0, True)
        e = delta - x2
        return x1, x2, p1, p2, e @ jnp.linalg.solve(p2, e), nis

    x1, x2, p1, p2, nees, nis = jax.vmap(one)(jax.random.split(jax.random.key(0), 2000))
    np.testing.assert_allclose(x2 @ h_mean.T, x1 @ h_mean.T, atol=1e-6)  # m
    assert 12.2 < float(jnp.mean(nees)) < 13.8  # 13 states; ±0.8 ≫ the draws' scatter
    assert N_FIX - 2 < float(jnp.mean(nis)) < N_FIX + 2
    vel = lambda q: jnp.trace(q[0, 2:4, 2:4])  # noqa: E731
    assert float(vel(p2)) < 0.5 * float(vel(p1))
    assert float(p2[0, 12, 12]) <= float(p1[0, 12, 12])  # the bias: along one straight leg
    # the plane's gradient confounds it with the offset, so only not worse


def test_the_shape_update_is_skipped_where_not_accepted():
    grid = _plane()
    h_mean, b, p, lat, lon, v_e, v_n = _setting()
    x = jnp.arange(13.0) * 0.01
    g = grid.sample(lat, lon)
    x2, p2, nis = shape_update(grid, DenseConfig(noise_mgal=0.3, map_error_mgal=3.0), lat, lon,
                               g, v_e, v_n, b, h_mean, jnp.zeros(13), x, p, jnp.zeros(2), 2.0,
                               jnp.asarray(False))
    np.testing.assert_array_equal(x2, x)
    np.testing.assert_array_equal(p2, p)
    assert np.isnan(float(nis))


def test_the_shape_update_needs_the_segment_error_linear_in_the_state():
    with pytest.raises(ValueError, match="shape_update needs the dense matcher and "
                                         "segment_error 'linear' or 'conditional'"):
        LooseConfig(shape_update=True)


@pytest.mark.parametrize("dof", [10, 30, 60, 120])
def test_the_gate_is_the_chi2_quantile(dof):
    from scipy.stats import chi2

    from jaxgrav.navigate.loose_shape import SHAPE_GATE_P, chi2_quantile
    assert chi2_quantile(SHAPE_GATE_P, dof) == pytest.approx(chi2.ppf(SHAPE_GATE_P, dof),
                                                             rel=6e-3)
