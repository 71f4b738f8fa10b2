"""Paper C: layered DOV interpolation along the paper's climbing trajectory.

Prints the accuracy table in two settings: (1) truth = the exact degree-360 model the
layers are synthesised from, point by point (the perfect-model best case); (2) truth
= EGM2008 to degree 2159 at each fix (the shipped ``qinling`` ``paper_c_truth``,
evaluated exactly by pyshtools), so the model's omission of degrees 361-2159 counts.
Optimises the middle layer's height with optax (setting 1), gives the Schuler position
error of the residual in both settings, and saves a figure like the paper's Fig. 3-5
(DOV along the track, errors of each method, total error in setting 2).

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
from jaxgrav.scenarios.paper_c import PaperTrajectory, paper_c_trajectory  # noqa: E402

SMOKE_STRIDE = 68  # --smoke: every 68th of the 3333 fixes (50 fixes, 68 s apart)


def rms(e):
    return float(np.sqrt(np.mean(np.square(e))))


def print_table(title, rows):
    """Print and return the rows' RMS ξ, η, total and max total (arcsec)."""
    print(f"\n{title}")
    print(f"{'case':34s} {'RMS xi':>9s} {'RMS eta':>9s} {'RMS |e|':>9s} {'max |e|':>9s}  (arcsec)")
    table = []
    for name, e in rows:
        tot = np.hypot(e[0], e[1])
        r = dict(case=name, rms_xi=rms(e[0]), rms_eta=rms(e[1]), rms_total=rms(tot),
                 max_total=float(tot.max()))
        table.append(r)
        print(f"{name:34s} {r['rms_xi']:9.5f} {r['rms_eta']:9.5f} {r['rms_total']:9.5f} "
              f"{r['max_total']:9.5f}")
    return table


def fine_truth(data, tr, stride):
    """ξ, η (2, T) of the degree-2159 truth at the fixes ``tr`` (every ``stride``-th)."""
    fine = data["paper_c_truth"]
    for name in ("lat", "lon", "h"):
        got = getattr(fine, name)[::stride]
        if not np.allclose(got, getattr(tr, name), rtol=0, atol=1e-9):
            raise ValueError(f"the shipped paper_c_truth is not on this trajectory ({name})")
    return np.stack([fine.xi[::stride], fine.eta[::stride]])


def schuler_max(e, dt):
    """Largest horizontal Schuler position error (m) driven by the residual ``e``."""
    r = sensitivity.schuler_error(jnp.asarray(e[0]), jnp.asarray(e[1]), dt)
    return float(jnp.max(jnp.hypot(r.north, r.east)))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default="paper_c_output")
    p.add_argument("--smoke", action="store_true", help="tiny sizes for the tests")
    p.add_argument("--force", action="store_true")
    p.add_argument("--steps", type=int, default=20, help="optax steps")
    a = p.parse_args(argv)
    out = Path(a.out)
    stride = SMOKE_STRIDE if a.smoke else 1
    data = datasets.load("qinling")
    model = data["coefficients"] if not a.smoke else data["coefficients"].truncate(60)
    tr = PaperTrajectory(*(np.asarray(v)[::stride] for v in paper_c_trajectory(3333)))
    xi, eta = (np.asarray(v) for v in deflection(model, tr.lat, tr.lon, tr.h))
    truth = np.stack([xi, eta])
    layers = dov.paper_c_layers() if not a.smoke else dov.paper_c_layers(
        spacing_arcmin=30.0, nmax=60)
    fine = fine_truth(data, tr, stride)
    g0 = np.stack([layers.layer(0, c).sample(tr.lat, tr.lon, "bicubic") for c in (0, 1)])
    est = {m: np.asarray(dov.interpolate(layers, tr.lat, tr.lon, tr.h, m).values)
           for m in dov.METHODS}
    errs = {m: v - truth for m, v in est.items()}
    errs_fine = {m: v - fine for m, v in est.items()}
    omission = truth - fine  # the exact model used as the compensation
    rows = [("uncompensated", truth), ("single layer h=0 (bicubic)", truth - g0),
            *((f"layered {m}", errs[m]) for m in dov.METHODS)]
    table = print_table(f"setting 1 (perfect model, best case): truth = the degree-{model.nmax} "
                        f"model itself, {tr.lat.size} fixes", rows)
    rows_fine = [("uncompensated", fine), ("single layer h=0 (bicubic)", g0 - fine),
                 *((f"layered {m}", errs_fine[m]) for m in dov.METHODS),
                 (f"exact degree-{model.nmax} model", omission)]
    table_fine = print_table(
        f"setting 2 (finer truth): truth = EGM2008 to degree 2159 at each fix; the layers and "
        f"the model stop at degree {model.nmax} (last row: the omission error alone)", rows_fine)
    print()
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
    ins, ins_fine = {}, {}
    for name, e in [("uncompensated", truth), *((m, errs[m]) for m in
                                                 ("bilinear-linear", dov.DEFAULT_METHOD))]:
        ins[name] = schuler_max(e, dt)
        print(f"INS max horizontal position error, {name}: {ins[name]:.3f} m")
    for name, e in [("uncompensated", fine), *((m, errs_fine[m]) for m in
                                                ("bilinear-linear", dov.DEFAULT_METHOD)),
                    (f"exact-degree-{model.nmax}-model", omission)]:
        ins_fine[name] = schuler_max(e, dt)
        print(f"INS max horizontal position error (truth degree 2159), {name}: "
              f"{ins_fine[name]:.3f} m")

    fig, ax = plt.subplots(4, 1, figsize=(8, 12), sharex=True)
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
    ax[1].set_title(f"setting 1: against the degree-{model.nmax} model", fontsize=9)
    for name, e in (("bilinear-linear", errs_fine["bilinear-linear"]),
                    (dov.DEFAULT_METHOD, errs_fine[dov.DEFAULT_METHOD]),
                    (f"omission (exact degree-{model.nmax} model)", omission)):
        ax[3].plot(tr.t, np.hypot(e[0], e[1]), lw=0.8, label=name)
    ax[3].set_ylabel('total error (")')
    ax[3].set_title("setting 2: against EGM2008 to degree 2159", fontsize=9)
    ax[3].set_xlabel("time (s)")
    ax[3].legend(fontsize=8)
    ax[1].legend(fontsize=8)
    out.mkdir(parents=True, exist_ok=True)
    save_figure(fig, out / "paper_c_dov.png", force=a.force)
    with atomic_output(out / "paper_c_table.json", force=a.force) as tmp:
        tmp.write_text(json.dumps(dict(
            settings={"table": f"truth = the degree-{model.nmax} model (perfect model)",
                      "table_truth_n2159": "truth = EGM2008 to degree 2159 at each fix",
                      "optax": f"truth = the degree-{model.nmax} model"},
            table=table, improvement=base / best, optax=opt, ins_max_m=ins,
            table_truth_n2159=table_fine, ins_max_m_truth_n2159=ins_fine,
            fixes=int(tr.lat.size)), indent=1))
    print(f"wrote {out / 'paper_c_dov.png'} and {out / 'paper_c_table.json'}")


if __name__ == "__main__":
    main()
