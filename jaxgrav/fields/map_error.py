"""Map-error models: the field the sensors see when the map is not the truth.

* :class:`CorrelatedMapError` (:func:`map_error`): truth = map + a stationary Gaussian
  error of standard deviation σ (map units) and correlation length L (m), covariance
  ``C(r) = σ² (1 + r/L) e^{−r/L}`` (``"markov2"``, the default) or ``σ² e^{−r/L}``
  (``"markov1"``, exponential);
* :class:`TruthGrid` (:func:`truth_grid`): an explicit truth grid (e.g. a finer field).

:func:`truth_field` draws a run's truth from a PRNG key; :func:`along_track_covariance`
gives the map error's covariance between the fixes of a track (for GLS matching).
"""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import check_finite, concrete
from jaxgrav.fields.random import markov_spectrum
from jaxgrav.grid import Grid

__all__ = [
    "FAMILIES", "MAP_ERROR_STREAM", "CorrelatedMapError", "TruthGrid", "along_track_covariance",
    "check_covers", "error_field", "map_error", "map_error_key", "truth_field", "truth_grid",
]

FAMILIES = {"markov1": 1, "markov2": 2}
"""Spectrum families: name -> Gauss–Markov order (1 exponential, 2 second order)."""

MAP_ERROR_STREAM = 0x6D6170  # fold-in constant of :func:`map_error_key` ("map")


@pytree_dataclass
class CorrelatedMapError:
    """Truth = map + a stationary, isotropic Gaussian error field.

    Build one with :func:`map_error` (validates). ``sigma`` and ``length_m`` are
    pytree data (sweeping them never recompiles); ``family`` is static.

    Attributes
    ----------
    sigma : Array, scalar
        Standard deviation of the map error (map units, e.g. mGal), ≥ 0 (0: perfect map).
    length_m : Array, scalar
        Correlation length L (m), > 0 (``markov2``: correlation 2/e at L, 1/2 at 1.68 L).
    family : {"markov2", "markov1"}
        ``C = σ² (1 + r/L) e^{−r/L}`` or ``C = σ² e^{−r/L}`` (static).
    """

    sigma: jax.Array
    length_m: jax.Array
    family: str = static_field("markov2")

    @property
    def order(self):
        """Gauss–Markov order of the family (1 or 2)."""
        return FAMILIES[self.family]

    def covariance(self, r):
        """Covariance of the map error at horizontal distance ``r`` (m), map units²."""
        unit = markov_spectrum(1.0, self.length_m, order=self.order)
        return self.sigma**2 * unit.covariance(r)


@pytree_dataclass
class TruthGrid:
    """Truth = an explicit grid (e.g. a finer field than the map); see :func:`truth_grid`.

    Attributes
    ----------
    grid : Grid
        The field the sensors see (map units).
    error : CorrelatedMapError or None
        Statistical description of ``truth − map`` (σ, L) if known.
    """

    grid: Grid
    error: CorrelatedMapError | None = None


def _real(x, name, unit, *, allow_zero):
    """Validate a concrete real, finite, (non-)negative number or array; pass tracers."""
    arr = concrete(x)
    if arr is None:
        return x
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be a real number ({unit}); got {x!r} ({type(x).__name__})")
    bad = ~np.isfinite(arr) | ((arr < 0) if allow_zero else (arr <= 0))
    if np.any(bad):
        rule = ">= 0" if allow_zero else "> 0"
        val = arr.reshape(-1)[np.argmax(bad)].item()
        raise ValueError(f"{name} must be finite and {rule} ({unit}); got {val!r}")
    return x


def map_error(sigma, length_m, *, family="markov2"):
    """A correlated map-error model (validated).

    Parameters
    ----------
    sigma : float or array_like
        Standard deviation of the map error (map units, e.g. mGal), finite, ≥ 0
        (0 = perfect map). Scalar for :func:`truth_field` (arrays: to ``vmap`` over).
    length_m : float or array_like
        Correlation length L (m), finite, > 0.
    family : {"markov2", "markov1"}, default "markov2"
        Second-order Gauss–Markov ``σ² (1 + r/L) e^{−r/L}`` or exponential ``σ² e^{−r/L}``.

    Returns
    -------
    CorrelatedMapError

    Raises TypeError if ``sigma`` or ``length_m`` is not a real number (a string, a
    bool, None), ValueError if ``sigma`` < 0, ``length_m`` ≤ 0, either is NaN or inf,
    or ``family`` is unknown (concrete values only; traced values pass unchecked).
    """
    if not isinstance(family, str) or family not in FAMILIES:
        raise ValueError(f"family must be one of {sorted(FAMILIES)}; got {family!r}")
    _real(sigma, "sigma", "map units", allow_zero=True)
    _real(length_m, "length_m", "m", allow_zero=False)
    dtype = jnp.result_type(float)
    return CorrelatedMapError(
        sigma=jnp.asarray(sigma, dtype=dtype), length_m=jnp.asarray(length_m, dtype=dtype),
        family=family,
    )


def truth_grid(grid, *, error=None, map_grid=None):
    """An explicit truth grid (TypeError unless ``grid`` is a Grid).

    Parameters
    ----------
    grid : Grid
        The field the sensors see (map units).
    error : CorrelatedMapError, optional
        Statistical description of ``truth − map`` for :func:`along_track_covariance`.
    map_grid : Grid, optional
        The map; if given, ``grid`` must cover it (ValueError), else
        :func:`truth_field` checks.

    Returns
    -------
    TruthGrid
    """
    if not isinstance(grid, Grid):
        raise TypeError(f"grid must be a jaxgrav Grid (the truth field); got {type(grid).__name__}")
    if error is not None and not isinstance(error, CorrelatedMapError):
        raise TypeError(
            "error must be a CorrelatedMapError (map_error(...)) or None; got "
            f"{type(error).__name__}"
        )
    if map_grid is not None:
        check_covers(grid, map_grid, "grid")
    return TruthGrid(grid=grid, error=error)


def check_covers(truth, grid, name="truth"):
    """Raise ``ValueError`` (naming ``name``) unless Grid ``truth`` covers Grid ``grid``.

    The two may use different longitude conventions (0–360 or ±180).
    """
    lon_min, lon_max, lat_min, lat_max = grid.extent
    t_lon_min, t_lon_max, t_lat_min, t_lat_max = truth.extent
    tol = 1e-6 * max(grid.dlat, grid.dlon, truth.dlat, truth.dlon) + 1e-9
    w0 = t_lon_min + np.mod(lon_min - t_lon_min, 360.0)  # map's west edge in truth's range
    if w0 - t_lon_min > 360.0 - tol:
        w0 -= 360.0
    ok = (lat_min >= t_lat_min - tol and lat_max <= t_lat_max + tol
          and w0 >= t_lon_min - tol and w0 + (lon_max - lon_min) <= t_lon_max + tol)
    if not ok:
        raise ValueError(
            f"{name} must cover the map's area (lat {lat_min:g}..{lat_max:g} deg, lon "
            f"{lon_min:g}..{lon_max:g} deg); got a truth grid over lat {t_lat_min:g}.."
            f"{t_lat_max:g} deg, lon {t_lon_min:g}..{t_lon_max:g} deg"
        )


def map_error_key(key):
    """The key of a run's map-error draw, independent of the run's other draws.

    ``jax.random.fold_in(key, MAP_ERROR_STREAM)``: a scenario drawing its map error
    from it keeps its other draws (split from ``key`` as before) unchanged, so runs
    with and without map error differ only by the map error. ``key``: the run's key.
    """
    return jax.random.fold_in(key, MAP_ERROR_STREAM)


def error_field(key, model, shape, spacing):
    """Draw a map-error field on a regular grid with the model's exact node covariance.

    Circulant embedding on the grid's torus: the nodes' covariance ``C(r)`` at the
    wrapped distance ``r`` is FFT'd into the variance of every Fourier mode, and white
    noise coloured by their square roots has exactly that covariance, for both
    families, at every lag up to half the grid. (A synthesis from the spectrum
    ``S(|k|)`` truncates it at the grid's Nyquist: for ``markov1`` at L ≈ 2.7 cells the
    correlation at one cell comes out 0.77 instead of 0.69.) Negative mode variances
    (possible when L is not small against the grid) are zeroed and the level
    restored: each node's variance is exactly σ². The map mean is not removed.

    Parameters
    ----------
    key : PRNG key
    model : CorrelatedMapError
        Scalar σ and L (may be traced).
    shape, spacing : tuple
        ``(ny, nx)`` nodes and ``(dy, dx)`` node spacing (m), static.

    Returns
    -------
    Array, shape (ny, nx)
        The error (map units), rows south to north.
    """
    shape, spacing = tuple(int(v) for v in shape), tuple(float(v) for v in spacing)
    return _error_field(key, model, shape=shape, spacing=spacing)


@functools.partial(jax.jit, static_argnames=("shape", "spacing"))
def _error_field(key, model, *, shape, spacing):
    ny, nx = shape
    dtype = jnp.result_type(float)
    iy = np.minimum(np.arange(ny), ny - np.arange(ny)) * spacing[0]  # wrapped distances (m)
    ix = np.minimum(np.arange(nx), nx - np.arange(nx)) * spacing[1]
    r = jnp.asarray(np.hypot(iy[:, None], ix[None, :]), dtype)
    unit = dataclasses.replace(model, sigma=jnp.asarray(1.0, dtype))
    lam = jnp.fft.rfft2(unit.covariance(r)).real  # mode variances × N, rfft half-plane
    pos = lam > 0
    lam_pos = jnp.where(pos, lam, 0.0)
    # Σ over the full plane of the clipped variances, from the half plane (Hermitian pairs)
    weight = np.full(lam.shape[-1], 2.0)
    weight[0] = 1.0
    if nx % 2 == 0:
        weight[-1] = 1.0
    level = (ny * nx) / jnp.sum(lam_pos * weight)  # Σ λ = N·C(0) = N before clipping
    amp = jnp.where(pos, jnp.sqrt(jnp.where(pos, lam * level, 1.0)), 0.0)  # finite grads
    noise = jax.random.normal(key, shape, dtype=dtype)
    return model.sigma * jnp.fft.irfft2(jnp.fft.rfft2(noise) * amp, s=shape)


def truth_field(key, grid, model):
    """The field the sensors see: the map plus a drawn error, or an explicit truth.

    For :class:`CorrelatedMapError` an error drawn from ``key`` by :func:`error_field`
    on the map's own nodes (node covariance exactly ``C(r)``, σ = 0 included) is
    added to the map: same geometry, sampled (interpolated) exactly like the map.

    * Metric spacing: one node spacing ``(dlat·M(φm), dlon·N(φm)·cos φm)`` in metres
      at the grid's middle latitude φm (M, N the WGS84 meridian and prime-vertical
      radii). At another latitude φ the true east-west distance between nodes is
      ``cos φ / cos φm`` times that, so there the error's east-west correlation
      length is ``L·cos φ/cos φm`` (on a map over 24–36° N: from +5 % of L at the
      south edge to −7 % at the north edge); north-south and the variance are exact.
    * Periodic wrap: the error is periodic over the grid, as if the map's west edge
      adjoined its east edge (and the south edge the north edge): nodes near
      opposite edges are correlated as if they were neighbours. Harmless when L is a
      small fraction of the map's size.

    One field per run: ``jax.vmap(lambda k: truth_field(k, grid, model))(keys)``, or
    inside a vmapped run from :func:`map_error_key` of the run's key. One field per
    batch: draw it once with one key and give that truth to every run. jit-able with
    σ and L traced (no recompilation when they change), differentiable in both.

    Parameters
    ----------
    key : PRNG key
        The draw's key (unused for TruthGrid, None or σ = 0).
    grid : Grid
        The navigation map, values ``(ny, nx)`` (map units).
    model : CorrelatedMapError, TruthGrid or None
        The map-error model; None is a perfect map.

    Returns
    -------
    Grid
        CorrelatedMapError: the map's geometry, values ``map + error`` ``(ny, nx)``
        (map's float dtype); TruthGrid: its grid; None or concrete σ = 0: the map.

    Raises TypeError for a wrong ``grid`` or ``model`` type, ValueError if a TruthGrid
    does not cover the map, σ or L is not a scalar or the map's values are not 2-D.
    """
    if not isinstance(grid, Grid):
        raise TypeError(f"grid must be a jaxgrav Grid (the map); got {type(grid).__name__}")
    if model is None:
        return grid
    if isinstance(model, TruthGrid):
        check_covers(model.grid, grid, "model.grid (the truth grid)")
        return model.grid
    if not isinstance(model, CorrelatedMapError):
        raise TypeError(
            "model must be a CorrelatedMapError (map_error(...)), a TruthGrid (truth_grid(...))"
            f" or None; got {type(model).__name__}"
        )
    if np.ndim(model.sigma) != 0 or np.ndim(model.length_m) != 0:
        raise ValueError("model.sigma and model.length_m must be scalars (vmap over models to "
                         f"sweep them); got shapes {np.shape(model.sigma)}, "
                         f"{np.shape(model.length_m)}")
    sigma = concrete(model.sigma)
    if sigma is not None and sigma == 0:
        return grid
    if grid.values.ndim != 2:
        raise ValueError(f"grid.values must be 2-D (ny, nx); got shape {grid.values.shape}")
    dtype = grid.values.dtype
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    with jax.ensure_compile_time_eval():  # the static geometry's spacing, also under jit
        spacing = grid.spacing_m()
    error = error_field(key, model, grid.values.shape, spacing)
    values = grid.values.astype(dtype) + error.astype(dtype)
    return dataclasses.replace(grid, values=values)


def along_track_covariance(model, north_m, east_m):
    """Covariance of the map error between fixes at local north/east positions.

    ``C[i, j] = C_map(|p_i − p_j|)`` at the horizontal distance between fixes i and j;
    the reading noise ``σ_n² I`` is not included (add it for a GLS score).

    Parameters
    ----------
    model : CorrelatedMapError, TruthGrid or None
        A TruthGrid needs its ``error`` description (σ, L): an arbitrary truth grid's
        covariance is unknown, so one without it is refused. None gives zeros.
    north_m, east_m : array_like, shape (..., N)
        Fix positions (m) in a local frame (e.g. from
        :func:`jaxgrav.geodesy.local_offsets_m`), broadcast together.

    Returns
    -------
    Array, shape (..., N, N)
        Symmetric positive semi-definite covariance (map units²).

    Raises TypeError for a wrong ``model`` type, ValueError for a TruthGrid without
    ``error``, scalar positions or NaN/inf positions.
    """
    if isinstance(model, TruthGrid):
        if model.error is None:
            raise ValueError(
                "model is a TruthGrid without an error description, so the covariance of "
                "its map error is unknown; build it with truth_grid(grid, "
                "error=map_error(sigma, length_m)) to state σ and L"
            )
        model = model.error
    if model is not None and not isinstance(model, CorrelatedMapError):
        raise TypeError(
            "model must be a CorrelatedMapError, a TruthGrid or None; got "
            f"{type(model).__name__}"
        )
    check_finite(north_m, "north_m")
    check_finite(east_m, "east_m")
    north, east = jnp.broadcast_arrays(jnp.asarray(north_m, float), jnp.asarray(east_m, float))
    if north.ndim < 1:
        raise ValueError(f"north_m and east_m must have shape (..., N); got shape {north.shape}")
    if model is None:
        return jnp.zeros(north.shape + north.shape[-1:], north.dtype)
    return _pairwise_covariance(model, north, east)


@jax.jit
def _pairwise_covariance(model, north, east):
    dn = north[..., :, None] - north[..., None, :]
    de = east[..., :, None] - east[..., None, :]
    r2 = dn**2 + de**2
    pos = r2 > 0
    r = jnp.where(pos, jnp.sqrt(jnp.where(pos, r2, 1.0)), 0.0)  # finite gradients at r = 0
    return model.covariance(r)
