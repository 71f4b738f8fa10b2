"""``jaxgrav montecarlo``'s numeric options, range-checked in one place.

:func:`check_options` refuses a run count, chunk, device count, drift, noise or fix count
out of range with one line naming the option (``--noise``, not the library's
``noise``), before any map is read or anything compiled; :func:`told_from_args` parses
``--told-map-error SIGMA[,L]``.
"""

import math

from jaxgrav.cli.simulate import DEFAULT_MAP_ERROR_LENGTH_M
from jaxgrav.fields.map_error import map_error

__all__ = ["check_options", "told_from_args"]


def check_options(args):
    """ValueError naming the option for a numeric option out of range.

    ``--runs``, ``--chunk``, ``--devices`` at least 1; ``--drift`` a finite angle > 0;
    ``--noise`` a finite standard deviation ≥ 0; ``--fixes`` at least 5 (unset options
    take the method's defaults and are not checked here).
    """
    for name, value in (("--runs", args.runs), ("--chunk", args.chunk)):
        if value is not None and value < 1:
            raise ValueError(f"{name} must be a positive number of runs; got {value}")
    if args.devices is not None and args.devices < 1:
        raise ValueError(f"--devices must be at least 1; got {args.devices}")
    if args.drift is not None and not (math.isfinite(args.drift) and args.drift > 0):
        raise ValueError(f"--drift must be a finite positive angle (degrees of arc); got "
                         f"{args.drift:g}")
    if args.noise is not None and not (math.isfinite(args.noise) and args.noise >= 0):
        raise ValueError(f"--noise must be a finite standard deviation >= 0 (mGal); got "
                         f"{args.noise:g}")
    if args.fixes is not None and args.fixes < 5:
        raise ValueError(f"--fixes must be at least 5 per track (filters: readings per run); "
                         f"got {args.fixes}")


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
    length = nums[1] if len(nums) == 2 else (
        DEFAULT_MAP_ERROR_LENGTH_M if args.map_error_length is None else args.map_error_length)
    if sigma > 0 and not (math.isfinite(length) and length > 0):
        raise ValueError(f"--told-map-error L must be a finite correlation length > 0 (m); "
                         f"got {length!r}")
    return None if sigma == 0 else map_error(sigma, length)
