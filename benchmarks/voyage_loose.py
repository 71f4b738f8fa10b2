"""How fast is loosely coupled voyage navigation, and where does its time go?

``patrol-12h`` voyages (navigation-grade INS, map error 3 mGal / 10 km) on the shipped
2.5′ ``ryukyu`` map, navigated by :func:`jaxgrav.navigate.navigate_loose` with the
settings of ``examples/voyage_loose.py`` (:func:`jaxgrav.navigate.loose_config`: a
60-fix dense match every hour, the first on 30 fixes, :data:`jaxgrav.navigate.DENSE_LOOP`).

Lines (JSON, ``_common.emit``):

* ``voyage_loose``: ``n`` voyages in one call, batched with ``vmap`` (case ``vmap``)
  or run one after another inside the call with ``lax.map`` (case ``lax.map``),
  against the same voyages one call each (baseline: a Python loop over the compiled
  single-voyage entry point); ``runs_per_s`` and ``projected_1000_s`` (1000 voyages at
  that rate; the issue's goal is 1000 × 12 h within 600 s on the 2-core machine).
  ``vmap`` turns the matcher's branches (white or GLS score, refinement) into selects
  that run both sides, so on a CPU the sequential map is the faster batch.
* ``voyage_loose_share``: the matcher alone on the same full segments (each voyage's
  segments ending every ``stride`` fixes, batched with ``vmap``; the first segments'
  shorter ones and the segment's own error told are left out) against the whole loop:
  the share
  of the loop's time spent matching (the rest is the filter, the segment
  corrections and the Eötvös correction).

Voyages are simulated before timing; timed calls exclude compilation. Run
``python benchmarks/voyage_loose.py [--quick]``; absolute times on a shared machine
are noise, compare within one run.
"""

import pathlib
import sys

import jax
import jax.numpy as jnp

from jaxgrav import datasets
from jaxgrav.fields.map_error import map_error
from jaxgrav.match.dense import match_dense
from jaxgrav.navigate import loose_config, navigate_loose
from jaxgrav.prepared import prepare_map
from jaxgrav.scenarios import voyage_preset, voyage_scenario

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _common import batch_timings, best_time, emit, parse_args

jax.config.update("jax_enable_x64", True)  # a script, not the library: geodesy in float64



def main():
    args = parse_args(__doc__.split("\n")[0])
    n, hours, repeats = (4, 2.0, 1) if args.quick else (64, 12.0, 2)
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    pm = prepare_map(grid)
    scenario = voyage_preset("patrol-12h", hours=hours)
    model = map_error(3.0, 10000.0)
    cfg = loose_config(scenario.ins, 3.0, 10000.0)
    keys = jax.random.split(jax.random.key(0), n)
    voyages = jax.jit(jax.vmap(lambda g, k: voyage_scenario(k, g, scenario, model),
                               in_axes=(None, 0)))(grid, keys)
    jax.block_until_ready(voyages)
    t_batch, t_loop, t_seq = batch_timings(navigate_loose, pm, voyages, cfg, repeats)
    for case, t in (("vmap", t_batch), ("lax.map", t_seq)):
        emit("voyage_loose", f"patrol {hours:g} h, {case} vs loop", n, t,
             "python loop of compiled single-voyage calls", t_loop,
             runs_per_s=round(n / t, 3), projected_1000_s=round(1000 * t / n, 1))
    t_batch = t_seq

    m, w = cfg.fix_every, cfg.n_fixes * cfg.fix_every
    starts = jnp.arange(0, scenario.n_steps - w, cfg.stride * m)  # full segments' first steps
    n_seg = starts.shape[0]
    rows = starts[:, None] + jnp.arange(w)
    ins = voyages.ins

    def blocks(a):
        return a[:, rows].reshape(n * n_seg, cfg.n_fixes, m).mean(-1)

    lat, lon, g = blocks(ins.lat), blocks(ins.lon), blocks(voyages.gravity)
    matcher = cfg.matcher
    match = jax.jit(jax.vmap(lambda pm, a, b, c: match_dense(pm, a, b, c, matcher),
                             in_axes=(None, 0, 0, 0)))

    def run_match():
        jax.block_until_ready(match(pm, lat, lon, jnp.nan_to_num(g)))

    run_match()
    t_match = best_time(run_match, repeats)
    emit("voyage_loose_share", "matcher alone vs the whole loop", n * n_seg, t_match,
         "navigate_loose (lax.map)", t_batch, share_matching=round(t_match / t_batch, 3))


if __name__ == "__main__":
    main()
