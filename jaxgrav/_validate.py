"""Input validators shared by the public functions.

Each check runs only on concrete inputs (NumPy arrays, Python numbers, committed
JAX arrays); under ``jit``/``vmap`` tracing there is nothing to inspect, and the
traced code reports problems through NaN results and validity masks instead.
Messages name the argument, the offending value and what was
expected.
"""

import jax
import numpy as np

__all__ = [
    "check_finite",
    "check_latitude",
    "check_points",
    "check_same_shape",
    "concrete",
]


def concrete(x):
    """Return ``x`` as a NumPy array, or ``None`` if it is a tracer (not inspectable)."""
    if isinstance(x, jax.core.Tracer):
        return None
    if isinstance(x, (list, tuple)) and any(isinstance(v, jax.core.Tracer) for v in x):
        return None
    return np.asarray(x)


def _first_bad(values, bad):
    idx = np.flatnonzero(bad)
    return values.reshape(-1)[idx[0]].item(), int(idx.size)  # a Python number in messages


def check_latitude(lat, name="lat"):
    """Raise ``ValueError`` if a concrete latitude lies outside [−90, 90] degrees or is NaN."""
    arr = concrete(lat)
    if arr is None:
        return
    arr = arr.astype(float, copy=False)
    bad = ~((arr >= -90.0) & (arr <= 90.0))
    if np.any(bad):
        val, n = _first_bad(arr, bad)
        raise ValueError(
            f"{name} must be a latitude in degrees within [-90, 90]; got {val!r}"
            f" ({n} value(s) out of range)"
        )


def check_finite(x, name):
    """Raise ``ValueError`` if a concrete array holds NaN or infinity."""
    arr = concrete(x)
    if arr is None:
        return
    bad = ~np.isfinite(arr)
    if np.any(bad):
        val, n = _first_bad(arr, bad)
        raise ValueError(f"{name} must be finite; found {val!r} ({n} non-finite value(s))")


def check_same_shape(**arrays):
    """Raise ``ValueError`` unless all the named arrays broadcast together."""
    shapes = {k: np.shape(v) for k, v in arrays.items()}
    try:
        np.broadcast_shapes(*shapes.values())
    except ValueError:
        desc = ", ".join(f"{k} {s}" for k, s in shapes.items())
        raise ValueError(f"arrays must have matching (broadcastable) shapes; got {desc}") from None


def check_points(lat, lon, h):
    """Validate geodetic points: shapes broadcast, latitudes in [−90, 90]°, lon and h finite.

    Parameters
    ----------
    lat, lon : array_like
        Degrees.
    h : array_like
        Height above the ellipsoid (m).

    Raises
    ------
    ValueError
        Naming the first offending argument and value (concrete inputs only).
    """
    check_same_shape(lat=lat, lon=lon, h=h)
    check_latitude(lat, "lat")
    check_finite(lon, "lon")
    check_finite(h, "h")
