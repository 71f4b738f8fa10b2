"""Paper D: gravity-aided INS filtering over a point-mass anomaly, Monte Carlo.

For each run: a ship sails 2 h at 5 m/s over paper D's three-mass area (straight
east-west tracks across the masses, or north along the mass line for an hour and
then east), the INS starts with a 2 km position and 0.2 m/s velocity error (fixed
sizes, random directions) and drifts with the Schuler-coupled error model of
``jaxgrav.sim.ins``; the gravimeter reads every 10 s with 1 mGal noise and a 1 mGal
bias. Free INS, EKF, UKF, a Gaussian-sum UKF and the grid point-mass filter run on
the same runs. Reported per method: the ratio of the filter's RMS position error
over the second hour to the INS's (mean, median, worst, share of runs above 1.05),
and the mean position NEES (expected 2 for honest 1-σ bounds).

The filters step at the reading rate (10 s): with no reading in between, the
prediction over five 2 s steps is the single 10 s prediction of the same exact
discretisation, so the numbers are those of a 2 s filter sampled at the readings.

Run::

    python examples/paper_d_ukf.py --runs 1000          # paper D's area
    python examples/paper_d_ukf.py --runs 1000 --map ryukyu   # shipped 2.5' map
    python examples/paper_d_ukf.py --smoke      # 8 runs of 20 min, EKF and UKF
    # the map is not the truth: a 3 mGal, 10 km map error (markov2) drawn per run
    python examples/paper_d_ukf.py --runs 200 --map ryukyu --map-error 3 \
        --methods ukf,ukf-white,ukf-fogm,gsf-fogm

With ``--map-error`` the readings see ``truth_field(map_error_key(key), map,
map_error(SIGMA, L))``. ``ukf``, ``ekf``, ``pmf`` are told nothing of it; ``*-white``
add ``SIGMA²`` to their reading variance; ``*-fogm`` (ukf, ekf, gsf) carry a
first-order Gauss–Markov map-error state of σ = SIGMA and length 2 L (the markov2
field's integral scale; :mod:`jaxgrav.filters.map_state`).

The runs are simulated once, then every method filters the same runs; each method's
time (compilation included) is printed after its row.
"""

import argparse
import os
import time

# XLA's multi-threaded Eigen pool can wedge on large vmapped linear algebra on CPU
# (seen here with JAX 0.10.2: all threads parked on a futex); single-threaded Eigen
# avoids it at little cost, since the batch is parallel anyway.
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import datasets
from jaxgrav.fields.map_error import map_error
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.filters import ekf, gaussian_sum, pmf, run_filter, ukf
from jaxgrav.filters.map_state import augment, fogm_length, map_error_state
from jaxgrav.scenarios import FilterScenario, filter_scenario, initial_state, run_metrics, run_steps


def make_simulate(scenario, truth_error=None):
    """Simulate runs once for every method: (run, dynamics, steps) per key, vmapped."""

    def one(key, field):
        run = filter_scenario(key, field, scenario, truth_error)
        dynamics, steps = run_steps(run, scenario)
        return run, dynamics, steps

    return jax.jit(jax.vmap(one, in_axes=(0, None)))


def make_one(method, scenario, truth_error=None):
    """Filter one simulated run; returns (INS RMS, filter RMS, NEES, geometry flag)."""
    base, _, told = method.partition("-")
    if base == "gsf" and told == "ukf":
        told = ""

    def one(run, dynamics, steps, field):
        x0, p0 = initial_state(scenario)
        meas = None
        if told and truth_error is None:
            raise ValueError(f"--methods {method}: *-white and *-fogm need --map-error")
        if told == "white":
            steps = steps._replace(r=steps.r + jnp.square(truth_error.sigma))
        elif told == "fogm":
            cfg = map_error_state(truth_error.sigma, fogm_length(truth_error))
            dynamics, x0, p0, meas = augment(cfg, dynamics, x0, p0, scenario.speed)
        if base == "pmf":
            filt = pmf()  # its own error model (with the step length) at the mean latitude
            dynamics = filt.dynamics(jnp.mean(steps.lat), scenario.dt)
        else:
            make = {"ekf": ekf, "ukf": ukf,
                    "gsf": lambda *m: gaussian_sum(ukf(*m), 3, 1.0)}[base]
            filt = make() if meas is None else make(meas)
        _, info = run_filter(filt, field, dynamics, x0, p0, steps)
        m = run_metrics(run, info)
        turned = jnp.abs(run.truth.lat[-1] - run.truth.lat[0]) > 0.05
        return m["ins_err_m"], m["err_m"], m["nees"], turned

    return one


def summarize(name, rms_i, rms_f, nees, turned, seconds):
    ratio = rms_f / rms_i
    row = (f"{name:9s} {np.mean(ratio):6.3f} {np.median(ratio):6.3f} {np.max(ratio):6.2f} "
           f"{100 * np.mean(ratio > 1.05):6.1f}% {np.median(rms_f):8.0f} {np.mean(nees):6.2f}")
    if turned.any() and (~turned).any():
        row += f"   {np.mean(ratio[~turned]):.3f} / {np.mean(ratio[turned]):.3f}"
    return row + f"   ({seconds:.0f} s)"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=1000)
    p.add_argument("--map", choices=["paper-d", "ryukyu"], default="paper-d")
    p.add_argument("--methods", default=None,
                   help="comma-separated: ekf, ukf, pmf, gsf-ukf (9x cost); default "
                        "ekf,ukf,pmf (--smoke: ekf,ukf); with --map-error also ukf-white, "
                        "ekf-white, pmf-white (told SIGMA^2 white) and ukf-fogm, ekf-fogm, "
                        "gsf-fogm (FOGM map-error state)")
    p.add_argument("--map-error", type=float, default=0.0, metavar="SIGMA",
                   help="with --map ryukyu: the readings see the map + a drawn error of this "
                        "sigma (mGal, markov2; default 0: the map is the truth)")
    p.add_argument("--map-error-length", type=float, default=10e3, metavar="L",
                   help="the map error's correlation length (m, default 10000)")
    p.add_argument("--minutes", type=float, default=None,
                   help="run length (default 120; --smoke: 20)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--smoke", action="store_true",
                   help="a quick check: 8 runs of 20 minutes, EKF and UKF")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)

    minutes = args.minutes or (20.0 if args.smoke else 120.0)
    n_steps = round(minutes * 6) + 1  # a step (and a reading) every 10 s
    runs = 8 if args.smoke else args.runs
    methods = (args.methods or ("ekf,ukf" if args.smoke else "ekf,ukf,pmf")).split(",")
    if args.map == "paper-d":
        field = paper_d()
        scenario = FilterScenario(dt=10.0, reading_every=1, n_steps=n_steps)
    else:
        field = datasets.load("ryukyu")["anomaly_2p5min"]
        scenario = FilterScenario(dt=10.0, reading_every=1, n_steps=n_steps, geometry="random")
    truth_error = None
    if args.map_error:
        if args.map == "paper-d":
            p.error("--map-error needs --map ryukyu (the point masses have no grid)")
        truth_error = map_error(args.map_error, args.map_error_length)
    keys = jax.random.split(jax.random.key(args.seed), runs)
    t0 = time.perf_counter()
    sims = jax.block_until_ready(make_simulate(scenario, truth_error)(keys, field))
    where = args.map + (f" + map error {args.map_error:g} mGal, L {args.map_error_length:g} m"
                        if truth_error is not None else "")
    print(f"paper D filtering, map {where}, {runs} runs of {(n_steps - 1) * 10 / 3600:.1f} h "
          f"(simulated in {time.perf_counter() - t0:.0f} s; filter step 10 s, run_filter "
          "every=1: a reading every step)")
    print("method    mean   median  worst  >1.05  median-m  NEES   E-W / N-then-E mean")
    ins_row = None
    for method in methods:
        fn = jax.jit(jax.vmap(make_one(method, scenario, truth_error), in_axes=(0, 0, 0, None)))
        t0 = time.perf_counter()
        rms_i, rms_f, nees, turned = jax.tree.map(np.asarray, fn(*sims, field))
        seconds = time.perf_counter() - t0
        if ins_row is None:
            ins_row = f"{'INS':9s} {1:6.3f} {1:6.3f} {1:6.2f} {0:6.1f}% {np.median(rms_i):8.0f}"
            print(ins_row)
        print(summarize(method, rms_i, rms_f, nees, turned, seconds), flush=True)


if __name__ == "__main__":
    main()
