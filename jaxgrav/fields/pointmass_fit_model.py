"""The dimensionless point-mass model that :func:`~jaxgrav.fields.fit_point_masses` fits.

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

The problem (:class:`Problem`) is built from the data by
:func:`jaxgrav.fields.pointmass_fit_inputs.build_problem`; the optimiser is
:mod:`jaxgrav.fields.pointmass_fit_solver`. Everything here is package-internal: the
public entry point is :func:`jaxgrav.fields.fit_point_masses`.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import constants as c
from jaxgrav.fields.pointmass import PointMasses

# --- the problem (all arrays, so new data of the same shape never retraces) ---------


class Problem(NamedTuple):
    """The fit's data in dimensionless form (built by ``build_problem``)."""

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


class RawParams(NamedTuple):
    """Unconstrained raw parameters of ``K`` masses and the offset (see the module notes)."""

    lat: jax.Array  # (K,)
    lon: jax.Array  # (K,)
    depth: jax.Array  # (K,)
    mass: jax.Array  # (K,)
    offset: jax.Array  # ()


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


def mass_positions(raw, p):
    """Offsets from the origin (degrees) and depths (m) of the masses, shape (K,)."""
    dlat = p.lat_lo + p.lat_span * jax.nn.sigmoid(raw.lat)
    dlon = p.lon_lo + p.lon_span * jax.nn.sigmoid(raw.lon)
    depth = p.depth_lo + p.depth_span * jax.nn.sigmoid(raw.depth)
    return dlat, dlon, depth


def unit_anomalies(dlat, dlon, depth, p):
    """(N, K) anomaly of each mass at each point for ``u_mass = 1``, in units of scale.

    A mass ``M = scale·L²/G`` gives ``G M (d·û)/ℓ³ = scale · (d'·û)/ℓ'³`` with
    primed lengths in units of L.
    """
    xm = _ecef_offset(dlat, dlon, -depth, p)
    d = [p.obs[i][:, None] - xm[i][None, :] / p.length for i in range(3)]
    inv = jax.lax.rsqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    proj = d[0] * p.up[0][:, None] + d[1] * p.up[1][:, None] + d[2] * p.up[2][:, None]
    return proj * inv**3


def predict_scaled(raw, p, fit_offset):
    """Modelled anomaly at the data points, in units of scale about the centre, (N,)."""
    a = unit_anomalies(*mass_positions(raw, p), p)
    out = a @ raw.mass
    return out + raw.offset if fit_offset else out


def misfit_loss(raw, p, fit_offset):
    """Mean squared normalised misfit (dimensionless); RMS (mGal) is sqrt(loss)·scale."""
    r = predict_scaled(raw, p, fit_offset) - p.target
    return jnp.mean(r**2)


def to_masses(raw, p, scale):
    """Physical PointMasses (float64 host arithmetic) from raw parameters of one fit."""
    dlat, dlon, depth = (np.asarray(v, dtype=float) for v in mass_positions(raw, p))
    length = float(p.length)
    mass = np.asarray(raw.mass, dtype=float) * scale * c.MGAL * length**2 / c.G_NEWTON
    order = np.argsort(-np.abs(mass), kind="stable")
    return PointMasses.create(
        lat=float(p.lat0) + dlat[order],
        lon=float(p.lon0) + dlon[order],
        depth=depth[order],
        mass=mass[order],
    )
