"""How much faster is jaxgrav's batched ICCP than a NumPy ICCP loop?

Tracks of paper B's experiment (60 fixes a minute apart at 10 m/s, INS offset
0.02–0.03° and rotated 1.5° about its start, 1 mGal noise) on the shipped 2.5′
``ryukyu`` gravity map are matched by ICCP alone (window covering the drift):
one track by ``match_iccp``, batches of 1000 tracks (256 with ``--quick``) by the
library's batch matcher ``match_iccp_batch`` (chunks of 100 tracks) and, for
reference, by one ``jit(vmap(match_iccp))`` over the whole batch (case ``-vmap``).

The baseline is the plain NumPy way, one track at a time: a Python loop over
iterations (stopping early at convergence; the batched loop runs until every track
of the batch has converged or ``max_iter``), the same bicubic interpolant
(jaxgrav's spline coefficients evaluated by a NumPy Hermite formula with its analytic
gradient), the same Newton projection onto each contour, window and contour tests,
and the Kabsch transform by ``numpy.linalg.svd`` (its angle limited to the INS
heading-error bound, 2°, as jaxgrav's). The loop's time is linear in the number of
tracks, so it is timed on a subset and scaled to the batch (``baseline_tracks`` says how many);
``max_offset_diff_m`` compares its answers with jaxgrav's on that subset.

The machine is shared, so timing is done in ``rounds`` (5; 2 with ``--quick``): each
round times the baseline and every jaxgrav case back to back. ``ratio`` is the best
baseline time over the best jaxgrav time; ``ratio_per_round`` shows the spread.
"""

import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import best_time, emit, parse_args

jax.config.update("jax_enable_x64", True)  # a script, not the library: float64 cases need it

from jaxgrav import datasets, interp  # noqa: E402
from jaxgrav.constants import DEG  # noqa: E402
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius  # noqa: E402
from jaxgrav.grid import Grid  # noqa: E402
from jaxgrav.match.iccp import match_iccp, match_iccp_batch  # noqa: E402
from jaxgrav.match.sizing import iccp_config_for  # noqa: E402
from jaxgrav.scenarios.paper_b import PaperBScenario, paper_b_scenario  # noqa: E402
from jaxgrav.sim import DEG_ARC_M  # noqa: E402


# ---------------------------------------------------------------- NumPy baseline
def _hermite(t):
    t2, t3 = t * t, t * t * t
    h = (2 * t3 - 3 * t2 + 1, -2 * t3 + 3 * t2, t3 - 2 * t2 + t, t3 - t2)
    dh = (6 * t2 - 6 * t, -6 * t2 + 6 * t, 3 * t2 - 4 * t + 1, 3 * t2 - 2 * t)
    return h, dh


def np_bicubic(coef, iy, ix):
    """Value and (d/diy, d/dix) of jaxgrav's bicubic interpolant; NaN off the grid.

    Vectorised over points and over the 4 corners × 4 coefficients of each cell.
    """
    ny, nx = coef.shape[:2]
    inside = (iy >= 0) & (iy <= ny - 1) & (ix >= 0) & (ix <= nx - 1)
    iy_c = np.clip(np.nan_to_num(iy), 0, ny - 1)
    ix_c = np.clip(np.nan_to_num(ix), 0, nx - 1)
    r0 = np.minimum(np.floor(iy_c).astype(int), ny - 2)
    c0 = np.minimum(np.floor(ix_c).astype(int), nx - 2)
    (hy0, hy1, gy0, gy1), (dhy0, dhy1, dgy0, dgy1) = _hermite(iy_c - r0)
    (hx0, hx1, gx0, gx1), (dhx0, dhx1, dgx0, dgx1) = _hermite(ix_c - c0)
    k = coef[r0[:, None, None] + _01[:, None], c0[:, None, None] + _01[None, :]]  # (N,2,2,4)
    k = k.reshape(-1, 2, 2, 2, 2)  # [point, row, col, y-kind (value/slope), x-kind]
    by = np.stack([np.stack([hy0, gy0], -1), np.stack([hy1, gy1], -1)], 1)  # (N, row, kind)
    bx = np.stack([np.stack([hx0, gx0], -1), np.stack([hx1, gx1], -1)], 1)
    dby = np.stack([np.stack([dhy0, dgy0], -1), np.stack([dhy1, dgy1], -1)], 1)
    dbx = np.stack([np.stack([dhx0, dgx0], -1), np.stack([dhx1, dgx1], -1)], 1)
    f = np.einsum("nrcyx,nry,ncx->n", k, by, bx)
    fy = np.einsum("nrcyx,nry,ncx->n", k, dby, bx)
    fx = np.einsum("nrcyx,nry,ncx->n", k, by, dbx)
    nan = np.where(inside, 1.0, np.nan)
    return f * nan, fy * nan, fx * nan


_01 = np.arange(2)


def np_iccp(coef, grid, lat, lon, z, cfg):
    """One track's ICCP in NumPy; returns (translation (2,), rotation_rad)."""
    lat_c, lon_c = lat.mean(), lon.mean()
    m_c = float(meridian_radius(lat_c)) * DEG
    n_c = float(prime_vertical_radius(lat_c)) * np.cos(lat_c * DEG) * DEG
    p0 = np.stack([(lat - lat_c) * m_c, (lon - lon_c) * n_c], axis=-1)
    to_iy = lambda x: (lat_c + x[:, 0] / m_c - grid.lat0) / grid.dlat  # noqa: E731
    to_ix = lambda x: (lon_c + x[:, 1] / n_c - grid.lon0) / grid.dlon  # noqa: E731
    sy, sx = 1.0 / (m_c * grid.dlat), 1.0 / (n_c * grid.dlon)
    r, t = np.eye(2), np.zeros(2)
    bound = np.deg2rad(cfg.max_rotation_deg)
    for _ in range(cfg.max_iter):
        y = p0 @ r.T + t
        x = y.copy()
        for _ in range(cfg.newton_steps):
            f, fy, fx = np_bicubic(coef, to_iy(x), to_ix(x))
            g = np.stack([fy * sy, fx * sx], axis=-1)
            g2 = np.sum(g * g, axis=-1)
            ok = np.isfinite(f) & (g2 > 0)
            d = -np.where(ok, f - z, 0.0)[:, None] * g / np.where(ok, g2, 1.0)[:, None]
            length = np.linalg.norm(d, axis=-1)
            scale = np.minimum(1.0, cfg.max_step_m / np.where(length > 0, length, 1.0))
            x = x + d * scale[:, None]
        f, _, _ = np_bicubic(coef, to_iy(x), to_ix(x))
        ok = (np.isfinite(f) & (np.abs(f - z) <= cfg.contour_tol)
              & (np.linalg.norm(x - y, axis=-1) <= cfg.window_m))
        if ok.sum() < 3:
            continue
        w = ok / ok.sum()
        pc, xc = w @ p0, w @ x
        h = (p0 - pc).T @ ((x - xc) * w[:, None])
        u, _, vt = np.linalg.svd(h)
        d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
        r_new = vt.T @ np.diag([1.0, d]) @ u.T
        theta = np.arctan2(r_new[1, 0], r_new[0, 0])
        if abs(theta) > bound:  # the heading-error bound: the nearest bound is optimal
            c, s = np.cos(bound), np.copysign(np.sin(bound), theta)
            r_new = np.array([[c, -s], [s, c]])
        t_new = xc - r_new @ pc
        move = np.max(np.linalg.norm(p0 @ r_new.T + t_new - y, axis=-1))
        r, t = r_new, t_new
        if move <= cfg.tol_m:
            break
    return t, np.arctan2(r[1, 0], r[0, 0])


# ---------------------------------------------------------------- benchmark
def main():
    args = parse_args(__doc__)
    batches = (1, 256) if args.quick else (1, 1000)
    dtypes = (np.float32,) if args.quick else (np.float32, np.float64)
    rounds = 2 if args.quick else 5
    n_base = 16 if args.quick else 50
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    grid64 = Grid(jnp.asarray(grid.values, jnp.float64), grid.lat0, grid.dlat, grid.lon0,
                  grid.dlon)
    w, e, s, n = grid.extent
    scen = PaperBScenario(region=(s, n, w, e))
    cfg = iccp_config_for(grid, 0.035 * DEG_ARC_M, stage="alone", noise=1.0,
                          max_rotation_deg=scen.rotation_deg + 0.5)
    keys = jax.random.split(jax.random.key(0), max(batches))
    runs = jax.jit(jax.vmap(paper_b_scenario, in_axes=(0, None, None)))(keys, grid64, scen)
    lat, lon, z = (np.asarray(a, np.float64) for a in (runs.ins_lat, runs.ins_lon, runs.readings))
    coef = np.asarray(interp.bicubic_coefficients(grid64.values))

    def baseline():
        return [np_iccp(coef, grid64, lat[i], lon[i], z[i], cfg) for i in range(n_base)]

    # compile every case first
    cases = []
    for dtype in dtypes:
        g = Grid(jnp.asarray(grid.values, dtype), grid.lat0, grid.dlat, grid.lon0, grid.dlon)
        fv = jax.jit(jax.vmap(match_iccp, in_axes=(None, 0, 0, 0, None)))
        f1 = jax.jit(match_iccp)
        for b in batches:
            la, lo, zz = (jnp.asarray(a[:b], dtype) for a in (lat, lon, z))
            if b == 1:
                calls = {"": lambda f1=f1, a=(g, la[0], lo[0], zz[0], cfg): f1(*a)}
            else:
                calls = {"": lambda a=(g, la, lo, zz, cfg): match_iccp_batch(*a),
                         "-vmap": lambda fv=fv, a=(g, la, lo, zz, cfg): fv(*a)}
            for suffix, call in calls.items():
                t0 = time.perf_counter()
                out = jax.block_until_ready(call())
                cases.append((dtype, b, suffix, call, out, time.perf_counter() - t0, []))

    # timing rounds, interleaved: on a shared machine the load changes between rounds,
    # so each round times the baseline and every case back to back
    base_times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        base = baseline()
        base_times.append((time.perf_counter() - t0) / n_base)
        for *_, call, _, _, times in cases:
            times.append(best_time(lambda call=call: jax.block_until_ready(call()), 2))
    per_track = min(base_times)

    for dtype, b, suffix, _, out, compile_s, times in cases:
        t = min(times)
        m = min(b, n_base)
        rot = np.atleast_1d(np.asarray(out.rotation_deg, np.float64))[:m]
        dn = np.atleast_1d(np.asarray(out.offset_north_m, np.float64))[:m]
        # the NumPy loop's translation (about the centroid) vs jaxgrav's mean offset
        d_rot = max(abs(np.rad2deg(base[i][1]) - rot[i]) for i in range(m))
        d_off = max(abs(base[i][0][0] - dn[i]) for i in range(m))
        per_round = [bt * b / jt for bt, jt in zip(base_times, times, strict=True)]
        emit(
            "match_iccp",
            f"batch{b}-{np.dtype(dtype).name}{suffix}",
            b,
            t,
            "numpy ICCP loop (numpy.linalg.svd Kabsch)",
            per_track * b,
            compile_s=round(compile_s, 3),
            tracks_per_s=round(b / t, 1),
            baseline_tracks_per_s=round(1.0 / per_track, 1),
            baseline_tracks=n_base,
            rounds=rounds,
            ratio_per_round=[round(r, 1) for r in per_round],
            max_rotation_diff_deg=round(float(d_rot), 5),
            max_offset_north_diff_m=round(float(d_off), 3),
        )


if __name__ == "__main__":
    main()
