"""Paper D: the marine gravimeter signal chain and the speed bound, on the ryukyu map.

A vehicle runs due east along 26.5°N across the Ryukyu arc at 1 Hz for ``--n``
samples (default 1800, 30 min) at several speeds. The true anomaly is the shipped
2.5′ ``ryukyu`` map (bicubic) at the true positions; the gravimeter record adds
swell (3 sinusoids, 5–8 cm/s² at 0.07–0.25 Hz), platform tilt coupling (a_h 0.1 and
0.05 m/s² at 0.09/0.16 Hz), the Eötvös effect and 1 mGal white noise
(:class:`jaxgrav.sim.GravimeterConfig` defaults). The INS velocity is off by
(0.2, 0.1) m/s (east, north), so its track drifts and its Eötvös correction is off.

The chain: tilt Kalman filter (gyro + accelerometer) → tilt correction → Eötvös
correction (from the INS velocity, or from the map: mean of map minus mean of the
filtered record along the INS track) → Parks–McClellan low-pass (pass band to
0.05π, stop band from 0.1π rad/sample, δ1 = 1e-3, δ2 = 1e-4), delay-compensated.

Columns (RMS of estimate − true anomaly over the filter's valid samples, mGal, mean
over ``--runs`` PRNG keys):

- ``raw``: before filtering (tilt and velocity-Eötvös corrected): the swell;
- ``loss``: the filter applied to the true anomaly alone — what the low-pass takes
  from the signal itself (the speed bound's concern);
- ``no-tilt`` / ``tilt-KF``: filtered, exact Eötvös (true velocity), without / with
  the tilt correction;
- ``vel-E`` / ``map-E``: filtered, tilt-corrected, Eötvös from the INS velocity /
  from the map (the map-based estimate also absorbs any constant: bias, tilt).

``f_t/lim`` is ``(v / n_d) / (0.05 Hz / 2.5)`` with n_d the map's east–west node
spacing: above 1 the speed bound of paper D is exceeded.

Run ``python examples/paper_d_gravimeter.py [--smoke] [--n 1800] [--runs 8]``.
"""

import argparse
import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)  # a script, not the library

import jaxgrav as jg  # noqa: E402
from jaxgrav import datasets  # noqa: E402
from jaxgrav.constants import DEG, KNOT  # noqa: E402
from jaxgrav.fields.random import gaussian_random_field, markov_spectrum  # noqa: E402
from jaxgrav.interp import bicubic, bicubic_coefficients  # noqa: E402
from jaxgrav.sim import (  # noqa: E402
    GravimeterConfig,
    apply_fir,
    design_lowpass,
    eotvos_from_map,
    max_speed,
    run_tilt_kf,
    simulate_gravimeter,
    straight_track,
    tilt_correction,
)

LAT0, LON0 = 26.5, 125.0
INS_VEL_ERR = (0.2, 0.1)  # m/s, east and north
SPEEDS = (2.0, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0)
SMOKE_SPEEDS = (5.0, 80.0, 320.0)
FINE_SPEEDS = (1.0, 2.0, 5.0, 10.0, 20.0, 40.0)
SMOKE_FINE_SPEEDS = (2.0, 10.0, 40.0)


def make_run(grid, fir, cfg, n):
    """All runs: (keys (R,), speeds (S,)) -> RMS errors (mGal) (S, R, 6) of each chain variant.

    The map's bicubic coefficients are computed once and passed to the compiled
    program as an argument: closed over, they would be embedded in it as a constant,
    which costs compilation time.
    """
    coef = bicubic_coefficients(grid.values)

    def rms(x, valid):
        return jnp.sqrt(jnp.sum(jnp.where(valid, x, 0.0) ** 2) / jnp.sum(valid))

    def run(coef, key, speed):
        def sampler(lat, lon):  # the map, as make_sampler(grid, "bicubic") samples it
            return bicubic(coef, *grid.fractional_index(lat, lon))

        true = straight_track(LAT0, LON0, speed, 0.0, n, 1.0)
        ins = straight_track(LAT0, LON0, speed + INS_VEL_ERR[0], INS_VEL_ERR[1], n, 1.0)
        truth = sampler(true.lat, true.lon)
        map_ins = sampler(ins.lat, ins.lon)
        rec = simulate_gravimeter(key, true, truth, cfg)
        kf = run_tilt_kf(cfg.platform, 1.0, rec.gyro, rec.accel_h, cfg.accel_noise,
                         cfg.gyro_noise)
        tilted = rec.reading - tilt_correction(kf.x[:, 0], rec.accel_h)
        e_true = rec.truth.eotvos
        e_vel = jg.eotvos(ins.lat, ins.v_east, ins.v_north)
        loss = apply_fir(truth, fir)
        valid = loss.valid
        no_tilt = apply_fir(rec.reading + e_true, fir).values
        tilt_kf = apply_fir(tilted + e_true, fir).values
        vel = apply_fir(tilted + e_vel, fir).values
        filt = apply_fir(tilted, fir).values
        map_e = filt + eotvos_from_map(filt, map_ins, valid)
        return jnp.stack([
            rms(tilted + e_vel - truth, valid),
            rms(loss.values - truth, valid),
            rms(no_tilt - truth, valid),
            rms(tilt_kf - truth, valid),
            rms(vel - truth, valid),
            rms(map_e - truth, valid),
        ])

    runs = jax.jit(jax.vmap(jax.vmap(run, in_axes=(None, 0, None)), in_axes=(None, None, 0)))
    return functools.partial(runs, coef)


def fine_map(seed, spacing=250.0, ny=32, nx=330):
    """Synthetic map with detail at its node spacing: exponential-covariance random
    field, rms 10 mGal, correlation length = spacing, east of (LAT0, LON0)."""
    dlat = spacing / float(jg.geodesy.meridian_radius(LAT0)) / DEG
    dlon = spacing / float(jg.geodesy.prime_vertical_radius(LAT0) * np.cos(LAT0 * DEG)) / DEG
    lat = LAT0 + (np.arange(ny) - ny // 2) * dlat
    lon = LON0 - 4 * dlon + np.arange(nx) * dlon
    v = gaussian_random_field(jax.random.key(seed), (ny, nx), (spacing, spacing),
                              markov_spectrum(10.0, spacing, order=1), rms=10.0)
    return jg.Grid.from_arrays(lat, lon, np.asarray(v), name="synthetic", units="mGal")


def table(title, grid, speeds, fir, cfg, n, keys):
    """Run all speeds × keys in one call and print the table."""
    n_d = grid.spacing_m(LAT0)[1]
    v_lim = float(max_speed(n_d, 0.05, 2.5))
    print(f"\n{title}: east-west node spacing n_d = {n_d:.0f} m; speed bound "
          f"v ≤ n_d · 0.05 Hz / 2.5 = {v_lim:.1f} m/s ({v_lim / KNOT:.1f} kn)")
    t0 = time.perf_counter()
    err = np.asarray(make_run(grid, fir, cfg, n)(keys, jnp.asarray(speeds)))
    dt = time.perf_counter() - t0
    mean = err.mean(axis=1)  # (speeds, 6)
    head = ("v m/s", "kn", "f_t/lim", "raw", "loss", "no-tilt", "tilt-KF", "vel-E", "map-E")
    print(" ".join(f"{h:>8}" for h in head))
    for v, row in zip(speeds, mean, strict=True):
        cells = [f"{v:8.0f}", f"{v / KNOT:8.1f}", f"{v / v_lim:8.2f}", f"{row[0]:8.0f}"]
        print(" ".join(cells + [f"{x:8.2f}" for x in row[1:]]))
    print(f"({len(speeds) * len(keys)} runs in one jitted, vmapped call, {dt:.1f} s with "
          "compilation)")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--smoke", action="store_true", help="3 speeds per map, 600 samples, 2 runs")
    p.add_argument("--n", type=int, default=1800, help="samples per record (1 Hz)")
    p.add_argument("--runs", type=int, default=8, help="PRNG keys per speed")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    if a.smoke:
        n, runs, speeds, fine_speeds = 600, 2, SMOKE_SPEEDS, SMOKE_FINE_SPEEDS
    else:
        n, runs, speeds, fine_speeds = a.n, a.runs, SPEEDS, FINE_SPEEDS
    if max(fine_speeds) * n > 75_000:
        p.error(f"--n {n} too long for the synthetic map at {max(fine_speeds)} m/s (≤ 1875)")

    fir = design_lowpass(0.025, 0.025, 1e-3, 1e-4)
    cfg = GravimeterConfig()
    print(f"FIR: {fir.numtaps} taps (delay {fir.delay} s), pass ≤ {fir.cutoff} / stop ≥ "
          f"{fir.stop_edge} cycles/sample, achieved δ1 = {fir.achieved_pass:.2e}, "
          f"δ2 = {fir.achieved_stop:.2e}; {n} samples at 1 Hz, {runs} runs per speed; "
          "RMS error of the anomaly (mGal)")
    keys = jax.random.split(jax.random.key(a.seed), runs)
    table("ryukyu 2.5' map (real data)", datasets.load("ryukyu")["anomaly_2p5min"], speeds,
          fir, cfg, n, keys)
    table("synthetic 250 m map (exponential covariance, 10 mGal rms, L = 250 m)",
          fine_map(a.seed), fine_speeds, fir, cfg, n, keys)


if __name__ == "__main__":
    main()
