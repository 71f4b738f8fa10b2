"""Gravity/INS filtering (paper D): UKF, EKF and a grid point-mass filter.

All filters share the measurement of :mod:`jaxgrav.match.filters.model` and the
INS error model of :mod:`jaxgrav.sim.ins`; each is an optax-style ``init`` /
``update`` pair run with ``lax.scan`` (:func:`run_filter`; ``every=k`` updates only on
the reading steps of a fixed stride) and vmapped over runs. :func:`guard_run` holds
back the position corrections in weakly observed directions (paper D's "no harm").
"""

from jaxgrav.match.filters.gaussian_sum import GaussianSumState, gaussian_sum, split_prior
from jaxgrav.match.filters.guard import GuardConfig, free_covariance, guard_infos, guard_run
from jaxgrav.match.filters.kalman import ekf, predict, sigma_weights, ukf
from jaxgrav.match.filters.model import (
    STATUS_FILTER,
    Dynamics,
    Filter,
    FilterState,
    MapPlusBias,
    Step,
    StepInfo,
    gravity_measurement,
    map_anomaly,
    map_at_error,
    predict_only,
    run_filter,
    status_messages_filter,
)
from jaxgrav.match.filters.paper_d import (
    FilterRun,
    FilterScenario,
    filter_scenario,
    initial_state,
    run_metrics,
    run_steps,
)
from jaxgrav.match.filters.pmf import PMFState, pmf, run_pmf

__all__ = [
    "STATUS_FILTER",
    "Dynamics",
    "Filter",
    "FilterRun",
    "FilterScenario",
    "FilterState",
    "GaussianSumState",
    "GuardConfig",
    "MapPlusBias",
    "PMFState",
    "Step",
    "StepInfo",
    "ekf",
    "filter_scenario",
    "free_covariance",
    "gaussian_sum",
    "gravity_measurement",
    "guard_infos",
    "guard_run",
    "initial_state",
    "map_anomaly",
    "map_at_error",
    "pmf",
    "predict",
    "predict_only",
    "run_filter",
    "run_metrics",
    "run_pmf",
    "run_steps",
    "sigma_weights",
    "split_prior",
    "status_messages_filter",
    "ukf",
]
