"""Does a map closed over by the caller's jit compile as fast as a map passed in?

Compile time (``jax.jit(...).lower(...).compile()``, a new function each time so nothing
is reused) of the dense matcher, :func:`~jaxgrav.match.sizing.config_for`'s white-noise
and GLS configs on the shipped 2.5′ ``ryukyu`` map (289 × 289), one 30-fix track of
:class:`~jaxgrav.scenarios.MatchingScenario`, two ways: the map closed over by the
jitted function (a constant of its program: ``jax.jit(lambda la, lo, g:
match_dense(grid, la, lo, g, cfg))``) and the map passed as an argument (the baseline).
Before the map passed an optimisation barrier in ``interp.bicubic_coefficients``, XLA
folded its gap filling and spline products at compile time, and the closed-over form took
about twice as long. Ratio = argument / closed over (≥ 1: closing over costs nothing).
"""

import time

import jax
from _common import emit, parse_args

jax.config.update("jax_enable_x64", True)  # a script, not the library: as the CLI runs it

from jaxgrav import datasets  # noqa: E402
from jaxgrav.fields.map_error import map_error  # noqa: E402
from jaxgrav.match import config_for, match_dense  # noqa: E402
from jaxgrav.scenarios import MatchingScenario, matching_scenario  # noqa: E402


def compile_time(make, args, repeats):
    """Best time (s) to lower and compile ``make()`` (a new jitted function) at ``args``."""
    best = float("inf")
    for _ in range(repeats):
        f = make()
        t0 = time.perf_counter()
        f.lower(*args).compile()
        best = min(best, time.perf_counter() - t0)
    return best


def main():
    args = parse_args(__doc__)
    repeats = 1 if args.quick else 3
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    run = matching_scenario(jax.random.key(0), grid, MatchingScenario())
    track = (run.ins_lat, run.ins_lon, run.readings)
    for name, me in (("white", None), ("gls", map_error(3.0, 1e4))):
        cfg = config_for("dense", grid, 4500.0, map_error=me)
        closed = compile_time(
            lambda cfg=cfg: jax.jit(lambda la, lo, g: match_dense(grid, la, lo, g, cfg)),
            track, repeats)
        passed = compile_time(
            lambda cfg=cfg: jax.jit(lambda m, la, lo, g: match_dense(m, la, lo, g, cfg)),
            (grid, *track), repeats)
        emit("compile_dense", f"dense {name}, map closed over", len(run.ins_lat), closed,
             "the map as an argument", passed, score_model=cfg.score_model)


if __name__ == "__main__":
    main()
