"""Simulation: trajectories, INS drift and sensor readings."""

from jaxgrav.sim.drift import (
    DEG_ARC_M,
    Drift,
    apply_drift,
    drift_offsets,
    drift_sigma,
    rayleigh_quantile,
    rayleigh_sigma,
    sample_drift,
)
from jaxgrav.sim.readings import field_along, gravity_readings
from jaxgrav.sim.trajectory import (
    Track,
    random_start,
    straight_track,
    track_error_m,
    track_from_heading,
    turning_track,
)

__all__ = [
    "DEG_ARC_M",
    "Drift",
    "Track",
    "apply_drift",
    "drift_offsets",
    "drift_sigma",
    "field_along",
    "gravity_readings",
    "random_start",
    "rayleigh_quantile",
    "rayleigh_sigma",
    "sample_drift",
    "straight_track",
    "track_error_m",
    "track_from_heading",
    "turning_track",
]

# --- gravimeter signal chain of paper D (jaxgrav.sim.gravimeter, jaxgrav.sim.fir)
from jaxgrav.sim.fir import (
    PAPER_CUTOFF_RANGE,
    FilteredRecord,
    LowpassFIR,
    apply_fir,
    design_lowpass,
    estimate_numtaps,
    max_speed,
    min_map_spacing,
    signal_frequency,
)
from jaxgrav.sim.gravimeter import (
    Disturbances,
    GravimeterConfig,
    GravimeterRecord,
    PlatformModel,
    TiltKF,
    TiltKFState,
    eotvos_from_map,
    platform_discrete,
    platform_response,
    run_tilt_kf,
    simulate_gravimeter,
    tilt_correction,
    tilt_kalman,
)

# --- voyages: routes sailed by an autopilot, INS drift and readings over hours
from jaxgrav.sim.route import Route, great_circle, sail
from jaxgrav.sim.voyage import indicated_track, simulate_voyage
from jaxgrav.sim.voyage_log import Voyage

__all__ += ["Route", "Voyage", "great_circle", "indicated_track", "sail", "simulate_voyage"]
__all__ += [
    "PAPER_CUTOFF_RANGE",
    "Disturbances",
    "FilteredRecord",
    "GravimeterConfig",
    "GravimeterRecord",
    "LowpassFIR",
    "PlatformModel",
    "TiltKF",
    "TiltKFState",
    "apply_fir",
    "design_lowpass",
    "eotvos_from_map",
    "estimate_numtaps",
    "max_speed",
    "min_map_spacing",
    "platform_discrete",
    "platform_response",
    "run_tilt_kf",
    "signal_frequency",
    "simulate_gravimeter",
    "tilt_correction",
    "tilt_kalman",
]
