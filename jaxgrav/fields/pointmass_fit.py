"""Fit a few buried point masses to a gravity anomaly map (paper D's model, automated).

Paper D describes its match area by three point masses found "by repeated
experiment". :func:`fit_point_masses` finds ``K`` masses by least squares instead:
it minimises the mean squared misfit between the point-mass anomaly
(:func:`jaxgrav.fields.pointmass.gravity_anomaly`, exact WGS84/ECEF geometry) plus an
optional constant offset and the map values, over the latitude, longitude, depth and
mass of every mass.

This module is the public entry point and its results. The pieces:

* :mod:`jaxgrav.fields.pointmass_fit_model` — the bounded parameterisation and the
  dimensionless model and loss;
* :mod:`jaxgrav.fields.pointmass_fit_inputs` — input checks and the problem built
  from the data;
* :mod:`jaxgrav.fields.pointmass_fit_solver` — linear start, Adam, Levenberg–Marquardt
  over vmapped random restarts, in one compiled call. The restart with the smallest
  misfit is returned.

Using the fit as a map
----------------------
The result's ``masses`` is an ordinary :class:`~jaxgrav.fields.pointmass.PointMasses`,
so ``gravity_anomaly(fit.masses, lat, lon, h) + fit.offset`` (or
:meth:`PointMassFit.anomaly`) is a smooth, differentiable, analytic map function for
the filters and matchers (paper D uses exactly this as its map ``Δg_M``).

:func:`save_point_masses` writes a fit (or any :class:`PointMasses` and an offset) to
a small JSON file, atomically; :func:`load_point_masses` reads it back exactly, and
``jaxgrav filter --point-masses FILE.json`` uses it as its map.
"""

import json
import math
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._io import atomic_output
from jaxgrav.fields.pointmass import PointMasses, gravity_anomaly
from jaxgrav.fields.pointmass_fit_inputs import build_problem, check_int, is_int
from jaxgrav.fields.pointmass_fit_model import to_masses
from jaxgrav.fields.pointmass_fit_solver import fit_batch, initial_positions

__all__ = [
    "MODEL_FORMAT",
    "PointMassFit",
    "PointMassSweep",
    "fit_point_masses",
    "load_point_masses",
    "save_point_masses",
    "sweep_point_masses",
]

MODEL_FORMAT = "jaxgrav.point_masses"
"""The ``format`` tag of a point-mass model file (:func:`save_point_masses`)."""
_MODEL_VERSION = 1
_MODEL_FIELDS = ("lat", "lon", "depth", "mass")


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
    bounds built into the parameterisation (see
    :mod:`jaxgrav.fields.pointmass_fit_model`), from
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
    k = check_int(k, "k", 1)
    n_restarts = check_int(n_restarts, "n_restarts", 1)
    steps = check_int(steps, "steps", 0)
    polish_steps = check_int(polish_steps, "polish_steps", 0)
    if steps + polish_steps < 1:
        raise ValueError(
            f"steps + polish_steps must be >= 1; got steps={steps}, polish_steps={polish_steps}"
        )
    for name, v in (("learning_rate", learning_rate), ("rtol", rtol)):
        if not (np.ndim(v) == 0 and np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a finite number > 0; got {v!r}")
    fit_offset = bool(fit_offset)
    p, centre, scale = build_problem(data, lat, lon, h, depth_bounds, margin, fit_offset, k)
    if is_int(key):
        key = jax.random.PRNGKey(int(key))
    dt = p.target.dtype
    raw_pos = initial_positions(key, n_restarts, k, dt)
    raws, losses, converged = fit_batch(
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
        masses=to_masses(raw, p, scale),
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
        check_int(kk, "k_values element", 1)
    fits = tuple(fit_point_masses(data, kk, **kwargs) for kk in ks)
    return PointMassSweep(
        k=np.asarray(ks, dtype=int), rms=np.asarray([f.rms for f in fits]), fits=fits
    )


# --- model files ---------------------------------------------------------------------


def save_point_masses(path, model, *, offset=None, force=False):
    """Write a point-mass model to a JSON file, atomically (temp file + rename).

    Parameters
    ----------
    path : str or Path
        Output file (``.json`` by convention).
    model : PointMassFit or PointMasses
        A fit (its masses, offset and residual RMS are written) or bare masses.
    offset : float, optional
        Constant added to the masses' anomaly (mGal); default the fit's offset, or 0
        for bare masses.
    force : bool
        Replace an existing file.

    Notes
    -----
    The file holds ``format`` (:data:`MODEL_FORMAT`), ``version``, the per-mass lists
    ``lat``, ``lon`` (degrees), ``depth`` (m), ``mass`` (kg), ``offset`` (mGal) and,
    for a fit, ``rms`` (mGal). Floats are written in their shortest exact form, so
    :func:`load_point_masses` returns the same numbers.

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``force`` is false.
    ValueError
        If the offset is not finite.
    """
    rms = None
    if isinstance(model, PointMassFit):
        rms = float(model.rms)
        offset = model.offset if offset is None else offset
        model = model.masses
    if not isinstance(model, PointMasses):
        raise TypeError(f"model must be a PointMassFit or PointMasses; got {type(model).__name__}")
    offset = 0.0 if offset is None else float(offset)
    if not math.isfinite(offset):
        raise ValueError(f"offset must be a finite number of mGal; got {offset!r}")
    doc = {"format": MODEL_FORMAT, "version": _MODEL_VERSION,
           "units": {"lat": "degree", "lon": "degree", "depth": "m", "mass": "kg",
                     "offset": "mGal"}}
    for name in _MODEL_FIELDS:
        doc[name] = [float(v) for v in np.asarray(getattr(model, name), dtype=float)]
    doc["offset"] = offset
    if rms is not None:
        doc["rms"] = rms
    with atomic_output(path, force=force) as tmp:
        tmp.write_text(json.dumps(doc, indent=1) + "\n")


def load_point_masses(path):
    """Read a point-mass model written by :func:`save_point_masses`.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    masses : PointMasses
        The ``K`` masses (validated as :meth:`PointMasses.create`).
    offset : float
        Constant (mGal) the model adds to the masses' anomaly; the map is
        ``gravity_anomaly(masses, lat, lon, h) + offset``.

    Raises
    ------
    FileNotFoundError
        If there is no such file.
    ValueError
        If the file is not a JSON point-mass model (wrong format tag or version, a
        field missing or of the wrong type, non-finite values, unequal lengths, a
        latitude out of range); the message names the file and the problem.
    """
    path = Path(path)
    where = f"point-mass model {str(path)!r}"
    expected = ('a point-mass model is a JSON object with "format": "jaxgrav.point_masses", '
                '"version": 1, the lists "lat", "lon", "depth", "mass" and an "offset", as '
                "written by jaxgrav.fields.pointmass_fit.save_point_masses in Python")
    if not path.exists():
        raise FileNotFoundError(f"{where}: no such file")
    if not path.is_file():
        raise ValueError(f"{where} is not a file")
    try:
        # utf-8-sig: a byte-order mark, as Windows editors write, is read too (it was
        # refused as "Unexpected UTF-8 BOM")
        doc = json.loads(path.read_text(encoding="utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"{where} is not JSON ({err}); {expected}") from None
    if not isinstance(doc, dict) or doc.get("format") != MODEL_FORMAT:
        got = (f"it holds {_json_text(doc)}, not a JSON object" if not isinstance(doc, dict)
               else 'it has no "format" field' if "format" not in doc
               else f"its \"format\" is {_json_text(doc['format'])}")
        raise ValueError(f"{where} is not a jaxgrav point-mass model ({got}); {expected}")
    if doc.get("version") != _MODEL_VERSION:
        raise ValueError(f"{where}: version must be {_MODEL_VERSION}; got "
                         f"{_json_text(doc.get('version'))}")
    missing = [k for k in (*_MODEL_FIELDS, "offset") if k not in doc]
    if missing:
        raise ValueError(f"{where} lacks field{'s' * (len(missing) > 1)} "
                         f"{', '.join(missing)}; {expected}")
    values = {}
    for name in _MODEL_FIELDS:
        v = doc[name]
        if not (isinstance(v, list) and all(isinstance(a, int | float) and not isinstance(a, bool)
                                            for a in v)):
            raise ValueError(f"{where}: {name} must be a list of numbers; got {_json_text(v)}")
        values[name] = v
    offset = doc["offset"]
    if isinstance(offset, bool) or not isinstance(offset, int | float) or not math.isfinite(
            offset):
        raise ValueError(f"{where}: offset must be a finite number of mGal; got "
                         f"{_json_text(offset)}")
    try:
        masses = PointMasses.create(**values)
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None
    return masses, float(offset)


def _json_text(value):
    """A value of a JSON file as the file writes it (``null``, ``"grid"``), shortened."""
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."
