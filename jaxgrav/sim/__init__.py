"""Simulation: trajectories, INS drift and sensor readings."""

from jaxgrav.sim.drift import (
    DEG_ARC_M,
    Drift,
    apply_drift,
    drift_offsets,
    rayleigh_quantile,
    rayleigh_sigma,
    sample_drift,
)
from jaxgrav.sim.readings import field_along, gravity_readings
from jaxgrav.sim.trajectory import (
    Track,
    random_start,
    straight_track,
    track_from_heading,
    turning_track,
)

__all__ = [
    "DEG_ARC_M",
    "Drift",
    "Track",
    "apply_drift",
    "drift_offsets",
    "field_along",
    "gravity_readings",
    "random_start",
    "rayleigh_quantile",
    "rayleigh_sigma",
    "sample_drift",
    "straight_track",
    "track_from_heading",
    "turning_track",
]
