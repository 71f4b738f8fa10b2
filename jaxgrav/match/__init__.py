"""Map matching: correlation-extremum gravity matching (paper A).

``match_track`` is the validated entry point for one track; ``match_dense`` and
``match_chains`` are the jitted single-track cores to ``jax.vmap`` over many.
"""

from jaxgrav.match.api import METHODS, MIN_FIXES, config_for, match_track
from jaxgrav.match.correlation import ChainConfig, match_chains
from jaxgrav.match.dense import DenseConfig, match_dense, shifted_tracks
from jaxgrav.match.result import STATUS, MatchResult, status_messages
from jaxgrav.match.scoring import SCORES, bias_precision, decreasing_weights, score_track

__all__ = [
    "METHODS",
    "MIN_FIXES",
    "SCORES",
    "STATUS",
    "ChainConfig",
    "DenseConfig",
    "MatchResult",
    "bias_precision",
    "config_for",
    "decreasing_weights",
    "match_chains",
    "match_dense",
    "match_track",
    "score_track",
    "shifted_tracks",
    "status_messages",
]
