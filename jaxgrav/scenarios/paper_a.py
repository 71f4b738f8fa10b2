"""Ready-made simulation scenarios, one PRNG key in, one run out (vmap them).

``matching_scenario`` is paper A's experiment: a ship at constant velocity, an INS
whose error is a (nearly) constant offset, gravimeter readings of a true field.
It is what the demo, the paper-A example, the benchmarks and the Monte Carlo runner
simulate, so that they all mean the same thing by "a track".
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import sim
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.constants import KNOT

__all__ = ["MatchingRun", "MatchingScenario", "matching_scenario"]



@pytree_dataclass
class MatchingScenario:
    """Paper A's matching experiment.

    Attributes
    ----------
    region : tuple of float
        ``(lat_min, lat_max, lon_min, lon_max)`` where tracks may start (degrees);
        static.
    v_east, v_north : float
        Ship velocity (m/s); paper A: 10 kn each.
    dt : float
        Interval between fixes (s).
    drift_deg : float
        INS drift radius (degrees of arc): fixed size, or Rayleigh scale σ.
    drift_growth, drift_rotation_deg : float
        Growth and rotation of the drift along the track (0 = exactly parallel).
    noise_mgal, bias_mgal : float
        Reading noise σ and constant gravimeter bias (mGal).
    n_fixes : int
        Fixes per track (static).
    drift_law : {"fixed", "rayleigh"}
        Static.
    eotvos : {"full", "simple", None}
        Eötvös effect in the readings (static).
    truth_method : {"bicubic", "bilinear"}
        Interpolation of a Grid truth field (static).
    """

    region: tuple = static_field((24.0, 36.0, 124.0, 136.0))
    v_east: float = 10 * KNOT
    v_north: float = 10 * KNOT
    dt: float = 120.0
    drift_deg: float = 0.035
    drift_growth: float = 0.0
    drift_rotation_deg: float = 0.0
    noise_mgal: float = 1.0
    bias_mgal: float = 0.0
    n_fixes: int = static_field(30)
    drift_law: str = static_field("fixed")
    eotvos: str = static_field("full")
    truth_method: str = static_field("bicubic")

    @property
    def step_m(self):
        """Distance between consecutive fixes (m)."""
        return float(np.hypot(self.v_east, self.v_north) * self.dt)


class MatchingRun(NamedTuple):
    """One simulated run: true track, INS fixes, readings and the drift."""

    truth: sim.Track
    ins_lat: jax.Array
    ins_lon: jax.Array
    readings: jax.Array
    drift_north_m: jax.Array
    drift_east_m: jax.Array


def matching_scenario(key, truth_field, scenario=MatchingScenario()):  # noqa: B008
    """Simulate one matching run.

    The start point is uniform in ``scenario.region`` with a margin so that the
    whole track stays inside it; the drift direction is uniform.

    Parameters
    ----------
    key : PRNG key
    truth_field : Grid or callable
        Field the gravimeter senses (mGal).
    scenario : MatchingScenario

    Returns
    -------
    MatchingRun
    """
    k_start, k_drift, k_noise = jax.random.split(key, 3)
    s = scenario
    span = (s.n_fixes - 1) * s.dt
    dlat = abs(s.v_north) * span / sim.DEG_ARC_M
    dlon = abs(s.v_east) * span / (sim.DEG_ARC_M * jnp.cos(jnp.deg2rad(s.region[1])))
    margin = jnp.stack([
        jnp.where(s.v_north >= 0, 0.0, dlat), jnp.where(s.v_north >= 0, dlat, 0.0),
        jnp.where(s.v_east >= 0, 0.0, dlon), jnp.where(s.v_east >= 0, dlon, 0.0),
    ]) + 1.5 * s.drift_deg
    lat0, lon0 = sim.random_start(k_start, s.region, margin)
    truth = sim.straight_track(lat0, lon0, s.v_east, s.v_north, s.n_fixes, s.dt)
    drift = sim.sample_drift(k_drift, s.drift_deg * sim.DEG_ARC_M, growth=s.drift_growth,
                             rotation_deg=s.drift_rotation_deg, law=s.drift_law)
    dn, de = sim.drift_offsets(drift, s.n_fixes)
    ins_lat, ins_lon = sim.apply_drift(truth.lat, truth.lon, dn, de)
    g = sim.gravity_readings(k_noise, truth_field, truth, noise_mgal=s.noise_mgal,
                             bias_mgal=s.bias_mgal, eotvos_form=s.eotvos, method=s.truth_method)
    return MatchingRun(truth, ins_lat, ins_lon, g, dn, de)
