"""Gravity/INS filtering: UKF, EKF, Gaussian sum, grid point-mass and particle filters.

All filters share the measurement of :mod:`jaxgrav.filters.model` and the
INS error model of :mod:`jaxgrav.sim.ins`; each is an optax-style ``init`` /
``update`` / ``predict`` triple (:class:`Filter`) run by the one runner
:func:`run_filter` with ``lax.scan`` (``every=k`` updates only on the reading steps of
a fixed stride; :func:`pad_to_stride` puts a run's readings there) and vmapped over
runs. The map is prepared once per run (:func:`prepare_field`). :func:`guard_run` holds
back the position corrections in weakly observed directions (paper D's "no harm").
:func:`filter_track` is the validated single-track entry point. When the map is not
the truth, :func:`augment` appends a first- or second-order Gauss–Markov map-error
state (:mod:`jaxgrav.filters.map_state`) that the UKF, EKF and Gaussian sum carry
unchanged; the point-mass filter carries a first-order one per grid cell.
The particle filters — :func:`pf` (SIR over the whole state) and :func:`rbpf`
(particles over the position error, one shared Kalman covariance for the rest) — take
the same protocol and runner; ``run_filter(..., key=k)`` seeds them. :func:`pcrlb`
is the posterior Cramér–Rao bound any of them can be held against.
"""

from jaxgrav.filters.api import (
    FILTER_METHODS,
    PARTICLES,
    eotvos_part,
    filter_track,
    pad_to_stride,
    run_pmf,
)
from jaxgrav.filters.gaussian_sum import GaussianSumState, gaussian_sum, split_prior
from jaxgrav.filters.guard import GuardConfig, free_covariance, guard_infos, guard_run
from jaxgrav.filters.kalman import ekf, predict, sigma_weights, ukf
from jaxgrav.filters.map_state import (
    MapErrorState,
    augment,
    fogm_length,
    fogm_transition,
    map_error_measurement,
    map_error_state,
    matched_state,
    sogm_transition,
)
from jaxgrav.filters.model import (
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
    prepare_field,
    run_filter,
    status_messages_filter,
)
from jaxgrav.filters.particles import (
    RESAMPLERS,
    effective_sample_size,
    residual_resample,
    systematic_resample,
)
from jaxgrav.filters.pcrlb import PCRLBResult, pcrlb
from jaxgrav.filters.pf import ParticleState, pf
from jaxgrav.filters.pmf import PMFFilter, PMFState, pmf
from jaxgrav.filters.rbpf import RBPFState, rbpf

__all__ = [
    "FILTER_METHODS",
    "PARTICLES",
    "RESAMPLERS",
    "STATUS_FILTER",
    "Dynamics",
    "Filter",
    "FilterState",
    "GaussianSumState",
    "GuardConfig",
    "MapErrorState",
    "MapPlusBias",
    "PCRLBResult",
    "PMFFilter",
    "PMFState",
    "ParticleState",
    "RBPFState",
    "Step",
    "StepInfo",
    "augment",
    "effective_sample_size",
    "ekf",
    "eotvos_part",
    "filter_track",
    "fogm_length",
    "fogm_transition",
    "free_covariance",
    "gaussian_sum",
    "gravity_measurement",
    "guard_infos",
    "guard_run",
    "map_anomaly",
    "map_at_error",
    "map_error_measurement",
    "map_error_state",
    "matched_state",
    "pad_to_stride",
    "pcrlb",
    "pf",
    "pmf",
    "predict",
    "predict_only",
    "prepare_field",
    "rbpf",
    "residual_resample",
    "run_filter",
    "run_pmf",
    "sigma_weights",
    "sogm_transition",
    "split_prior",
    "status_messages_filter",
    "systematic_resample",
    "ukf",
]
