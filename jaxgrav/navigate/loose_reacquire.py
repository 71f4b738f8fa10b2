"""Re-acquisition: a loop whose fixes keep failing widens its own covariance.

The loop's search window, its prior on the offsets and the segment's error told to the
matcher all come from the filter's covariance. On a few voyages in a thousand the INS
error is a tail draw of the error model (a 2 m/s velocity error after an hour, where the
filter expects a few tenths), or one wrong fix leaves the filter confidently off: the
truth is then outside the window, every later fix lands on the window's edge (or its
readings do not fit the segment), and, with nothing
accepted, the filter's covariance grows only as fast as the error model says — slower
than that voyage's error. The loop never gets back (docs/voyages.md: on the perfect map,
seed 0, three such voyages carried 83 % of the last hour's mean square error).

A run of ``reacquire_after`` such failures is taken as what it is, evidence that the
filter is off by more than it says: after each failure of the run the whole covariance is
multiplied by ``reacquire_inflation`` (a fading memory, the state's correlations kept),
so the next window is wider, the prior on the offsets weaker and the segment's bend told
to the matcher larger; the fix that re-acquires is then weighed against that broader
prior, and its posterior is what the filter keeps. Its readings must still fit the
segment (the shape test: without it, on the perfect map, seed 1, a wrong fix in the
widened window led one voyage 200 km off), but they do not update the rest of the state
(``LooseConfig.reacquire_skip_shape``: the filter was off by more than it said, so the
linearised shape update from there is not to be trusted). An accepted fix ends the run.
A fix rejected for a reason that says nothing about the filter (a posterior too wide,
two modes: a flat or ambiguous map) neither counts nor ends it.
"""

import jax.numpy as jnp

from jaxgrav.match.correlation import ChainConfig
from jaxgrav.match.dense import DenseConfig
from jaxgrav.match.integrity import largest_sigma
from jaxgrav.navigate.loose_match import CHAIN_REACH_M
from jaxgrav.sim.drift import rayleigh_quantile

__all__ = ["LOST_STATUS", "lost_fix", "reacquire", "widest_reach_m"]

LOST_STATUS = 4096 | 2048
"""Matcher status bits of a rejection that says the truth may be outside the window:
posterior mass on the search edge (4096) or a misfit inconsistent with the error model
(2048)."""


def widest_reach_m(config):
    """The farthest (m) the loop's matcher can search from the corrected segment.

    Parameters
    ----------
    config : LooseConfig

    Returns
    -------
    float
        The offset grid's ``half_size · max_spacing_m`` (dense, entropy+ICCP), or the
        chains' fixed window :data:`~jaxgrav.navigate.loose_match.CHAIN_REACH_M`.
    """
    m = config.matcher
    if isinstance(m, ChainConfig):
        return CHAIN_REACH_M
    offsets = m if isinstance(m, DenseConfig) else m[0]
    return offsets.half_size * config.max_spacing_m


def lost_fix(event, status):
    """Whether a segment end's outcome says the filter may be off by more than it states.

    Parameters
    ----------
    event : Array of int
        :data:`~jaxgrav.navigate.loose.FIX_EVENTS` code.
    status : Array of int
        The matcher's status bits.

    Returns
    -------
    Array of bool
        True for a fix on the window's edge or misfitting (event 3 with
        :data:`LOST_STATUS`) or whose readings do not fit the segment (event 5). Not a
        fix the innovation gate rejected (event 4): that is mostly a wrong mode far from
        an honest filter, and widening the covariance for it would let the same wrong
        mode through at the next end.
    """
    edge = (event == 3) & ((status & LOST_STATUS) != 0)
    return edge | (event == 5)


def reacquire(config, p, run, event, status):
    """The covariance after a segment end, widened on a run of failed fixes.

    Parameters
    ----------
    config : LooseConfig
        Its ``reacquire_after`` (static; None: never) and ``reacquire_inflation``.
    p : Array, shape ``(13, 13)``
        The filter's covariance after the segment end.
    run : Array of int
        Failed fixes in a row before this segment end.
    event, status : Array of int
        This segment end's outcome (:func:`lost_fix`).

    Returns
    -------
    p : Array, shape ``(13, 13)``
        ``p × reacquire_inflation`` when this end failed and the run has reached
        ``reacquire_after``, else ``p``.
    run : Array of int
        The run's length after this end: 0 after an accepted fix, one more after a failed
        one, unchanged otherwise.
    """
    lost = lost_fix(event, status)
    run = jnp.where(lost, run + 1, jnp.where(event == 0, 0, run)).astype(run.dtype)
    if config.reacquire_after is None:
        return p, run
    widen = lost & (run >= config.reacquire_after)
    # no wider than the widest window the matcher can search: beyond it a larger
    # covariance only weakens the prior and the fix's weight, it finds nothing further off
    sigma = widest_reach_m(config) / rayleigh_quantile(1.0, config.window_p)
    room = sigma**2 / largest_sigma(p[:2, :2]) ** 2
    factor = jnp.clip(room, 1.0, config.reacquire_inflation)
    return jnp.where(widen, factor * p, p), run
