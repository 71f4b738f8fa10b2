"""Map matching of one track: correlation-extremum matching (dense offsets, iso-point
chains) and entropy + ICCP matching.

:func:`match_track` is the validated entry point for one track, with ``method`` in
:data:`METHODS` (``dense``, ``chains``, ``entropy``, ``iccp``, ``entropy+iccp``); its
status bits are in the one table :data:`STATUS` (:func:`status_messages`).
``match_dense``, ``match_chains``, ``match_entropy``, ``match_iccp`` and
``match_entropy_iccp`` are the jitted single-track cores to ``jax.vmap`` over many;
each takes a :class:`~jaxgrav.grid.Grid` or a :class:`~jaxgrav.prepared.PreparedMap`
(the map prepared once, passed as data).

``match_track_b``, ``METHODS_B`` and ``status_messages_b`` are deprecated (one
release): use ``match_track``, ``METHODS`` and ``status_messages``.
"""

from jaxgrav.match import entropy_iccp as _entropy_iccp
from jaxgrav.match.api import ENTROPY_HALF_SIZE, METHODS, MIN_FIXES, match_track, validate_track
from jaxgrav.match.combined import match_entropy_iccp
from jaxgrav.match.correlation import ChainConfig, match_chains
from jaxgrav.match.dense import DenseConfig, lattice_table, match_dense
from jaxgrav.match.entropy import (
    EntropyConfig,
    difference_entropy,
    entropy_config_for,
    information_entropy,
    match_entropy,
    sequence_entropy,
)
from jaxgrav.match.entropy_iccp import match_track_b, status_messages_b
from jaxgrav.match.iccp import IccpConfig, kabsch_2d, match_iccp, match_iccp_batch
from jaxgrav.match.offsets import shifted_tracks
from jaxgrav.match.result import (
    IMPLAUSIBLE_FIT,
    P_IMPLAUSIBLE,
    STATUS,
    MatchResult,
    fit_p_value,
    status_messages,
)
from jaxgrav.match.scoring import SCORES, bias_precision, decreasing_weights, score_track
from jaxgrav.match.sizing import CHAIN_NODE_DEG, chain_grid, config_for, iccp_config_for
from jaxgrav.match.suitability import DESCRIPTORS, Suitability, suitability
from jaxgrav.prepared import PreparedMap, prepare_map

__all__ = [
    "CHAIN_NODE_DEG",
    "DESCRIPTORS",
    "ENTROPY_HALF_SIZE",
    "IMPLAUSIBLE_FIT",
    "METHODS",
    "MIN_FIXES",
    "P_IMPLAUSIBLE",
    "SCORES",
    "STATUS",
    "ChainConfig",
    "DenseConfig",
    "EntropyConfig",
    "IccpConfig",
    "MatchResult",
    "PreparedMap",
    "Suitability",
    "bias_precision",
    "chain_grid",
    "config_for",
    "decreasing_weights",
    "difference_entropy",
    "entropy_config_for",
    "fit_p_value",
    "iccp_config_for",
    "information_entropy",
    "kabsch_2d",
    "lattice_table",
    "match_chains",
    "match_dense",
    "match_entropy",
    "match_entropy_iccp",
    "match_iccp",
    "match_iccp_batch",
    "match_track",
    "match_track_b",
    "prepare_map",
    "score_track",
    "sequence_entropy",
    "shifted_tracks",
    "status_messages",
    "status_messages_b",
    "suitability",
    "validate_track",
]


def __getattr__(name):
    """Deprecated constants (``METHODS_B``), with a ``DeprecationWarning``."""
    if name in ("METHODS_B", "ALL_STATUS_B"):
        return getattr(_entropy_iccp, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
