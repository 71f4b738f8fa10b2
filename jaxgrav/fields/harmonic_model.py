"""The spherical-harmonic disturbing-potential model: coefficients, validation, NetCDF.

:class:`SphericalHarmonics` holds 4π-normalised real coefficients (geodesy
normalisation, no Condon–Shortley phase, pyshtools ``normalization='4pi',
csphase=1``) of the disturbing potential; its convention and the quantities
synthesised from it are described in :mod:`jaxgrav.fields.harmonics`.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr

from jaxgrav import constants as const
from jaxgrav._io import atomic_output
from jaxgrav._pytree import pytree_dataclass, static_field
from jaxgrav._validate import check_finite, concrete

__all__ = ["SphericalHarmonics"]


@pytree_dataclass
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
