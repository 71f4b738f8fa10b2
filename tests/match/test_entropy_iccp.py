"""Paper B matchers: entropies by hand, Kabsch, ICCP convergence, coarse search, transforms."""

import dataclasses
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.grid import make_sampler
from jaxgrav.match import entropy as entropy_mod
from jaxgrav.match import shifted_tracks
from jaxgrav.match.api import match_track
from jaxgrav.match.combined import FAR_FIX, match_entropy_iccp
from jaxgrav.match.contour import local_field, patch_coefficients, value_grad
from jaxgrav.match.entropy import EntropyConfig, entropy_config_for
from jaxgrav.match.iccp import (
    IccpConfig,
    kabsch_2d,
    local_track_frame,
    match_iccp,
    match_iccp_batch,
)
from jaxgrav.match.rigid import refine_local, rotation_matrix, solve3
from jaxgrav.match.sizing import FAR_FIX_RADII, iccp_config_for
from jaxgrav.prepared import prepare_map
from jaxgrav.sim import Track, track_error_m

# jitted once per input shape: eager dispatch of many tiny ops is slow on a loaded machine
information_entropy = jax.jit(entropy_mod.information_entropy)
difference_entropy = jax.jit(entropy_mod.difference_entropy)
sequence_entropy = jax.jit(entropy_mod.sequence_entropy, static_argnames="kind")


def _track(n=20):
    lat = 29.85 + 0.0045 * np.arange(n)
    lon = 129.85 + 0.0035 * np.arange(n)
    return lat, lon


# ---------------------------------------------------------------------- entropies
def test_entropies_by_hand():
    h = jnp.array([1.0, 2.0, 3.0, 4.0])
    p = np.array([0.1, 0.2, 0.3, 0.4])
    assert float(information_entropy(h)) == pytest.approx(-np.sum(p * np.log(p)), rel=1e-12)
    # C = |h - 2.5| = 1.5, .5, .5, 1.5 -> q = 3/8, 1/8, 1/8, 3/8
    hand = -2 * (0.375 * math.log(0.375) + 0.125 * math.log(0.125))
    assert float(difference_entropy(h)) == pytest.approx(hand, rel=1e-12)
    # uniform sequence: H_XX = ln N; two-valued step: H_CY = ln N
    assert float(information_entropy(jnp.full(5, 7.0))) == pytest.approx(math.log(5))
    assert float(difference_entropy(jnp.array([0.0, 0.0, 2.0, 2.0]))) == pytest.approx(math.log(4))
    # a zero deviation contributes 0 log 0 = 0: C = (1, 0, 1) -> q = (1/2, 0, 1/2)
    assert float(difference_entropy(jnp.array([-1.0, 0.0, 1.0]))) == pytest.approx(math.log(2))


def test_entropy_invariances_and_undefined_cases():
    rng = np.random.default_rng(1)
    h = jnp.asarray(rng.normal(size=30))
    assert float(difference_entropy(h + 1234.5)) == pytest.approx(float(difference_entropy(h)))
    assert float(difference_entropy(3.0 * h)) == pytest.approx(float(difference_entropy(h)))
    # H_XX is undefined (NaN, not clipped) for values <= 0; a shift makes it defined
    assert np.isnan(float(information_entropy(h)))
    assert np.isfinite(float(sequence_entropy(h, kind="information", shift=10.0)))
    assert float(sequence_entropy(h, kind="information", shift=10.0)) == pytest.approx(
        float(information_entropy(h + 10.0)))
    assert np.isnan(float(difference_entropy(jnp.full(4, 2.0))))
    # batched over leading axes, gradient finite at a zero deviation
    hb = jnp.stack([h, h + 1.0, 2 * h])
    looped = [difference_entropy(hb[i]) for i in range(3)]
    np.testing.assert_allclose(difference_entropy(hb), looped)
    g = jax.jit(jax.grad(entropy_mod.difference_entropy))(jnp.array([-1.0, 0.0, 1.0, 3.0]))
    assert np.all(np.isfinite(g))
    with pytest.raises(ValueError, match="kind"):
        entropy_mod.sequence_entropy(h, "shannon")


# ---------------------------------------------------------------------- Kabsch
def test_kabsch_recovers_rotation_and_translation():
    rng = np.random.default_rng(2)
    p = rng.normal(size=(25, 2)) * 1000.0
    th = np.deg2rad(17.3)
    r = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    t = np.array([312.5, -87.25])
    x = p @ r.T + t
    r_est, t_est = kabsch_2d(jnp.asarray(p), jnp.asarray(x))
    np.testing.assert_allclose(r_est, r, atol=1e-12)
    np.testing.assert_allclose(t_est, t, atol=1e-9)
    # zero weights drop outliers exactly
    x_bad = x.copy()
    x_bad[:3] += 5000.0
    w = np.ones(25)
    w[:3] = 0.0
    r_w, t_w = kabsch_2d(jnp.asarray(p), jnp.asarray(x_bad), jnp.asarray(w))
    np.testing.assert_allclose(r_w, r, atol=1e-12)
    np.testing.assert_allclose(t_w, t, atol=1e-9)
    # a mirror image is not a rotation: det stays +1
    r_m, _ = kabsch_2d(jnp.asarray(p), jnp.asarray(p * np.array([1.0, -1.0])))
    assert float(jnp.linalg.det(r_m)) == pytest.approx(1.0)


def test_kabsch_rotation_bound_is_the_constrained_optimum():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(30, 2)) * 1000.0
    x = p @ np.asarray(rotation_matrix(np.deg2rad(17.3))).T + np.array([50.0, -20.0])
    x += rng.normal(size=x.shape) * 30.0
    w = rng.uniform(0.5, 2.0, 30)
    bound = np.deg2rad(5.0)
    r, t = kabsch_2d(jnp.asarray(p), jnp.asarray(x), jnp.asarray(w), bound)
    assert float(jnp.arctan2(r[1, 0], r[0, 0])) == pytest.approx(bound, rel=1e-12)

    def cost(theta):  # optimal translation for a fixed angle: the weighted centroids
        rot = np.asarray(rotation_matrix(theta))
        tt = (w @ (x - p @ rot.T)) / w.sum()
        return np.sum(w * np.sum((x - p @ rot.T - tt) ** 2, axis=1)), tt

    thetas = np.linspace(-bound, bound, 2001)
    best = thetas[np.argmin([cost(th)[0] for th in thetas])]
    assert best == pytest.approx(bound)
    np.testing.assert_allclose(t, cost(bound)[1], atol=1e-9)
    # inside the bound nothing changes
    r_free, t_free = kabsch_2d(jnp.asarray(p), jnp.asarray(x), jnp.asarray(w))
    r_wide, t_wide = kabsch_2d(jnp.asarray(p), jnp.asarray(x), jnp.asarray(w), np.deg2rad(30.0))
    np.testing.assert_allclose(r_wide, r_free, atol=1e-14)
    np.testing.assert_allclose(t_wide, t_free, atol=1e-9)


def test_solve3_matches_numpy():
    rng = np.random.default_rng(4)
    a = rng.normal(size=(3, 3))
    a = a @ a.T + np.eye(3)
    b = rng.normal(size=3)
    np.testing.assert_allclose(solve3(jnp.asarray(a), jnp.asarray(b)), np.linalg.solve(a, b),
                               rtol=1e-10)
    assert np.all(np.asarray(solve3(jnp.zeros((3, 3)), jnp.ones(3))) == 0.0)


@pytest.mark.long
def test_patch_coefficients_are_the_bicubic_interpolant(smooth_grid):
    """Value and analytic gradient in local metres = the Grid's bicubic sampler + autodiff."""
    lat_c, lon_c = jnp.asarray(30.0), jnp.asarray(130.0)
    lat, lon = np.full(2, 30.0), np.array([129.99, 130.01])  # a two-point "track" about the centre
    p0, field = local_track_frame(patch_coefficients(smooth_grid.values), smooth_grid,
                                  jnp.asarray(lat), jnp.asarray(lon))
    assert np.abs(np.asarray(p0[:, 0])).max() < 1e-6
    rng = np.random.default_rng(6)
    x = jnp.asarray(rng.uniform(-40e3, 40e3, (200, 2)))
    f, g = jax.jit(value_grad)(field, x)
    sample = make_sampler(smooth_grid, "bicubic")
    m_c, n_c = 1.0 / (field.sy * smooth_grid.dlat), 1.0 / (field.sx * smooth_grid.dlon)
    fn = lambda q: sample(lat_c + q[0] / m_c, lon_c + q[1] / n_c)  # noqa: E731
    np.testing.assert_allclose(f, jax.vmap(fn)(x), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(g, jax.vmap(jax.grad(fn))(x), rtol=1e-9, atol=1e-12)
    # off the map: NaN value, zero gradient
    f_off, g_off = value_grad(field, jnp.array([[1e7, 0.0]]))
    assert np.isnan(float(f_off[0])) and np.all(np.asarray(g_off) == 0.0)
    assert local_field  # the public constructor used by local_track_frame


@pytest.mark.long
def test_least_squares_refinement_and_rotation_bound(smooth_grid):
    lat, lon = _track()
    z = smooth_grid.sample(lat, lon, "bicubic")
    ins_lat, ins_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), 120.0, -90.0,
                                      jnp.deg2rad(1.0))
    p0, field = local_track_frame(patch_coefficients(smooth_grid.values), smooth_grid, ins_lat,
                                  ins_lon)
    bound = jnp.deg2rad(3.0)
    r, t, m = jax.jit(refine_local, static_argnums=6)(field, p0, jnp.asarray(z), jnp.eye(2),
                                                      jnp.zeros(2), bound, 15)
    rot = float(jnp.arctan2(r[1, 0], r[0, 0]))
    res_lat, res_lon = shifted_tracks(ins_lat, ins_lon, t[0], t[1], rot)
    truth = Track(lat, lat, lon, lat, lat)
    assert float(m) < 1e-6
    assert float(track_error_m(res_lat, res_lon, truth)) < 1.0
    # a bound tighter than the true 1° is respected by ICCP and by the refinement
    cfg = IccpConfig(window_m=600.0, max_step_m=300.0, max_rotation_deg=0.4, refine_steps=5)
    res = match_iccp(smooth_grid, ins_lat, ins_lon, z, cfg)
    assert abs(float(res.rotation_deg)) <= 0.4 + 1e-9


# ---------------------------------------------------------------------- ICCP
@pytest.mark.parametrize("d_n,d_e,rot_deg", [(300.0, -200.0, 0.0), (-150.0, 250.0, 1.5)])
@pytest.mark.long
def test_iccp_converges_from_small_offsets(smooth_grid, d_n, d_e, rot_deg):
    lat, lon = _track()
    z = smooth_grid.sample(lat, lon, "bicubic")  # noiseless readings at the truth
    ins_lat, ins_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), d_n, d_e,
                                      jnp.deg2rad(rot_deg))
    truth = Track(lat, lat, lon, lat, lat)
    # ICCP converges linearly: a tight tolerance gives a near-exact answer
    cfg = IccpConfig(window_m=1500.0, max_step_m=500.0, max_iter=200, tol_m=0.01)
    res = match_iccp(smooth_grid, ins_lat, ins_lon, z, cfg)
    assert float(track_error_m(ins_lat, ins_lon, truth)) > 250.0
    assert float(track_error_m(res.lat, res.lon, truth)) < 0.5
    assert abs(float(res.rotation_deg) + rot_deg) < 0.01
    assert int(res.status) == 0  # converged, enough contour points
    # the default tolerance (1 m per iteration) stops within ~10 m
    res = match_iccp(smooth_grid, ins_lat, ins_lon, z, dataclasses.replace(cfg, tol_m=1.0))
    assert float(track_error_m(res.lat, res.lon, truth)) < 10.0
    # a tolerance never met: status bit 16 (same compiled function: tol_m is data)
    res = match_iccp(smooth_grid, ins_lat, ins_lon, z, dataclasses.replace(cfg, tol_m=-1.0))
    assert int(res.status) & 16


@pytest.mark.long
def test_iccp_batch_in_chunks_equals_looped(smooth_grid):
    rng = np.random.default_rng(7)
    lat, lon = _track()
    z0 = np.asarray(smooth_grid.sample(lat, lon, "bicubic"))
    ins_lat, ins_lon, z = [], [], []
    for _ in range(5):  # 5 tracks in chunks of 2: 3 equal chunks, the last one padded
        la, lo = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), *rng.uniform(-300, 300, 2),
                                jnp.deg2rad(rng.uniform(-1.0, 1.0)))
        ins_lat.append(la)
        ins_lon.append(lo)
        z.append(z0 + 0.2 * rng.normal(size=lat.size))
    ins_lat, ins_lon, z = (jnp.asarray(np.stack(a)) for a in (ins_lat, ins_lon, z))
    cfg = IccpConfig(window_m=1500.0, max_step_m=500.0, max_rotation_deg=2.0, contour_tol=1.0)
    batched = match_iccp_batch(smooth_grid, ins_lat, ins_lon, z, cfg, chunk=2)
    assert batched.lat.shape == (5, lat.size)
    for i in range(5):
        one = match_iccp(smooth_grid, ins_lat[i], ins_lon[i], z[i], cfg)
        for a, b in zip(one, batched, strict=True):
            np.testing.assert_allclose(np.asarray(b)[i], np.asarray(a), rtol=1e-9, atol=1e-9)
    with pytest.raises(ValueError, match="chunk"):
        match_iccp_batch(smooth_grid, ins_lat, ins_lon, z, cfg, chunk=0)


ENT = EntropyConfig(spacing_m=200.0, half_size=4)
ICP = IccpConfig(window_m=600.0, max_step_m=300.0, contour_tol=2.0)
# every combined call below shares these static settings and a 20-fix track: one compile


@pytest.mark.long
def test_entropy_coarse_finds_exact_offset(smooth_grid):
    lat, lon = _track()
    # truth = INS shifted by a grid offset: that candidate has ΔH = 0 and zero misfit
    ins_lat, ins_lon = jnp.asarray(lat), jnp.asarray(lon)
    t_lat, t_lon = shifted_tracks(ins_lat, ins_lon, 400.0, -600.0, 0.0)
    z = smooth_grid.sample(t_lat, t_lon, "bicubic")
    res = match_entropy_iccp(smooth_grid, ins_lat, ins_lon, z, ENT, ICP)
    np.testing.assert_allclose(res.topk_lat[0], t_lat, atol=1e-9)  # the coarse stage
    np.testing.assert_allclose(res.topk_lon[0], t_lon, atol=1e-9)
    np.testing.assert_allclose(res.lat, t_lat, atol=1e-6)  # ICCP stays there
    np.testing.assert_allclose(res.lon, t_lon, atol=1e-6)
    assert float(res.topk_score[0]) < 1e-12
    assert int(res.status) & ~16 == 0
    # H_XX needs the shift: the config sets one for a map with negative values
    assert entropy_config_for(smooth_grid, 800.0, kind="information").shift > 0
    assert entropy_config_for(smooth_grid, 800.0).shift == 0


@pytest.mark.long
def test_combined_batched_equals_looped_and_no_retrace(smooth_grid):
    rng = np.random.default_rng(5)
    lat, lon = _track()
    truth_lat, truth_lon, ins_lat, ins_lon, z = [], [], [], [], []
    for _ in range(3):  # truth = a shifted, turned copy of a base track; INS = base
        d_n, d_e = rng.uniform(-700, 700, 2)
        t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), d_n, d_e,
                                      jnp.deg2rad(rng.uniform(-1.5, 1.5)))
        truth_lat.append(t_lat)
        truth_lon.append(t_lon)
        ins_lat.append(lat)
        ins_lon.append(lon)
        z.append(smooth_grid.sample(t_lat, t_lon, "bicubic") + 0.3 * rng.normal(size=lat.size))
    ins_lat, ins_lon, z = (jnp.asarray(np.stack(a)) for a in (ins_lat, ins_lon, z))
    batched = jax.vmap(match_entropy_iccp, in_axes=(None, 0, 0, 0, None, None))(
        smooth_grid, ins_lat, ins_lon, z, ENT, ICP)
    for i in range(3):
        one = match_entropy_iccp(smooth_grid, ins_lat[i], ins_lon[i], z[i], ENT, ICP)
        for a, b in zip(one, batched, strict=True):
            np.testing.assert_allclose(np.asarray(b)[i], np.asarray(a), rtol=1e-9, atol=1e-9)
        truth = Track(truth_lat[i], truth_lat[i], truth_lon[i], truth_lat[i], truth_lat[i])
        # the matcher improves on the INS track
        err = float(track_error_m(one.lat, one.lon, truth))
        assert err < 0.5 * float(track_error_m(ins_lat[i], ins_lon[i], truth))
    # sweeping numbers does not recompile
    size = match_entropy_iccp._cache_size()
    match_entropy_iccp(smooth_grid, ins_lat[0], ins_lon[0], z[0],
                       dataclasses.replace(ENT, spacing_m=120.0, accept_ratio=0.9),
                       dataclasses.replace(ICP, window_m=800.0, tol_m=0.5))
    assert match_entropy_iccp._cache_size() == size


@pytest.mark.long
def test_combined_keeps_coarse_unless_significantly_better(smooth_grid):
    lat, lon = _track()
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), 330.0, -510.0,
                                  jnp.deg2rad(0.5))
    z = smooth_grid.sample(t_lat, t_lon, "bicubic")
    truth = Track(t_lat, t_lat, t_lon, t_lat, t_lat)
    fine = match_entropy_iccp(smooth_grid, lat, lon, z, ENT, ICP)
    assert int(fine.chosen) == 1 and not int(fine.status) & 128
    assert float(fine.score) < float(fine.topk_score[0])
    assert float(track_error_m(fine.lat, fine.lon, truth)) < 20.0
    # the same data with a noise σ so large that no gain is significant: coarse kept
    kept = match_entropy_iccp(smooth_grid, lat, lon, z, ENT, dataclasses.replace(ICP, noise=1e3))
    assert int(kept.chosen) == 0 and int(kept.status) & 128
    np.testing.assert_allclose(kept.lat, kept.topk_lat[0])
    # a fix (here 600 m out) beyond max_offset_m is rejected: status 65536, the INS track
    assert bool(fine.accepted) and not int(fine.status) & FAR_FIX
    far = match_entropy_iccp(smooth_grid, lat, lon, z, ENT,
                             dataclasses.replace(ICP, max_offset_m=400.0))
    assert not bool(far.accepted) and int(far.status) & FAR_FIX
    np.testing.assert_allclose(far.lat, lat)
    cfg = iccp_config_for(smooth_grid, 3000.0, stage="fine")
    assert cfg.max_offset_m == FAR_FIX_RADII * 3000.0
    assert iccp_config_for(smooth_grid, 3000.0).max_offset_m == np.inf  # alone: no test


@pytest.mark.long
def test_match_track_validates_the_contour_methods(smooth_grid):
    lat, lon = _track()
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), -200.0, 400.0, 0.0)
    z = np.asarray(smooth_grid.sample(t_lat, t_lon, "bicubic"))
    res = match_track(smooth_grid, lat, lon, z, method="entropy+iccp", config=(ENT, ICP),
                      warn=False)
    assert float(track_error_m(res.lat, res.lon, Track(t_lat, t_lat, t_lon, t_lat, t_lat))) < 20
    b = dict(method="entropy+iccp")
    with pytest.raises(ValueError, match="method"):
        match_track(smooth_grid, lat, lon, z, method="icp")
    with pytest.raises(ValueError, match="equal lengths"):
        match_track(smooth_grid, lat, lon[:-1], z, **b)
    with pytest.raises(ValueError, match="leaves the map"):
        match_track(smooth_grid, lat + 5.0, lon, z, **b)
    with pytest.raises(ValueError, match="config for method 'entropy\\+iccp' must be a pair"):
        match_track(smooth_grid, lat, lon, z, config=ICP, **b)
    with pytest.raises(ValueError, match="max_rotation_deg bounds ICCP's rotation"):
        match_track(smooth_grid, lat, lon, z, method="dense", max_rotation_deg=2.0)
    with pytest.raises(ValueError, match="estimates no bias"):
        match_track(smooth_grid, lat, lon, z, method="iccp", bias_sigma_mgal=3.0)
    with pytest.raises(ValueError, match="drift_radius_m"):
        iccp_config_for(smooth_grid, -1.0)
    with pytest.raises(ValueError, match="max_iter"):
        IccpConfig(max_iter=0)
    with pytest.raises(ValueError, match="kind"):
        EntropyConfig(kind="shannon")
    with pytest.raises(ValueError, match="noise"):
        match_track(smooth_grid, lat, lon, z, noise=-1.0, **b)
    with pytest.raises(ValueError, match=r"max_rotation_deg .* between 0 and 180; got -2"):
        match_track(smooth_grid, lat, lon, z, max_rotation_deg=-2.0, **b)
    with pytest.raises(ValueError, match="entropy_half_size"):
        match_track(smooth_grid, lat, lon, z, entropy_half_size=0, **b)


# ---------------------------------------------------------------------- entropy alone
def _hcy(h):
    """H_CY of the rows of ``h`` in plain NumPy (paper B's definition)."""
    c = np.abs(h - h.mean(axis=-1, keepdims=True))
    q = c / c.sum(axis=-1, keepdims=True)
    return -np.sum(np.where(q > 0, q * np.log(np.where(q > 0, q, 1.0)), 0.0), axis=-1)


@pytest.mark.parametrize("kind", ["difference", "information"])
def test_match_entropy_finds_the_lattice_offset(smooth_grid, kind):
    lat, lon = _track()
    # truth = INS shifted by an offset of the lattice (200 m spacing), noiseless readings
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), 400.0, -600.0, 0.0)
    z = smooth_grid.sample(t_lat, t_lon, "bicubic")
    shift = entropy_config_for(smooth_grid, 800.0, kind=kind).shift  # > 0 for H_XX here
    cfg = dataclasses.replace(ENT, kind=kind, shift=shift)
    # on the prepared map, as match_track passes it: one compiled matcher for both calls
    res = entropy_mod.match_entropy(prepare_map(smooth_grid), lat, lon, z, cfg)
    np.testing.assert_allclose(res.lat, t_lat, atol=1e-9)
    np.testing.assert_allclose(res.lon, t_lon, atol=1e-9)
    assert float(res.offset_north_m) == pytest.approx(400.0, abs=0.5)
    assert float(res.offset_east_m) == pytest.approx(-600.0, abs=0.5)
    assert float(res.rotation_deg) == 0.0 and float(res.score) < 1e-12
    assert int(res.status) == 0
    # the checked entry point runs the same matcher and warns about nothing
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        via = match_track(smooth_grid, lat, lon, np.asarray(z), method="entropy", config=cfg)
    np.testing.assert_allclose(via.lat, res.lat, atol=0)
    np.testing.assert_allclose(via.lon, res.lon, atol=0)


ENT1 = EntropyConfig(spacing_m=300.0, half_size=1)  # 9 candidates, checked by hand below


def _candidate_values(grid, lat, lon):
    """Map along the INS track shifted by each of ENT1's 9 offsets (north-major), NumPy."""
    offs = [(a * 300.0, b * 300.0) for a in (-1, 0, 1) for b in (-1, 0, 1)]
    vals = [np.asarray(grid.sample(*shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), dn, de,
                                                   0.0), "bicubic")) for dn, de in offs]
    return np.array(offs), np.array(vals)


@pytest.mark.long
def test_entropy_acceptance_test_by_hand(smooth_grid):
    """Paper B's acceptance test: only candidates whose RMS misfit beats the INS track's."""
    lat, lon = _track()
    offs, vals = _candidate_values(smooth_grid, lat, lon)
    ins, a = vals[4], 8  # offset (0, 0) is the INS track; the truth is offset (300, 300)
    # readings = truth + bias b: the truth's ΔH is 0 (H_CY ignores a bias) but its RMS is
    # |b|, while the INS track's is sqrt(b² + 2bm + s) with m, s the mean and mean square
    # of truth − INS: for b·m < −s/2 the truth fails the test and must be passed over
    m, s = np.mean(vals[a] - ins), np.mean((vals[a] - ins) ** 2)
    b = -np.sign(m) * (s / (2 * abs(m)) + 5.0)
    z = vals[a] + b
    rms = np.sqrt(np.mean((z - vals) ** 2, axis=1))
    d_h = np.abs(_hcy(vals) - _hcy(z))
    accepted = rms < rms[4]
    assert not accepted[a] and d_h[a] < 1e-12 and accepted.sum() >= 2
    want = np.flatnonzero(accepted)[np.argmin(d_h[accepted])]  # least |ΔH| among accepted
    res = entropy_mod.match_entropy(smooth_grid, lat, lon, z, ENT1)
    # accepted: no bit 32; bit 8 only because with one offset per side every nonzero one
    # lies on the edge of the search region
    assert int(res.status) == (8 if np.abs(offs[want]).max() >= 300.0 else 0)
    assert float(res.offset_north_m) == pytest.approx(offs[want, 0], abs=0.5)
    assert float(res.offset_east_m) == pytest.approx(offs[want, 1], abs=0.5)
    assert float(res.score) == pytest.approx(d_h[want], rel=1e-9)
    np.testing.assert_allclose(res.topk_score[:accepted.sum()], np.sort(d_h[accepted]), rtol=1e-9)
    assert np.all(np.isinf(np.asarray(res.topk_score[accepted.sum():])))
    # readings = INS track + small noise: no shifted candidate beats the INS misfit, so
    # none is accepted: bit 32, the INS track kept, score = |ΔH| of the INS track.
    # At the default accept_ratio = 1 the zero offset, whose misfit is the INS track's,
    # must not be accepted for beating itself by a rounding error.
    z = ins + 0.5 * np.random.default_rng(0).normal(size=ins.size)
    rms = np.sqrt(np.mean((z - vals) ** 2, axis=1))
    assert np.all(np.delete(rms, 4) > rms[4])
    res = entropy_mod.match_entropy(smooth_grid, lat, lon, z, ENT1)
    assert int(res.status) == 32
    np.testing.assert_array_equal(res.lat, lat)
    np.testing.assert_array_equal(res.lon, lon)
    assert float(res.offset_north_m) == 0.0 and float(res.offset_east_m) == 0.0
    assert float(res.score) == pytest.approx(abs(_hcy(ins) - _hcy(z)), rel=1e-9)
    assert np.all(np.isinf(np.asarray(res.topk_score)))


# ---------------------------------------------------------------------- no retrace
@pytest.mark.long
def test_match_entropy_and_iccp_numbers_do_not_retrace(smooth_grid):
    lat, lon = _track()
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), 150.0, -100.0,
                                  jnp.deg2rad(0.5))
    z = smooth_grid.sample(t_lat, t_lon, "bicubic")
    arr = jnp.asarray
    ent = dataclasses.replace(ENT, spacing_m=arr(200.0), shift=arr(0.0), accept_ratio=arr(1.0))
    first = entropy_mod.match_entropy(smooth_grid, lat, lon, z, ent)
    size = entropy_mod.match_entropy._cache_size()
    # accept_ratio 0: nothing is accepted, so the new value is used, not a stale constant
    swept = entropy_mod.match_entropy(smooth_grid, lat, lon, z, dataclasses.replace(
        ent, spacing_m=arr(150.0), shift=arr(3.0), accept_ratio=arr(0.0)))
    assert entropy_mod.match_entropy._cache_size() == size
    assert not int(first.status) & 32 and int(swept.status) & 32
    icp = IccpConfig(window_m=arr(1500.0), max_step_m=arr(500.0), contour_tol=arr(np.inf),
                     tol_m=arr(1.0), max_rotation_deg=arr(90.0), noise=arr(0.0),
                     accept_chi2=arr(7.81))
    first = match_iccp(smooth_grid, lat, lon, z, icp)
    size = match_iccp._cache_size()
    swept = match_iccp(smooth_grid, lat, lon, z, IccpConfig(
        window_m=arr(800.0), max_step_m=arr(300.0), contour_tol=arr(2.0), tol_m=arr(-1.0),
        max_rotation_deg=arr(0.2), noise=arr(1.0), accept_chi2=arr(3.0)))
    assert match_iccp._cache_size() == size
    assert not int(first.status) & 16 and int(swept.status) & 16  # tol_m < 0: never met
    assert abs(float(swept.rotation_deg)) <= 0.2 + 1e-9 < abs(float(first.rotation_deg))


# ---------------------------------------------------------------------- ICCP, noisy
def test_iccp_converges_with_noisy_readings(smooth_grid):
    lat, lon = _track()
    values = np.asarray(smooth_grid.values)
    sigma = 0.005 * float(values.max() - values.min())  # 0.5 % of the field range, ~0.9 mGal
    truth = Track(lat, lat, lon, lat, lat)
    # the static settings of test_iccp_converges_from_small_offsets: compiled once
    cfg = IccpConfig(window_m=1500.0, max_step_m=500.0, max_iter=200, tol_m=0.02,
                     contour_tol=3.0 * sigma)
    starts = [(300.0, -200.0, 1.0), (-150.0, 250.0, -1.5)]
    err0, err, rot_ratio = [], [], []
    for seed in range(4):
        z = (np.asarray(smooth_grid.sample(lat, lon, "bicubic"))
             + sigma * np.random.default_rng(seed).normal(size=lat.size))
        fixed = []
        for d_n, d_e, rot in starts:
            ins_lat, ins_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), d_n, d_e,
                                              jnp.deg2rad(rot))
            res = match_iccp(smooth_grid, ins_lat, ins_lon, z, cfg)
            assert int(res.status) == 0  # converged (no bit 16), enough contour points
            err0.append(float(track_error_m(ins_lat, ins_lon, truth)))
            err.append(float(track_error_m(res.lat, res.lon, truth)))
            rot_ratio.append(abs(float(res.rotation_deg) + rot) / abs(rot))
            fixed.append(np.stack([np.asarray(res.lat), np.asarray(res.lon)]))
        # both starts reach the same fixed point (noise sets it, not the start): within 2 m
        assert np.abs(fixed[0] - fixed[1]).max() * 111e3 < 2.0
    err0, err = np.array(err0), np.array(err)
    assert err0.min() > 250.0
    assert np.all(err < 0.5 * err0)
    assert np.median(err / err0) < 0.25
    assert np.median(rot_ratio) < 0.5  # the heading error shrinks too


def test_combined_marginalises_a_reading_bias(smooth_grid):
    """Readings with a 4 mGal offset: told ``bias_sigma``, the combined matcher fits the
    truth as well as on bias-free readings and reports the bias; ICCP on the raw
    readings would chase contours 4 mGal off."""
    lat, lon = _track()
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), 350.0, -250.0, 0.0)
    z = np.asarray(smooth_grid.sample(t_lat, t_lon, "bicubic"))
    truth = Track(t_lat, t_lat, t_lon, t_lat, t_lat)
    noise = dataclasses.replace(ICP, noise=0.3, contour_tol=float("inf"))

    def err(readings, iccp):
        res = match_entropy_iccp(smooth_grid, lat, lon, jnp.asarray(readings), ENT, iccp)
        return float(track_error_m(res.lat, res.lon, truth)), float(res.bias)

    clean, _ = err(z, noise)
    told, bias = err(z + 4.0, dataclasses.replace(noise, bias_sigma=float("inf")))
    untold, _ = err(z + 4.0, noise)
    assert told < max(2.0 * clean, 20.0), (clean, told)
    assert abs(bias - 4.0) < 0.3, bias  # 7, 16 and 720 m here
    assert told < untold, (told, untold)
    with pytest.raises(ValueError, match="bias_sigma must be >= 0"):
        IccpConfig(bias_sigma=-1.0)
