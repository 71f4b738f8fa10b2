"""Spherical-harmonic synthesis of a disturbing-potential model, in JAX.

Model convention (fixed; other modules rely on it): 4π-normalised real coefficients
(geodesy normalisation, no Condon–Shortley phase, pyshtools ``normalization='4pi',
csphase=1``) of the disturbing potential

.. math:: T(r, φ, λ) = \\frac{GM}{r} \\sum_{n=0}^{N} \\left(\\frac{R}{r}\\right)^n
          \\sum_{m=0}^{n} (\\bar C_{nm} \\cos mλ + \\bar S_{nm} \\sin mλ) \\bar P_{nm}(\\sin φ).

**Spherical approximation.** A point (lat, lon, h) is mapped to the sphere point
φ = lat, λ = lon, r = R + h: the latitude is used as a spherical latitude and the
height as a radial offset. This is the standard spherical approximation of physical
geodesy (relative error O(flattening) ≈ 0.3 % in the anomalous quantities) and is how
the shipped EGM2008-derived data are built. Derived quantities, in the same
approximation:

* gravity disturbance ``δg = −∂T/∂r = GM/r² Σ (n+1) (R/r)^n Y_n`` (mGal);
* gravity anomaly ``Δg = −∂T/∂r − 2T/r = GM/r² Σ (n−1) (R/r)^n Y_n`` (mGal);
* deflection of the vertical, Heiskanen–Moritz signs, ``ξ = −∂T/(γ r ∂φ)``,
  ``η = −∂T/(γ r cos φ ∂λ)`` (arcsec), γ = :func:`jaxgrav.geodesy.normal_gravity`.

**Legendre functions.** The fully normalised P̄nm are computed by the forward-column
recursion of Holmes & Featherstone (2002, J. Geodesy 76:279) on the scaled values
``X̄nm = 10⁻²⁸⁰ P̄nm / cos^m φ`` (the sectorals X̄mm are constants), run over degree n
for all orders at once; the factor ``10²⁸⁰ cos^m φ`` is applied to each order's sum at
the end. The heights enter the recursion, ``(R/r)^n`` being folded into it. The
scaled recursion is valid at every latitude up to degree ≈2700 (H&F; beyond it X̄nm
overflows near the poles); terms that underflow are below 1e-280 of the field and are
dropped. Against pyshtools the fields agree to ≈1e-12 relative at degree 2190 at 30°,
60° and 85° latitude. float64 is required (the scaling needs it): enable
``jax_enable_x64``.
∂P̄nm/∂φ uses ``cos φ ∂P̄nm/∂φ = −n sin φ P̄nm + f_nm P̄(n−1)m`` for m ≥ 1 and
``∂P̄n0/∂φ = √(n(n+1)/2) P̄n1``, so no division by cos φ occurs.

**Poles.** At lat = ±90° (where ``cos φ`` is ≈6e-17 in floating point) every output
is finite: ``η`` is evaluated through ``∂T/∂λ / cos φ`` written as a series in
``cos^(m−1) φ``, ``ξ`` and ``η`` are then the components along the meridian of the
given longitude. Gradients are finite there too, but the lat/lon frame is singular, so
derivatives of ``ξ, η`` with respect to ``lon`` at a pole are frame rotations, not
field changes.

**Cost.** The recursion costs ``O(N²)`` per point, or per latitude row for
:func:`synthesize_grid` (plus a matrix product over longitudes). Degrees run in up to
four blocks, each carrying only the orders ``m < n_block_end`` (≈⅜ less work at high
degree); points are processed in chunks of 8192/(N+1) clipped to [8, 256]
(``lax.map``), which keeps the working set in cache and bounds memory. Compilation
takes a few seconds (each block is one more compiled loop). Reverse-mode gradients
recompute each block (``jax.checkpoint``), so their memory grows with ``N²/blocks``
per point of a chunk.
"""

import dataclasses
import functools
import itertools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxgrav import constants as const
from jaxgrav._io import atomic_output
from jaxgrav._pytree import static_field
from jaxgrav._validate import check_finite, check_latitude, check_same_shape, concrete
from jaxgrav.geodesy import normal_gravity

__all__ = [
    "FieldValues",
    "SphericalHarmonics",
    "deflection",
    "disturbing_potential",
    "gravity_anomaly",
    "gravity_disturbance",
    "synthesize",
    "synthesize_grid",
]

_LOG_SCALE = 280.0 * math.log(10.0)  # ln(1e280): the H&F scale factor
_ELEMS_PER_CHUNK = 8192  # points × orders per recursion batch (measured on a 2-core Xeon)
_DEG_PER_STEP = 2  # degrees per loop iteration for N ≥ 128 (fewer passes over the sums)
_DEGREES_PER_BLOCK = 90  # at least this many degrees per block
_MAX_BLOCKS = 4  # degree blocks: −20 % run time per doubling, +1.5 s compile


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SphericalHarmonics:
    """A disturbing-potential model as 4π-normalised spherical-harmonic coefficients.

    ``c`` and ``s`` are data (pytree leaves, differentiable); ``gm`` and ``radius`` are
    static metadata. Build one with :meth:`from_arrays` (validated) or
    :meth:`from_netcdf`; the plain constructor stores its inputs unchecked.

    Attributes
    ----------
    c, s : Array, shape (nmax+1, nmax+1)
        Cosine and sine coefficients C̄nm, S̄nm indexed ``[n, m]``, zero for m > n
        (dimensionless, 4π normalisation, no Condon–Shortley phase).
    gm : float
        Geocentric gravitational constant of the model (m³/s²).
    radius : float
        Reference radius R of the coefficients (m).
    """

    c: jax.Array
    s: jax.Array
    gm: float = static_field()
    radius: float = static_field()

    @property
    def nmax(self):
        """Maximum degree N (int)."""
        return int(np.shape(self.c)[0]) - 1

    @classmethod
    def from_arrays(cls, c, s, gm=const.WGS84_GM, radius=const.WGS84_A):
        """Build a validated model from coefficient arrays.

        Parameters
        ----------
        c, s : array_like, shape (nmax+1, nmax+1)
            Cosine and sine coefficients, index ``[n, m]``, zero for m > n.
        gm : float, default WGS84 GM
            Gravitational constant times mass (m³/s², > 0).
        radius : float, default WGS84 semi-major axis
            Reference radius (m, > 0).

        Returns
        -------
        SphericalHarmonics

        Raises
        ------
        ValueError
            If the arrays are not square, differ in shape, hold non-finite values or
            non-zero entries with m > n, or ``gm``/``radius`` are not positive finite.
        """
        dtype = jnp.result_type(float)
        c_arr, s_arr = jnp.asarray(c, dtype=dtype), jnp.asarray(s, dtype=dtype)
        for name, arr in (("c", c_arr), ("s", s_arr)):
            if arr.ndim != 2 or arr.shape[0] != arr.shape[1] or arr.shape[0] < 1:
                raise ValueError(
                    f"{name} must be a square array of shape (nmax+1, nmax+1); got {arr.shape}"
                )
        if c_arr.shape != s_arr.shape:
            raise ValueError(
                f"c and s must have the same shape; got {c_arr.shape} and {s_arr.shape}"
            )
        for name, arr in (("c", c_arr), ("s", s_arr)):
            check_finite(arr, name)
            vals = concrete(arr)
            if vals is not None and np.any(np.triu(vals, k=1) != 0.0):
                n, m = np.argwhere(np.triu(vals, k=1) != 0.0)[0]
                raise ValueError(
                    f"{name}[n, m] must be zero for m > n; got {name}[{n}, {m}] = {vals[n, m]!r}"
                )
        for name, val in (("gm", gm), ("radius", radius)):
            if not (np.isscalar(val) and np.isfinite(val) and val > 0):
                raise ValueError(f"{name} must be a positive finite number; got {val!r}")
        return cls(c=c_arr, s=s_arr, gm=float(gm), radius=float(radius))

    def truncate(self, nmax):
        """Return the model truncated to degree ``nmax`` (int, 0 ≤ nmax ≤ self.nmax)."""
        if not (isinstance(nmax, (int, np.integer)) and 0 <= nmax <= self.nmax):
            raise ValueError(f"nmax must be an integer in [0, {self.nmax}]; got {nmax!r}")
        k = int(nmax) + 1
        return dataclasses.replace(self, c=self.c[:k, :k], s=self.s[:k, :k])

    @classmethod
    def from_netcdf(cls, path):
        """Read a model written by :meth:`to_netcdf`.

        Parameters
        ----------
        path : str or os.PathLike
            NetCDF file with variables ``c`` and ``s`` on dims (``degree``, ``order``)
            and global attributes ``gm`` (m³/s²) and ``radius`` (m).

        Raises
        ------
        ValueError
            If variables, dims or attributes are missing, or the file declares a
            different normalisation or phase convention.
        """
        import xarray as xr

        with xr.open_dataset(path) as ds:
            for var in ("c", "s"):
                if var not in ds.variables or ds[var].dims != ("degree", "order"):
                    raise ValueError(
                        f"{path}: expected variable {var!r} on dims ('degree', 'order')"
                    )
            attrs = dict(ds.attrs)
            c, s = np.asarray(ds["c"].values), np.asarray(ds["s"].values)
        for key in ("gm", "radius"):
            if key not in attrs:
                raise ValueError(f"{path}: missing global attribute {key!r}")
        if str(attrs.get("normalization", "4pi")) != "4pi" or int(attrs.get("csphase", 1)) != 1:
            raise ValueError(
                f"{path}: expected normalization='4pi', csphase=1; got "
                f"{attrs.get('normalization')!r}, {attrs.get('csphase')!r}"
            )
        return cls.from_arrays(c, s, float(attrs["gm"]), float(attrs["radius"]))

    def to_netcdf(self, path, force=False):
        """Write the model to NetCDF atomically (temp file + rename).

        Parameters
        ----------
        path : str or os.PathLike
            Output file.
        force : bool, default False
            Overwrite an existing file; otherwise ``FileExistsError`` is raised.

        The file holds ``c`` and ``s`` on dims (``degree``, ``order``) and global
        attributes ``gm``, ``radius``, ``normalization='4pi'``, ``csphase=1`` and
        ``quantity='disturbing potential'``.
        """
        import xarray as xr

        deg = np.arange(self.nmax + 1)
        ds = xr.Dataset(
            {
                "c": (("degree", "order"), np.asarray(self.c, dtype=np.float64)),
                "s": (("degree", "order"), np.asarray(self.s, dtype=np.float64)),
            },
            coords={"degree": deg, "order": deg},
            attrs={
                "gm": self.gm,
                "radius": self.radius,
                "normalization": "4pi",
                "csphase": 1,
                "quantity": "disturbing potential",
            },
        )
        with atomic_output(path, force=force) as tmp:
            ds.to_netcdf(tmp)


class FieldValues(NamedTuple):
    """All synthesised quantities at the same points (each the points' shape).

    Attributes
    ----------
    potential : Array
        Disturbing potential T (m²/s²).
    anomaly : Array
        Gravity anomaly Δg, spherical approximation (mGal).
    disturbance : Array
        Gravity disturbance δg (mGal).
    xi, eta : Array
        Deflection of the vertical, north–south and east–west components (arcsec,
        Heiskanen–Moritz signs).
    """

    potential: jax.Array
    anomaly: jax.Array
    disturbance: jax.Array
    xi: jax.Array
    eta: jax.Array


# --- Legendre lattice ----------------------------------------------------------------


def _recursion_tables(nmax, width, dtype):
    """Per-degree recursion coefficients, each shape (nmax+1, width), built in-graph."""
    n = jnp.arange(nmax + 1, dtype=dtype)[:, None]
    m = jnp.arange(width, dtype=dtype)[None, :]
    d = n - m
    ok1 = d >= 1
    ok2 = d >= 2
    nm = jnp.where(ok1, d * (n + m), 1.0)
    a = jnp.where(ok1, jnp.sqrt((2 * n - 1) * (2 * n + 1) / nm), 0.0)
    den = jnp.where(ok2, 2 * n - 3, 1) * nm
    b = jnp.where(ok2, jnp.sqrt((2 * n + 1) * (n + m - 1) * (d - 1) / den), 0.0)
    f = jnp.where(ok1, jnp.sqrt((2 * n + 1) / jnp.where(ok1, 2 * n - 1, 1) * nm), 0.0)
    return a, b, f


def _sectorals(nmax):
    """Scaled sectorals 1e-280·P̄mm/cos^m φ for m = 0..nmax (NumPy, shape (nmax+1,))."""
    k = np.arange(max(nmax, 1) + 1, dtype=np.float64)
    ratio = np.ones(k.size)
    ratio[1] = math.sqrt(3.0)
    ratio[2:] = np.sqrt((2 * k[2:] + 1) / (2 * k[2:]))
    return 1e-280 * np.cumprod(ratio)[: nmax + 1]


def _lattice(c, s, t, q):
    """Per-order sums for a batch of (φ, r) values.

    Parameters
    ----------
    c, s : Array, shape (N+1, W)
        Coefficients (W = max(N+1, 2) columns, zero-padded).
    t, q : Array, shape (P,)
        sin φ and R/r.

    Returns
    -------
    tuple of 6 Arrays, shape (P, W)
        ``Σ_n (R/r)^n X̄nm c[n, m]`` and the same with ``s`` (potential), the same
        weighted by ``n + 1`` (radial derivative), and ``Σ_n (R/r)^n c[n, m] ∂P̄nm/∂φ``
        divided by ``1e280 cos^|m−1| φ`` (latitude derivative); X̄nm = 1e-280 P̄nm /
        cos^m φ. :func:`_unscale` gives the factors that undo the scaling.

    Notes
    -----
    With Y = q^n X̄, ``Σ_n c_n ∂P̄nm/∂φ`` is ``q Σ_n c_n f_n Y(n−1) − t Σ_n n c_n Y(n)``
    for m ≥ 1 and ``Σ_n c_n √(n(n+1)/2) Y(n, 1)`` for m = 0 (accumulated in column 0
    of the f-sums), so the loop only carries multiply-adds.
    """
    nmax, width = c.shape[0] - 1, c.shape[1]
    dtype = c.dtype
    k = _DEG_PER_STEP if nmax >= 128 else 1  # small N: compile time dominates
    nd = -(-(nmax + 1) // k) * k  # degrees padded to a multiple of k (zero coefficients)
    c, s = (jnp.pad(x, ((0, nd - nmax - 1), (0, 0))) for x in (c, s))
    a_tab, b_tab, f_tab = _recursion_tables(nd - 1, width, dtype)
    nn = jnp.arange(nd, dtype=dtype)
    f_tab = f_tab.at[:, 0].set(jnp.sqrt(nn * (nn + 1) / 2))  # ∂P̄n0/∂φ = √(n(n+1)/2) P̄n1
    cf, sf = c * f_tab, s * f_tab
    sect = jnp.asarray(np.pad(_sectorals(nmax), (0, nd - nmax - 1)), dtype)
    p = t.shape[0]
    tq, q2 = (t * q)[:, None], (q * q)[:, None]
    nblocks = max(1, min(_MAX_BLOCKS, nd // _DEGREES_PER_BLOCK))
    edges = np.unique(np.round(np.linspace(0, nd // k, nblocks + 1)).astype(int) * k)

    def block(carry, xs, wk):
        midx = jnp.arange(wk, dtype=dtype)

        def step(carry, x):
            y1, y2, qn, ac, as_, nc, ns, fc, fs = carry
            n, sec, a, b, cr, sr, cfr, sfr = x  # tuples of k per-degree rows
            ys = [y2, y1]
            for j in range(k):
                onehot = jnp.where(midx == n[j], sec[j], 0.0)  # start of column m = n
                ys.append(a[j] * tq * ys[-1] - b[j] * q2 * ys[-2] + onehot * qn[:, None])
                qn = qn * q
            y = ys[2:]
            # f-sums: column 0 takes Y(n, m=1) for ∂P̄n0/∂φ, the others Y(n−1, m)
            yp = [jnp.where(midx == 0, yn[:, 1:2], yo) for yn, yo in zip(y, ys[1:-1], strict=True)]
            ac, as_ = _madd(ac, cr, y), _madd(as_, sr, y)
            nc = _madd(nc, [nj * cj for nj, cj in zip(n, cr, strict=True)], y)
            ns = _madd(ns, [nj * sj for nj, sj in zip(n, sr, strict=True)], y)
            fc, fs = _madd(fc, cfr, yp), _madd(fs, sfr, yp)
            return (ys[-1], ys[-2], qn, ac, as_, nc, ns, fc, fs), None

        # k strided row tables rather than one (steps, k, W) table: XLA vectorises
        # the plain 2-D per-step slices far better (measured ×2)
        xs = tuple(tuple(x[j::k] for j in range(k)) for x in xs)
        return jax.lax.scan(step, carry, xs)[0]

    def widen(x, wk):
        return x if x.ndim == 1 else jnp.pad(x, ((0, 0), (0, wk - x.shape[1])))

    # reverse mode recomputes each block (only useful when there are several)
    run_block = jax.checkpoint(block, static_argnums=(2,)) if len(edges) > 2 else block
    zeros = jnp.zeros((p, 2), dtype)
    carry = (zeros, zeros, jnp.ones((p,), dtype)) + (zeros,) * 6
    for lo, hi in itertools.pairwise(edges):
        wk = int(min(max(hi, 2), width))  # orders m ≤ n < hi (and column 1 for ∂P̄n0)
        carry = tuple(widen(x, wk) for x in carry)
        rows = (a_tab, b_tab, c, s, cf, sf)
        xs = (nn[lo:hi], sect[lo:hi], *(x[lo:hi, :wk] for x in rows))
        carry = run_block(carry, xs, wk)
    ac, as_, nc, ns, fc, fs = (widen(x, width) for x in carry[3:])
    qq, tt = q[:, None], t[:, None]
    m0 = jnp.arange(width) == 0
    dc = jnp.where(m0, fc, qq * fc - tt * nc)
    ds = jnp.where(m0, fs, qq * fs - tt * ns)
    return ac, as_, ac + nc, as_ + ns, dc, ds


def _madd(acc, coefs, vals):
    """``acc + Σ_j coefs[j] * vals[j]`` (one fused pass over ``acc``)."""
    for cj, vj in zip(coefs, vals, strict=True):
        acc = acc + cj * vj
    return acc


def _unscale(u, width):
    """Factors 1e280·cos^m φ and 1e280·cos^|m−1| φ, each shape (P, W)."""
    m = jnp.arange(width, dtype=u.dtype)
    logu = jnp.log(jnp.maximum(u, 1e-300))[:, None]  # u ≥ 6e-17 for |lat| ≤ 90°
    return jnp.exp(m * logu + _LOG_SCALE), jnp.exp(jnp.abs(m - 1) * logu + _LOG_SCALE)


def _prepare(model):
    if jnp.result_type(float) != jnp.float64:
        raise RuntimeError(
            "jaxgrav.fields.harmonics needs float64 (its Legendre scaling underflows in "
            "float32); call jax.config.update('jax_enable_x64', True) at program start"
        )
    c = jnp.asarray(model.c, jnp.float64)
    s = jnp.asarray(model.s, jnp.float64)
    if c.shape[1] < 2:
        c, s = jnp.pad(c, ((0, 0), (0, 1))), jnp.pad(s, ((0, 0), (0, 1)))
    return c, s


def _finish(model, lat, h, sums):
    """Turn the four sums (T, δg, ∂φ, ∂λ/cos φ) into the stacked fields (T, Δg, δg, ξ,
    η), shape (5, ...), in public units; NaN where |lat| > 90 (reachable under jit)."""
    bad = jnp.abs(lat) > 90.0
    v_t, v_b, v_d, v_l = (jnp.where(bad, jnp.nan, v) for v in sums)
    r = model.radius + h
    gm_r = model.gm / r
    pot = gm_r * v_t
    dist = gm_r / r * v_b
    defl = -gm_r / (normal_gravity(lat, h) * const.MGAL * r * const.ARCSEC)
    # one stacked output (fewer kernels to compile); slicing a row keeps the others dead
    return jnp.stack([pot, (dist - 2.0 * pot / r) / const.MGAL, dist / const.MGAL,
                      defl * v_d, defl * v_l])  # fmt: skip


def _trig_lat(lat, h, radius):
    phi = jnp.deg2rad(lat)
    return jnp.sin(phi), jnp.cos(phi), radius / (radius + h)


@functools.partial(jax.jit, static_argnames=("chunk",))
def _synthesize_points(model, lat, lon, h, chunk):
    """Core of :func:`synthesize` on flat float64 arrays of shape (P,)."""
    c, s = _prepare(model)
    width = c.shape[1]
    npts = lat.shape[0]
    nchunk = -(-npts // chunk)
    pad = nchunk * chunk - npts
    stacked = jnp.stack([lat, lon, h]).astype(jnp.float64)
    stacked = jnp.pad(stacked, ((0, 0), (0, pad))).reshape(3, nchunk, chunk)
    m = jnp.arange(width, dtype=jnp.float64)

    def one_chunk(x):
        la, lo, hh = x
        t, u, q = _trig_lat(la, hh, model.radius)
        ac, as_, bc, bs, dc, ds = _lattice(c, s, t, q)
        f0, f1 = _unscale(u, width)
        ml = jnp.deg2rad(lo)[:, None] * m
        cm, sm = jnp.cos(ml), jnp.sin(ml)
        terms = (f0 * (ac * cm + as_ * sm), f0 * (bc * cm + bs * sm),
                 f1 * (dc * cm + ds * sm), f1 * m * (as_ * cm - ac * sm))  # fmt: skip
        # separate outputs, so that XLA drops the unused sums (and their accumulators)
        return tuple(jnp.sum(v, axis=-1) for v in terms)

    if nchunk == 1:  # no loop over chunks (smaller program to compile and differentiate)
        sums = one_chunk(stacked[:, 0])
    else:
        sums = jax.lax.map(one_chunk, jnp.moveaxis(stacked, 1, 0))
    return _finish(model, lat, h, [v.reshape(-1)[:npts] for v in sums])


def _default_chunk(model, size):
    per_chunk = min(256, max(8, _ELEMS_PER_CHUNK // (model.nmax + 1)))
    return int(max(1, min(size, per_chunk)))


def _check_model(model):
    if not isinstance(model, SphericalHarmonics):
        raise TypeError(
            "model must be a SphericalHarmonics (see SphericalHarmonics.from_arrays); "
            f"got {type(model).__name__}"
        )


def synthesize(model, lat, lon, h=0.0, *, chunk=None):
    """Synthesise T, Δg, δg, ξ and η at points, sharing the Legendre work.

    Parameters
    ----------
    model : SphericalHarmonics
        Disturbing-potential model (degree N from its coefficient shape).
    lat : array_like
        Latitude (degrees, within [−90, 90]), used as spherical latitude.
    lon : array_like
        Longitude (degrees, 0–360 or ±180).
    h : array_like, default 0
        Height above the reference sphere (m): r = model.radius + h.
    chunk : int, optional
        Points per recursion batch (static); default 8192/(N+1) clipped to [8, 256].

    ``lat``, ``lon`` and ``h`` broadcast together (any shape S).

    Returns
    -------
    FieldValues
        potential (m²/s²), anomaly and disturbance (mGal), xi and eta (arcsec), each
        of shape S.

    Raises
    ------
    ValueError
        For concrete inputs: a latitude outside [−90, 90] (under ``jit`` such points
        give NaN instead), non-finite values, ``radius + h ≤ 0``, shapes that do not
        broadcast, or a bad ``chunk``.

    Notes
    -----
    The single-quantity functions (:func:`disturbing_potential`, ...) call this one.
    Under an enclosing ``jax.jit`` XLA drops the sums a caller does not use (T alone
    costs about half of all five fields); called eagerly, all five are computed.
    """
    _check_model(model)
    check_same_shape(lat=lat, lon=lon, h=h)
    check_latitude(lat, "lat")
    check_finite(lon, "lon")
    check_finite(h, "h")
    h_c = concrete(h)
    if h_c is not None and np.any(model.radius + h_c <= 0):
        raise ValueError(f"h must be > -radius = {-model.radius} m; got {np.min(h_c)!r}")
    dt = jnp.result_type(float)
    lat, lon, h = jnp.broadcast_arrays(*(jnp.asarray(x, dt) for x in (lat, lon, h)))
    if chunk is None:
        chunk = _default_chunk(model, max(lat.size, 1))
    if not (isinstance(chunk, (int, np.integer)) and chunk >= 1):
        raise ValueError(f"chunk must be a positive integer; got {chunk!r}")
    out = _synthesize_points(model, *(x.reshape(-1) for x in (lat, lon, h)), int(chunk))
    return FieldValues(*out.reshape((5, *lat.shape)))


def disturbing_potential(model, lat, lon, h=0.0, *, chunk=None):
    """Disturbing potential T (m²/s²) at points; arguments as in :func:`synthesize`."""
    return synthesize(model, lat, lon, h, chunk=chunk).potential


def gravity_anomaly(model, lat, lon, h=0.0, *, chunk=None):
    """Gravity anomaly Δg = −∂T/∂r − 2T/r (mGal); arguments as in :func:`synthesize`."""
    return synthesize(model, lat, lon, h, chunk=chunk).anomaly


def gravity_disturbance(model, lat, lon, h=0.0, *, chunk=None):
    """Gravity disturbance δg = −∂T/∂r (mGal); arguments as in :func:`synthesize`."""
    return synthesize(model, lat, lon, h, chunk=chunk).disturbance


def deflection(model, lat, lon, h=0.0, *, chunk=None):
    """Deflection of the vertical ``(xi, eta)`` (arcsec, Heiskanen–Moritz signs).

    ``ξ = −∂T/(γ r ∂φ)``, ``η = −∂T/(γ r cos φ ∂λ)`` with γ the WGS84 normal gravity
    at (lat, h); arguments as in :func:`synthesize`.
    """
    out = synthesize(model, lat, lon, h, chunk=chunk)
    return out.xi, out.eta


@functools.partial(jax.jit, static_argnames=("chunk",))
def _synthesize_grid(model, lat, lon, h, chunk):
    c, s = _prepare(model)
    width = c.shape[1]
    nlat = lat.shape[0]
    nchunk = -(-nlat // chunk)
    lat_p = jnp.pad(lat, (0, nchunk * chunk - nlat)).reshape(nchunk, chunk)

    def rows(la):
        t, u, q = _trig_lat(la, h, model.radius)
        q = jnp.broadcast_to(q, la.shape)
        ac, as_, bc, bs, dc, ds = _lattice(c, s, t, q)
        f0, f1 = _unscale(u, width)
        m = jnp.arange(width, dtype=jnp.float64)
        return (jnp.stack([f0 * ac, f0 * bc, f1 * dc, -f1 * m * ac]),
                jnp.stack([f0 * as_, f0 * bs, f1 * ds, f1 * m * as_]))  # fmt: skip

    lc, ls = jax.lax.map(rows, lat_p)  # (nchunk, 4, chunk, W)
    lc = jnp.moveaxis(lc, 1, 0).reshape(4, -1, width)[:, :nlat]
    ls = jnp.moveaxis(ls, 1, 0).reshape(4, -1, width)[:, :nlat]
    ml = jnp.arange(width, dtype=jnp.float64)[:, None] * jnp.deg2rad(lon)[None, :]
    cm, sm = jnp.cos(ml), jnp.sin(ml)  # (W, nlon)
    hi = jax.lax.Precision.HIGHEST
    # columns 0-2 pair (c, s) with (cos, sin); column 3 (∂/∂λ) with (sin, cos)
    v = jnp.matmul(lc[:3], cm, precision=hi) + jnp.matmul(ls[:3], sm, precision=hi)
    v_l = jnp.matmul(lc[3], sm, precision=hi) + jnp.matmul(ls[3], cm, precision=hi)
    lat2 = jnp.broadcast_to(lat[:, None], v_l.shape)
    return _finish(model, lat2, jnp.broadcast_to(h, v_l.shape), jnp.concatenate([v, v_l[None]]))


def synthesize_grid(model, lat_1d, lon_1d, h=0.0, *, chunk=None):
    """Synthesise all quantities on a regular lat/lon grid.

    The Legendre lattice is computed once per latitude row; the sum over orders is
    then a matrix product with ``cos mλ``/``sin mλ`` over the longitudes.

    Parameters
    ----------
    model : SphericalHarmonics
        Disturbing-potential model.
    lat_1d : array_like, shape (nlat,)
        Row latitudes (degrees, within [−90, 90]).
    lon_1d : array_like, shape (nlon,)
        Column longitudes (degrees).
    h : float, default 0
        Height above the reference sphere for the whole grid (m).
    chunk : int, optional
        Latitude rows per recursion batch (static); default 8192/(N+1) clipped to
        [8, 256].

    Returns
    -------
    FieldValues
        Each field of shape (nlat, nlon), units as in :func:`synthesize`.

    Raises
    ------
    ValueError
        If ``lat_1d``/``lon_1d`` are not 1-D, ``h`` is not a scalar, or values are out
        of range or non-finite (concrete inputs).
    """
    _check_model(model)
    for name, v in (("lat_1d", lat_1d), ("lon_1d", lon_1d)):
        if np.ndim(v) != 1 or np.shape(v)[0] == 0:
            raise ValueError(f"{name} must be a non-empty 1-D array; got shape {np.shape(v)}")
    if np.ndim(h) != 0:
        raise ValueError(f"h must be a scalar height (m) for a grid; got shape {np.shape(h)}")
    check_latitude(lat_1d, "lat_1d")
    check_finite(lon_1d, "lon_1d")
    check_finite(h, "h")
    h_c = concrete(h)
    if h_c is not None and model.radius + h_c <= 0:
        raise ValueError(f"h must be > -radius = {-model.radius} m; got {float(h_c)!r}")
    if chunk is None:
        chunk = _default_chunk(model, np.shape(lat_1d)[0])
    if not (isinstance(chunk, (int, np.integer)) and chunk >= 1):
        raise ValueError(f"chunk must be a positive integer; got {chunk!r}")
    dt = jnp.result_type(float)
    out = _synthesize_grid(
        model, jnp.asarray(lat_1d, dt), jnp.asarray(lon_1d, dt), jnp.asarray(h, dt), int(chunk)
    )
    return FieldValues(*out)
