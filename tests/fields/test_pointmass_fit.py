"""Point-mass fitting: recovery of synthetic models, the exact forward model, jit/vmap/grad.

Every fit in this module uses one of two configurations (K = 1 on a 13×13 map,
K = 3 on a 15×15 map) so that the fitting program compiles only a few times.
"""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from jax.flatten_util import ravel_pytree

from jaxgrav import constants as c
from jaxgrav import filters as fl
from jaxgrav.fields import pointmass as pm
from jaxgrav.fields import pointmass_fit as pf
from jaxgrav.fields import pointmass_fit_inputs as pfi
from jaxgrav.fields import pointmass_fit_model as pfm
from jaxgrav.fields import pointmass_fit_solver as pfs
from jaxgrav.grid import Grid
from jaxgrav.sim import ins

ONE = dict(n_restarts=4, steps=60, polish_steps=30, key=0)
THREE = dict(n_restarts=8, steps=150, polish_steps=100, key=0)


def _map(masses, lat, lon, h=0.0):
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    return np.asarray(pm.gravity_anomaly(masses, la, lo, h), dtype=float)


def _grid1(masses):
    lat = np.linspace(24.0, 24.6, 13)
    lon = np.linspace(122.7, 123.3, 13)
    return Grid.from_arrays(lat, lon, _map(masses, lat, lon) + 7.0, units="mGal")


def _one_mass(mass=3.0e16, lat=24.37, lon=122.93, depth=30.0e3):
    return pm.PointMasses.create(lat=lat, lon=lon, depth=depth, mass=mass)


def _make_problem(k=2, fit_offset=True, h=0.0, dtype=None):
    g = _grid1(_one_mass())
    p, centre, scale = pfi.build_problem(g, None, None, h, (5e3, 100e3), 0.0, fit_offset, k)
    if dtype is not None:
        p = jax.tree_util.tree_map(lambda x: x.astype(dtype), p)
    return g, p, centre, scale


def _raw(k, seed=0, dtype=jnp.float64):
    rng = np.random.default_rng(seed)
    return pfm.RawParams(*(jnp.asarray(rng.normal(size=k), dtype) for _ in range(4)),
                   jnp.asarray(rng.normal(), dtype))


def _unit(raw, p):
    return pfm.unit_anomalies(*pfm.mass_positions(raw, p), p)


def _check_recovered(fit, truth, pos_km, rel_mass):
    order_f = np.argsort(np.asarray(fit.masses.lat))
    order_t = np.argsort(np.asarray(truth.lat))
    lat_f, lat_t = np.asarray(fit.masses.lat)[order_f], np.asarray(truth.lat)[order_t]
    lon_f, lon_t = np.asarray(fit.masses.lon)[order_f], np.asarray(truth.lon)[order_t]
    dy = (lat_f - lat_t) * 111.0
    dx = (lon_f - lon_t) * 111.0 * np.cos(np.deg2rad(lat_t))
    assert np.max(np.hypot(dx, dy)) < pos_km
    np.testing.assert_allclose(np.asarray(fit.masses.depth)[order_f],
                               np.asarray(truth.depth)[order_t], rtol=0, atol=pos_km * 1e3)
    np.testing.assert_allclose(np.asarray(fit.masses.mass)[order_f],
                               np.asarray(truth.mass)[order_t], rtol=rel_mass)


# --- the forward model ---------------------------------------------------------------


def test_forward_model_equals_gravity_anomaly():
    h = np.linspace(-50.0, 800.0, 13 * 13).reshape(13, 13)  # ellipsoidal heights (m)
    g, p, _, scale = _make_problem(k=3, h=h)
    raw = _raw(3, seed=1)
    dlat, dlon, depth = (np.asarray(v) for v in pfm.mass_positions(raw, p))
    length = float(p.length)
    masses = pm.PointMasses.create(
        lat=float(p.lat0) + dlat, lon=float(p.lon0) + dlon, depth=depth,
        mass=np.asarray(raw.mass) * scale * c.MGAL * length**2 / c.G_NEWTON,
    )
    la, lo = np.meshgrid(g.lat, g.lon, indexing="ij")
    ref = np.asarray(pm.gravity_anomaly(masses, la, lo, h)).ravel()
    ours = scale * np.asarray(jax.jit(_unit)(raw, p) @ raw.mass)
    assert np.max(np.abs(ref)) > 5.0  # mGal: a meaningful comparison
    np.testing.assert_allclose(ours, ref, rtol=1e-10, atol=1e-10 * np.max(np.abs(ref)))
    # the masses stay inside the data's box and the depth bounds, by construction
    assert np.all((masses.lat >= 24.0) & (masses.lat <= 24.6))
    assert np.all((masses.depth >= 5e3) & (masses.depth <= 100e3))


def test_float32_forward_is_well_conditioned():
    _, p64, _, _ = _make_problem(k=3)
    _, p32, _, _ = _make_problem(k=3, dtype=jnp.float32)
    raw = _raw(3, seed=2)
    raw32 = jax.tree_util.tree_map(lambda x: x.astype(jnp.float32), raw)
    a64 = np.asarray(jax.jit(_unit)(raw, p64))
    a32 = np.asarray(jax.jit(_unit)(raw32, p32))
    assert a32.dtype == np.float32
    np.testing.assert_allclose(a32, a64, rtol=0, atol=1e-5 * np.max(np.abs(a64)))


def test_loss_gradient_matches_finite_differences():
    _, p, _, _ = _make_problem(k=2)
    raw = _raw(2, seed=3)
    flat, unravel = ravel_pytree(raw)

    def loss(x):
        return pfm.misfit_loss(unravel(x), p, True)

    g = np.asarray(jax.jit(jax.grad(loss))(flat))
    eps = 1e-6
    steps = eps * np.eye(flat.size)
    both = np.asarray(jax.jit(jax.vmap(loss))(jnp.concatenate([flat + steps, flat - steps])))
    fd = (both[: flat.size] - both[flat.size :]) / (2 * eps)
    assert np.max(np.abs(g)) > 1e-3
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-8 * np.max(np.abs(g)))


# --- recovery ------------------------------------------------------------------------


@pytest.mark.long
def test_recovers_one_mass_and_fit_is_a_map():
    truth = _one_mass()
    g = _grid1(truth)
    fit = pf.fit_point_masses(g, 1, **ONE)
    assert isinstance(fit.masses, pm.PointMasses) and fit.masses.size == 1
    _check_recovered(fit, truth, pos_km=0.01, rel_mass=1e-4)
    assert fit.offset == pytest.approx(7.0, abs=1e-4)
    assert fit.rms < 1e-4 and fit.converged
    assert fit.iterations == ONE["steps"] + ONE["polish_steps"]
    assert fit.restart_rms.shape == (ONE["n_restarts"],) and fit.rms == np.min(fit.restart_rms)
    # the fit is an analytic, jit-able map function
    la, lo = np.meshgrid(g.lat, g.lon, indexing="ij")
    resid = np.asarray(jax.jit(fit.anomaly)(la, lo)) - np.asarray(g.values)
    assert np.sqrt(np.mean(resid**2)) == pytest.approx(fit.rms, rel=1e-6, abs=1e-9)


PAPER_D_OFFSET = 7.0  # mGal added to paper D's map: the fitted offset must carry it


@pytest.fixture(scope="module")
def paper_d_fit():
    """K = 3 fitted to paper D's masses on a 15×15 map of their area (+ an offset)."""
    lat = np.linspace(23.9, 24.6, 15)
    lon = np.linspace(122.6, 123.3, 15)
    values = _map(pm.three_mass_model(), lat, lon) + PAPER_D_OFFSET
    # arrays with 1-D axes instead of a Grid
    return values, pf.fit_point_masses(values, 3, lat=lat, lon=lon, **THREE)


@pytest.mark.long
def test_recovers_paper_d_three_masses(paper_d_fit):
    values, fit = paper_d_fit
    _check_recovered(fit, pm.three_mass_model(), pos_km=1.0, rel_mass=0.03)
    assert fit.rms < 0.01 * np.std(values)
    assert fit.offset == pytest.approx(PAPER_D_OFFSET, abs=0.05)


def _filter_runs(n_runs, n_steps=120, dt=10.0, seed=0):
    """Paper D-like runs built in NumPy (no simulation program to compile): eastward tracks
    at 5 m/s across the masses, INS error from a 2 km / 0.2 m/s start propagated with F, Q
    by SciPy's Van Loan, a reading every step (map + 1 mGal bias + 1 mGal noise)."""
    model, lat_ref, n = ins.INSErrorModel(), 24.27, ins.N_STATES
    a, qc = (np.asarray(m) for m in ins.continuous_model(model, lat_ref))
    e = scipy.linalg.expm(np.block([[-a, qc], [np.zeros((n, n)), a.T]]) * dt)
    f = e[n:, n:].T
    q = f @ e[:n, n:]
    q = 0.5 * (q + q.T)
    w, v = np.linalg.eigh(q)
    root = v * np.sqrt(np.clip(w, 0.0, None))
    rng = np.random.default_rng(seed)
    lat = rng.uniform(24.15, 24.40, n_runs)[:, None] + np.zeros(n_steps + 1)
    lon = 122.86 + 5.0 * dt * np.arange(n_steps + 1) / (111320.0 * np.cos(np.deg2rad(lat)))
    err = np.zeros((n_runs, n_steps + 1, n))
    ang = rng.uniform(0, 2 * np.pi, (2, n_runs))
    err[:, 0, :4] = np.stack([2000 * np.cos(ang[0]), 2000 * np.sin(ang[0]),
                              0.2 * np.cos(ang[1]), 0.2 * np.sin(ang[1])], -1)
    err[:, 0, 12] = 1.0
    for k in range(n_steps):
        err[:, k + 1] = err[:, k] @ f.T + rng.standard_normal((n_runs, n)) @ root.T
    rm, rn = (c.WGS84_A * (1 - c.WGS84_E2) / (1 - c.WGS84_E2 * np.sin(np.deg2rad(lat)) ** 2) ** 1.5,
              c.WGS84_A / np.sqrt(1 - c.WGS84_E2 * np.sin(np.deg2rad(lat)) ** 2))
    ins_lat = lat + np.rad2deg(err[..., 0] / rm)
    ins_lon = lon + np.rad2deg(err[..., 1] / (rn * np.cos(np.deg2rad(lat))))
    z = _map_points(pm.three_mass_model(), lat, lon) + err[..., 12] + rng.standard_normal(lat.shape)
    steps = fl.Step(*(jnp.asarray(v[:, 1:]) for v in (ins_lat, ins_lon, z)),
                    jnp.ones((n_runs, n_steps)))
    p0 = ins.initial_covariance(model, 2000.0 / np.sqrt(2.0), 0.2 / np.sqrt(2.0))
    return fl.Dynamics(jnp.asarray(f), jnp.asarray(q)), p0, steps, err[:, 1:, :2]


def _map_points(masses, lat, lon):
    return np.asarray(pm.gravity_anomaly(masses, lat, lon), dtype=float)


@pytest.mark.long
def test_fitted_model_as_a_filter_map():
    """The UKF on paper D-like runs with a fitted model as its map (masses + offset, fitted
    to a noisy map window) does about as well as with the true masses."""
    lat = np.linspace(23.9, 24.6, 15)
    lon = np.linspace(122.6, 123.3, 15)
    noisy = (_map(pm.three_mass_model(), lat, lon) + PAPER_D_OFFSET
             + 0.1 * np.random.default_rng(4).standard_normal((15, 15)))
    fit = pf.fit_point_masses(noisy, 3, lat=lat, lon=lon, **THREE)
    assert 0.05 < fit.rms < 0.15  # the noise, not an exact copy of the truth
    dynamics, p0, steps, err = _filter_runs(8)
    x0 = jnp.zeros(p0.shape[0])

    @jax.jit
    def filtered(field, offset):
        # the readings are of the truth (no offset); the filter's map is field + offset
        run = jax.vmap(fl.run_filter, in_axes=(None, None, None, None, None, 0))
        _, info = run(fl.ukf(), field, dynamics, x0, p0, steps._replace(z=steps.z - offset))
        return info.x[..., :2], info.status

    def score(field, offset):
        x, status = (np.asarray(a) for a in filtered(field, offset))
        assert not np.any(status)
        half = err.shape[1] // 2
        rms = np.sqrt(np.mean(np.sum((err - x)[:, half:] ** 2, -1), -1))
        return rms / np.sqrt(np.mean(np.sum(err[:, half:] ** 2, -1), -1))

    ratio_true = score(pm.three_mass_model(), 0.0)
    ratio_fit = score(fit.masses, fit.offset - PAPER_D_OFFSET)
    assert np.mean(ratio_true) < 0.8  # the map is informative on these runs
    assert not np.allclose(ratio_fit, ratio_true, rtol=0, atol=1e-4)  # a different map ...
    np.testing.assert_allclose(ratio_fit, ratio_true, rtol=0, atol=0.05)  # ... as good
    assert abs(np.mean(ratio_fit) - np.mean(ratio_true)) < 0.02
    # ignoring the fitted offset (7 mGal against a 1 mGal bias prior) is not as good
    assert np.mean(score(fit.masses, -PAPER_D_OFFSET)) > np.mean(ratio_true) + 0.05


@pytest.mark.long
def test_jit_no_retrace_on_new_data_and_sweep():
    pf.fit_point_masses(_grid1(_one_mass()), 1, **ONE)
    size = pfs.fit_batch._cache_size()
    truth = _one_mass(mass=-1.5e16, lat=24.12, lon=123.2, depth=18e3)
    fit = pf.fit_point_masses(_grid1(truth), 1, learning_rate=0.03, rtol=1e-3, **ONE)
    assert pfs.fit_batch._cache_size() == size
    _check_recovered(fit, truth, pos_km=0.01, rel_mass=1e-4)
    sweep = pf.sweep_point_masses(_grid1(truth), [1], **ONE)
    assert pfs.fit_batch._cache_size() == size
    assert sweep.k.tolist() == [1] and sweep.rms[0] == sweep.fits[0].rms


@pytest.mark.long  # 4-8 s: the fast tier is at its 5-minute budget
def test_vmap_over_restarts_equals_loop():
    # Restart i alone (replicated into every slot, so the compiled program of the
    # other tests is reused) gives what restart i gives inside the batch.
    _, p, _, _ = _make_problem(k=1)
    n = ONE["n_restarts"]
    raw = pfs.initial_positions(jax.random.PRNGKey(5), n, 1, jnp.float64)
    args = (p, jnp.asarray(0.05, jnp.float64), jnp.asarray(1e-4, jnp.float64))
    kw = dict(fit_offset=True, steps=ONE["steps"], polish_steps=ONE["polish_steps"])
    batched = pfs.fit_batch(raw, *args, **kw)
    size = pfs.fit_batch._cache_size()
    assert batched[1].shape == (n,) and batched[0].mass.shape == (n, 1)
    assert len({float(v) for v in np.round(np.asarray(batched[1]), 12)}) > 1  # distinct runs
    for i in range(n):
        alone = pfs.fit_batch(jnp.repeat(raw[i : i + 1], n, axis=0), *args, **kw)
        for b, a in zip(jax.tree_util.tree_leaves(batched), jax.tree_util.tree_leaves(alone),
                        strict=True):
            np.testing.assert_allclose(np.asarray(b[i]), np.asarray(a[0]), rtol=1e-9,
                                       atol=1e-12)
    assert pfs.fit_batch._cache_size() == size


# --- model files ---------------------------------------------------------------------


@pytest.mark.long
def test_save_and_load_round_trip(paper_d_fit, tmp_path):
    _, fit = paper_d_fit
    path = tmp_path / "model.json"
    pf.save_point_masses(path, fit)
    doc = json.loads(path.read_text())
    assert doc["format"] == pf.MODEL_FORMAT and doc["rms"] == fit.rms
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind
    masses, offset = pf.load_point_masses(path)
    assert isinstance(masses, pm.PointMasses) and offset == fit.offset
    for name in ("lat", "lon", "depth", "mass"):  # bit-exact
        np.testing.assert_array_equal(np.asarray(getattr(masses, name)),
                                      np.asarray(getattr(fit.masses, name)), err_msg=name)
    # no overwrite without force; bare masses get offset 0 unless given
    with pytest.raises(FileExistsError, match="exists"):
        pf.save_point_masses(path, pm.three_mass_model())
    pf.save_point_masses(path, pm.three_mass_model(), offset=-2.5, force=True)
    masses, offset = pf.load_point_masses(path)
    assert offset == -2.5 and "rms" not in json.loads(path.read_text())
    np.testing.assert_array_equal(np.asarray(masses.mass), np.asarray(pm.three_mass_model().mass))


def _model_doc(**change):
    doc = {"format": "jaxgrav.point_masses", "version": 1, "lat": [24.2, 24.3],
           "lon": [123.0, 123.1], "depth": [3e4, 4e4], "mass": [1e16, -1e16], "offset": 0.0}
    doc.update(change)
    return {k: v for k, v in doc.items() if v is not None}


@pytest.mark.parametrize(("text", "match"), [
    ("{not json", r"is not JSON .*; a point-mass model is a JSON object with \"format\": "
                  r"\"jaxgrav.point_masses\".*save_point_masses in Python$"),
    ('[1, 2]', r"is not a jaxgrav point-mass model \(it holds \[1, 2\], not a JSON object\)"),
    (_model_doc(format="grid"), r"not a jaxgrav point-mass model \(its \"format\" is \"grid\"\)"),
    (_model_doc(format=None), r"\(it has no \"format\" field\); a point-mass model is a JSON"),
    (_model_doc(version=2), r"version must be 1; got 2"),
    (_model_doc(mass=None), r"lacks field mass; a point-mass model"),
    (_model_doc(depth=[3e4, "deep"]), r"depth must be a list of numbers"),
    (_model_doc(lat=[24.2]), r"same length K"),
    (_model_doc(lat=[24.2, 95.0]), r"[Ll]atitude"),
    (_model_doc(offset=float("nan")), r"offset must be a finite number of mGal; got NaN"),
    (_model_doc(mass=[1e16, float("inf")]), r"finite"),
])
def test_load_rejects_bad_model_files(tmp_path, text, match):
    path = tmp_path / "bad.json"
    path.write_text(text if isinstance(text, str) else json.dumps(text))
    with pytest.raises(ValueError, match=match) as err:
        pf.load_point_masses(path)
    assert str(path) in str(err.value)


def test_load_missing_file_and_directory(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"'.*nope.json': no such file"):
        pf.load_point_masses(tmp_path / "nope.json")
    with pytest.raises(ValueError, match="is not a file"):
        pf.load_point_masses(tmp_path)


# --- bad input -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(k=0), r"k must be an integer >= 1; got 0"),
        (dict(k=2.0), r"k must be an integer >= 1; got 2.0"),
        (dict(depth_bounds=(50e3, 10e3)), r"depth_bounds must be finite with d_min < d_max"),
        (dict(depth_bounds=(-100.0, 10e3)), r"depth_bounds\[0\] = -100.0 m must put every"),
        (dict(depth_bounds=5e3), r"depth_bounds must be a pair"),
        (dict(n_restarts=0), r"n_restarts must be an integer >= 1; got 0"),
        (dict(steps=0, polish_steps=0), r"steps \+ polish_steps must be >= 1"),
        (dict(learning_rate=-1.0), r"learning_rate must be a finite number > 0; got -1.0"),
        (dict(margin=-0.1), r"margin must be a finite number of degrees >= 0; got -0.1"),
        (dict(k=42), r"data has 169 point\(s\); fitting K = 42 masses and an offset needs "
                     r"more than 169"),
    ],
)
def test_bad_arguments(kwargs, match):
    g = _grid1(_one_mass())
    kwargs = {"k": 1, **kwargs}
    with pytest.raises(ValueError, match=match):
        pf.fit_point_masses(g, **kwargs)


def test_bad_data():
    lat, lon = np.linspace(24.0, 24.6, 5), np.linspace(122.7, 123.3, 6)
    v = np.zeros((5, 6))
    v[2, 3] = np.nan
    with pytest.raises(ValueError, match=r"data must be finite; found .*nan.* \(1 non-finite"):
        pf.fit_point_masses(v, 1, lat=lat, lon=lon)
    with pytest.raises(ValueError, match=r"lat and lon are required"):
        pf.fit_point_masses(np.zeros((5, 6)), 1)
    with pytest.raises(ValueError, match=r"lat \(4,\) and lon \(6,\) must broadcast"):
        pf.fit_point_masses(np.zeros((5, 6)), 1, lat=lat[:4], lon=lon)
    with pytest.raises(ValueError, match=r"lat and lon must be None when data is a Grid"):
        pf.fit_point_masses(_grid1(_one_mass()), 1, lat=lat, lon=lon)
    with pytest.raises(ValueError, match=r"must span a latitude and a longitude range"):
        pf.fit_point_masses(np.zeros(9), 1, lat=24.0, lon=np.linspace(122, 123, 9))
    with pytest.raises(ValueError, match=r"fitting K = 2 masses needs more than 8"):
        pf.fit_point_masses(np.ones(8), 2, lat=np.linspace(24, 25, 8), lon=123.0, margin=0.1,
                            fit_offset=False)
    with pytest.raises(ValueError, match=r"k_values must hold at least one K"):
        pf.sweep_point_masses(_grid1(_one_mass()), [])
