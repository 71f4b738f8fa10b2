"""Correlation matcher (paper A): each step against brute force, transformations, accuracy."""

import dataclasses
import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrav as jg
from jaxgrav import sim
from jaxgrav.constants import KNOT
from jaxgrav.match import candidates as cand_mod
from jaxgrav.match import chains
from jaxgrav.match.correlation import ChainConfig, chain_tolerances, match_chains, pair_cost
from jaxgrav.match.dense import (
    DenseConfig,
    lattice_table,
    match_dense,
    shifted_tracks,
)
from jaxgrav.match.dense_batch import match_dense_batch
from jaxgrav.match.scoring import bias_precision, decreasing_weights, score_track

RNG = np.random.default_rng(0)
# the chain steps jitted: one program each instead of hundreds of eagerly dispatched ones
iso_candidates = jax.jit(cand_mod.iso_candidates, static_argnames=("half_size", "capacity"))
eliminate = jax.jit(chains.eliminate)
compact = jax.jit(chains.compact, static_argnums=2)
count_chains = jax.jit(chains.count_chains)
LAT = np.linspace(29, 31, 41)
LON = np.linspace(129, 131, 41)

@pytest.fixture(scope="module")
def rough_grid():
    return jg.Grid.from_arrays(LAT, LON, RNG.normal(size=(41, 41)) * 5)


@pytest.mark.long
def test_scores_by_hand():
    g = jnp.array([1.0, 2.0, 4.0])
    m = jnp.array([[1.0, 2.0, 4.0], [2.0, 3.0, 5.0], [0.0, 2.0, 4.0]])
    w = jnp.ones(3) / 3
    s_abs, _ = score_track(g, m, w, "absolute")
    np.testing.assert_allclose(s_abs, [0.0, 1.0, 1 / 3])
    s_dif, _ = score_track(g, m, w, "difference")
    np.testing.assert_allclose(s_dif, [0.0, 0.0, 0.5])  # a constant shift cancels
    s_b, b = score_track(g, m, w, "bias")
    np.testing.assert_allclose(b, [0.0, -1.0, 1 / 3])
    np.testing.assert_allclose(s_b, [0.0, 0.0, 2 / 9])
    # bias prior: sigma_b -> 0 is the absolute form, sigma_b = inf the bias form
    k0 = bias_precision(w, 1.0, jnp.inf)
    assert k0 == 0.0
    s_hi, _ = score_track(g, m, w, "bias", bias_precision(w, 1.0, 1e-6))
    np.testing.assert_allclose(s_hi, s_abs, rtol=1e-6)
    # NaN map values (off the map) give an infinite score
    s_nan, _ = score_track(g, m.at[1, 0].set(jnp.nan), w, "bias")
    assert np.isinf(s_nan[1]) and np.isfinite(s_nan[0])
    np.testing.assert_allclose(decreasing_weights(4, 0.0), 0.25)
    wd = decreasing_weights(5, 1.0)
    assert np.all(np.diff(wd) < 0) and np.isclose(wd[-1] / wd[0], np.exp(-1))


def _brute_force(cands, steps, tol, g, wd):
    """All complete chains through iso-points, with difference-form scores (NumPy)."""
    cn, ce, cv, cm = (np.asarray(a) for a in (cands.north_m, cands.east_m, cands.value,
                                              cands.mask))
    n = cn.shape[0]
    compat = [np.asarray(chains.compatibility(steps[0][i], steps[1][i], cn[i], ce[i], cn[i + 1],
                                              ce[i + 1], *tol)) for i in range(n - 1)]
    found = []
    for ch in itertools.product(*[np.flatnonzero(cm[i]) for i in range(n)]):
        if all(compat[i][ch[i], ch[i + 1]] for i in range(n - 1)):
            d = np.diff(g) - np.diff([cv[i, ch[i]] for i in range(n)])
            found.append((float(np.sum(np.asarray(wd) * d**2)), ch))
    return sorted(found)


@pytest.mark.long
def test_chain_steps_against_brute_force(rough_grid):
    n = 4
    flat = 30 + np.arange(n) * 0.06
    flon = 130 + np.arange(n) * 0.05
    g = np.asarray(rough_grid.sample(flat + 0.011, flon - 0.013)) + RNG.normal(size=n) * 0.2
    cands = iso_candidates(rough_grid, flat, flon, g, half_size=2, capacity=25, delta=3.0)
    # iso masks: exactly the window nodes within the tolerance
    win = rough_grid.window(flat, flon, 2)
    assert int(cands.mask.sum()) == int(cands.count.sum())
    assert np.all(np.asarray(cands.count) <= 25) and not np.any(cands.overflow)
    for i in range(n):
        vals = np.sort(np.asarray(cands.value[i])[np.asarray(cands.mask[i])])
        assert set(vals) <= set(np.asarray(win.values[i]).ravel())
    steps = cand_mod.local_offsets_m(flat[1:], flon[1:], flat[:-1], flon[:-1])
    tol = (3000.0, 10.0)
    alive = np.asarray(eliminate(cands, steps, *tol))
    w = decreasing_weights(n, 0.5)
    wd = w[:-1] / jnp.sum(w[:-1])
    brute = _brute_force(cands, steps, tol, g, wd)
    assert len(brute) > 10
    on_chain = np.zeros_like(alive)
    for _, ch in brute:
        on_chain[np.arange(n), list(ch)] = True
    np.testing.assert_array_equal(alive, on_chain)  # elimination keeps exactly the chain nodes
    assert float(count_chains(cands, jnp.asarray(alive), steps, *tol)) == len(brute)
    res = chains.kbest_chains(cands, jnp.asarray(alive), steps, *tol, jnp.zeros((n, 25)),
                              pair_cost(jnp.asarray(g), wd), 6)
    np.testing.assert_allclose(res.score, [s for s, _ in brute[:6]], rtol=1e-10)
    np.testing.assert_array_equal(res.index, [c for _, c in brute[:6]])


@pytest.mark.long
def test_kmin_and_overflow_reported(rough_grid):
    x = jnp.array([[3.0, 1.0, 2.0, 0.5]])
    v, i = chains.kmin(x, 2)
    np.testing.assert_array_equal(i, [[3, 1]])
    np.testing.assert_allclose(v, [[0.5, 1.0]])
    c = cand_mod.iso_candidates(rough_grid, np.array([30.0]), np.array([130.0]),
                                np.array([0.0]), half_size=3, capacity=4, delta=100.0)
    assert bool(c.overflow[0]) and int(c.count[0]) == 49 and int(c.mask.sum()) == 4


def _iso_brute_force(grid, lat, lon, g, k, delta, slope_factor):
    """NumPy iso-value rule: per fix, {window node : |g − M| ≤ δ + ¾·f·spread}, where the
    window is the (2k+1)² nodes about the nearest node (shifted inside the map) and
    spread is the largest |change| to a neighbouring node inside the window. Returns
    per fix a dict node (row, col) -> misfit ratio, and the smallest distance of any
    node's |g − M| to its tolerance (to keep float ties out of the comparison)."""
    v = np.asarray(grid.values)
    ny, nx = v.shape
    s = 2 * k + 1
    sets, closest = [], np.inf
    for la, lo, gi in zip(lat, lon, g, strict=True):
        r0 = int(np.clip(np.round((la - float(grid.lat0)) / float(grid.dlat)) - k, 0, ny - s))
        c0 = int(np.clip(np.round((lo - float(grid.lon0)) / float(grid.dlon)) - k, 0, nx - s))
        w = v[r0:r0 + s, c0:c0 + s]
        found = {}
        for a in range(s):
            for b in range(s):
                spread = max(abs(w[a + da, b + db] - w[a, b])
                             for da in (-1, 0, 1) for db in (-1, 0, 1)
                             if 0 <= a + da < s and 0 <= b + db < s)
                tol = delta + 0.75 * slope_factor * spread
                closest = min(closest, abs(abs(gi - w[a, b]) - tol))
                if abs(gi - w[a, b]) <= tol:
                    found[(r0 + a, c0 + b)] = abs(gi - w[a, b]) / tol
        sets.append(found)
    return sets, closest


@pytest.mark.parametrize(("slope_factor", "delta", "small_cap"), [(0.0, 6.0, 9), (1.0, 1.0, 20)])
@pytest.mark.long
def test_iso_masks_equal_the_rule_by_brute_force(smooth_grid, slope_factor, delta, small_cap):
    """Candidates are exactly the window nodes within δ (+ the node allowance); with too
    small a capacity the count and overflow are still right and the best fits are kept."""
    grid, k = smooth_grid, 3
    # fixes inside the map and two near its corners (windows shifted inside)
    lat = np.array([30.013, 29.9, 30.21, 29.503, 30.49])
    lon = np.array([130.021, 130.3, 129.77, 129.52, 130.49])
    rng = np.random.default_rng(0)
    g = np.asarray(grid.sample(lat + 0.004, lon - 0.006)) + rng.normal(size=5)
    brute, closest = _iso_brute_force(grid, lat, lon, g, k, delta, slope_factor)
    assert closest > 1e-9  # no node within float rounding of its tolerance
    counts = np.array([len(b) for b in brute])
    assert counts.min() < small_cap < counts.max()  # some windows overflow, some do not

    def nodes(c, i):
        m = np.asarray(c.mask[i])
        rows = np.round((np.asarray(c.lat[i])[m] - float(grid.lat0)) / float(grid.dlat))
        cols = np.round((np.asarray(c.lon[i])[m] - float(grid.lon0)) / float(grid.dlon))
        return [(int(r), int(q)) for r, q in zip(rows, cols, strict=True)]

    v = np.asarray(grid.values)
    for cap in (49, small_cap):
        c = iso_candidates(grid, lat, lon, g, half_size=k, capacity=cap, delta=delta,
                           slope_factor=slope_factor)
        np.testing.assert_array_equal(c.count, counts)
        np.testing.assert_array_equal(c.overflow, counts > cap)
        np.testing.assert_array_equal(np.asarray(c.mask).sum(axis=1), np.minimum(counts, cap))
        np.testing.assert_array_equal(c.window_complete, [True, True, True, False, False])
        for i in range(5):
            got = nodes(c, i)
            assert len(set(got)) == len(got)
            np.testing.assert_allclose(np.asarray(c.value[i])[np.asarray(c.mask[i])],
                                       [v[n] for n in got])
            if cap == 49:
                assert set(got) == set(brute[i])
            else:  # the `cap` best-fitting nodes (ranked in float32: allow its resolution)
                assert set(got) <= set(brute[i])
                rest = [brute[i][n] for n in brute[i] if n not in got]
                if rest:
                    assert max(brute[i][n] for n in got) <= min(rest) * (1 + 1e-6)


def _angle_between(an, ae, bn, be):
    return np.abs(np.arctan2(an * be - ae * bn, an * bn + ae * be))


@pytest.mark.parametrize("short_step", [False, True])
def test_compatibility_against_sqrt_and_arctan2(short_step):
    """Step constraints by their definition: | |s| − |d| | ≤ tol and the angle between
    s and the INS step d ≤ angle_tol + asin(tol/|d|) (any angle when |d| ≤ tol)."""
    rng = np.random.default_rng(1)
    tol, ang = 300.0, 3.0
    checked = 0
    for _ in range(6):
        d_len = rng.uniform(50.0, 280.0) if short_step else rng.uniform(400.0, 2000.0)
        heading = rng.uniform(0, 2 * np.pi)
        dn, de = d_len * np.cos(heading), d_len * np.sin(heading)
        n0, e0, n1, e1 = rng.uniform(-2 * tol, 2 * tol, size=(4, 40))
        got = np.asarray(chains.compatibility(dn, de, n0, e0, n1, e1, tol, ang))
        sn = dn + n1[None, :] - n0[:, None]
        se = de + e1[None, :] - e0[:, None]
        length_err = np.abs(np.sqrt(sn**2 + se**2) - d_len) - tol
        turn = _angle_between(sn, se, dn, de)
        max_turn = np.pi if d_len <= tol else np.deg2rad(ang) + np.arcsin(tol / d_len)
        want = (length_err <= 0) & (turn <= max_turn)
        clear = (np.abs(length_err) > 1e-6) & (np.abs(turn - max_turn) > 1e-9)
        assert want[clear].any() and (~want[clear]).any()
        np.testing.assert_array_equal(got[clear], want[clear])
        checked += int(clear.sum())
    assert checked > 0.99 * 6 * 40 * 40


def _scenario(key, grid, n, dt, drift_m, noise, method="bilinear"):
    k1, k2, k3 = jax.random.split(key, 3)
    w, e, s, nn = grid.extent
    lat0, lon0 = sim.random_start(k1, (s, nn, w, e), (0.1, 0.3, 0.1, 0.3))
    tr = sim.straight_track(lat0, lon0, 10 * KNOT, 10 * KNOT, n, dt)
    dn, de = sim.drift_offsets(sim.sample_drift(k2, drift_m, law="fixed"), n)
    ilat, ilon = sim.apply_drift(tr.lat, tr.lon, dn, de)
    g = sim.gravity_readings(k3, grid, tr, noise_mgal=noise, eotvos_form=None, method=method)
    return tr, ilat, ilon, g


@pytest.mark.parametrize(("strict", "dt"), [(False, 300.0), (True, 300.0), (False, 60.0)])
@pytest.mark.long
def test_elimination_never_removes_true_chain_noiseless(smooth_grid, strict, dt):
    """Exact readings at off-node positions: the true chain (node nearest the truth at
    every fix) is a complete chain under the library's tolerances and survives.

    ``strict=False`` uses ChainConfig's defaults; ``strict=True`` leaves only the node
    allowance (δ ≈ 0, 1 m step tolerance for the local-metre geometry, no angle
    tolerance), so it is that allowance alone that keeps the truth. ``dt=300`` gives
    INS steps (2.2 km) longer than the step tolerance (the paper's regime), ``dt=60``
    shorter ones (0.44 km, less than the 1.5 km node diagonal), where every direction
    must be accepted."""
    fine = smooth_grid
    cfg = ChainConfig(half_size=8, capacity=17 * 17)  # capacity = window: no overflow
    if strict:
        cfg = dataclasses.replace(cfg, delta=1e-9, step_tol_m=1.0, angle_tol_deg=0.0)

    def one(key):
        tr, ilat, ilon, g = _scenario(key, fine, 8, dt, 700.0, 0.0)
        cands = cand_mod.iso_candidates(fine, ilat, ilon, g, half_size=cfg.half_size,
                                        capacity=cfg.capacity, delta=cfg.delta,
                                        slope_factor=cfg.node_allowance)
        steps = cand_mod.local_offsets_m(ilat[1:], ilon[1:], ilat[:-1], ilon[:-1])
        tol = chain_tolerances(fine, ilat, cfg)
        alive = chains.eliminate(cands, steps, *tol)
        compat = chains.step_compatibility(cands, steps, *tol)
        # node nearest each true position, and its slot in the candidate set
        r = jnp.round((tr.lat - fine.lat0) / fine.dlat)
        c = jnp.round((tr.lon - fine.lon0) / fine.dlon)
        hit = cands.mask & (jnp.abs(cands.lat - (fine.lat0 + r[:, None] * fine.dlat)) < 1e-9) & (
            jnp.abs(cands.lon - (fine.lon0 + c[:, None] * fine.dlon)) < 1e-9)
        slot = jnp.argmax(hit, axis=1)
        i = jnp.arange(8)
        off_node = jnp.hypot(*cand_mod.local_offsets_m(
            tr.lat, tr.lon, fine.lat0 + r * fine.dlat, fine.lon0 + c * fine.dlon))
        return dict(is_iso=jnp.any(hit, axis=1), alive=alive[i, slot],
                    compatible=compat[i[:-1], slot[:-1], slot[1:]],
                    overflow=jnp.any(cands.overflow), complete=jnp.all(cands.window_complete),
                    off_node_m=jnp.max(off_node), ins_step_m=jnp.min(jnp.hypot(*steps)),
                    tol_m=tol[0])

    keys = jax.random.split(jax.random.key(3), 24)
    out = {k: np.asarray(v) for k, v in jax.jit(jax.vmap(one))(keys).items()}
    assert not out["overflow"].any() and out["complete"].all()
    assert np.median(out["off_node_m"]) > 200.0  # the truth is really off the nodes
    assert np.all(out["ins_step_m"] > out["tol_m"]) == (dt == 300.0)
    assert out["is_iso"].all()  # every true node passes its iso-value mask
    assert out["compatible"].all()  # every true step passes the constraints
    assert out["alive"].all()  # and elimination keeps the whole chain


@pytest.mark.long
def test_match_chains_recovers_a_node_track_and_reports_work(smooth_grid):
    """Truth on map nodes, exact readings: the true chain scores zero and is returned."""
    i = np.arange(10)
    t_lat = smooth_grid.lat[20 + 3 * i]
    t_lon = smooth_grid.lon[30 + 2 * i]
    g = np.asarray(smooth_grid.values)[20 + 3 * i, 30 + 2 * i]
    ilat, ilon = t_lat + 0.0263, t_lon - 0.0242  # INS drift of about 3.7 km
    for score in ("difference", "bias", "absolute"):
        cfg = ChainConfig(delta=0.05, half_size=4, capacity=81, score=score, selection="best")
        r = match_chains(smooth_grid, ilat, ilon, g, cfg)
        assert int(r.status) & 1 == 0
        np.testing.assert_allclose(r.lat, t_lat, atol=1e-9)
        np.testing.assert_allclose(r.lon, t_lon, atol=1e-9)
        np.testing.assert_allclose(r.score, 0.0, atol=1e-12)
    assert r.topk_lat.shape == (5, 10) and np.all(np.diff(np.asarray(r.topk_score)) >= 0)
    assert float(r.work_unconstrained) >= float(r.work_constrained) >= 1
    assert float(r.work_unconstrained) == np.prod(np.asarray(r.n_candidates, float))
    np.testing.assert_allclose(r.offset_north_m, -0.0263 * 110.85e3, rtol=2e-3)


@pytest.mark.parametrize("score", ["bias", "difference", "absolute"])
@pytest.mark.long
def test_match_dense_recovers_offset(smooth_grid, score):
    tr, ilat, ilon, g = _scenario(jax.random.key(7), smooth_grid, 12, 60.0, 1500.0, 0.0,
                                  "bicubic")
    cfg = DenseConfig(spacing_m=400.0, half_size=5, score=score, method="bicubic",
                      score_model="white")
    r = match_dense(smooth_grid, ilat, ilon, g, cfg)
    err = np.hypot(*cand_mod.local_offsets_m(r.lat, r.lon, tr.lat, tr.lon))
    assert int(r.status) == 0
    assert np.mean(err) < 5.0, np.mean(err)  # exact up to the refinement's convergence


@pytest.mark.long
def test_match_dense_exact_on_bicubic_truth_and_rotation(smooth_grid):
    key = jax.random.key(11)
    tr = sim.straight_track(29.8, 129.8, 6.0, 4.0, 15, 60.0)
    # INS track: the truth turned by 1.5 degrees about its centroid and shifted
    ilat, ilon = shifted_tracks(tr.lat, tr.lon, 900.0, -1200.0, jnp.deg2rad(1.5))
    g = smooth_grid.sample(tr.lat, tr.lon, "bicubic") + 3.0
    del key
    cfg = DenseConfig(spacing_m=300.0, half_size=6, n_rotations=5, max_rotation_deg=2.0,
                      refine_steps=12, score_model="white")
    r = match_dense(smooth_grid, ilat, ilon, g, cfg)
    err = np.hypot(*cand_mod.local_offsets_m(r.lat, r.lon, tr.lat, tr.lon))
    assert np.max(err) < 5.0, err
    np.testing.assert_allclose(r.bias, 3.0, atol=1e-3)


@pytest.mark.parametrize("score", ["bias", "difference"])
@pytest.mark.long
def test_dense_grid_search_paths_agree(smooth_grid, score):
    """Separable lattice (small block, large block) and point-by-point sampling agree."""
    _, ilat, ilon, g = _scenario(jax.random.key(5), smooth_grid, 12, 60.0, 600.0, 0.5,
                                  "bicubic")
    # the offsets span 2*6*150 m = 1.8 km, 1.6-1.9 cells of this 0.01 degree map
    base = DenseConfig(spacing_m=150.0, half_size=6, n_rotations=3, score=score,
                       selection="nearest", bias_sigma_mgal=4.0, score_model="white")
    table = lattice_table(smooth_grid)
    runs = {block: match_dense(smooth_grid, ilat, ilon, g,
                               dataclasses.replace(base, lattice_block=block), table)
            for block in (6, 3, 0)}  # fits the small block; needs the large one; points
    ref = runs[0]
    for block in (6, 3):
        r = runs[block]
        assert int(r.chosen) == int(ref.chosen)
        np.testing.assert_allclose(r.topk_score, ref.topk_score, rtol=1e-9)
        np.testing.assert_allclose(r.topk_lat, ref.topk_lat, rtol=0, atol=1e-12)
        np.testing.assert_allclose(r.lat, ref.lat, rtol=0, atol=1e-9)
        np.testing.assert_allclose(r.score, ref.score, rtol=1e-7)
    if score == "bias":  # the prepared table is what match_dense computes when none is given
        np.testing.assert_allclose(match_dense(smooth_grid, ilat, ilon, g, base).lat, ref.lat,
                                   atol=1e-9)
    with pytest.raises(ValueError, match="prepared must have shape"):
        match_dense(smooth_grid, ilat, ilon, g, base, table[:-2])


@pytest.mark.long
def test_jit_no_retrace_and_vmap_equals_loop(smooth_grid):
    # the sizes and config of test_match_dense_recovers_offset[bias]: its compiled matcher
    keys = jax.random.split(jax.random.key(2), 4)
    data = [_scenario(k, smooth_grid, 12, 60.0, 800.0, 0.5)[1:] for k in keys]
    cfg = DenseConfig(spacing_m=400.0, half_size=5, score_model="white")
    match_dense(smooth_grid, *data[0], cfg)
    size = match_dense._cache_size()
    match_dense(smooth_grid, *data[1], DenseConfig(spacing_m=350.0, half_size=5, noise_mgal=2.0,
                                                     score_model="white"))
    assert match_dense._cache_size() == size  # new numbers in the config do not recompile
    lat, lon, g = (jnp.stack(x) for x in zip(*data, strict=True))
    batched = jax.vmap(match_dense, in_axes=(None, 0, 0, 0, None))(smooth_grid, lat, lon, g, cfg)
    for i in range(4):
        one = match_dense(smooth_grid, lat[i], lon[i], g[i], cfg)
        np.testing.assert_allclose(batched.lat[i], one.lat, atol=1e-9)
        np.testing.assert_allclose(batched.score[i], one.score, rtol=1e-8)
    chunked = match_dense_batch(smooth_grid, lat, lon, g, cfg, chunk=3)  # 3 + a remainder of 1
    np.testing.assert_allclose(chunked.lat, batched.lat, atol=1e-9)
    np.testing.assert_allclose(chunked.score, batched.score, rtol=1e-8)
    np.testing.assert_array_equal(chunked.chosen, batched.chosen)
    np.testing.assert_allclose(chunked.topk_score, batched.topk_score, rtol=1e-10)
    # chains on the first 10 fixes with the static settings of the node-track test's
    # difference run (its compiled matcher)
    cc = ChainConfig(half_size=4, capacity=81, delta=2.0, selection="best")
    lat, lon, g = lat[:, :10], lon[:, :10], g[:, :10]
    bc = jax.vmap(match_chains, in_axes=(None, 0, 0, 0, None))(smooth_grid, lat, lon, g, cc)
    for i in range(4):
        one = match_chains(smooth_grid, lat[i], lon[i], g[i], cc)
        np.testing.assert_array_equal(bc.lat[i], one.lat)
        np.testing.assert_array_equal(bc.status[i], one.status)


@pytest.mark.long
def test_match_chains_no_retrace_when_tolerances_change(smooth_grid):
    """δ, the node allowance, step/angle tolerances and the weight decay are pytree
    leaves: new values (and a new track) reuse the compiled matcher."""
    traces = []

    def f(grid, lat, lon, g, cfg):
        traces.append(1)
        return match_chains(grid, lat, lon, g, cfg)

    f = jax.jit(f)
    a = jnp.asarray
    data = [_scenario(k, smooth_grid, 8, 120.0, 600.0, 0.3)[1:]
            for k in jax.random.split(jax.random.key(4), 2)]
    cfg1 = ChainConfig(delta=a(1.0), node_allowance=a(1.0), step_tol_m=a(100.0),
                       angle_tol_deg=a(2.0), weight_decay=a(0.5), half_size=4, capacity=81)
    cfg2 = ChainConfig(delta=a(3.0), node_allowance=a(0.5), step_tol_m=a(250.0),
                       angle_tol_deg=a(5.0), weight_decay=a(0.0), half_size=4, capacity=81)
    r1 = f(smooth_grid, *data[0], cfg1)
    r2 = f(smooth_grid, *data[0], cfg2)
    r3 = f(smooth_grid, *data[1], cfg1)
    assert len(traces) == 1
    # the new numbers did take effect (they were not baked in as constants)
    assert not np.array_equal(r2.n_candidates, r1.n_candidates)
    assert float(r2.work_constrained) != float(r1.work_constrained)
    assert int(r1.status) & 1 == 0 and int(r3.status) & 1 == 0


@pytest.mark.long
def test_chain_survivor_compaction(smooth_grid):
    """Compacting survivors changes nothing but the work; too few slots raise overflow."""
    keys = jax.random.split(jax.random.key(9), 3)
    data = [_scenario(k, smooth_grid, 6, 60.0, 500.0, 0.3)[1:] for k in keys]
    lat, lon, g = (jnp.stack(x) for x in zip(*data, strict=True))
    base = ChainConfig(half_size=4, capacity=81, delta=1.5, k_dp=8)
    run = jax.jit(jax.vmap(match_chains, in_axes=(None, 0, 0, 0, None)))
    full = run(smooth_grid, lat, lon, g, base)
    alive = jax.jit(jax.vmap(lambda a, b, c: jnp.sum(chains.eliminate(
        cand_mod.iso_candidates(smooth_grid, a, b, c, half_size=4, capacity=81, delta=1.5),
        cand_mod.local_offsets_m(a[1:], b[1:], a[:-1], b[:-1]),
        base.step_tol_m + jnp.hypot(*smooth_grid.spacing_m(jnp.mean(a))),
        base.angle_tol_deg), axis=1)))(lat, lon, g)
    most = int(jnp.max(alive))
    assert 3 < most < 81
    assert not np.any(np.asarray(full.status) & 2)
    comp = run(smooth_grid, lat, lon, g, dataclasses.replace(base, survivor_capacity=most))
    for name in ("lat", "lon", "score", "topk_score", "topk_lat", "topk_lon", "chosen",
                 "status", "work_constrained", "work_pairs", "n_candidates"):
        np.testing.assert_array_equal(getattr(comp, name), getattr(full, name), err_msg=name)
    # fewer slots than survivors (and than k_dp): flagged, still a valid result
    tight = run(smooth_grid, lat, lon, g, dataclasses.replace(base, survivor_capacity=3))
    over = np.asarray(jnp.max(alive, axis=1)) > 3
    np.testing.assert_array_equal((np.asarray(tight.status) & 2) > 0, over)
    assert np.all(np.isfinite(np.asarray(tight.topk_score)[:, 0]) | (np.asarray(tight.status) & 1))
    with pytest.raises(ValueError, match="survivor_capacity"):
        ChainConfig(survivor_capacity=-1)


@pytest.mark.long
def test_compact_and_small_capacity_kbest(rough_grid):
    """compact keeps survivors in slot order; the k-best programme with fewer slots than
    k equals brute force."""
    n = 3
    flat = 30 + np.arange(n) * 0.06
    flon = 130 + np.arange(n) * 0.05
    g = np.asarray(rough_grid.sample(flat + 0.011, flon - 0.013))
    cands = iso_candidates(rough_grid, flat, flon, g, half_size=2, capacity=25, delta=2.0)
    steps = cand_mod.local_offsets_m(flat[1:], flon[1:], flat[:-1], flon[:-1])
    tol = (3000.0, 10.0)
    alive = eliminate(cands, steps, *tol)
    n_alive = np.asarray(alive.sum(axis=1))
    cap = int(n_alive.max())
    small, lost = compact(cands, alive, cap)
    assert not np.any(lost)
    for i in range(n):
        keep = np.flatnonzero(np.asarray(alive[i]))
        np.testing.assert_array_equal(np.asarray(small.value[i])[:keep.size],
                                      np.asarray(cands.value[i])[keep])
        np.testing.assert_array_equal(np.asarray(small.mask[i]), np.arange(cap) < keep.size)
    np.testing.assert_array_equal(eliminate(small, steps, *tol), small.mask)
    w = decreasing_weights(n, 0.5)
    wd = w[:-1] / jnp.sum(w[:-1])
    brute = _brute_force(small, steps, tol, g, wd)
    k = cap + 3  # more chains than slots per fix
    res = chains.kbest_chains(small, small.mask, steps, *tol, jnp.zeros((n, cap)),
                              pair_cost(jnp.asarray(g), wd), k)
    m = min(k, len(brute))
    np.testing.assert_allclose(res.score[:m], [s for s, _ in brute[:m]], rtol=1e-10)
    assert np.all(np.isinf(np.asarray(res.score[m:])))
    _, lost = compact(cands, alive, 1)
    np.testing.assert_array_equal(lost, n_alive > 1)


@pytest.mark.long
def test_no_chain_returns_ins_with_status(rough_grid):
    lat = 30 + np.arange(5) * 0.05
    lon = 130 + np.arange(5) * 0.05
    r = match_chains(rough_grid, lat, lon, np.full(5, 1e4), ChainConfig(half_size=2, capacity=25))
    assert int(r.status) & 1
    np.testing.assert_allclose(r.lat, lat)
    assert np.isinf(r.score)


@pytest.mark.long
def test_grad_of_score_through_the_map(smooth_grid):
    """The dense score is differentiable in the offset (used by the refinement)."""
    tr = sim.straight_track(29.8, 129.8, 6.0, 4.0, 10, 60.0)
    g = smooth_grid.sample(tr.lat, tr.lon, "bicubic")
    w = decreasing_weights(10, 0.0)

    @jax.jit  # one program, not hundreds of eagerly dispatched ones
    def s(dn):
        la, lo = shifted_tracks(tr.lat, tr.lon, dn, 0.0, 0.0)
        return score_track(g, smooth_grid.sample(la, lo, "bicubic"), w, "bias")[0]

    x0 = 120.0
    fd = (s(x0 + 0.01) - s(x0 - 0.01)) / 0.02
    np.testing.assert_allclose(jax.grad(s)(x0), fd, rtol=1e-5)
    np.testing.assert_allclose(jax.jacfwd(s)(x0), jax.grad(s)(x0), rtol=1e-10)
