"""What a Monte Carlo method is: :class:`MethodSpec`, the metrics of every run, checks."""

from collections.abc import Callable

from jaxgrav import datasets
from jaxgrav._pytree import pytree_dataclass, static_field

__all__ = ["METRICS", "MethodSpec", "check_settings", "default_grid", "region_of"]

METRICS = ("ins_err_m", "err_m", "status")
"""Metrics every method returns per run."""


@pytree_dataclass
class MethodSpec:
    """A method ready for :func:`jaxgrav.montecarlo.run`.

    A pytree whose only data field is ``args`` (the rest is static).

    Attributes
    ----------
    fn : callable
        ``fn(key, *args) -> dict`` of per-run metrics (at least :data:`METRICS`).
    args : tuple
        Extra arguments of ``fn`` (map, scenario, configurations).
    settings : dict
        The resolved scenario settings and a one-line description (for file attributes).
    status_bits : dict of int to str
        Meaning of the ``status`` bits.
    """

    fn: Callable = static_field()
    args: tuple
    settings: dict = static_field()
    status_bits: dict = static_field()


def default_grid():
    """The shipped 2.5′ ``ryukyu`` gravity anomaly map (mGal), 24–36°N, 124–136°E."""
    return datasets.load("ryukyu")["anomaly_2p5min"]


def region_of(grid):
    """``(south, north, west, east)`` of a map (degrees), as scenarios take a region."""
    w, e, s, n = grid.extent
    return (float(s), float(n), float(w), float(e))


def check_settings(drift, noise, n):
    """One clear error for a non-positive drift, a negative noise or fewer than 5 fixes."""
    if not drift > 0:
        raise ValueError(f"drift must be a positive angle (degrees of arc); got {drift!r}")
    if not noise >= 0:
        raise ValueError(f"noise must be a non-negative standard deviation (mGal); got {noise!r}")
    if n < 5:
        raise ValueError(f"fixes must be at least 5 per track; got {n}")
