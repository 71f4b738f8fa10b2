"""How much faster is jit-compiled Grid.sample than SciPy's RegularGridInterpolator?

Samples the shipped 2.5′ ``ryukyu`` anomaly grid (289 × 289) at 1e6 random points
(1e5 with ``--quick``), bilinear and bicubic, in float32 and float64. SciPy's
interpolator is built once outside the timing (its spline fit included in the
build, with the exact ``spsolve`` solver); jaxgrav's bicubic fits its spline slopes
inside every call (the ``bicubic-prepared`` cases reuse slopes computed once, as the
matchers do through ``make_sampler``). Compile time is reported separately.
"""

import time

import jax
import numpy as np
from _common import best_time, emit, parse_args
from scipy.interpolate import RegularGridInterpolator
from scipy.sparse.linalg import spsolve

jax.config.update("jax_enable_x64", True)  # a script, not the library: float64 cases need it

import jaxgrav as jg  # noqa: E402
from jaxgrav import datasets, interp  # noqa: E402


def main():
    args = parse_args(__doc__)
    n = 100_000 if args.quick else 1_000_000
    repeats = 3 if args.quick else 7
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    rng = np.random.default_rng(0)
    w, e, s, nn = grid.extent
    lat = rng.uniform(s, nn, n)
    lon = rng.uniform(w, e, n)
    values = np.asarray(grid.values, dtype=np.float64)
    for method, scipy_method in (("bilinear", "linear"), ("bicubic", "cubic")):
        kw = {"solver": spsolve} if scipy_method == "cubic" else {}
        ref = RegularGridInterpolator((grid.lat, grid.lon), values, method=scipy_method, **kw)
        pts = np.c_[lat, lon]
        baseline_s = best_time(lambda ref=ref, pts=pts: ref(pts), max(1, repeats // 2))
        for dtype in (np.float32, np.float64):
            g = jg.Grid(
                jax.numpy.asarray(values, dtype), grid.lat0, grid.dlat, grid.lon0, grid.dlon
            )
            la, lo = jax.numpy.asarray(lat, dtype), jax.numpy.asarray(lon, dtype)
            f = jax.jit(lambda g, a, b, m=method: g.sample(a, b, m))
            t0 = time.perf_counter()
            out = f(g, la, lo).block_until_ready()
            compile_s = time.perf_counter() - t0
            t = best_time(lambda f=f, g=g, la=la, lo=lo: f(g, la, lo).block_until_ready(), repeats)
            err = float(np.max(np.abs(np.asarray(out, np.float64) - ref(pts))))
            emit(
                "grid_sample",
                f"{method}-{np.dtype(dtype).name}",
                n,
                t,
                f"scipy.RegularGridInterpolator({scipy_method})",
                baseline_s,
                compile_s=round(compile_s, 3),
                max_abs_diff_mgal=err,
            )
            if method == "bicubic":  # spline slopes computed once, as the matchers do
                coef = interp.bicubic_coefficients(g.values)
                fp = jax.jit(lambda c, a, b, g=g: interp.bicubic(c, *g.fractional_index(a, b)))
                fp(coef, la, lo).block_until_ready()
                tp = best_time(
                    lambda fp=fp, c=coef, la=la, lo=lo: fp(c, la, lo).block_until_ready(), repeats
                )
                emit("grid_sample", f"bicubic-prepared-{np.dtype(dtype).name}", n, tp,
                     f"scipy.RegularGridInterpolator({scipy_method})", baseline_s)


if __name__ == "__main__":
    main()
