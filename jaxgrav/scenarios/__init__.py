"""The papers' simulated experiments as scenario objects: one PRNG key in, one run out.

This package is the only place where library code is named after a paper:

- :mod:`~jaxgrav.scenarios.paper_a`: correlation-extremum matching (constant INS offset);
- :mod:`~jaxgrav.scenarios.paper_b`: entropy + ICCP matching (offset and rotated INS);
- :mod:`~jaxgrav.scenarios.paper_c`: the climbing DOV trajectory over Qinling;
- :mod:`~jaxgrav.scenarios.paper_d`: UKF filtering across a point-mass anomaly;
- :mod:`~jaxgrav.scenarios.voyage`: hours-long voyages (``patrol-12h``, ``transit-24h``).

Every scenario is a frozen dataclass pytree; ``vmap`` the scenario function over keys
(or hand it to :func:`jaxgrav.montecarlo.run`).
"""

from jaxgrav.scenarios.paper_a import MatchingRun, MatchingScenario, matching_scenario
from jaxgrav.scenarios.paper_b import PaperBScenario, paper_b_scenario
from jaxgrav.scenarios.paper_c import PaperTrajectory, paper_c_trajectory
from jaxgrav.scenarios.paper_d import (
    FilterRun,
    FilterScenario,
    filter_scenario,
    initial_state,
    run_metrics,
    run_steps,
)
from jaxgrav.scenarios.voyage import (
    INS_GRADES,
    NAVIGATION_GRADE,
    PRESETS,
    VoyageScenario,
    voyage_preset,
    voyage_scenario,
)
from jaxgrav.sim.trajectory import track_error_m

__all__ = [
    "INS_GRADES",
    "NAVIGATION_GRADE",
    "PRESETS",
    "FilterRun",
    "FilterScenario",
    "MatchingRun",
    "MatchingScenario",
    "PaperBScenario",
    "PaperTrajectory",
    "VoyageScenario",
    "filter_scenario",
    "initial_state",
    "matching_scenario",
    "paper_b_scenario",
    "paper_c_trajectory",
    "run_metrics",
    "run_steps",
    "track_error_m",
    "voyage_preset",
    "voyage_scenario",
]
