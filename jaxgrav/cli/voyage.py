"""``jaxgrav simulate-voyage``: write a voyage's INS log and truth from a preset.

Wire into :mod:`jaxgrav.cli` with ``add_parser(sub)``.

::

    LOG.csv    t (s), lat, lon (INS-indicated, degrees), v_east, v_north (INS, m/s),
               gravity (raw gravimeter anomaly, mGal: Eötvös NOT corrected, as a
               navigation system receives it; it must correct it with its own velocity)
    TRUTH.csv  t, lat, lon, v_east, v_north (the true trajectory), and the true INS
               position error d_north, d_east (m, INS − true)

The voyage is :func:`~jaxgrav.scenarios.voyage_scenario` of the preset
(:data:`~jaxgrav.scenarios.PRESETS`: ``patrol-12h``, ``transit-24h``) on ``--map`` (in the
preset's region, or the map's own extent when the map does not cover it, as
``montecarlo --method voyage-*`` does),
the readings seeing the map plus ``--map-error`` (or ``--truth-map``). On a map (or truth
map) with missing (NaN, land-masked) nodes the route is drawn again, up to
:data:`~jaxgrav.montecarlo.matcher_runs.MISSING_MAP_START_TRIES` times, until its true
track reads none (the first route kept when it is clear); if none is, the command says so.

The voyage is simulated by one compiled program (through :func:`jaxgrav.executables.call`,
kept on disk like the other commands' programs): run eagerly, each of its ~170 operations
was compiled on its own (a 12 h patrol on ``ryukyu``: 14.4 s eager against 6.5 s compiled
as one, the same values to 1e-11).
"""

import dataclasses
import math

import jax
import numpy as np

from jaxgrav import executables
from jaxgrav._io import check_outputs
from jaxgrav.cli.inputs import check_bicubic_nodes, check_map_field, check_out_format
from jaxgrav.cli.simulate import (
    add_map_error_options,
    check_seed,
    describe_map_error,
    map_error_from_args,
)
from jaxgrav.datasets import load_map
from jaxgrav.montecarlo.matcher_runs import MISSING_MAP_START_TRIES
from jaxgrav.montecarlo.spec import region_of
from jaxgrav.scenarios import PRESETS, voyage_preset, voyage_scenario
from jaxgrav.scenarios.paper_a import check_region_covered
from jaxgrav.tracks import write_track_csv

__all__ = ["add_parser", "cmd_simulate_voyage"]

MAX_HOURS = 240.0
"""Longest voyage ``--hours`` accepts (h)."""


@jax.jit
def _voyage_program(key_data, grid, scenario, model):
    """:func:`~jaxgrav.scenarios.voyage_scenario` from raw key data, one compiled program."""
    return voyage_scenario(jax.random.wrap_key_data(key_data), grid, scenario, model)


def add_parser(sub):
    """Add the ``simulate-voyage`` sub-command to an ``argparse`` sub-parser set."""
    p = sub.add_parser("simulate-voyage",
                       help="write a voyage's INS log (raw readings) and truth from a preset")
    p.add_argument("--preset", default="patrol-12h", choices=sorted(PRESETS),
                   help="the voyage (default patrol-12h)")
    p.add_argument("--map", default="ryukyu",
                   help="map the readings are simulated from: NetCDF grid or shipped map "
                        "(default ryukyu, 2.5')")
    p.add_argument("--var", default=None)
    p.add_argument("--hours", type=float, default=None,
                   help="length of the voyage (h; default the preset's)")
    p.add_argument("--out", required=True, help="INS log CSV")
    p.add_argument("--truth", default=None, help="also write the truth here")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="store_true", help="overwrite existing files")
    add_map_error_options(p)
    p.set_defaults(func=cmd_simulate_voyage)
    return p


def cmd_simulate_voyage(args):
    """Run ``simulate-voyage`` (see the module notes)."""
    if args.hours is not None and not (math.isfinite(args.hours) and 0 < args.hours <= MAX_HOURS):
        raise ValueError(f"--hours must be a positive length of at most {MAX_HOURS:g} h; "
                         f"got {args.hours!r}")
    check_seed(args.seed)
    scenario = voyage_preset(args.preset)
    if args.hours is not None:
        try:  # VoyageScenario's own rule; its message named the library's "hours"
            scenario = dataclasses.replace(scenario, hours=args.hours)
        except ValueError:
            raise ValueError(f"--hours must cover at least two readings {scenario.dt:g} s apart "
                             f"(>= {2 * scenario.dt / 3600.0:.3g} h); got {args.hours!r}") from None
    check_outputs([args.out, args.truth], force=args.force, names=["--out", "--truth"],
                  inputs={"--map": args.map, "--truth-map": args.truth_map})
    check_out_format(args.out, "CSV")
    if args.truth is not None:
        check_out_format(args.truth, "CSV", "--truth")
    grid = load_map(args.map, args.var, allow_nan=True)  # missing nodes: checked on the route
    check_map_field(grid, "gravity", args.map)  # nT were written as gravity
    check_bicubic_nodes(grid, f"--map {str(args.map)!r}")
    try:
        check_region_covered(grid, scenario.region, f"--map {args.map}")
        own = ""
    except ValueError:  # a regional map (a user's own): refused; montecarlo voyage-* ran
        # on it (voyage_builder), so the voyage keeps to the map's own extent, as there
        scenario = dataclasses.replace(scenario, region=region_of(grid))
        s, n, w, e = scenario.region
        own = f" on the map's own region (lat {s:.4g}..{n:.4g}, lon {w:.4g}..{e:.4g})"
    model = map_error_from_args(args, grid, allow_nan=True)
    # land masked: the route is drawn again until it reads no missing node
    tries = (MISSING_MAP_START_TRIES if grid.n_missing or
             getattr(getattr(model, "grid", None), "n_missing", 0) else 1)
    scenario = dataclasses.replace(scenario, start_tries=tries)
    key_data = jax.random.key_data(jax.random.key(args.seed))
    voyage = executables.call(_voyage_program, key_data, grid, scenario, model)
    off = ~np.asarray(grid.contains(voyage.truth.lat, voyage.truth.lon))
    if off.any():  # was reported as missing (NaN) map values along the route
        i = int(np.flatnonzero(off)[0])
        raise ValueError(f"the {args.preset} route leaves --map {args.map} after "
                         f"{float(voyage.truth.t[i]) / 3600:.3g} h (at lat "
                         f"{float(voyage.truth.lat[i]):.5g}, lon {float(voyage.truth.lon[i]):.5g}; "
                         f"{int(off.sum())} of {off.size} readings off the map){own}; give a "
                         "shorter --hours, another --preset or a larger map")
    bad = ~np.isfinite(np.asarray(voyage.gravity))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        source = f"--truth-map {args.truth_map}" if args.truth_map else f"--map {args.map}"
        raise ValueError(f"{source} has missing (NaN) values along the simulated route: "
                         f"{int(bad.sum())} of {bad.size} readings, the first at lat "
                         f"{float(voyage.truth.lat[i]):.5g}, lon {float(voyage.truth.lon[i]):.5g} "
                         f"(none of the {tries} routes tried is clear); choose another --seed "
                         "or a map complete there (missing nodes away from the route are fine)")
    ins, truth = voyage.ins, voyage.truth
    write_track_csv(args.out, {"t": ins.t, "lat": ins.lat, "lon": ins.lon,
                               "v_east": ins.v_east, "v_north": ins.v_north,
                               "gravity": voyage.gravity}, force=args.force)
    if args.truth:
        write_track_csv(args.truth, {"t": truth.t, "lat": truth.lat, "lon": truth.lon,
                                     "v_east": truth.v_east, "v_north": truth.v_north,
                                     "d_north": voyage.ins_error[:, 0],
                                     "d_east": voyage.ins_error[:, 1]}, force=args.force)
    end = float(np.hypot(voyage.ins_error[-1, 0], voyage.ins_error[-1, 1]))
    also = f" and {args.truth}" if args.truth else ""
    print(f"wrote {args.out}{also}: {args.preset}{own}, {scenario.hours:g} h, "
          f"{ins.t.shape[0]} rows every {scenario.dt:g} s, free INS error at the end "
          f"{end / 1000:.1f} km, {describe_map_error(args)}")
