"""The Gaussian sum's reweighting and its predicted reading (found by a review, helper-30).

On a linear map (5 mGal/km northward) the components of a 3 × 3 sum differ only in where
they put the position, so a reading that the northern row explains must move the weight
there, whether or not the others are gated; and over truths drawn from the filter's own
prior, the reported innovation's NIS must average 1, as the UKF's does.
"""

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import filters as fl
from jaxgrav.sim import ins

LAT, LON, DT = 24.3, 123.0, 10.0
GRAD = 0.005  # mGal per metre northward


def _field(lat, lon):
    return GRAD * (lat - LAT) * 111000.0


def _setup():
    model = ins.INSErrorModel()
    f, q = jax.jit(ins.transition)(model, LAT, DT)  # 2.2 s op by op, 0.8 s jitted
    p0 = ins.initial_covariance(model, 1414.0, 0.14)
    return fl.Dynamics(f, q, DT), jnp.zeros(13), p0


def _step(z):
    return fl.Step(jnp.asarray(LAT), jnp.asarray(LON), jnp.asarray(z), jnp.asarray(1.0))


# jitted, one program for every case (gate and hole traced): op by op their many small
# operations took most of these tests' time
@jax.jit
def _init(x0, p0):
    return fl.gaussian_sum(fl.ukf(), per_axis=3).init(x0, p0)


@jax.jit
def _updates(gate, hole_lat, st, k, dyn):
    """The reading of component ``k``'s truth, on the linear map (NaN south of
    ``hole_lat``, −∞: nowhere): the mixture updated, and its base on every component."""
    z = fl.gravity_measurement(_field, dyn.f @ st.components.x[k], LAT, LON)

    def field(lat, lon):
        return jnp.where(lat < hole_lat, jnp.nan, _field(lat, lon))

    new, info = fl.gaussian_sum(fl.ukf(gate=gate), per_axis=3).update(st, _step(z), field, dyn)
    _, infos = jax.vmap(fl.ukf(gate=gate).update, in_axes=(0, None, None, None))(
        st.components, _step(z), field, dyn)
    return new, info, infos


def test_a_gated_component_loses_weight_like_any_other():
    dyn, x0, p0 = _setup()
    out = {}
    for gate in (jnp.inf, 3.0):
        st = _init(x0, p0)
        xs = st.components.x
        north = int(jnp.argmax(xs[:, 0]))  # the north row's reading, no hole
        new, info, infos = _updates(gate, -jnp.inf, st, north, dyn)
        w0, w1 = np.exp(np.asarray(st.log_w)), np.exp(np.asarray(new.log_w))
        south = np.asarray(xs[:, 0]) < -1.0
        out[float(gate)] = (w0, w1, south, np.asarray(infos.status), float(info.x[0]))
    w0, w1, south, status, mean_gated = out[3.0]
    assert np.all(status[south] & fl.STATUS_FILTER["gated"])  # the southern row is gated
    assert np.all(w1[south] < w0[south])  # ... and loses weight, as without the gate
    assert np.all(w1[~south].sum() > 0.9)
    assert mean_gated > 500.0  # the mixture moves north (it moved 589 m south before)
    np.testing.assert_allclose(out[float("inf")][1], w1, rtol=1e-12)  # the same weights


def test_the_mixture_innovation_is_the_predictive_one():
    """Truths from the filter's own prior, the first reading: mean NIS 1 for every sum
    (0.65 and 0.30 for 3 × 3 and 5 × 5 before: posterior weights, no spread term)."""
    dyn, x0, p0 = _setup()
    n = 2000
    k1, k2 = jax.random.split(jax.random.PRNGKey(0))
    chol = np.linalg.cholesky(np.asarray(dyn.f @ p0 @ dyn.f.T + dyn.q))
    xt = jax.random.normal(k1, (n, 13), jnp.float64) @ chol.T
    zs = jax.jit(jax.vmap(lambda x: fl.gravity_measurement(_field, x, LAT, LON)))(xt)
    zs = zs + jax.random.normal(k2, (n,), jnp.float64)  # vmap jitted: 0.9 s less CPU than op by op

    for filt in (fl.ukf(), fl.gaussian_sum(fl.ukf(), 3), fl.gaussian_sum(fl.ukf(), 5)):
        def one(z, filt=filt):
            _, info = filt.update(filt.init(x0, p0), _step(z), _field, dyn)
            return info.innovation, info.innovation_var

        nu, s = (np.asarray(a) for a in jax.jit(jax.vmap(one))(zs))
        nis = nu**2 / s
        assert abs(np.mean(nis) - 1.0) < 0.1, np.mean(nis)


def test_a_component_off_the_map_counts_as_the_least_likely():
    """The map NaN 2.8 km south of the INS position: the row of components that put the
    truth there (a north error, truth = INS − error) cannot predict the reading and gets
    the smallest log-likelihood of the others, not 0 (which was more than any component
    that could); the mixture's predicted reading comes from the others."""
    dyn, x0, p0 = _setup()
    st = _init(x0, p0)
    xs = st.components.x
    new, info, infos = _updates(jnp.inf, LAT - 0.025, st, int(jnp.argmin(xs[:, 0])), dyn)
    off = (np.asarray(infos.status) & fl.STATUS_FILTER["off_map"]) > 0
    np.testing.assert_array_equal(off, np.asarray(xs[:, 0]) > 1.0)
    w0, w1 = np.exp(np.asarray(st.log_w)), np.exp(np.asarray(new.log_w))
    ratio = w1 / w0
    np.testing.assert_allclose(ratio[off], ratio[~off].min(), rtol=1e-9)
    assert np.isfinite(float(info.innovation)) and float(info.innovation_var) > 0
