"""How much cheaper is layered DOV interpolation than evaluating the harmonic model?

Layered interpolation (shipped qinling layers, 3', 0/10/20 km; jit, batch of 1e5
points, 1e4 with ``--quick``) against (a) the JAX spherical-harmonic synthesis at
degree 360, (b) pyshtools point evaluation (``SHGravCoeffs.expand`` at points),
(c) SciPy's ``RegularGridInterpolator`` in 3-D (linear, = bilinear-linear), built once,
on one channel (ξ) and, for the prepared lines, on both (ξ and η, as jaxgrav does).
Each method is timed as ``make_interpolator`` inside the jitted call (spline slopes
refitted every call) and, as ``*-prepared``, with the interpolator made once outside
(how filters and sensitivity studies use it). The SH
baselines run on fewer points; their times are scaled to the same n (cost is linear
in points). Also reports bytes of the layers against the coefficients.
"""

import time

import jax
import numpy as np
from _common import best_time, emit, parse_args
from scipy.interpolate import RegularGridInterpolator

jax.config.update("jax_enable_x64", True)  # a script, not the library

import jax.numpy as jnp  # noqa: E402

from jaxgrav import datasets, dov  # noqa: E402
from jaxgrav.fields.harmonics import deflection  # noqa: E402


def main():
    args = parse_args(__doc__)
    n = 10_000 if args.quick else 100_000
    n_sh = 500 if args.quick else 2000
    repeats = 3 if args.quick else 5
    d = datasets.load("qinling")
    layers64 = dov.paper_c_layers()
    rng = np.random.default_rng(0)
    lat = rng.uniform(33.0, 40.0, n)
    lon = rng.uniform(106.0, 113.0, n)
    h = rng.uniform(0.0, 20000.0, n)
    model = d["coefficients"]

    f_sh = jax.jit(lambda a, b, c: deflection(model, a, b, c))
    a, b, c = (jnp.asarray(x[:n_sh]) for x in (lat, lon, h))
    jax.block_until_ready(f_sh(a, b, c))
    t_sh = best_time(lambda: jax.block_until_ready(f_sh(a, b, c)), 2) * n / n_sh

    import pyshtools

    clm = pyshtools.SHGravCoeffs.from_array(
        np.stack([np.asarray(model.c), np.asarray(model.s)]), gm=model.gm, r0=model.radius)
    k = max(50, n_sh // 10)
    t0 = time.perf_counter()
    clm.expand(lat=lat[:k], lon=lon[:k], a=model.radius + 10000.0, f=0.0)
    t_pysh = (time.perf_counter() - t0) * n / k

    ref = RegularGridInterpolator(
        (np.asarray(layers64.heights), layers64.lat, layers64.lon),
        np.asarray(layers64.values[:, 0], np.float64))
    pts = np.c_[h, lat, lon]
    t_rgi = best_time(lambda: ref(pts), 2)
    ref2 = RegularGridInterpolator(  # both channels, as jaxgrav interpolates them
        (np.asarray(layers64.heights), layers64.lat, layers64.lon),
        np.moveaxis(np.asarray(layers64.values, np.float64), 1, -1))
    t_rgi2 = best_time(lambda: ref2(pts), 2)

    for dtype in (np.float32, np.float64):
        lay = dov.LayeredGrid(jnp.asarray(layers64.values, dtype),
                              jnp.asarray(layers64.heights, dtype), layers64.lat0,
                              layers64.dlat, layers64.lon0, layers64.dlon)
        la, lo, hh = (jnp.asarray(x, dtype) for x in (lat, lon, h))
        for method in ("bilinear-linear", "bicubic-lagrange", "bicubic-harmonic"):
            f = jax.jit(lambda L, x, y, z, m=method: dov.make_interpolator(L, m)(x, y, z)[0])
            t0 = time.perf_counter()
            jax.block_until_ready(f(lay, la, lo, hh))
            compile_s = time.perf_counter() - t0
            t = best_time(
                lambda f=f, lay=lay, la=la, lo=lo, hh=hh: jax.block_until_ready(
                    f(lay, la, lo, hh)), repeats)
            case = f"{method}-{np.dtype(dtype).name}"
            emit("dov", case, n, t, "jax SH synthesis n=360 (xi,eta)", t_sh,
                 compile_s=round(compile_s, 3), points_per_s=round(n / t))
            emit("dov", case, n, t, "pyshtools SHGravCoeffs.expand points n=360", t_pysh)
            emit("dov", case, n, t, "scipy RegularGridInterpolator 3-D linear (1 channel)",
                 t_rgi)
            # the per-map work done once, outside the timed call, as a filter or a
            # sensitivity study uses it (and as SciPy's interpolator is built once)
            # (a PreparedLayers pytree, passed to the jitted call as an argument)
            prepared = dov.make_interpolator(lay, method)
            g = jax.jit(lambda p, x, y, z: p(x, y, z)[0])
            jax.block_until_ready(g(prepared, la, lo, hh))
            tp = best_time(lambda g=g, p=prepared, la=la, lo=lo, hh=hh: jax.block_until_ready(
                g(p, la, lo, hh)), repeats)
            emit("dov", case + "-prepared", n, tp,
                 "scipy RegularGridInterpolator 3-D linear (1 channel)", t_rgi,
                 points_per_s=round(n / tp), unprepared_over_prepared=round(t / tp, 2))
            emit("dov", case + "-prepared", n, tp,
                 "scipy RegularGridInterpolator 3-D linear (xi and eta)", t_rgi2)
    coef_bytes = int(np.asarray(model.c).nbytes + np.asarray(model.s).nbytes)
    lay32 = 3 * 2 * 181 * 181 * 4
    print(f'{{"bench": "dov", "case": "storage", "layers_float32_bytes": {lay32}, '
          f'"coefficients_float64_bytes": {coef_bytes}, '
          f'"ratio": {round(lay32 / coef_bytes, 2)}}}', flush=True)


if __name__ == "__main__":
    main()
