"""The record of one voyage: the true and the INS-indicated trajectories, the readings.

Shared by the voyage simulator (:mod:`jaxgrav.sim`), the navigation loops
(:mod:`jaxgrav.navigate`) and the ``simulate-voyage`` / ``navigate`` commands, so that a
simulated voyage and a user's log go through the same code.
"""

from typing import NamedTuple

import jax

from jaxgrav.sim.trajectory import Track

__all__ = ["Voyage"]


class Voyage(NamedTuple):
    """One voyage sampled at the INS step.

    Attributes
    ----------
    ins : Track
        INS-indicated trajectory: time (s), position (degrees) and velocity (m/s), each
        shape ``(N,)``. This is all a real navigation system sees, with ``gravity``. The
        navigation loops step at the mean step, ``(t[-1] − t[0]) / (N − 1)``: a row per
        step, no gaps (``jaxgrav navigate`` fills a log's with
        :func:`~jaxgrav.time_steps.on_steps`).
    gravity : Array, shape ``(N,)``
        Raw gravimeter anomaly (mGal) at the true position, Eötvös effect of the true
        velocity *not* corrected; NaN where there is no reading.
    truth : Track or None
        True trajectory, same times (simulations only; ``None`` for a user's log).
    ins_error : Array, shape ``(N, 13)``, or None
        True INS error states of :mod:`jaxgrav.sim.ins` (INS − true; simulations only).
    """

    ins: Track
    gravity: jax.Array
    truth: Track | None = None
    ins_error: jax.Array | None = None
