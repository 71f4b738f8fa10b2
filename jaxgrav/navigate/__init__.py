"""Voyage navigation: map-aided INS over hours.

Loosely coupled (:func:`navigate_loose`: matcher fixes as position measurements of the
INS error Kalman filter) and tightly coupled (the gravity filters on the readings
directly) navigation over a :class:`~jaxgrav.sim.voyage_log.Voyage`, the voyage
figures (:func:`voyage_errors`, :func:`hourly_rms`), the block test of a filter's
innovations (:func:`innovation_blocks`) and the bound no estimator beats on a
simulated voyage (:func:`voyage_bound`).
"""

from jaxgrav.navigate.error_kf import (
    ErrorKFTables,
    error_kf_tables,
    fix_update,
    innovation_nis,
    spread,
)
from jaxgrav.navigate.innovation_blocks import (
    INNOVATION_BLOCK,
    InnovationBlocks,
    implausible_block_count,
    implausible_rows,
    innovation_blocks,
)
from jaxgrav.navigate.loose import (
    CHAIN_REACH_M,
    FIX_EVENTS,
    LOOSE_MATCHERS,
    LooseResult,
    eotvos_sigma,
    first_segment_ends,
    first_tables,
    fix_segment,
    less_cell,
    navigate_loose,
)
from jaxgrav.navigate.loose_config import DENSE_LOOP, SEGMENT_ERRORS, LooseConfig, loose_config
from jaxgrav.navigate.loose_match import loose_map
from jaxgrav.navigate.metrics import VoyageErrors, hourly_rms, voyage_errors, voyage_summary
from jaxgrav.navigate.tight import (
    TIGHT_METHODS,
    TightConfig,
    TightResult,
    navigate_tight,
    voyage_bound,
)
from jaxgrav.navigate.tight_reacquire import REACQUIRE_EVENTS, Reacquisition

__all__ = [
    "CHAIN_REACH_M",
    "DENSE_LOOP",
    "FIX_EVENTS",
    "INNOVATION_BLOCK",
    "LOOSE_MATCHERS",
    "REACQUIRE_EVENTS",
    "SEGMENT_ERRORS",
    "TIGHT_METHODS",
    "ErrorKFTables",
    "InnovationBlocks",
    "LooseConfig",
    "LooseResult",
    "Reacquisition",
    "TightConfig",
    "TightResult",
    "VoyageErrors",
    "eotvos_sigma",
    "error_kf_tables",
    "first_segment_ends",
    "first_tables",
    "fix_segment",
    "fix_update",
    "hourly_rms",
    "implausible_block_count",
    "implausible_rows",
    "innovation_blocks",
    "innovation_nis",
    "less_cell",
    "loose_config",
    "loose_map",
    "navigate_loose",
    "navigate_tight",
    "spread",
    "voyage_bound",
    "voyage_errors",
    "voyage_summary",
]
