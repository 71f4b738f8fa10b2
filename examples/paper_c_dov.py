"""Paper C: layered DOV interpolation along the paper's climbing trajectory.

Prints the accuracy table (RMS and max error against the exact degree-360 model,
point by point), optimises the middle layer's height with optax, and saves a figure
like the paper's Fig. 3-5 (DOV along the track, errors of each method).

    python examples/paper_c_dov.py [--out paper_c] [--smoke] [--force]
"""

import argparse
import json
from pathlib import Path

import jax
import matplotlib

jax.config.update("jax_enable_x64", True)  # a script, not the library
matplotlib.use("Agg")

import jax.numpy as jnp  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from jaxgrav import datasets, dov  # noqa: E402
from jaxgrav._io import atomic_output  # noqa: E402
from jaxgrav.dov import sensitivity  # noqa: E402
from jaxgrav.fields.harmonics import deflection  # noqa: E402
from jaxgrav.plot import save_figure  # noqa: E402
from jaxgrav.scenarios.paper_c import paper_c_trajectory  # noqa: E402


def rms(e):
    return float(np.sqrt(np.mean(np.square(e))))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default="paper_c_output")
    p.add_argument("--smoke", action="store_true", help="tiny sizes for the tests")
    p.add_argument("--force", action="store_true")
    p.add_argument("--steps", type=int, default=20, help="optax steps")
    a = p.parse_args(argv)
    out = Path(a.out)
    n = 40 if a.smoke else 3333
    data = datasets.load("qinling")
    model = data["coefficients"] if not a.smoke else data["coefficients"].truncate(60)
    tr = paper_c_trajectory(n)
    xi, eta = (np.asarray(v) for v in deflection(model, tr.lat, tr.lon, tr.h))
    truth = np.stack([xi, eta])
    layers = dov.paper_c_layers() if not a.smoke else dov.paper_c_layers(
        spacing_arcmin=30.0, nmax=60)
    rows = [("uncompensated", truth)]
    g0 = [layers.layer(0, c).sample(tr.lat, tr.lon, "bicubic") for c in (0, 1)]
    rows.append(("single layer h=0 (bicubic)", truth - np.stack(g0)))
    errs = {}
    for m in dov.METHODS:
        v = np.asarray(dov.interpolate(layers, tr.lat, tr.lon, tr.h, m).values)
        errs[m] = v - truth
        rows.append((f"layered {m}", errs[m]))
    table = []
    print(f"{'case':34s} {'RMS xi':>9s} {'RMS eta':>9s} {'RMS |e|':>9s} {'max |e|':>9s}  (arcsec)")
    for name, e in rows:
        tot = np.hypot(e[0], e[1])
        r = dict(case=name, rms_xi=rms(e[0]), rms_eta=rms(e[1]), rms_total=rms(tot),
                 max_total=float(tot.max()))
        table.append(r)
        print(f"{name:34s} {r['rms_xi']:9.5f} {r['rms_eta']:9.5f} {r['rms_total']:9.5f} "
              f"{r['max_total']:9.5f}")
    base = rms(np.hypot(*errs["bilinear-linear"]))
    best = rms(np.hypot(*errs[dov.DEFAULT_METHOD]))
    print(f"improvement {dov.DEFAULT_METHOD} over bilinear-linear: x{base / best:.1f}")

    # optax: middle layer height (3 layers) and a 4-layer variant, bilinear-linear
    sub = slice(None, None, 1 if a.smoke else 10)
    build = sensitivity.harmonic_layers(model, layers.lat, layers.lon)
    args = (tr.lat[sub], tr.lon[sub], tr.h[sub], truth[:, sub])
    steps = 2 if a.smoke else a.steps
    s3 = sensitivity.optimise_heights(build, [0.0, 1e4, 2e4], *args,
                                      free=[False, True, False], steps=steps)
    s4 = sensitivity.optimise_heights(build, [0.0, 2e4 / 3, 4e4 / 3, 2e4], *args,
                                      free=[False, True, True, False], steps=steps)
    opt = {}
    for name, s in (("3 layers", s3), ("4 layers", s4)):
        k = int(np.argmin(s.rms))
        opt[name] = dict(initial_heights=s.heights[0].tolist(), best_heights=s.heights[k].tolist(),
                         initial_rms=float(s.rms[0]), best_rms=float(s.rms[k]),
                         gain=float(s.rms[0] / s.rms[k]), grad_initial=s.grad.tolist())
        print(f"optax {name}: heights {np.round(s.heights[0]).tolist()} -> "
              f"{np.round(s.heights[k]).tolist()} m, RMS {s.rms[0]:.5f} -> {s.rms[k]:.5f}\" "
              f"(x{s.rms[0] / s.rms[k]:.2f}); d rms/d h = {s.grad} \"/m")

    # INS: Schuler error driven by each method's compensation error
    dt = float(tr.t[1] - tr.t[0])
    ins = {}
    for name, e in [("uncompensated", truth), *((m, errs[m]) for m in
                                                 ("bilinear-linear", dov.DEFAULT_METHOD))]:
        r = sensitivity.schuler_error(jnp.asarray(e[0]), jnp.asarray(e[1]), dt)
        ins[name] = float(jnp.max(jnp.hypot(r.north, r.east)))
        print(f"INS max horizontal position error, {name}: {ins[name]:.3f} m")

    fig, ax = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    ax[0].plot(tr.t, xi, label="ξ")
    ax[0].plot(tr.t, eta, label="η")
    ax[0].set_ylabel('DOV (")')
    ax[0].legend()
    ax[0].set_title("DOV along the trajectory (degree-360 model)")
    for m in ("bilinear-linear", "bicubic-lagrange", dov.DEFAULT_METHOD):
        ax[1].plot(tr.t, errs[m][0], lw=0.8, label=m)
        ax[2].plot(tr.t, errs[m][1], lw=0.8, label=m)
    ax[1].set_ylabel('ξ error (")')
    ax[2].set_ylabel('η error (")')
    ax[2].set_xlabel("time (s)")
    ax[1].legend(fontsize=8)
    out.mkdir(parents=True, exist_ok=True)
    save_figure(fig, out / "paper_c_dov.png", force=a.force)
    with atomic_output(out / "paper_c_table.json", force=a.force) as tmp:
        tmp.write_text(json.dumps(dict(table=table, improvement=base / best, optax=opt,
                                       ins_max_m=ins), indent=1))
    print(f"wrote {out / 'paper_c_dov.png'} and {out / 'paper_c_table.json'}")


if __name__ == "__main__":
    main()
