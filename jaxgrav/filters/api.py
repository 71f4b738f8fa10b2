"""Validated single-track filtering: :func:`filter_track`, the engine of ``jaxgrav filter``.

As :mod:`jaxgrav.match.api` is for matching: the entry point takes one track in
degrees, builds the INS error model's prior and dynamics, runs a filter of this
package (UKF, EKF, Gaussian sum, point-mass, SIR or Rao–Blackwellised particle filter)
once jitted, and returns the corrected positions with their 1-σ and per-row status.
The jitted runners are module functions: one compilation per process, filter and
track shape. Also the deprecated :func:`run_pmf` (the point-mass filter's old runner).
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import executables
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav.constants import DEG
from jaxgrav.filters.gaussian_sum import gaussian_sum
from jaxgrav.filters.guard import GuardConfig, guard_run
from jaxgrav.filters.kalman import ekf, ukf
from jaxgrav.filters.map_state import augment
from jaxgrav.filters.model import Dynamics, Step, gravity_measurement, run_filter
from jaxgrav.filters.pf import pf
from jaxgrav.filters.pmf import pmf
from jaxgrav.filters.rbpf import rbpf
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.sim.ins import GRAV, N_STATES, VEL, INSErrorModel, initial_covariance, transition
from jaxgrav.time_steps import time_steps

__all__ = [
    "FILTER_METHODS",
    "PARTICLES",
    "PMF_CELLS",
    "PMF_Q_POS",
    "PMF_SPAN_SIGMA",
    "STRATEGIC_INS",
    "eotvos_part",
    "filter_track",
    "pad_to_stride",
    "reading_stride",
    "run_pmf",
]

FILTER_METHODS = ("ukf", "ekf", "gsf", "pmf", "pf", "rbpf")
"""The filters :func:`filter_track` runs."""
PARTICLES = {"pf": 2000, "rbpf": 1000}
"""Default particle counts of the SIR and Rao–Blackwellised particle filters."""
PMF_CELLS = 61
"""Cells per axis of the point-mass filter's grid."""
PMF_SPAN_SIGMA = 4.0
"""The grid spans ±this many ``--sigma-pos``: at ±3σ the boundary cells would already
hold 0.2 % of the prior (the ``grid_edge`` flag's threshold is 0.1 %)."""
PMF_Q_POS = 4.0
"""The point-mass filter's random-walk density (m²/s) at ``sigma_vel = 0.2/√2 m/s``;
it scales with ``sigma_vel²``."""
STRATEGIC_INS = INSErrorModel()
""":func:`filter_track`'s default INS error model: paper D's, the default
:class:`~jaxgrav.sim.ins.INSErrorModel` (0.001 °/h gyro, 10 µg accelerometer biases), the
``strategic`` grade of :data:`jaxgrav.scenarios.INS_GRADES`."""


def pad_to_stride(steps, every, first=None):
    """Pad a run at both ends so that its readings fall on ``run_filter(..., every=k)``'s updates.

    :func:`~jaxgrav.filters.model.run_filter` with ``every=k`` updates on steps
    ``k − 1, 2k − 1, …``. A run whose readings sit on a stride of ``k`` steps from step
    ``first`` is shifted by ``(k − 1 − first) mod k`` prediction-only steps in front
    and padded behind to a whole number of blocks of ``k`` steps. The padding repeats
    the first (or last) step's position and noise variance, with no reading.

    Parameters
    ----------
    steps : Step
        Leading axis ``T`` (concrete or traced arrays).
    every : int
        Steps per reading ``k`` (static).
    first : int, optional
        Index of a reading step (e.g. the first reading; static). Default ``k − 1``:
        the readings already sit on the update steps, and only the end is padded.

    Returns
    -------
    padded : Step
        Leading axis a multiple of ``k``.
    start : int
        ``padded[start : start + T]`` are the given steps; the rows of a run's
        :class:`~jaxgrav.filters.model.StepInfo` there are the causal output for them.
    """
    t = steps.z.shape[0]
    first = every - 1 if first is None else int(first)
    start = (every - 1 - first) % every
    total = start + t + (-(start + t) % every)
    idx = np.clip(np.arange(total) - start, 0, t - 1)
    inside = (np.arange(total) >= start) & (np.arange(total) < start + t)
    z = jnp.where(inside, jnp.asarray(steps.z)[idx], jnp.nan)
    h_lin = None if steps.h_lin is None else jnp.asarray(steps.h_lin)[idx]
    return Step(jnp.asarray(steps.lat)[idx], jnp.asarray(steps.lon)[idx], z,
                jnp.asarray(steps.r)[idx], h_lin), start


def reading_stride(rows, where=None):
    """Rows between the point-mass filter's updates: the stride every reading sits on.

    The point-mass filter updates every ``k`` rows and predicts the rows between in one
    step (:func:`~jaxgrav.filters.model.run_filter` ``every=k``). ``k`` is the greatest
    common divisor of the rows between readings, so a reading missing on the stride (a
    gap, a dropped record) is an update without a reading, and irregular readings are
    taken too: at worst ``k = 1``, an update on every row, slower but the same filter.

    Parameters
    ----------
    rows : numpy.ndarray of int, shape ``(R,)``
        Rows with a reading, ascending.
    where : str, optional
        Unused: kept for callers of the version that refused irregular readings.

    Returns
    -------
    int
        The stride (1 for a single reading).
    """
    if rows.size < 2:
        return 1
    return int(np.gcd.reduce(np.diff(rows)))


def eotvos_part(jacobian, n_states):
    """The Eötvös error of the velocity error as a step's :attr:`Step.h_lin`.

    Parameters
    ----------
    jacobian : Array, shape ``(T, 2)``
        ``∂E/∂v`` (mGal per m/s, north then east; :func:`~jaxgrav.geodesy.eotvos_jacobian`)
        at the velocity the readings were Eötvös-corrected with.
    n_states : int
        The filter's state size (13 INS error states, plus any map-error states).

    Returns
    -------
    Array, shape ``(T, n_states)``
        The Jacobian in the velocity-error columns, zeros elsewhere.
    """
    jacobian = jnp.asarray(jacobian)
    return jnp.zeros((jacobian.shape[0], n_states), jacobian.dtype).at[:, VEL].set(jacobian)


@jax.jit
def _radii(lat):
    """Meridian and prime-vertical radii (m) at ``lat`` (degrees), one compiled program for
    the host's conversions (eager, they compiled five small programs per call)."""
    return meridian_radius(lat), prime_vertical_radius(lat)


_eotvos_part = jax.jit(eotvos_part, static_argnums=1)


@jax.jit
def _prior_and_dynamics(model, lat_mean, dt, sigma_pos, sigma_vel):
    # model: traced leaves, so one compilation serves every INS grade
    return initial_covariance(model, sigma_pos, sigma_vel), Dynamics(*transition(model,
                                                                               lat_mean, dt))


@pytree_dataclass
class _Program:
    """The static choices of :func:`filter_track`'s program (no traced fields)."""

    kind: str = static_field("ukf")
    n_particles: int = static_field(0)
    every: int = static_field(1)
    missing: str = static_field("gaps")


@jax.jit
def _gaussian_run(program, field, dynamics, p0, steps, guard, meas, key=None):
    # meas: a MapPlusBias (a pytree without leaves: its layout is part of the compiled code)
    n_particles = program.n_particles
    filt = {"ukf": ukf, "ekf": ekf, "gsf": lambda m: gaussian_sum(ukf(m), 3),
            "pf": lambda m: pf(n_particles, m),
            "rbpf": lambda m: rbpf(n_particles, m)}[program.kind](meas)
    _, infos = run_filter(filt, field, dynamics, jnp.zeros(p0.shape[0]), p0, steps, key=key)
    # guard: a traced ratio (inf = off), so one compilation serves both
    guarded = guard_run(infos, dynamics, p0, GuardConfig(guard, guard))
    return jax.tree.map(lambda g, a: jnp.where(jnp.isfinite(guard), g, a), guarded, infos)


@jax.jit
def _pmf_run(program, field, dt, p0, cell_m, q_pos, steps, map_error, speed, ins):
    # ins: traced, one compilation for every grade
    filt = pmf(PMF_CELLS, cell_m, q_pos=q_pos, ins=ins, missing=program.missing)
    dynamics = filt.dynamics(jnp.mean(steps.lat), dt)
    dynamics, x0, p0, _ = augment(map_error, dynamics, jnp.zeros(p0.shape[0]), p0, speed)
    _, infos = run_filter(filt, field, dynamics, x0, p0, steps, program.every)
    return infos


def filter_track(field, t, lat, lon, gravity, method="ukf", *, sigma_pos=1414.2,
                 sigma_vel=0.1414, sigma_gravity=1.0, guard=None, map_error=None,
                 eotvos_velocity=None, where="track", n_particles=None, seed=0,
                 ins=STRATEGIC_INS, missing="gaps"):
    """Filter one track; the engine of ``jaxgrav filter`` (inputs already validated).

    Run with x64 enabled (the CLI does): positions are in degrees.

    Parameters
    ----------
    field : Grid or PointMasses
        Anomaly map (mGal).
    t : numpy.ndarray, shape ``(T,)``
        Times (s) on a regular step (:func:`~jaxgrav.time_steps.time_steps`: jitter up
        to a tenth of a step; a gap is refused).
    lat, lon : numpy.ndarray, shape ``(T,)``
        INS-indicated position (degrees).
    gravity : numpy.ndarray, shape ``(T,)``
        Eötvös-corrected anomaly readings (mGal), NaN where none.
    method : {"ukf", "ekf", "gsf", "pmf", "pf", "rbpf"}
    sigma_pos, sigma_vel, sigma_gravity : float
        Prior 1-σ per axis of the INS position (m) and velocity (m/s) errors; reading
        noise 1-σ (mGal).
    guard : float, optional
        No-harm guard ratio for ``ukf``, ``ekf``, ``gsf``, ``pf``, ``rbpf``
        (:func:`~jaxgrav.filters.guard_run` with ``GuardConfig(guard, guard)``);
        None: the filter's own output.
    map_error : MapErrorState, optional
        The map's error (:func:`~jaxgrav.filters.map_state.map_error_state`: σ mGal,
        L m, order). A Gauss–Markov map-error state over the distance travelled,
        ``τ = L / speed`` with the track's mean ground speed (m/s, from the INS
        positions: distance over time, so the time at rest counts, as in
        :func:`~jaxgrav.navigate.navigate_tight`); ``pmf``: first order only, per grid
        cell.
        None or σ = 0: today's filters.
    eotvos_velocity : numpy.ndarray, shape ``(T, 2)``, optional
        ``∂E/∂v`` (mGal per m/s, north then east;
        :func:`~jaxgrav.geodesy.eotvos_jacobian`) at the velocity the readings were
        Eötvös-corrected with: the filter carries the Eötvös error of the INS velocity
        error, ``∂E/∂v · δv``, in its measurement (:attr:`~jaxgrav.filters.Step.h_lin`;
        the point-mass filter updates each cell's Gaussian states with it). None: the
        readings are taken as exactly corrected.
    where : str
        How error messages name the track.
    n_particles : int, optional
        ``pf``, ``rbpf``: the particle count (default :data:`PARTICLES`).
    seed : int
        ``pf``, ``rbpf``: the seed of the filter's PRNG key (the run is reproducible).
    ins : INSErrorModel
        The filter's INS error model (:class:`~jaxgrav.sim.ins.INSErrorModel`: gyro
        and accelerometer biases in rad/s and m/s², their correlation times in s, the
        gravimeter's systematic error in mGal). Default :data:`STRATEGIC_INS`, paper
        D's; a log from a navigation-grade INS (``jaxgrav simulate-voyage``) needs
        ``jaxgrav.scenarios.INS_GRADES["navigation"]``, or the 1-σ is over-confident.
    missing : {"gaps", "land"}
        ``pmf``: how a cell on a missing (NaN) map node is read (:func:`~jaxgrav.filters.pmf`).

    Returns
    -------
    dict
        Each shape ``(T,)``, the causal posterior after each row: ``lat``, ``lon``
        (filtered, degrees), ``sigma_north``, ``sigma_east`` (m), ``cov_north_east``
        (m²), ``v_north_error``, ``v_east_error`` (estimated INS velocity error, m/s),
        ``sigma_v_north``, ``sigma_v_east`` (m/s), ``gravimeter_bias`` and
        ``sigma_gravimeter_bias`` (mGal), ``innovation`` and ``innovation_sigma``
        (mGal; NaN on rows without a reading), ``status`` (int32 flags of
        :data:`~jaxgrav.filters.STATUS_FILTER`), with ``map_error`` and
        ``sigma_map_error`` (mGal) when the map-error state is carried; and
        ``pmf_every`` (the point-mass filter's update stride, else None).

    Raises
    ------
    ValueError
        Times not on a regular step, or with gaps; ``n_particles`` for a filter
        without particles, or not an int >= 2; a field of ``ins`` out of range (a σ or
        noise not finite and ≥ 0, a ``*_tau`` not > 0; ``inf`` allowed).
    TypeError
        ``ins`` not an :class:`~jaxgrav.sim.ins.INSErrorModel`.
    """
    if not isinstance(ins, INSErrorModel):
        raise TypeError(f"ins must be an INSErrorModel (e.g. jaxgrav.scenarios.INS_GRADES"
                        f"['navigation']); got {type(ins).__name__}")
    if missing != "gaps" and method != "pmf":
        raise ValueError(f"missing={missing!r} is for method 'pmf'; got method={method!r}")
    if n_particles is not None and method not in PARTICLES:
        raise ValueError(f"n_particles is for the particle filters {tuple(PARTICLES)}; got "
                         f"method={method!r}")
    steps = time_steps(t, where)  # jitter up to a tenth of a step; gaps refused below
    if steps.n_inserted:
        raise ValueError(f"{where}: filter_track needs a row on every step; {steps.n_gaps} "
                         f"gap(s) of {steps.n_inserted} step(s) of {steps.dt:g} s (fill them "
                         "with rows without a reading: jaxgrav.time_steps.on_steps)")
    dt = steps.dt
    n = t.size
    r = float(sigma_gravity) ** 2
    ins = INSErrorModel(*(float(v) for v in ins))
    for name, value in ins._asdict().items():
        tau = name.endswith("_tau")
        if not (value > 0 if tau else np.isfinite(value) and value >= 0):
            want = "> 0 (s; inf: a random constant)" if tau else "a finite number >= 0"
            raise ValueError(f"ins.{name} must be {want}; got {value!r}")
    p0, dynamics = executables.call(_prior_and_dynamics, ins, float(np.mean(lat)), dt,
                                    sigma_pos, sigma_vel)
    every = None
    meas = gravity_measurement
    speed = 0.0
    m, e = (np.asarray(r) for r in _radii(lat))  # m per radian north; east, times cos(lat)
    e = e * np.cos(lat * DEG)
    if map_error is not None:
        dn = np.diff(lat) * DEG * m[1:]
        de = np.diff(lon) * DEG * e[1:]
        # the map error decorrelates at the distance travelled per time: the mean speed, as
        # navigate's tight filter (the median of a track mostly at rest was 0: a map error
        # that never decorrelates while moving; a singular second-order prior)
        speed = float(np.mean(np.hypot(dn, de))) / dt if n > 1 else 0.0
    if map_error is not None and method != "pmf":
        dynamics = dynamics._replace(dt=jnp.asarray(dt))
        dynamics, _, p0, meas = augment(map_error, dynamics, jnp.zeros(p0.shape[0]), p0, speed)
    h_lin = None
    if eotvos_velocity is not None:
        h_lin = _eotvos_part(jnp.asarray(eotvos_velocity, p0.dtype), p0.shape[0])
    steps = Step(jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(gravity),
                 jnp.asarray(np.full(n, r)), h_lin)  # np.full: jnp.full compiles a program
    if method == "pmf":
        rows = np.flatnonzero(np.isfinite(gravity))
        every = reading_stride(rows)
        cell_m = 2.0 * PMF_SPAN_SIGMA * sigma_pos / (PMF_CELLS - 1)
        q_pos = PMF_Q_POS * (sigma_vel / 0.1414) ** 2
        padded, start = pad_to_stride(steps, every, rows[0])
        infos = executables.call(_pmf_run, _Program("pmf", every=every, missing=missing),
                                 field, dt, p0, cell_m, q_pos, padded, map_error, speed, ins)
        # causal: rows between readings show the prediction
        infos = jax.tree.map(lambda a: np.asarray(a)[start:start + n], infos)
    else:
        ratio = np.inf if guard is None else float(guard)
        program, key = _Program(method), None
        if method in PARTICLES:
            count = PARTICLES[method] if n_particles is None else n_particles
            program, key = _Program(method, count), jax.random.PRNGKey(seed)
        # one program per call, kept on disk when the command line set a folder for it
        infos = executables.call(_gaussian_run, program, field, dynamics, p0, steps, ratio,
                                 meas, key)
        infos = jax.tree.map(np.asarray, infos)
    x, sigma = infos.x, infos.sigma
    out = dict(lat=lat - x[:, 0] / m / DEG, lon=lon - x[:, 1] / e / DEG,
               sigma_north=sigma[:, 0], sigma_east=sigma[:, 1],
               cov_north_east=infos.p_pos[:, 0, 1],
               v_north_error=x[:, VEL.start], v_east_error=x[:, VEL.start + 1],
               sigma_v_north=sigma[:, VEL.start], sigma_v_east=sigma[:, VEL.start + 1],
               gravimeter_bias=x[:, GRAV], sigma_gravimeter_bias=sigma[:, GRAV],
               innovation=infos.innovation,
               innovation_sigma=np.sqrt(np.maximum(infos.innovation_var, 0.0)),
               status=infos.status.astype(np.int32), pmf_every=every)
    if x.shape[1] > N_STATES:  # the map-error state, appended last
        out.update(map_error=x[:, N_STATES], sigma_map_error=sigma[:, N_STATES])
    return out


def run_pmf(filt, field, dt, x0, p0, steps, every=1):
    """Deprecated: :func:`~jaxgrav.filters.model.run_filter` runs the point-mass filter.

    ``run_pmf(filt, field, dt, x0, p0, steps, every)`` is
    ``run_filter(filt, field, filt.dynamics(mean(steps.lat), dt), x0, p0, steps, every)``
    (the error model at the mean INS latitude) for ``T`` a multiple of ``every``; pad
    other runs with :func:`~jaxgrav.filters.api.pad_to_stride`. Kept for one release.

    Raises
    ------
    ValueError
        ``every`` not a positive int dividing the number of steps.
    """
    warnings.warn("run_pmf is deprecated: use run_filter(filt, field, filt.dynamics(lat, dt), "
                  "x0, p0, steps, every=k) (and pad_to_stride for runs off the stride)",
                  DeprecationWarning, stacklevel=2)
    t = steps.z.shape[0]
    if not isinstance(every, int) or every < 1 or t % every:
        raise ValueError(f"every must be a positive int dividing the {t} steps; got {every!r}")
    return run_filter(filt, field, filt.dynamics(jnp.mean(steps.lat), dt), x0, p0, steps, every)
