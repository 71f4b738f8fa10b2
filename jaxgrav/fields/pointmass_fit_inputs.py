"""Input checks of the point-mass fit and the dimensionless problem built from the data.

:func:`build_problem` validates a map (a :class:`~jaxgrav.grid.Grid` or values with
coordinates), the depth bounds and the margin, and builds the
:class:`~jaxgrav.fields.pointmass_fit_model.Problem` of
:mod:`jaxgrav.fields.pointmass_fit_model` in host float64 arithmetic. Everything here is
package-internal: the public entry point is :func:`jaxgrav.fields.fit_point_masses`.
"""

import numbers

import jax.numpy as jnp
import numpy as np

from jaxgrav import constants as c
from jaxgrav.fields.pointmass_fit_model import Problem
from jaxgrav.grid import Grid


def is_int(v):
    """True for a Python or NumPy integer that is not a bool."""
    return isinstance(v, numbers.Integral) and not isinstance(v, bool)


def check_int(value, name, minimum):
    """Return ``value`` as an ``int`` ≥ ``minimum``, or raise ``ValueError`` naming ``name``."""
    if not is_int(value) or value < minimum:
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
            f"{name} must be finite; found {float(x[bad][0])!r} ({int(bad.sum())} non-finite "
            f"value(s) of {x.size}) — cut the window to the valid part or fill the gaps"
        )


def _ecef_np(lat, lon, h):
    """Geodetic to ECEF (m) in NumPy float64 (same formula as jaxgrav.geodesy)."""
    phi, lam = np.deg2rad(lat), np.deg2rad(lon)
    s, co = np.sin(phi), np.cos(phi)
    n = c.WGS84_A / np.sqrt(1.0 - c.WGS84_E2 * s**2)
    return np.stack(
        [(n + h) * co * np.cos(lam), (n + h) * co * np.sin(lam), (n * (1.0 - c.WGS84_E2) + h) * s]
    )


def build_problem(data, lat, lon, h, depth_bounds, margin, fit_offset, k):
    """Validate the inputs and build the dimensionless :class:`Problem` (host side)."""
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
    p = Problem(
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
