"""Map matching: correlation-extremum gravity matching (paper A) and entropy + ICCP
matching (paper B).

``match_track`` (paper A) and ``match_track_b`` (paper B) are the validated entry
points for one track; ``match_dense``, ``match_chains``, ``match_entropy``,
``match_iccp`` and ``match_entropy_iccp`` are the jitted single-track cores to
``jax.vmap`` over many.
"""

from jaxgrav.match.api import METHODS, MIN_FIXES, config_for, match_track
from jaxgrav.match.correlation import ChainConfig, match_chains
from jaxgrav.match.dense import DenseConfig, match_dense, shifted_tracks
from jaxgrav.match.entropy import (
    EntropyConfig,
    difference_entropy,
    entropy_config_for,
    information_entropy,
    match_entropy,
    sequence_entropy,
)
from jaxgrav.match.entropy_iccp import (
    METHODS_B,
    iccp_config_for,
    match_entropy_iccp,
    match_track_b,
    status_messages_b,
)
from jaxgrav.match.iccp import IccpConfig, kabsch_2d, match_iccp, match_iccp_batch
from jaxgrav.match.result import STATUS, MatchResult, status_messages
from jaxgrav.match.scoring import SCORES, bias_precision, decreasing_weights, score_track

__all__ = [
    "METHODS",
    "METHODS_B",
    "MIN_FIXES",
    "SCORES",
    "STATUS",
    "ChainConfig",
    "DenseConfig",
    "EntropyConfig",
    "IccpConfig",
    "MatchResult",
    "bias_precision",
    "config_for",
    "decreasing_weights",
    "difference_entropy",
    "entropy_config_for",
    "iccp_config_for",
    "information_entropy",
    "kabsch_2d",
    "match_chains",
    "match_dense",
    "match_entropy",
    "match_entropy_iccp",
    "match_iccp",
    "match_iccp_batch",
    "match_track",
    "match_track_b",
    "score_track",
    "sequence_entropy",
    "shifted_tracks",
    "status_messages",
    "status_messages_b",
]
