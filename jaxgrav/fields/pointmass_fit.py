"""Fit a few buried point masses to a gravity anomaly map (paper D's model, automated).

Paper D describes its match area by three point masses found "by repeated
experiment". :func:`fit_point_masses` finds ``K`` masses by least squares instead:
it minimises the mean squared misfit between the point-mass anomaly
(:func:`jaxgrav.fields.pointmass.gravity_anomaly`, exact WGS84/ECEF geometry) plus an
optional constant offset and the map values, over the latitude, longitude, depth and
mass of every mass.

Parameterisation (bounds by construction, nothing clipped)
----------------------------------------------------------
Each mass has four unconstrained raw parameters ``(u_lat, u_lon, u_depth, u_mass)``:

* ``lat = lat_min + (lat_max − lat_min)·σ(u_lat)``, likewise ``lon``: the masses stay
  inside the data's bounding box (widened by ``margin`` degrees);
* ``depth = d_min + (d_max − d_min)·σ(u_depth)`` with ``depth_bounds = (d_min, d_max)``;
* ``mass = M·u_mass`` with **unconstrained sign** (negative anomalies come from mass
  deficits, ``mass < 0``), ``M = s·L²/G`` the mass whose attraction at distance ``L``
  equals the data's standard deviation ``s`` (converted to m/s²), with
  ``L = (d_min + d_max)/2``, so ``u_mass = O(1)``;
* ``offset = mean + s·u_offset`` (mGal), when ``fit_offset`` (otherwise 0).

σ is the logistic sigmoid. Positions are carried relative to the window centre and
distances in units of ``L``, and the ECEF offsets from the centre are evaluated with
difference formulas (no subtraction of two ~6 400 km numbers), so float32 keeps about
1 cm of position resolution and the loss ``mean(((model − data)/s)²)`` is O(1).

Algorithm
---------
For each of ``n_restarts`` random starts (positions uniform in the inner 90 % of the
box, depths uniform in the inner 80 % of the bounds), the masses and offset are first
solved by ridge-regularised linear least squares (the model is linear in them), then
``steps`` Adam iterations (optax, cosine-decayed learning rate) update all parameters,
then ``polish_steps`` Levenberg–Marquardt (damped Gauss–Newton) steps finish the
descent. The restarts are ``jax.vmap``-ed and the iterations are ``lax.scan``-ned:
one compiled call runs them all (one compilation per ``K``, window size and iteration
counts). The restart with the smallest misfit is returned.

Using the fit as a map
----------------------
The result's ``masses`` is an ordinary :class:`~jaxgrav.fields.pointmass.PointMasses`,
so ``gravity_anomaly(fit.masses, lat, lon, h) + fit.offset`` (or
:meth:`PointMassFit.anomaly`) is a smooth, differentiable, analytic map function for
the filters and matchers (paper D uses exactly this as its map ``Δg_M``).
"""

import functools
import math
import numbers
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.flatten_util import ravel_pytree

from jaxgrav import constants as c
from jaxgrav.fields.pointmass import PointMasses, gravity_anomaly
from jaxgrav.grid import Grid

__all__ = [
    "PointMassFit",
    "PointMassSweep",
    "fit_point_masses",
    "sweep_point_masses",
]


class PointMassFit(NamedTuple):
    """Result of :func:`fit_point_masses`.

    Attributes
    ----------
    masses : PointMasses
        Best-fitting ``K`` masses (lat, lon in degrees, depth in m, mass in kg),
        ordered by decreasing ``|mass|``.
    offset : float
        Fitted constant (mGal) added to the masses' anomaly; 0 when
        ``fit_offset=False``.
    rms : float
        Residual RMS of the best restart (mGal), ``sqrt(mean((model − data)²))``.
    restart_rms : ndarray, shape (n_restarts,)
        Residual RMS of every restart (mGal), in restart order.
    iterations : int
        Iterations run by every restart (``steps + polish_steps``).
    converged : bool
        True when the best restart's misfit stopped decreasing (relative decrease
        of the loss over the last quarter of the polish steps, or the last tenth of
        the Adam steps without polish, at most ``rtol``) and is finite.
    """

    masses: PointMasses
    offset: float
    rms: float
    restart_rms: np.ndarray
    iterations: int
    converged: bool

    def anomaly(self, lat, lon, h=0.0):
        """Evaluate the fitted map, ``gravity_anomaly(masses, lat, lon, h) + offset``.

        Parameters
        ----------
        lat, lon : array_like
            Geodetic latitude and longitude (degrees), broadcast with ``h`` (shape S).
        h : array_like, default 0
            Ellipsoidal height (m).

        Returns
        -------
        Array, shape S
            Modelled anomaly (mGal). Differentiable and jit-able in the points.
        """
        return gravity_anomaly(self.masses, lat, lon, h) + self.offset


class PointMassSweep(NamedTuple):
    """Result of :func:`sweep_point_masses`.

    Attributes
    ----------
    k : ndarray of int, shape (M,)
        Numbers of masses tried.
    rms : ndarray, shape (M,)
        Residual RMS of the best fit for each ``K`` (mGal).
    fits : tuple of PointMassFit
        The fits, in the order of ``k``.
    """

    k: np.ndarray
    rms: np.ndarray
    fits: tuple


# --- the problem (all arrays, so new data of the same shape never retraces) ---------


class _Problem(NamedTuple):
    obs: jax.Array  # (3, N) observation ECEF minus origin ECEF, in units of length
    up: jax.Array  # (3, N) ellipsoidal normal at each observation point
    target: jax.Array  # (N,) (values − centre) / scale
    lat0: jax.Array  # () origin latitude (degrees)
    lon0: jax.Array  # () origin longitude (degrees)
    trig0: jax.Array  # (4,) sin, cos of the origin's latitude; sin, cos of its longitude
    lat_lo: jax.Array  # () south bound minus lat0 (degrees)
    lat_span: jax.Array  # () (degrees)
    lon_lo: jax.Array  # () west bound minus lon0 (degrees)
    lon_span: jax.Array
    depth_lo: jax.Array  # () (m)
    depth_span: jax.Array  # () (m)
    length: jax.Array  # () length unit L (m)


class _Raw(NamedTuple):
    lat: jax.Array  # (K,)
    lon: jax.Array  # (K,)
    depth: jax.Array  # (K,)
    mass: jax.Array  # (K,)
    offset: jax.Array  # ()


def _ecef_np(lat, lon, h):
    """Geodetic to ECEF (m) in NumPy float64 (same formula as jaxgrav.geodesy)."""
    phi, lam = np.deg2rad(lat), np.deg2rad(lon)
    s, co = np.sin(phi), np.cos(phi)
    n = c.WGS84_A / np.sqrt(1.0 - c.WGS84_E2 * s**2)
    return np.stack(
        [(n + h) * co * np.cos(lam), (n + h) * co * np.sin(lam), (n * (1.0 - c.WGS84_E2) + h) * s]
    )


def _ecef_offset(dlat, dlon, h, p):
    """ECEF of (lat0 + dlat, lon0 + dlon, h) minus ECEF of the origin (lat0, lon0, 0), m.

    Written with half-angle difference formulas so that no two Earth-sized numbers are
    subtracted: the relative error is that of the offset itself (≈1e-7 in float32).
    Only the sines and cosines of the half offsets are evaluated; the origin's are
    constants of the problem.
    """
    s0, co0, sl0, cl0 = p.trig0[0], p.trig0[1], p.trig0[2], p.trig0[3]
    half_phi, half_lam = jnp.deg2rad(0.5 * dlat), jnp.deg2rad(0.5 * dlon)
    sa, ca, sb, cb = jnp.sin(half_phi), jnp.cos(half_phi), jnp.sin(half_lam), jnp.cos(half_lam)
    s_mid, c_mid = s0 * ca + co0 * sa, co0 * ca - s0 * sa  # at φ0 + Δφ/2
    sl_mid, cl_mid = sl0 * cb + cl0 * sb, cl0 * cb - sl0 * sb  # at λ0 + Δλ/2
    s, co = s_mid * ca + c_mid * sa, c_mid * ca - s_mid * sa  # at φ
    sl, cl = sl_mid * cb + cl_mid * sb, cl_mid * cb - sl_mid * sb  # at λ
    ds = 2.0 * c_mid * sa  # sin φ − sin φ0
    dco = -2.0 * s_mid * sa  # cos φ − cos φ0
    dcl = -2.0 * sl_mid * sb  # cos λ − cos λ0
    dsl = 2.0 * cl_mid * sb  # sin λ − sin λ0
    e2 = c.WGS84_E2
    w, w0 = 1.0 - e2 * s**2, 1.0 - e2 * s0**2
    rw, rw0 = jnp.sqrt(w), jnp.sqrt(w0)
    n0 = c.WGS84_A / rw0
    dn = c.WGS84_A * e2 * ds * (s + s0) / (rw * rw0 * (rw + rw0))  # N − N0
    dp = (dn + h) * co + n0 * dco  # (N + h) cos φ − N0 cos φ0
    p0 = n0 * co0
    return (
        dp * cl + p0 * dcl,
        dp * sl + p0 * dsl,
        (1.0 - e2) * (dn * s + n0 * ds) + h * s,
    )


def _positions(raw, p):
    """Offsets from the origin (degrees) and depths (m) of the masses, shape (K,)."""
    dlat = p.lat_lo + p.lat_span * jax.nn.sigmoid(raw.lat)
    dlon = p.lon_lo + p.lon_span * jax.nn.sigmoid(raw.lon)
    depth = p.depth_lo + p.depth_span * jax.nn.sigmoid(raw.depth)
    return dlat, dlon, depth


def _unit_anomalies(dlat, dlon, depth, p):
    """(N, K) anomaly of each mass at each point for ``u_mass = 1``, in units of scale.

    A mass ``M = scale·L²/G`` gives ``G M (d·û)/ℓ³ = scale · (d'·û)/ℓ'³`` with
    primed lengths in units of L.
    """
    xm = _ecef_offset(dlat, dlon, -depth, p)
    d = [p.obs[i][:, None] - xm[i][None, :] / p.length for i in range(3)]
    inv = jax.lax.rsqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    proj = d[0] * p.up[0][:, None] + d[1] * p.up[1][:, None] + d[2] * p.up[2][:, None]
    return proj * inv**3


def _predict(raw, p, fit_offset):
    """Modelled anomaly at the data points, in units of scale about the centre, (N,)."""
    a = _unit_anomalies(*_positions(raw, p), p)
    out = a @ raw.mass
    return out + raw.offset if fit_offset else out


def _loss(raw, p, fit_offset):
    """Mean squared normalised misfit (dimensionless); RMS (mGal) is sqrt(loss)·scale."""
    r = _predict(raw, p, fit_offset) - p.target
    return jnp.mean(r**2)


def _linear_solve(raw_lat, raw_lon, raw_depth, p, fit_offset):
    """Masses (and offset) minimising the misfit at fixed positions (ridge 1e-3)."""
    a = _unit_anomalies(*_positions(_Raw(raw_lat, raw_lon, raw_depth, None, None), p), p)
    if fit_offset:
        a = jnp.concatenate([a, jnp.ones_like(a[:, :1])], axis=1)
    ata = a.T @ a
    lam = 1e-3 * jnp.trace(ata) / ata.shape[0]
    chol = jax.scipy.linalg.cho_factor(ata + lam * jnp.eye(ata.shape[0], dtype=ata.dtype))
    x = jax.scipy.linalg.cho_solve(chol, a.T @ p.target)
    k = raw_lat.shape[0]
    return x[:k], (x[k] if fit_offset else jnp.zeros((), x.dtype))


def _lm_step(x, mu, nu, loss, resid):
    """One Levenberg–Marquardt step on flat parameters; returns (x, mu, nu, loss).

    Marquardt scaling: the normal equations are solved for the column-normalised
    Jacobian, ``(ĴᵀĴ + μI) δ̂ = −Ĵᵀr``, by Cholesky. The damping follows Nielsen
    (1999): on a step with gain ratio ``ρ > 0`` it is accepted and
    ``μ ← μ·max(1/3, 1 − (2ρ − 1)³)``; otherwise it is rejected and ``μ ← μν``,
    ``ν ← 2ν``.
    """
    r = resid(x)
    jac = jax.jacfwd(resid)(x)  # (N, P)
    norm = jnp.sqrt(jnp.sum(jac**2, axis=0))
    norm = jnp.where(norm > 0, norm, 1.0)
    js = jac / norm
    eye = jnp.eye(x.shape[0], dtype=x.dtype)
    chol = jax.scipy.linalg.cho_factor(js.T @ js + mu * eye)
    step = -jax.scipy.linalg.cho_solve(chol, js.T @ r)
    x_new = x + step / norm
    loss_new = jnp.sum(resid(x_new) ** 2)
    predicted = loss - jnp.sum((r + js @ step) ** 2)
    rho = (loss - loss_new) / jnp.where(predicted > 0, predicted, jnp.inf)
    accept = jnp.isfinite(loss_new) & (loss_new < loss) & (rho > 0)
    x = jnp.where(accept, x_new, x)
    loss = jnp.where(accept, loss_new, loss)
    mu = jnp.where(accept, mu * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), mu * nu)
    nu = jnp.where(accept, 2.0, 2.0 * nu)
    mu = jnp.clip(mu, 100.0 * jnp.finfo(x.dtype).eps, 1e8)
    return x, mu, jnp.minimum(nu, 1e8), loss


def _fit_one(raw_pos, p, learning_rate, rtol, *, fit_offset, steps, polish_steps):
    """Fit from one start; raw_pos (3, K) raw lat/lon/depth. Returns (_Raw, loss, converged)."""
    mass, offset = _linear_solve(raw_pos[0], raw_pos[1], raw_pos[2], p, fit_offset)
    raw = _Raw(raw_pos[0], raw_pos[1], raw_pos[2], mass, offset)
    history = []
    if steps > 0:
        schedule = optax.cosine_decay_schedule(learning_rate, steps, alpha=0.02)
        opt = optax.adam(schedule)
        value_and_grad = jax.value_and_grad(_loss)

        def adam_step(carry, _):
            raw, state = carry
            loss, g = value_and_grad(raw, p, fit_offset)
            upd, state = opt.update(g, state, raw)
            return (optax.apply_updates(raw, upd), state), loss

        (raw, _), adam_hist = jax.lax.scan(adam_step, (raw, opt.init(raw)), None, length=steps)
        history.append(adam_hist)
    flat, unravel = ravel_pytree(raw)
    n = p.target.shape[0]

    def resid(x):
        return (_predict(unravel(x), p, fit_offset) - p.target) / math.sqrt(n)

    loss = loss_start = jnp.sum(resid(flat) ** 2)
    if polish_steps > 0:

        def lm(carry, _):
            carry = _lm_step(*carry, resid)
            return carry, carry[-1]

        init = (flat, jnp.asarray(1e-3, flat.dtype), jnp.asarray(2.0, flat.dtype), loss)
        (flat, _, _, loss), lm_hist = jax.lax.scan(lm, init, None, length=polish_steps)
        window = max(1, polish_steps // 4)
        before = lm_hist[-window - 1] if polish_steps > window else loss_start
    else:
        window = max(1, steps // 10)
        before = history[0][-window]
    # converged: stalled, or at the dtype's resolution (RMS <= sqrt(eps)·scale)
    stalled = (before - loss <= rtol * loss) | (loss <= jnp.finfo(flat.dtype).eps)
    converged = jnp.isfinite(loss) & stalled
    return unravel(flat), loss, converged


@functools.partial(jax.jit, static_argnames=("fit_offset", "steps", "polish_steps"))
def _fit_batch(raw_pos, p, learning_rate, rtol, *, fit_offset, steps, polish_steps):
    """vmap of :func:`_fit_one` over restarts; raw_pos (R, 3, K)."""
    one = functools.partial(
        _fit_one, fit_offset=fit_offset, steps=steps, polish_steps=polish_steps
    )
    return jax.vmap(one, in_axes=(0, None, None, None))(raw_pos, p, learning_rate, rtol)


def _initial_positions(key, n_restarts, k, dtype):
    """Raw (R, 3, K) starts: positions in the inner 90 %, depths in the inner 80 %."""
    u = jax.random.uniform(key, (n_restarts, 3, k), dtype=dtype)
    lo = jnp.asarray([0.05, 0.05, 0.1], dtype)[None, :, None]
    hi = jnp.asarray([0.95, 0.95, 0.9], dtype)[None, :, None]
    q = lo + (hi - lo) * u
    return jnp.log(q) - jnp.log1p(-q)


# --- input handling ----------------------------------------------------------------


def _is_int(v):
    return isinstance(v, numbers.Integral) and not isinstance(v, bool)


def _check_int(value, name, minimum):
    if not _is_int(value) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def _points(data, lat, lon):
    """Flatten a Grid or (values, lat, lon) to float64 NumPy arrays of shape (N,)."""
    if isinstance(data, Grid):
        if lat is not None or lon is not None:
            raise ValueError("lat and lon must be None when data is a Grid (it has its own)")
        if data.values.ndim != 2:
            raise ValueError(
                f"data must be a single-channel Grid of shape (ny, nx); got values of shape "
                f"{data.values.shape}"
            )
        values = np.asarray(data.values, dtype=float)
        lat_p, lon_p = np.meshgrid(data.lat, data.lon, indexing="ij")
        return lat_p.ravel(), lon_p.ravel(), values.ravel(), values.shape
    if lat is None or lon is None:
        raise ValueError(
            "lat and lon are required when data is an array of anomaly values (mGal); "
            "or pass a Grid"
        )
    values = np.asarray(data, dtype=float)
    lat, lon = np.asarray(lat, dtype=float), np.asarray(lon, dtype=float)
    if values.ndim == 2 and lat.ndim == 1 and lon.ndim == 1 and (
        lat.shape[0], lon.shape[0]) == values.shape and lat.shape != values.shape:
        lat, lon = np.meshgrid(lat, lon, indexing="ij")  # 1-D axes of a (ny, nx) map
    try:
        lat_p, lon_p = np.broadcast_to(lat, values.shape), np.broadcast_to(lon, values.shape)
    except ValueError:
        raise ValueError(
            f"lat {lat.shape} and lon {lon.shape} must broadcast to data's shape {values.shape} "
            f"(or be the 1-D axes (ny,), (nx,) of a (ny, nx) map)"
        ) from None
    return lat_p.ravel(), lon_p.ravel(), values.ravel(), values.shape


def _check_finite(x, name):
    bad = ~np.isfinite(x)
    if np.any(bad):
        raise ValueError(
            f"{name} must be finite; found {x[bad][0]!r} ({int(bad.sum())} non-finite "
            f"value(s) of {x.size}) — cut the window to the valid part or fill the gaps"
        )


def _problem(data, lat, lon, h, depth_bounds, margin, fit_offset, k):
    """Validate the inputs and build the dimensionless :class:`_Problem` (host side)."""
    lat_p, lon_p, values, shape = _points(data, lat, lon)
    _check_finite(values, "data")
    _check_finite(lat_p, "lat")
    _check_finite(lon_p, "lon")
    if np.any(np.abs(lat_p) > 90.0):
        raise ValueError(f"lat must lie within [-90, 90] degrees; got {np.max(np.abs(lat_p))!r}")
    h_arr = np.asarray(h, dtype=float)
    try:
        h_p = np.broadcast_to(h_arr, shape).ravel()
    except ValueError:
        raise ValueError(
            f"h {h_arr.shape} must be a scalar or broadcast to data's shape {shape}"
        ) from None
    _check_finite(h_p, "h")
    n_params = 4 * k + int(fit_offset)
    if values.size <= n_params:
        raise ValueError(
            f"data has {values.size} point(s); fitting K = {k} masses"
            f"{' and an offset' if fit_offset else ''} needs more than {n_params} "
            f"(4K{' + 1' if fit_offset else ''} parameters)"
        )
    try:
        d_min, d_max = (float(v) for v in depth_bounds)
    except (TypeError, ValueError):
        raise ValueError(
            f"depth_bounds must be a pair (d_min, d_max) of depths in m; got {depth_bounds!r}"
        ) from None
    if not (np.isfinite(d_min) and np.isfinite(d_max) and d_min < d_max):
        raise ValueError(
            f"depth_bounds must be finite with d_min < d_max (m, positive down); "
            f"got {depth_bounds!r}"
        )
    if d_min <= -np.min(h_p):
        raise ValueError(
            f"depth_bounds[0] = {d_min!r} m must put every mass below the lowest observation "
            f"point (depth > -min(h) = {-np.min(h_p)!r} m)"
        )
    margin = float(margin)
    if not (np.isfinite(margin) and margin >= 0.0):
        raise ValueError(f"margin must be a finite number of degrees >= 0; got {margin!r}")
    lat_lo, lat_hi = np.min(lat_p) - margin, np.max(lat_p) + margin
    lon_lo, lon_hi = np.min(lon_p) - margin, np.max(lon_p) + margin
    if lat_hi <= lat_lo or lon_hi <= lon_lo:
        raise ValueError(
            f"the data points must span a latitude and a longitude range (or margin > 0); "
            f"got lat {lat_lo!r}..{lat_hi!r}, lon {lon_lo!r}..{lon_hi!r}"
        )
    if lat_lo < -90.0 or lat_hi > 90.0:
        raise ValueError(
            f"margin {margin!r} takes the mass box beyond the poles (lat {lat_lo!r}..{lat_hi!r})"
        )
    lat0, lon0 = 0.5 * (lat_lo + lat_hi), 0.5 * (lon_lo + lon_hi)
    phi0, lam0 = np.deg2rad(lat0), np.deg2rad(lon0)
    length = 0.5 * (d_min + d_max)
    phi, lam = np.deg2rad(lat_p), np.deg2rad(lon_p)
    up = np.stack([np.cos(phi) * np.cos(lam), np.cos(phi) * np.sin(lam), np.sin(phi)])
    obs = (_ecef_np(lat_p, lon_p, h_p) - _ecef_np(lat0, lon0, 0.0)[:, None]) / length
    centre = float(np.mean(values)) if fit_offset else 0.0
    scale = float(np.std(values)) if fit_offset else float(np.sqrt(np.mean(values**2)))
    scale = scale if scale > 0 else 1.0
    dt = jnp.result_type(float)
    p = _Problem(
        obs=jnp.asarray(obs, dt),
        up=jnp.asarray(up, dt),
        target=jnp.asarray((values - centre) / scale, dt),
        lat0=jnp.asarray(lat0, dt),
        lon0=jnp.asarray(lon0, dt),
        trig0=jnp.asarray([np.sin(phi0), np.cos(phi0), np.sin(lam0), np.cos(lam0)], dt),
        lat_lo=jnp.asarray(lat_lo - lat0, dt),
        lat_span=jnp.asarray(lat_hi - lat_lo, dt),
        lon_lo=jnp.asarray(lon_lo - lon0, dt),
        lon_span=jnp.asarray(lon_hi - lon_lo, dt),
        depth_lo=jnp.asarray(d_min, dt),
        depth_span=jnp.asarray(d_max - d_min, dt),
        length=jnp.asarray(length, dt),
    )
    return p, centre, scale


def _to_masses(raw, p, scale):
    """Physical PointMasses (float64 host arithmetic) from raw parameters of one fit."""
    dlat, dlon, depth = (np.asarray(v, dtype=float) for v in _positions(raw, p))
    length = float(p.length)
    mass = np.asarray(raw.mass, dtype=float) * scale * c.MGAL * length**2 / c.G_NEWTON
    order = np.argsort(-np.abs(mass), kind="stable")
    return PointMasses.create(
        lat=float(p.lat0) + dlat[order],
        lon=float(p.lon0) + dlon[order],
        depth=depth[order],
        mass=mass[order],
    )


# --- public ------------------------------------------------------------------------


def fit_point_masses(
    data,
    k,
    *,
    lat=None,
    lon=None,
    h=0.0,
    depth_bounds=(5.0e3, 100.0e3),
    margin=0.0,
    fit_offset=True,
    n_restarts=16,
    steps=300,
    polish_steps=150,
    learning_rate=0.05,
    rtol=1e-4,
    key=0,
):
    """Fit ``K`` point masses (position, depth, mass) to a gravity anomaly map.

    Minimises ``mean((gravity_anomaly(masses, lat, lon, h) + offset − data)²)`` over the
    masses' latitudes, longitudes, depths and masses (and the offset), with the
    bounds built into the parameterisation (see the module docstring), from
    ``n_restarts`` random starts run together in one compiled, vmapped call.

    Parameters
    ----------
    data : Grid or array_like
        The map: a single-channel :class:`~jaxgrav.grid.Grid` of anomalies (mGal), or
        an array of anomaly values (mGal) of any shape ``S`` with ``lat``/``lon``.
        Cut the window you want to fit first (e.g. slice a Grid's values and build a
        new one with :meth:`Grid.from_arrays`).
    k : int
        Number of masses ``K >= 1`` (static: one compilation per ``K``).
    lat, lon : array_like, optional
        Point coordinates (degrees) when ``data`` is an array: broadcast to ``S``, or
        the 1-D axes ``(ny,)``, ``(nx,)`` of a ``(ny, nx)`` map. Not allowed with a Grid.
    h : float or array_like, default 0
        Ellipsoidal height of the data points (m), broadcast to ``S``.
    depth_bounds : (float, float), default (5e3, 100e3)
        Depth range ``(d_min, d_max)`` of the masses (m, positive down, ``d_min <
        d_max``, every mass below every data point).
    margin : float, default 0
        Degrees by which the masses' lat/lon box extends beyond the data's box.
    fit_offset : bool, default True
        Fit a constant offset (mGal) as well (started at the data mean). Static.
    n_restarts : int, default 16
        Random starts (static); all are fitted, the best is returned.
    steps : int, default 300
        Adam iterations per start (static).
    polish_steps : int, default 150
        Levenberg–Marquardt iterations after Adam (static; 0 to skip).
    learning_rate : float, default 0.05
        Initial Adam step on the raw (dimensionless) parameters; cosine-decayed to
        2 % of it over ``steps``. Traced: changing it does not recompile.
    rtol : float, default 1e-4
        Relative loss decrease below which the fit counts as converged (traced).
    key : int or jax.Array, default 0
        Seed or PRNG key of the random starts.

    Returns
    -------
    PointMassFit
        Best masses (a :class:`~jaxgrav.fields.pointmass.PointMasses`: use
        ``gravity_anomaly(fit.masses, lat, lon, h) + fit.offset`` or
        ``fit.anomaly(lat, lon, h)`` as a map), the offset, the residual RMS (mGal),
        every restart's RMS, the iteration count and the converged flag.

    Raises
    ------
    ValueError
        If ``k``, ``n_restarts``, ``steps`` or ``polish_steps`` is not a suitable
        integer, the data hold NaN/inf, the coordinates do not match the data, the
        depth bounds are inverted or above the data, or there are no more data points
        than the ``4K (+1)`` parameters.

    Notes
    -----
    The fit runs in JAX's default float dtype (float32 unless x64 is enabled); the
    dimensionless formulation keeps float32 accurate to well below 0.01 mGal in the
    model. Cost per iteration is ``O(N·K·n_restarts)``. The returned RMS is that of
    the fitted model evaluated in the fitting dtype.
    """
    k = _check_int(k, "k", 1)
    n_restarts = _check_int(n_restarts, "n_restarts", 1)
    steps = _check_int(steps, "steps", 0)
    polish_steps = _check_int(polish_steps, "polish_steps", 0)
    if steps + polish_steps < 1:
        raise ValueError(
            f"steps + polish_steps must be >= 1; got steps={steps}, polish_steps={polish_steps}"
        )
    for name, v in (("learning_rate", learning_rate), ("rtol", rtol)):
        if not (np.ndim(v) == 0 and np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a finite number > 0; got {v!r}")
    fit_offset = bool(fit_offset)
    p, centre, scale = _problem(data, lat, lon, h, depth_bounds, margin, fit_offset, k)
    if _is_int(key):
        key = jax.random.PRNGKey(int(key))
    dt = p.target.dtype
    raw_pos = _initial_positions(key, n_restarts, k, dt)
    raws, losses, converged = _fit_batch(
        raw_pos,
        p,
        jnp.asarray(learning_rate, dt),
        jnp.asarray(rtol, dt),
        fit_offset=fit_offset,
        steps=steps,
        polish_steps=polish_steps,
    )
    losses = np.asarray(losses, dtype=float)
    restart_rms = np.sqrt(np.where(np.isfinite(losses), losses, np.inf)) * scale
    best = int(np.argmin(restart_rms))
    if not np.isfinite(restart_rms[best]):
        raise FloatingPointError("every restart of the point-mass fit diverged (non-finite loss)")
    raw = jax.tree_util.tree_map(lambda x: x[best], raws)
    return PointMassFit(
        masses=_to_masses(raw, p, scale),
        offset=centre + float(raw.offset) * scale,
        rms=float(restart_rms[best]),
        restart_rms=restart_rms,
        iterations=steps + polish_steps,
        converged=bool(converged[best]),
    )


def sweep_point_masses(data, k_values=range(1, 11), **kwargs):
    """Fit ``K`` masses for each ``K`` in ``k_values`` and report the residual RMS.

    Parameters
    ----------
    data : Grid or array_like
        The map, as for :func:`fit_point_masses`.
    k_values : iterable of int, default 1..10
        Numbers of masses to try (each distinct ``K`` compiles once).
    **kwargs
        Passed to :func:`fit_point_masses` (``lat``, ``lon``, ``depth_bounds``,
        ``n_restarts``, ``steps``, ``key``, ...). Each ``K`` uses the same ``key``,
        i.e. the same random draws for its starts.

    Returns
    -------
    PointMassSweep
        ``k``, ``rms`` (mGal) and the fits.

    Raises
    ------
    ValueError
        If ``k_values`` is empty, or as :func:`fit_point_masses`.
    """
    ks = list(k_values)
    if not ks:
        raise ValueError(f"k_values must hold at least one K >= 1; got {k_values!r}")
    for kk in ks:
        _check_int(kk, "k_values element", 1)
    fits = tuple(fit_point_masses(data, kk, **kwargs) for kk in ks)
    return PointMassSweep(
        k=np.asarray(ks, dtype=int), rms=np.asarray([f.rms for f in fits]), fits=fits
    )
