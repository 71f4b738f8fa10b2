"""Tightly coupled navigation: the gravity filters on a voyage's readings, reading by reading.

Where the loosely coupled loop (:mod:`~jaxgrav.navigate.loose`) matches an hour of
readings into one position fix, here every reading updates the 13-state INS error
filter directly (UKF, EKF, Gaussian sum or Rao–Blackwellised particle filter of
:mod:`jaxgrav.filters`), with the same error model the voyage is simulated with,
discretised once at the voyage's mean latitude.

**Particles** (``rbpf``, :func:`~jaxgrav.filters.rbpf`): particles over the horizontal
position error, each with the Gaussian of the other states (velocity, attitude, sensor
biases, gravimeter bias, map error), which the reading, the Eötvös part included, is
linear in. No linearisation of the map, so no curvature term; a multimodal position
(a ship on a flat or repetitive stretch) stays multimodal instead of locking onto one
mode. Its draws come from ``key``.

**Grid** (``pmf``, :func:`~jaxgrav.filters.pmf`): Bergman's point-mass filter, the
position error on a grid that follows the estimate and re-sizes its cells to the
spread, each cell with its gravimeter bias (and first-order map error), the other
states one Gaussian conditional on the position; the Eötvös part of a reading updates
that Gaussian cell by cell (:mod:`~jaxgrav.filters.pmf_linear`). No gate.

**Eötvös, as a real system must.** The gravimeter reads the true field minus the
Eötvös effect of the *true* velocity; the navigation system corrects it with the
INS velocity, ``z = g_raw + E(v_INS)``. What is left is the Eötvös effect of the INS
velocity error, ``E(v_INS) − E(v_true) ≈ ∂E/∂v · δv`` — 12.6 mGal per m/s east at
30° N, more than the map error for a navigation-grade INS. The measurement carries it
as a known linear part (:attr:`~jaxgrav.filters.Step.h_lin`, the Jacobian of
:func:`~jaxgrav.geodesy.eotvos_jacobian` at the INS velocity, in the velocity-error columns), so
the filter estimates the velocity error from it instead of taking it for map or bias:

    z = Δg_M(p_INS − δp) + δg_a + ε_map + ∂E/∂v · δv + noise.

**Map error.** With ``map_error`` set, a first- or second-order Gauss–Markov map-error
state (:func:`~jaxgrav.filters.augment`) over the distance sailed (τ = L / the INS's
mean speed, time at rest included) is appended after the 13 INS states.

**Linearisation error, correlated.** Where the map is flat against its error the position
error grows to kilometres, and the filter linearises the map at its own, wrong, position.
That error is not white: consecutive readings 50 m apart share it for as long as the
ship is in the same map cell (2.5′ ≈ 4.6 km, ~90 readings at 10 kn and 10 s). Taken as
independent it is counted ~90 times, and the filter locks confidently onto a wrong
track with white innovations (an EKF linearised at the *true* position does not drift).
The UKF (``ukf``, ``gsf``) therefore adds the map's second-order term over the predicted
position covariance, ``½ tr((∇²Δg_M P)²)``, times the readings per map cell
(``curvature_cells`` cells of the map's mean node spacing over the INS's mean distance
per step while sailing, above :data:`MOVING_MS`, times the share of steps that carry a
reading), to the reading variance:
nothing where the position is well known, the reading's share of a cell where it is not.

A missing reading (NaN) or a sigma point off the map skips the update (status flags of
:data:`~jaxgrav.filters.STATUS_FILTER`): a voyage that leaves the map goes on on the
INS prediction, and says so row by row.
"""

import numbers
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import concrete
from jaxgrav.filters import (
    Dynamics,
    MapErrorState,
    Step,
    augment,
    ekf,
    eotvos_part,
    gaussian_sum,
    gravity_measurement,
    pcrlb,
    pmf,
    rbpf,
    run_filter,
    ukf,
)
from jaxgrav.filters.pmf_cells import MISSING
from jaxgrav.geodesy import eotvos, eotvos_jacobian
from jaxgrav.navigate.loose_config import LooseConfig
from jaxgrav.navigate.tight_reacquire import Reacquisition, run_reacquiring
from jaxgrav.sim.drift import apply_drift
from jaxgrav.sim.ins import VEL, INSErrorModel, initial_covariance, transition
from jaxgrav.sim.trajectory import Track

__all__ = ["MOVING_MS", "TIGHT_METHODS", "TightConfig", "TightResult", "navigate_tight",
           "voyage_bound"]

MOVING_MS = 0.5
"""Rows slower than this (m/s) are at rest: the readings-per-cell count of the curvature
term is taken over the sailing rows (and never below this speed)."""

TIGHT_METHODS = ("ukf", "ekf", "gsf", "rbpf", "pmf")
"""The filters :func:`navigate_tight` runs (``gsf``: a 3 × 3 Gaussian sum of UKFs;
``rbpf``: the Rao–Blackwellised particle filter; ``pmf``: the grid point-mass filter)."""


@pytree_dataclass
class TightConfig:
    """Settings of the tightly coupled filter.

    Attributes
    ----------
    ins : INSErrorModel
        The filter's INS error model.
    sigma_pos_m, sigma_vel : float
        Initial 1-σ position (m) and velocity (m/s) error per axis.
    noise_mgal : float
        1-σ of a reading's white noise (mGal).
    map_error : MapErrorState or None
        The map's error told to the filter (:func:`~jaxgrav.filters.map_error_state`);
        None: no map-error state (a perfect map).
    gate : float
        Skip readings whose normalised innovation squared exceeds this (1 degree of
        freedom; ``inf``: never).
    method : {"ukf", "ekf", "gsf", "rbpf", "pmf"}
        The filter (static).
    n_particles : int
        Particles of ``rbpf`` (static, ≥ 2; default 500).
    pmf_cells : int
        Cells per axis of ``pmf``'s grid (static, odd; default 61).
    pmf_cell_m : float
        Its first cell size (m; default 100; static: the block of map nodes from which
        the cells' map values are evaluated as one lattice is sized from it). The grid
        is adaptive: it follows the estimate and re-sizes its cells to span
        ±``pmf_span`` σ of the weights (between a quarter and 8 × this size).
    pmf_span : float
        σ the adaptive grid spans at least per side (static; default 4; it is re-sized
        to span 1.4 × this when it spans fewer or more than 1.4 × this,
        :mod:`~jaxgrav.filters.pmf_grid`; 0: a fixed grid of ``pmf_cell_m`` cells).
    pmf_resolve : float
        The adaptive grid's cells are kept small enough that the map changes from one cell
        to the next by at most this many of the reading's predictive 1-σ where the weights
        are (static; default 0.5; 0: no bound; :func:`~jaxgrav.filters.pmf`'s ``resolve``).
    pmf_q_pos : float
        Its extra random-walk density of the position error (m²/s; default 0.25, the
        ``jaxgrav filter`` value at this ``sigma_vel``).
    rbpf_q_pos : float
        ``rbpf``'s extra random walk of the particles' position (m²/s; default 1,
        :func:`~jaxgrav.filters.rbpf`'s ``q_pos``): on 100-patrol samples (seeds 0 / 1 / 2)
        it took the last-hour ratio from 0.269 / 0.088 / 0.204 to 0.106 / 0.095 / 0.154
        and the NEES from 423 / 4.6 / 10.8 to 3.9 / 4.1 / 6.9.
    pmf_missing : {"gaps", "land"}
        How ``pmf`` reads a cell on a missing (NaN) map node (static; default "gaps":
        unknown; "land": the vehicle cannot be there; :func:`~jaxgrav.filters.pmf`).
    curvature_cells : float
        Map cells over which the map's linearisation error is taken as correlated (see
        the module notes; ``ukf`` and ``gsf``); 0: off. Default 8 (1 until 2026-12-07):
        chosen for an honest NEES on three sets of 1000 12 h patrols (3 mGal map error
        told, seeds 0 / 1 / 2): NEES 1.87 / 2.05 / 1.94 against 2.89 / 4.01 / 2.99 with
        1 cell, and last-hour RMS / the free INS's 0.105 / 0.121 / 0.113 against
        0.126 / 0.130 / 0.125 (docs/voyages.md).
    eotvos_velocity : bool
        Carry the Eötvös effect of the velocity error in the measurement (static;
        True). False treats the Eötvös-corrected reading as exact, as a filter that
        ignores it would.
    reacquire : LooseConfig or None
        ``ukf`` and ``ekf``: check the filter every ``stride`` fixes with the loop's
        matcher over the last segment and reset it to the fix where it is lost
        (:mod:`~jaxgrav.navigate.tight_reacquire`; build it with
        :func:`~jaxgrav.navigate.loose_config` and ``fix_prior=False``); None (default):
        off. On 1000 perfect-map patrols (seed 1, ``examples/voyage_tight.py
        --reacquire``) the last hour went from 0.204 to 0.071 of the free INS and the
        NEES from 700 to 28 (one of the two voyages that lock onto a wrong track is
        brought back); with the 3 mGal map error told its fixes are as wide as the
        filter's covariance and it changes next to nothing (1000 patrols, seed 0: last
        hour 0.105 → 0.103, last / second hour 1.84 → 1.81, 24 % worse than the free INS
        in some hour, unchanged), so it is not the default.
    reacquire_gate, reacquire_ratio : float
        A fix resets the filter when its χ²(2) against the filter exceeds the gate
        (default 13.8, the 99.9 % point) or the filter's position σ exceeds the fix's
        by the ratio (default 3).
    reacquire_sigma_m : tuple of float
        The filter's position σ opened by these per axis (m) for the search window and
        the reset, one check per entry in turn (default one, 4000 m: the dense loop's
        widest window, ±15 km; a second, finer stage of 1000 m reset the perfect map's
        lost voyage 878 of seed 1 to wrong fixes: 19.7 km off at the end, against 7.4).
    reacquire_sigma_vel : float
        The velocity σ opened the same way (m/s; default 0.1).
    """

    ins: INSErrorModel = INSErrorModel()
    sigma_pos_m: float = 354.0
    sigma_vel: float = 0.035
    noise_mgal: float = 1.0
    map_error: MapErrorState | None = None
    gate: float = float("inf")
    curvature_cells: float = 8.0
    pmf_q_pos: float = 0.25
    rbpf_q_pos: float = 1.0
    method: str = static_field("ukf")
    n_particles: int = static_field(500)
    pmf_cells: int = static_field(61)
    pmf_span: float = static_field(4.0)
    pmf_resolve: float = static_field(0.5)
    pmf_cell_m: float = static_field(100.0)
    pmf_missing: str = static_field("gaps")
    eotvos_velocity: bool = static_field(True)
    reacquire: LooseConfig | None = None
    reacquire_gate: float = 13.8
    reacquire_ratio: float = 3.0
    reacquire_sigma_m: tuple = (4000.0,)
    reacquire_sigma_vel: float = 0.1

    def __post_init__(self):
        if self.method not in TIGHT_METHODS:
            raise ValueError(f"method must be one of {', '.join(TIGHT_METHODS)}; got "
                             f"{self.method!r}")
        if (isinstance(self.n_particles, bool) or not isinstance(self.n_particles, int)
                or self.n_particles < 2):
            raise ValueError(f"n_particles must be an integer >= 2; got {self.n_particles!r}")
        if self.map_error is not None and not isinstance(self.map_error, MapErrorState):
            raise TypeError("map_error must be a MapErrorState (map_error_state(sigma, length_m)) "
                            f"or None; got {type(self.map_error).__name__}")
        if not (isinstance(self.pmf_span, int | float) and self.pmf_span >= 0):
            raise ValueError(f"pmf_span must be >= 0 (0: a fixed grid); got {self.pmf_span!r}")
        if not (isinstance(self.pmf_resolve, int | float) and self.pmf_resolve >= 0):
            raise ValueError(f"pmf_resolve must be a number >= 0 (reading 1-sigma per cell; "
                             f"0: no bound); got {self.pmf_resolve!r}")
        cell = self.pmf_cell_m
        if isinstance(cell, bool) or not isinstance(cell, numbers.Real) or not cell > 0:
            raise ValueError(f"pmf_cell_m must be a number > 0 (m; static); got {cell!r}")
        q = concrete(self.rbpf_q_pos)  # None under tracing; an object leaf: not checked
        if (q is not None and q.dtype.kind in "fiu"
                and not (np.all(np.isfinite(q)) and np.all(q >= 0))):
            raise ValueError(f"rbpf_q_pos must be a finite number >= 0 (m^2/s); got "
                             f"{self.rbpf_q_pos!r}")
        if self.reacquire is not None and (self.method not in ("ukf", "ekf") or not isinstance(
                self.reacquire, LooseConfig) or self.reacquire.fix_prior):
            raise ValueError("reacquire needs method 'ukf' or 'ekf' and a LooseConfig without "
                             f"fix_prior; got method {self.method!r}, "
                             f"{type(self.reacquire).__name__}")
        if self.pmf_missing not in MISSING:
            raise ValueError(f"pmf_missing must be one of {MISSING}; got {self.pmf_missing!r}")
        if (self.method == "pmf" and self.map_error is not None
                and isinstance(self.map_error.order, int) and self.map_error.order != 1):
            raise ValueError("method 'pmf' carries a first-order map-error state only (per "
                             f"grid cell); got order {self.map_error.order}")


class TightResult(NamedTuple):
    """The navigation solution of one voyage, tightly coupled.

    Attributes
    ----------
    nav : Track
        Corrected trajectory at every INS step (positions in degrees, velocity in m/s).
    cov_north_east : Array, shape ``(N, 2, 2)``
        Covariance of the position error (m², north/east).
    error_estimate : Array, shape ``(N, n)``
        The filter's error estimate (13 INS states, then the map-error state(s)).
    sigma : Array, shape ``(N, n)``
        Its 1-σ.
    innovation, innovation_var : Array, shape ``(N,)``
        Reading minus prediction (mGal) and its predicted variance (mGal²); NaN without
        a reading.
    status : Array of int32, shape ``(N,)``
        Bits of :data:`~jaxgrav.filters.STATUS_FILTER` per step.
    reacquisition : Reacquisition or None
        With ``TightConfig.reacquire``: the matcher's checks; else None.
    """

    nav: Track
    cov_north_east: jax.Array
    error_estimate: jax.Array
    sigma: jax.Array
    innovation: jax.Array
    innovation_var: jax.Array
    status: jax.Array
    reacquisition: Reacquisition | None = None


def _filter(cfg, measurement, count):
    method, gate = cfg.method, cfg.gate
    if method == "pmf":  # its map-error state is per cell: the map alone per cell
        return pmf(cfg.pmf_cells, cfg.pmf_cell_m, q_pos=cfg.pmf_q_pos, ins=cfg.ins,
                   adapt_span=cfg.pmf_span or None, resolve=cfg.pmf_resolve or None,
                   missing=cfg.pmf_missing)
    if method == "ukf":
        return ukf(measurement, gate=gate, curvature_count=count)
    if method == "ekf":
        return ekf(measurement, gate=gate)
    if method == "rbpf":
        return rbpf(cfg.n_particles, measurement, gate=gate, q_pos=cfg.rbpf_q_pos)
    return gaussian_sum(ukf(measurement, gate=gate, curvature_count=count), 3)


def _cell_m(grid):
    """Mean node spacing (m) of a Grid or PreparedMap (0 for other fields)."""
    g = getattr(grid, "grid", grid)
    if not hasattr(g, "spacing_m"):
        return 0.0
    dy, dx = g.spacing_m()
    return (dy * dx) ** 0.5


class _Model(NamedTuple):
    """The filter's model of one voyage: dynamics, prior, measurement, steps."""

    dynamics: Dynamics
    x0: jax.Array
    p0: jax.Array
    measurement: object
    steps: Step
    sailing: jax.Array


def _model(cfg, voyage):
    """The model every tightly coupled filter and the bound use (see the module notes)."""
    ins = voyage.ins
    dt = (ins.t[-1] - ins.t[0]) / (ins.t.shape[0] - 1)  # the mean step, not the first's
    f, q = transition(cfg.ins, jnp.mean(ins.lat), dt)
    p0 = initial_covariance(cfg.ins, cfg.sigma_pos_m, cfg.sigma_vel)
    x0 = jnp.zeros(p0.shape[0], p0.dtype)
    # the map error decorrelates at the distance sailed per time (the mean speed; the
    # median of a log mostly in port was 0: an error that never decorrelates while sailing)
    rows = jnp.hypot(ins.v_east, ins.v_north)
    speed = jnp.mean(rows)
    dynamics, x0, p0, meas = augment(cfg.map_error, Dynamics(f, q, dt), x0, p0, speed,
                                     gravity_measurement)
    moving = rows > MOVING_MS
    sailing = jnp.sum(jnp.where(moving, rows, 0.0)) / jnp.maximum(jnp.sum(moving), 1)
    z = voyage.gravity + eotvos(ins.lat, ins.v_east, ins.v_north)
    h_lin = None
    if cfg.eotvos_velocity:
        h_lin = eotvos_part(eotvos_jacobian(ins.lat, ins.v_east, ins.v_north), x0.shape[0])
    r = jnp.full(z.shape, jnp.asarray(cfg.noise_mgal, z.dtype) ** 2)
    return _Model(dynamics, x0, p0, meas, Step(ins.lat, ins.lon, z, r, h_lin), sailing)


@jax.jit
def navigate_tight(grid, voyage, config, key=None):
    """Tightly coupled map-aided navigation over one voyage (see the module notes).

    Parameters
    ----------
    grid : Grid or PreparedMap
        The anomaly map (mGal).
    voyage : Voyage
        The INS log and the raw readings (Eötvös not corrected; NaN where none);
        ``truth`` is not used. Uniform step.
    config : TightConfig
    key : PRNG key, optional
        The particle filter's draws (``rbpf``; default ``PRNGKey(0)``); unused by the
        Kalman filters.

    Returns
    -------
    TightResult
    """
    cfg = config
    ins = voyage.ins
    m = _model(cfg, voyage)
    # readings per map cell: steps per cell times the share of steps with a reading
    # (a log with INS rows every second and a reading every tenth shares a cell's
    # linearisation error among a tenth as many readings)
    share = jnp.mean(jnp.isfinite(voyage.gravity))
    count = (cfg.curvature_cells * _cell_m(grid) * share
             / (jnp.maximum(m.sailing, MOVING_MS) * m.dynamics.dt))  # per cell while sailing
    filt = _filter(cfg, m.measurement, count)
    if cfg.method == "rbpf" and key is None:
        key = jax.random.PRNGKey(0)
    checks = None
    if cfg.reacquire is not None:
        infos, checks = run_reacquiring(
            filt, grid, m.dynamics, m.x0, m.p0, m.steps, ins, voyage.gravity, cfg.reacquire,
            gate=cfg.reacquire_gate, ratio=cfg.reacquire_ratio,
            sigma_pos=cfg.reacquire_sigma_m, sigma_vel=cfg.reacquire_sigma_vel)
    else:
        _, infos = run_filter(filt, grid, m.dynamics, m.x0, m.p0, m.steps,
                              key=key if cfg.method == "rbpf" else None)
    xs = infos.x
    lat, lon = apply_drift(ins.lat, ins.lon, -xs[:, 0], -xs[:, 1])
    nav = Track(ins.t, lat, lon, ins.v_east - xs[:, VEL.start + 1], ins.v_north - xs[:, VEL.start])
    return TightResult(nav, infos.p_pos, xs, infos.sigma, infos.innovation,
                       infos.innovation_var, infos.status, checks)


@jax.jit
def voyage_bound(grid, voyage, config):
    """The posterior Cramér–Rao bound of the position along one simulated voyage.

    Tichavský's recursion (:func:`~jaxgrav.filters.pcrlb`) with the tightly coupled
    filters' own model — ``config``'s INS error model, prior, reading noise, map-error
    state and Eötvös part — and the measurement row at the voyage's **true** error
    state: the covariance no estimator of this model can beat on this voyage, loosely or
    tightly coupled (the loosely coupled loop uses the same readings). No linearisation
    error, no curvature term, no gate: ``config.method`` and its settings are unused.

    Parameters
    ----------
    grid : Grid or PreparedMap
        The anomaly map the filters use (mGal).
    voyage : Voyage
        A simulated voyage (``ins_error`` is read: the true INS error, the filter's
        sign convention).
    config : TightConfig

    Returns
    -------
    PCRLBResult
        Per step: the bound on the error covariance (the filter's state order) and
        ``position_rms`` = √(B_nn + B_ee) (m).
    """
    m = _model(config, voyage)
    return pcrlb(grid, m.dynamics, m.p0, m.steps, voyage.ins_error[:, :2], m.measurement)
