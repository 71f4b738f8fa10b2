"""``jaxgrav simulate``: write a track CSV from paper A's matching scenario.

Wire into :mod:`jaxgrav.cli` with ``add_parser(sub)``.
"""

import jax
import numpy as np

from jaxgrav.constants import KNOT
from jaxgrav.datasets import load_map
from jaxgrav.scenarios import MatchingScenario, matching_scenario
from jaxgrav.sim import rayleigh_quantile
from jaxgrav.tracks import write_track_csv

__all__ = ["add_parser"]


def add_parser(sub):
    """Add the ``simulate`` sub-command to an ``argparse`` sub-parser set."""
    sim_p = sub.add_parser("simulate", help="write a track CSV from a matching scenario")
    sim_p.add_argument("--map", default="ryukyu",
                       help="truth map: NetCDF grid or shipped map (default ryukyu, 2.5')")
    sim_p.add_argument("--var", default=None)
    sim_p.add_argument("--out", required=True, help="track CSV (INS fixes and readings)")
    sim_p.add_argument("--truth", default=None, help="also write the true track here")
    sim_p.add_argument("--n", type=int, default=30, help="fixes (default 30)")
    sim_p.add_argument("--dt", type=float, default=120.0, help="interval (s, default 120)")
    sim_p.add_argument("--v-east", type=float, default=10.0, help="knots (default 10)")
    sim_p.add_argument("--v-north", type=float, default=10.0, help="knots (default 10)")
    sim_p.add_argument("--drift", type=float, default=0.035,
                       help="INS drift (degrees of arc, default 0.035)")
    sim_p.add_argument("--drift-law", choices=("fixed", "rayleigh"), default="fixed",
                       help="fixed: the drift is --drift; rayleigh: --drift is the Rayleigh "
                            "scale and the search radius its --probability quantile")
    sim_p.add_argument("--probability", type=float, default=0.99,
                       help="Rayleigh quantile written as drift_radius (default 0.99)")
    sim_p.add_argument("--noise", type=float, default=1.0, help="reading noise (mGal)")
    sim_p.add_argument("--bias", type=float, default=0.0, help="gravimeter bias (mGal)")
    sim_p.add_argument("--seed", type=int, default=0)
    sim_p.add_argument("--force", action="store_true")
    sim_p.set_defaults(func=_cmd_simulate)
    return sim_p


def _cmd_simulate(args):
    grid = load_map(args.map, args.var)
    w, e, s, n = grid.extent
    scen = MatchingScenario(
        region=(s, n, w, e), v_east=args.v_east * KNOT, v_north=args.v_north * KNOT,
        dt=args.dt, drift_deg=args.drift, noise_mgal=args.noise, bias_mgal=args.bias,
        n_fixes=args.n, drift_law=args.drift_law,
    )
    if args.n < 2:
        raise ValueError(f"--n must be at least 2; got {args.n}")
    run = matching_scenario(jax.random.key(args.seed), grid, scen)
    truth = run.truth
    write_track_csv(args.out, {
        "t": truth.t, "lat": run.ins_lat, "lon": run.ins_lon, "gravity": run.readings,
        "v_east": truth.v_east, "v_north": truth.v_north,
        "drift_radius": np.full(args.n, 1.2 * args.drift if args.drift_law == "fixed"
                                else float(rayleigh_quantile(args.drift, args.probability))),
    }, force=args.force)
    if args.truth:
        write_track_csv(args.truth, {"t": truth.t, "lat": truth.lat, "lon": truth.lon},
                        force=args.force)
    drift_m = float(np.hypot(run.drift_north_m, run.drift_east_m).mean())
    also = f" and {args.truth}" if args.truth else ""
    print(f"wrote {args.out}{also}: {args.n} fixes, INS drift {drift_m:.0f} m")
