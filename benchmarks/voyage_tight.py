"""How fast is tightly coupled voyage navigation, batched, against filterpy's UKF?

``patrol-12h`` voyages (navigation-grade INS, map error 3 mGal / 10 km told as a
second-order map-error state) on the shipped 2.5′ ``ryukyu`` map, navigated by
:func:`jaxgrav.navigate.navigate_tight` (UKF, a reading every 10 s, the Eötvös error of
the velocity error in the measurement).

Lines (JSON, ``_common.emit``):

* ``voyage_tight``: ``n`` voyages in one call, batched with ``vmap`` (case ``vmap``,
  what :func:`jaxgrav.montecarlo.run` does) or one after another inside the call with
  ``lax.map`` (case ``lax.map``), against a Python loop over the compiled single-voyage
  entry point; ``runs_per_s`` and ``projected_1000_s``.
* ``voyage_tight_filterpy``: per voyage, the batched call against filterpy's
  ``UnscentedKalmanFilter`` (the field's reference UKF, Merwe sigma points with the same
  α, β, κ) on the same model — 15 states, the same ``F``, ``Q``, prior and Eötvös term,
  the map as SciPy's bicubic ``RectBivariateSpline`` — on ``n_ref`` voyages; jaxgrav's
  time is its default filter, which also adds the map's correlated linearisation
  variance (a Hessian per reading) that the reference lacks, and
  ``rms_position_difference_m`` compares the two with that term off.

Voyages are simulated before timing; timed calls exclude compilation. Run
``python benchmarks/voyage_tight.py [--quick]``; absolute times on a shared machine
are noise, compare within one run.
"""

import dataclasses
import pathlib
import sys
import time

import jax
import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from scipy.interpolate import RectBivariateSpline

from jaxgrav import datasets
from jaxgrav.constants import DEG
from jaxgrav.fields.map_error import map_error
from jaxgrav.filters import Dynamics, augment, matched_state
from jaxgrav.geodesy import eotvos, eotvos_jacobian, meridian_radius, prime_vertical_radius
from jaxgrav.navigate import TightConfig, navigate_tight
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import voyage_preset, voyage_scenario
from jaxgrav.sim.ins import initial_covariance, transition

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _common import batch_timings, emit, parse_args

jax.config.update("jax_enable_x64", True)  # a script, not the library: geodesy in float64


def filterpy_voyage(grid, voyage, cfg):
    """The same filter written with filterpy, one reading at a time."""
    ins = voyage.ins
    lat, lon, ve, vn = (np.asarray(a) for a in (ins.lat, ins.lon, ins.v_east, ins.v_north))
    dt = float(ins.t[1] - ins.t[0])
    f, q = transition(cfg.ins, float(lat.mean()), dt)
    p0 = initial_covariance(cfg.ins, cfg.sigma_pos_m, cfg.sigma_vel)
    speed = float(np.mean(np.hypot(ve, vn)))  # the library model's mean speed
    dyn, x0, p0, _ = augment(cfg.map_error, Dynamics(f, q, dt), np.zeros(13), p0, speed)
    f, q = np.asarray(dyn.f), np.asarray(dyn.q)
    n = f.shape[0]
    spline = RectBivariateSpline(np.asarray(grid.lat), np.asarray(grid.lon),
                                 np.asarray(grid.values), kx=3, ky=3)
    m_rad = np.asarray(meridian_radius(lat))
    e_rad = np.asarray(prime_vertical_radius(lat)) * np.cos(lat * DEG)
    jac = np.asarray(eotvos_jacobian(lat, ve, vn))
    z = np.asarray(voyage.gravity) + np.asarray(eotvos(lat, ve, vn))

    def hx(x, k):
        return np.array([spline(lat[k] - x[0] / m_rad[k] / DEG, lon[k] - x[1] / e_rad[k] / DEG,
                                grid=False) + x[12] + x[13] + jac[k] @ x[2:4]])

    ukf = UnscentedKalmanFilter(n, 1, dt, hx=hx, fx=lambda x, dt: f @ x,
                                points=MerweScaledSigmaPoints(n, alpha=0.5, beta=2.0, kappa=0.0))
    ukf.x, ukf.P, ukf.Q, ukf.R = np.asarray(x0, float), np.asarray(p0, float), q, np.eye(1)
    out = np.empty((z.size, 2))
    for k in range(z.size):
        ukf.predict()
        ukf.update(np.array([z[k]]), k=k)
        out[k] = ukf.x[:2]
    return out


def main():
    args = parse_args(__doc__.split("\n")[0])
    n, n_ref, hours, repeats = (4, 1, 1.0, 1) if args.quick else (64, 2, 12.0, 2)
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    pm = prepare_map(grid)
    scenario = voyage_preset("patrol-12h", hours=hours)
    model = map_error(3.0, 10000.0)
    cfg = TightConfig(ins=scenario.ins, map_error=matched_state(model, 2))
    keys = jax.random.split(jax.random.key(0), n)
    voyages = jax.jit(jax.vmap(lambda g, k: voyage_scenario(k, g, scenario, model),
                               in_axes=(None, 0)))(grid, keys)
    jax.block_until_ready(voyages)
    t_batch, t_loop, t_seq = batch_timings(navigate_tight, pm, voyages, cfg, repeats)
    one = [jax.tree.map(lambda a, i=i: a[i], voyages) for i in range(n_ref)]
    for case, t in (("vmap", t_batch), ("lax.map", t_seq)):
        emit("voyage_tight", f"patrol {hours:g} h, {case} vs loop", n, t,
             "python loop of compiled single-voyage calls", t_loop,
             runs_per_s=round(n / t, 3), projected_1000_s=round(1000 * t / n, 1))

    t0 = time.perf_counter()
    ref = [filterpy_voyage(grid, one[i], cfg) for i in range(n_ref)]
    t_ref = (time.perf_counter() - t0) / n_ref
    plain = dataclasses.replace(cfg, curvature_cells=0.0)  # filterpy has no curvature term
    ours = navigate_tight(pm, one[0], plain).error_estimate[:, :2]
    diff = float(np.sqrt(np.mean((np.asarray(ours) - ref[0]) ** 2)))
    best = min(t_batch, t_seq) / n
    emit("voyage_tight_filterpy", f"patrol {hours:g} h, per voyage, batched vs filterpy", n_ref,
         best, "filterpy UnscentedKalmanFilter, SciPy bicubic spline map", t_ref,
         rms_position_difference_m=float(f"{diff:.3g}"),
         rms_position_estimate_m=float(f"{float(np.sqrt(np.mean(ref[0] ** 2))):.4g}"))


if __name__ == "__main__":
    main()
