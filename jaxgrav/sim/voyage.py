"""Simulate a voyage: true route, INS drift from the 13-state error model, gravimeter.

:func:`simulate_voyage` samples everything at the INS step ``dt``:

- the true trajectory from a :class:`~jaxgrav.sim.route.Route` (:func:`~jaxgrav.sim.route.sail`);
- the INS error from :mod:`jaxgrav.sim.ins` (Schuler, Earth-rate and Foucault coupling,
  gyro and accelerometer biases, random walks), discretised once at the route's mean
  latitude, started from :func:`~jaxgrav.sim.ins.sample_initial_error` (errors of a
  given size in a random direction); the INS indicates truth + error, in position and
  velocity;
- the gravimeter's raw anomaly at the true position: the true field (the map plus its
  error, drawn by the caller) + white noise + the gravimeter's systematic error (error
  state 12 of the INS model) − the Eötvös effect of the *true* velocity, which a
  navigation system must correct from its own velocity.
"""

import jax
import jax.numpy as jnp

from jaxgrav.geodesy import eotvos
from jaxgrav.sim.drift import apply_drift
from jaxgrav.sim.ins import sample_initial_error, simulate_errors, transition
from jaxgrav.sim.readings import field_along
from jaxgrav.sim.route import sail
from jaxgrav.sim.trajectory import Track
from jaxgrav.sim.voyage_log import Voyage

__all__ = ["indicated_track", "simulate_voyage"]


def indicated_track(truth, error):
    """The INS-indicated track: truth plus the error states' position and velocity.

    Parameters
    ----------
    truth : Track
        True trajectory, shape ``(N,)`` per field.
    error : Array, shape ``(N, 13)``
        Error states (INS − true) of :mod:`jaxgrav.sim.ins`: north and east position (m)
        in columns 0, 1 and velocity (m/s) in 2, 3.

    Returns
    -------
    Track
    """
    lat, lon = apply_drift(truth.lat, truth.lon, error[:, 0], error[:, 1])
    return Track(truth.t, lat, lon, truth.v_east + error[:, 3], truth.v_north + error[:, 2])


def simulate_voyage(key, field, route, n_steps, dt, ins_model, *, pos_error_m=500.0,
                    vel_error=0.05, noise_mgal=1.0, method="bicubic"):
    """One simulated voyage at the INS step.

    Parameters
    ----------
    key : PRNG key
        Decides the INS error (initial and process noise) and the reading noise.
    field : Grid or callable
        The true anomaly field (mGal): the map plus its error for an honest run.
    route : Route
    n_steps : int
        Samples (static), including the start; the voyage lasts ``(n_steps − 1)·dt``.
    dt : float
        INS and gravimeter step (s).
    ins_model : INSErrorModel
        Sensor errors of the INS and the gravimeter's systematic error.
    pos_error_m, vel_error : float
        Size of the initial horizontal position (m) and velocity (m/s) errors, each in a
        random direction.
    noise_mgal : float
        White noise of each reading (mGal).
    method : {"bicubic", "bilinear"}
        Interpolation of a Grid field.

    Returns
    -------
    Voyage
        With ``truth`` and ``ins_error`` filled; ``gravity`` NaN where the route leaves
        a Grid field.
    """
    k_x0, k_w, k_noise = jax.random.split(key, 3)
    truth, _ = sail(route, n_steps, dt)
    lat_mid = jnp.mean(jnp.asarray(route.lat, float))
    f, q = transition(ins_model, lat_mid, dt)
    x0 = sample_initial_error(k_x0, ins_model, pos_error_m, vel_error)
    error = simulate_errors(k_w, f, q, x0, n_steps)
    field_values = field_along(field, truth.lat, truth.lon, method)
    noise = noise_mgal * jax.random.normal(k_noise, field_values.shape, field_values.dtype)
    gravity = (field_values + noise + error[:, 12]
               - eotvos(truth.lat, truth.v_east, truth.v_north))
    return Voyage(indicated_track(truth, error), gravity, truth, error)
