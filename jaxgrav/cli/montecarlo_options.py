"""``jaxgrav montecarlo``'s numeric options, range-checked in one place.

:func:`check_options` refuses a run count, chunk, device count, drift, noise or fix count
out of range, more ``--devices`` than ``--runs``, and a ``--fixes`` x ``--chunk`` whose
runs would not fit in memory, with one line naming the option (``--noise``, not the
library's ``noise``), before any map is read or anything compiled; :func:`check_drift`
refuses a ``--drift`` whose search or initial error does not fit on the map, once the
map is known; :func:`told_from_args` parses ``--told-map-error SIGMA[,L]``;
:func:`check_results_size` refuses a run count whose results do not fit in memory or on
the disk, and announces a large one.
"""

import math
import shutil
import sys
from pathlib import Path

import jax

from jaxgrav.cli.filter_checks import memory_budget
from jaxgrav.cli.match_search import unresolved
from jaxgrav.cli.simulate import (
    DEFAULT_MAP_ERROR_LENGTH_M,
    MAX_BIAS_MGAL,
    check_map_error_size,
    check_seed,
)
from jaxgrav.fields.map_error import map_error
from jaxgrav.match import METHODS
from jaxgrav.montecarlo import DEFAULT_CHUNK
from jaxgrav.montecarlo.filter_runs import FILTER_METHODS
from jaxgrav.scenarios import MatchingScenario
from jaxgrav.sim import DEG_ARC_M

__all__ = ["BYTES_PER_FIX", "LARGE_RUNS", "PAPER_D_AREA_DEG", "check_drift", "check_options",
           "check_results_size", "told_from_args"]

BYTES_PER_FIX = {"dense": 20e3, "chains": 20e3, "entropy+iccp": 40e3, "entropy": 15e3,
                 "iccp": 5e3, **dict.fromkeys(FILTER_METHODS, 2e3)}
"""Memory a run takes per fix (bytes; filters: per reading), by method: the growth of
the process's peak resident memory over a one-run baseline (about 0.9 GB), measured
with ``--fixes`` 150–7200 and chunks of 64–256 runs (dense 9.4 kB, entropy+iccp 31 kB,
ukf 1.4 kB a fix and run), rounded up about 2 x. XLA's memory analysis of the vmapped
run (110 kB for dense) counts buffers that are never live at once and refused runs that
needed 1.5 GB. :func:`check_options` refuses a ``--fixes`` or ``--chunk`` the user gave
whose estimate exceeds 80 % of the machine's memory."""

MATCHER_METHODS = METHODS
"""Methods that take noiseless readings (``--noise 0``: paper A's setting; the matchers
weight by at least 0.1 mGal)."""

_BASELINE_BYTES = 1e9  # a one-run process (JAX, the map, the compiled program), rounded up

_DEFAULT_FIXES = {"dense": 30, "chains": 30, "entropy": 60, "iccp": 60, "entropy+iccp": 60}
"""The builders' default fixes per track (filters: 721 readings)."""

PAPER_D_AREA_DEG = 0.7
"""Side of paper D's match area (23.9-24.6 N, 122.6-123.3 E; degrees): the "map" of the
filter methods over its three point masses, for :func:`check_drift`."""


LARGE_RUNS = 10_000
"""From this many runs :func:`check_results_size` measures a run's results (tracing the
method once, about 1 s) and checks and announces their size."""

_KEY_BYTES = 16  # a run's PRNG key, split on the device and copied to the host


def check_results_size(args, spec, out):
    """Refuse ``--runs`` whose results exceed the memory or the disk; announce a large one.

    From :data:`LARGE_RUNS` runs, one run's results are measured (``jax.eval_shape`` of
    the method, no run computed): the runner keeps every run's results and key in memory
    until the NetCDF is written (counted twice: the file is written from a copy), and the
    NetCDF holds them uncompressed. ValueError naming ``--runs`` when that needs more than
    80 % of the machine's memory or more than the free space of ``out``'s folder;
    otherwise one line on stdout with the sizes (``--runs 1e9`` started splitting 16 GB
    of keys, silently).
    """
    if args.runs < LARGE_RUNS:
        return
    shapes = jax.eval_shape(spec.fn, jax.random.key(0), *spec.args)
    per_run = sum(leaf.size * leaf.dtype.itemsize for leaf in jax.tree.leaves(shapes))
    need = _BASELINE_BYTES + args.runs * (_KEY_BYTES + 2 * per_run)
    size = args.runs * per_run
    (budget, total), runs = memory_budget(), f"{args.runs:.3g}" if args.runs >= 1e7 else args.runs
    if budget and need > budget:
        fit = int((budget - _BASELINE_BYTES) // (_KEY_BYTES + 2 * per_run))
        raise ValueError(f"--runs {runs} needs about {need / 1e9:.3g} GB of memory "
                         f"({per_run} bytes of results and {_KEY_BYTES} of key a run, kept "
                         f"until the file is written), more than 80 % of this machine's "
                         f"{total / 1e9:.3g} GB; expected at most {fit} runs (run more batches "
                         "with other --seed values)")
    free = shutil.disk_usage(Path(out).resolve().parent).free
    if size > free:
        raise ValueError(f"--runs {runs} writes about {size / 1e9:.3g} GB to --out {out} "
                         f"({per_run} bytes a run), more than the {free / 1e9:.3g} GB free in "
                         "its folder; expected fewer --runs or another folder")
    when = ("no time estimate with --no-progress" if args.no_progress else
            "the progress bar estimates the time after the first compiled call")
    print(f"jaxgrav montecarlo: {runs} runs hold about {need / 1e9:.3g} GB in memory and "
          f"write about {size / 1e6:.3g} MB to {out} ({per_run} bytes a run); {when}")


def check_options(args):
    """ValueError naming the option for a numeric option out of range.

    ``--seed`` from 0 to 2**63 - 1; ``--runs``, ``--chunk``, ``--devices`` at least 1;
    ``--devices`` at most ``--runs`` (a warning for a ``--chunk`` rounded up to a multiple
    of ``--devices``, see :func:`_check_devices`);
    ``--drift`` a finite angle > 0; ``--noise`` a finite standard deviation > 0 (>= 0 for
    the matchers); ``--fixes`` at least 5 (unset options take the method's defaults and
    are not checked here); a
    ``--fixes`` or ``--chunk`` given within 80 % of the machine's memory
    (:data:`BYTES_PER_FIX`).
    """
    for name, value in (("--runs", args.runs), ("--chunk", args.chunk)):
        if value is not None and value < 1:
            raise ValueError(f"{name} must be a positive number of runs; got {value}")
    check_seed(args.seed)
    if args.devices is not None and args.devices < 1:
        raise ValueError(f"--devices must be at least 1; got {args.devices}")
    if args.drift is not None and not (math.isfinite(args.drift) and args.drift > 0):
        raise ValueError(f"--drift must be a finite positive angle (degrees of arc); got "
                         f"{args.drift:g}")
    # 0 weights a filter's readings infinitely: its NEES reached 4e8, no flag; the
    # matchers take noiseless readings (paper A's) and weight them by at least 0.1 mGal
    zero_ok = args.method in MATCHER_METHODS
    # 1e30 ran (every fix rejected, exit 0); simulate refuses above the same bound
    if args.noise is not None and not (math.isfinite(args.noise) and args.noise <= MAX_BIAS_MGAL
                                       and (args.noise >= 0 if zero_ok else args.noise > 0)):
        raise ValueError(f"--noise must be a finite standard deviation {'>=' if zero_ok else '>'}"
                         f" 0 (mGal) for --method {args.method}, at most {MAX_BIAS_MGAL:g} (a "
                         f"marine gravimeter's is about 1); got {args.noise:g}")
    if args.fixes is not None and args.method.startswith("voyage-"):
        raise ValueError(f"--fixes is not an option of {args.method}: a voyage runs over "
                         "--hours (default 12)")  # (--fixes 3 was refused as below 5)
    if args.fixes is not None and args.fixes < 5:
        raise ValueError(f"--fixes must be at least 5 per track (filters: readings per run); "
                         f"got {args.fixes}")
    _check_memory(args)
    _check_devices(args)  # last: its warning only for options that are otherwise fine


def _check_devices(args):
    """Refuse ``--devices`` above ``--runs``; warn of a ``--chunk`` rounded up to a
    multiple of ``--devices``.

    Each device takes whole runs: a call of the runner holds ``min(--chunk, --runs)``
    runs rounded up to a multiple of the devices, the extra slots filled with copies of
    a run whose results are dropped. With more devices than runs, the extra devices only
    compute such copies (and the summary and the file would name devices that did no
    run), so it is refused. A ``--chunk`` below ``--runs`` that is not a multiple of
    ``--devices`` is merely enlarged (more runs and memory a call than asked): one
    warning line on stderr.
    """
    if args.devices is None:
        return
    if args.devices > args.runs:
        raise ValueError(f"--devices {args.devices} is more than --runs {args.runs}: each "
                         "device takes whole runs, so the extra devices would only compute "
                         f"copies that are dropped; give --devices at most {args.runs} (or "
                         "more --runs)")
    chunk = args.chunk or DEFAULT_CHUNK
    if chunk < args.runs and chunk % args.devices:
        size = math.ceil(chunk / args.devices) * args.devices
        print(f"jaxgrav montecarlo: warning: --chunk {chunk} is not a multiple of --devices "
              f"{args.devices}: each compiled call holds {size} runs (and their memory), not "
              f"{chunk}; give a --chunk that is a multiple of --devices", file=sys.stderr)


def _check_memory(args):
    """Refuse a ``--fixes`` or ``--chunk`` given that needs more than 80 % of the memory."""
    per_fix, (budget, total) = BYTES_PER_FIX.get(args.method), memory_budget()
    if per_fix is None or not budget or (args.fixes is None and args.chunk is None):
        return  # a voyage (sized by --hours), a method registered elsewhere, the defaults
    fixes = args.fixes or _DEFAULT_FIXES.get(args.method, 721)
    chunk = min(args.chunk or DEFAULT_CHUNK, args.runs)
    room = budget - _BASELINE_BYTES
    need = per_fix * fixes * chunk
    if need <= room:
        return
    fit_chunk = int(room // (per_fix * fixes))
    fit_fixes = int(room // (per_fix * chunk))
    cure = (f"use --chunk {fit_chunk} or less" if fit_chunk >= 1 else
            f"use --fixes {fit_fixes} or fewer" if fit_fixes >= 5 else
            "use fewer --fixes and a smaller --chunk")
    given = "" if args.fixes else " (the default)"
    raise ValueError(f"--fixes {fixes}{given} with {chunk} runs per compiled call (--chunk) "
                     f"needs about {(need + _BASELINE_BYTES) / 1e9:.3g} GB for --method "
                     f"{args.method} ({per_fix / 1e3:g} kB a fix and run), more than 80 % of "
                     f"this machine's {total / 1e9:.3g} GB; {cure}")


def check_drift(args, grid, kind):
    """ValueError naming ``--drift`` when the INS error it sets does not fit on the map.

    Matchers search a disc of radius ``--drift`` around the INS track, filters and
    voyages start with that position error: ``2 x --drift`` (degrees of arc) must stay
    below the map's shorter side (east-west scaled by the cosine of its mid-latitude),
    the rule of ``jaxgrav match --drift-radius``. Without a grid (the filters over paper
    D's three point masses) the side is :data:`PAPER_D_AREA_DEG`.
    """
    if args.drift is None:
        return
    if grid is None:
        side, what = PAPER_D_AREA_DEG, "paper D's match area over its point masses"
    else:
        w, e, s, n = (float(v) for v in grid.extent)
        side = min(n - s, (e - w) * math.cos(math.radians((s + n) / 2)))
        what = f"the map ({n - s:.3g} x {e - w:.3g} degrees, lat x lon)"
    if 2 * args.drift >= side:
        use = "search radius" if kind == "matcher" else "initial position error"
        km = args.drift * DEG_ARC_M / 1e3
        raise ValueError(f"--drift {args.drift:g} degrees of arc ({km:.0f} km, the {use}) "
                         f"spans {2 * args.drift:g} degrees, more than "
                         f"{what}, {side:.3g} degrees of arc across; expected a drift below "
                         f"{side / 2:.3g} degrees")
    if kind != "matcher" or grid is None:  # a filter may start where it is known to be
        return
    default = MatchingScenario()  # the matchers' runs (paper A's scenario)
    noise = default.noise_mgal if args.noise is None else args.noise
    fixes = default.n_fixes if args.fixes is None else args.fixes
    text, least_m = unresolved(grid, 2.0 * args.drift * DEG_ARC_M, fixes, noise)
    if text is not None:  # --drift 1e-12 ran the runs, each fix the INS's
        raise ValueError(f"--drift {args.drift:g} degrees of arc (the search radius, "
                         f"{args.drift * DEG_ARC_M:.3g} m) searches a region across which "
                         f"{text}: every position in it would fit as the INS track does; "
                         f"expected a --drift of at least {least_m / 2 / DEG_ARC_M:.2g} "
                         "degrees of arc")


def told_from_args(args):
    """The ``map_error_told`` of ``--told-map-error SIGMA[,L]``: ``"auto"`` when absent,
    None for σ = 0, else a CorrelatedMapError. ValueError naming the option for a value
    that is not one or two numbers, σ negative, NaN or inf, L not finite and > 0."""
    text = args.told_map_error
    if text is None:
        return "auto"
    if str(text).strip().lower() == "none":
        return None
    parts = str(text).split(",")
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        nums = None
    if nums is None or len(nums) not in (1, 2):
        raise ValueError(f"--told-map-error must be SIGMA or SIGMA,L (numbers: map units, m) "
                         f"or none for --method dense; got {text!r}")
    sigma = nums[0]
    if not (math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"--told-map-error SIGMA must be a finite standard deviation >= 0 "
                         f"(map units, 0 = white-noise matcher); got {sigma!r}")
    check_map_error_size(sigma, "--told-map-error SIGMA")
    length = nums[1] if len(nums) == 2 else (
        DEFAULT_MAP_ERROR_LENGTH_M if args.map_error_length is None else args.map_error_length)
    if sigma > 0 and not (math.isfinite(length) and length > 0):
        raise ValueError(f"--told-map-error L must be a finite correlation length > 0 (m); "
                         f"got {length!r}")
    return None if sigma == 0 else map_error(sigma, length)
