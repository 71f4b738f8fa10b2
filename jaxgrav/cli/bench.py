"""``jaxgrav bench``: every benchmark script as a subprocess, one Markdown table of ratios.

Wire into :mod:`jaxgrav.cli` with ``add_parser(sub)``.
"""

import json
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

import jaxgrav
from jaxgrav._io import atomic_output, check_outputs
from jaxgrav.cli.inputs import check_out_format

__all__ = ["add_parser", "cmd_bench", "default_bench_dir", "is_result", "machine_info",
           "matmul_roofline"]


def add_parser(subparsers):
    """Add the ``bench`` sub-command to an ``argparse`` sub-parser set."""
    b = subparsers.add_parser("bench", help="run every benchmark script, write a Markdown table")
    b.add_argument("--quick", action="store_true", help="pass --quick to every script")
    b.add_argument("--dir", default=None,
                   help="folder of scripts (default ./benchmarks, else the benchmarks folder "
                        "of the repository holding the jaxgrav package)")
    b.add_argument("--out", default="bench.md", help="Markdown report (default bench.md)")
    b.add_argument("--timeout", type=float, default=3600.0,
                   help="seconds allowed per script (> 0, default 3600)")
    b.add_argument("--force", action="store_true", help="overwrite an existing report")
    b.set_defaults(func=cmd_bench)
    return b


_COLS = ("bench", "case", "n", "jaxgrav_s", "baseline", "baseline_s", "ratio")
"""The fields of a result line (``benchmarks/_common.py``'s ``emit``), the table's columns."""


def _number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def is_result(row):
    """Whether a parsed JSON line is a benchmark result in ``emit``'s format.

    Parameters
    ----------
    row : object
        One JSON line of a script's output, parsed.

    Returns
    -------
    bool
        A dict with every field of the table (bench, case, n, jaxgrav_s, baseline,
        baseline_s, ratio): bench and case strings, n a number, jaxgrav_s a number >= 0,
        baseline_s and ratio numbers or null (a baseline that did not finish).
    """
    if not (isinstance(row, dict) and all(c in row for c in _COLS)):
        return False
    return (isinstance(row["bench"], str) and isinstance(row["case"], str)
            and _number(row["n"]) and _number(row["jaxgrav_s"]) and row["jaxgrav_s"] >= 0
            and all(row[c] is None or _number(row[c]) for c in ("baseline_s", "ratio")))


def _json_lines(stdout):
    """The JSON objects among ``stdout``'s lines: (results, other objects)."""
    results, others = [], []
    for line in stdout.splitlines():
        line = line.strip()
        if line.startswith("{"):
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue
            if is_result(row):
                results.append(row)
            elif isinstance(row, dict):
                others.append(row)
    return results, others


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    return "" if v is None else str(v).replace("|", "\\|")


def cpu_model():
    """The CPU's model name (``/proc/cpuinfo``; else :func:`platform.processor`)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def matmul_roofline(n=1024, repeats=5):
    """Measured matrix-multiply throughput of the default device, the roofline ratios
    are read against.

    Parameters
    ----------
    n : int
        Side of the square matrices (``2 n³`` flops a product).
    repeats : int
        Timed products; the best is kept.

    Returns
    -------
    dict
        ``float64_gflops``, ``float32_gflops`` (GFLOP/s of a jit-compiled ``n × n``
        product, float64 enabled only inside this call) and ``n``.
    """
    out = {"n": n}
    with jax.enable_x64(True):
        for dtype in (jnp.float64, jnp.float32):
            a = jnp.full((n, n), 1.0 / n, dtype)
            f = jax.jit(jnp.dot)
            f(a, a).block_until_ready()
            best = float("inf")
            for _ in range(repeats):
                t0 = time.perf_counter()
                f(a, a).block_until_ready()
                best = min(best, time.perf_counter() - t0)
            out[f"{jnp.dtype(dtype).name}_gflops"] = 2.0 * n**3 / best / 1e9
    return out


def machine_info():
    """The machine a benchmark table was measured on: CPU model, cores, load average,
    jax version, devices and the matmul roofline (:func:`matmul_roofline`)."""
    return {"cpu": cpu_model(), "arch": platform.machine(), "cores": os.cpu_count(),
            "load_average": [round(x, 2) for x in os.getloadavg()],
            "jax": jax.__version__, "jaxgrav": jaxgrav.__version__,
            "devices": [str(d) for d in jax.devices()], "roofline": matmul_roofline()}


def _machine_lines(before, after):
    roof = before["roofline"]
    return [
        "## Machine", "",
        f"- CPU: {before['cpu']} ({before['arch']}), {before['cores']} cores; devices: "
        f"{', '.join(before['devices'])}",
        f"- jax {before['jax']}, jaxgrav {before['jaxgrav']}",
        f"- load average (1, 5, 15 min): {before['load_average']} before, "
        f"{after['load_average']} after",
        f"- matmul roofline ({roof['n']}² jit, best of 5, measured before the scripts): "
        f"float64 {roof['float64_gflops']:.1f} GFLOP/s, float32 "
        f"{roof['float32_gflops']:.1f} GFLOP/s", "",
    ]


def _report(command, rows, runs, failures, before, after, others):
    lines = [
        "# jaxgrav benchmarks", "",
        f"Command: `{command}`, {time.strftime('%Y-%m-%d %H:%M')}. `ratio` = baseline_s / "
        "jaxgrav_s (> 1: jaxgrav is faster). Times on a shared machine are noisy; ratios "
        "are measured within one run; read them against the load and the roofline below.",
        "", *_machine_lines(before, after),
        "## Results", "",
        "| script | " + " | ".join(_COLS) + " | other fields |", "|" + "---|" * (len(_COLS) + 2),
    ]
    for script, row in rows:
        other = ", ".join(f"{k}={_fmt(v)}" for k, v in row.items()
                          if k not in _COLS and k != "machine")
        other = other if len(other) <= 160 else other[:157] + "..."  # all in the JSON below
        lines.append(f"| {script} | " + " | ".join(_fmt(row.get(c)) for c in _COLS)
                     + f" | {other} |")
    lines += ["", "## Scripts", "", "| script | status | seconds | result lines |",
              "|---|---|---|---|"]
    lines += [f"| {s} | {st} | {sec:.1f} | {n} |" for s, st, sec, n in runs]
    if failures:
        lines += ["", "## Failed scripts", ""]
        for script, why, tail in failures:
            lines += [f"### {script}: {why}", "", "```", tail, "```", ""]
    lines += ["", "## Raw JSON lines", "", "```jsonl"]
    lines += [json.dumps(row) for _, row in rows]
    if others:
        lines += ["```", "", "## Other JSON lines (not results: without emit's fields)", "",
                  "```jsonl"]
        lines += [json.dumps({"script": script, **row}) for script, row in others]
    lines += ["```", "", "## Machine (JSON)", "", "```json", json.dumps(before), "```", ""]
    return "\n".join(lines)


def default_bench_dir():
    """``benchmarks`` in the working directory, else next to the installed package.

    The second is ``Path(jaxgrav.__file__).resolve().parents[1] / "benchmarks"``: the
    repository's folder for a source checkout or an editable install.

    Raises
    ------
    FileNotFoundError
        Neither folder exists (e.g. jaxgrav installed from a wheel); names both.
    """
    here = Path("benchmarks")
    repo = Path(jaxgrav.__file__).resolve().parents[1] / "benchmarks"
    for d in (here, repo):
        if d.is_dir():
            return d
    raise FileNotFoundError(
        f"no benchmark scripts found: neither {str(here.resolve())!r} (the working directory) "
        f"nor {str(repo)!r} (next to the jaxgrav package) is a folder; run from a jaxgrav "
        "checkout or pass --dir")


def cmd_bench(args):
    """Run ``jaxgrav bench``: every ``--dir/*.py`` not starting with ``_``, as a subprocess."""
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        raise ValueError(f"--timeout must be a finite number of seconds > 0 per script; got "
                         f"{args.timeout!r}")
    bdir, out = (default_bench_dir() if args.dir is None else Path(args.dir)), Path(args.out)
    if not bdir.is_dir():
        what = ("a file: give the folder of the scripts, e.g. "
                f"{str(bdir.parent)!r}" if bdir.is_file() else "not a folder of benchmark scripts")
        raise FileNotFoundError(f"--dir {str(bdir)!r} is {what}")
    scripts = sorted(p for p in bdir.glob("*.py") if not p.name.startswith("_"))
    if not scripts:
        raise ValueError(f"--dir {str(bdir)!r} has no benchmark scripts (*.py not starting "
                         "with _)")
    # the report never replaces a script or a helper module (_*.py) the scripts import
    check_outputs([out], force=args.force, names=["--out"],
                  inputs={f"script {p.name} of --dir": p for p in sorted(bdir.glob("*.py"))})
    check_out_format(out, "Markdown")  # --out b.csv ran every script, then wrote Markdown
    before = machine_info()
    print(f"machine: {before['cpu']}, {before['cores']} cores, load {before['load_average']}, "
          f"roofline float64 {before['roofline']['float64_gflops']:.1f} GFLOP/s", flush=True)
    rows, runs, failures, others = [], [], [], []
    for i, script in enumerate(scripts, 1):
        cmd = [sys.executable, str(script), *(["--quick"] if args.quick else [])]
        print(f"[{i}/{len(scripts)}] {' '.join(cmd[1:])} ...", end=" ", flush=True)
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
            stdout, stderr, code = proc.stdout, proc.stderr, proc.returncode
        except subprocess.TimeoutExpired as err:
            stdout = err.stdout.decode() if isinstance(err.stdout, bytes) else err.stdout or ""
            stderr = err.stderr.decode() if isinstance(err.stderr, bytes) else err.stderr or ""
            code = f"timeout after {args.timeout:g} s"
        sec = time.perf_counter() - t0
        found, other = _json_lines(stdout)
        rows += [(script.name, row) for row in found]
        others += [(script.name, row) for row in other]
        why = None
        if code != 0:
            why = code if isinstance(code, str) else f"exit code {code}"
        elif not found:
            why = ("exit code 0 but no result line: no JSON line with "
                   + ", ".join(_COLS) + (f"; {len(other)} JSON line(s) without them"
                                         if other else ""))
        if why is not None:
            tail = "\n".join((stderr or stdout).strip().splitlines()[-15:]) or "(no output)"
            failures.append((script.name, why, tail))
            runs.append((script.name, f"FAILED ({why})", sec, len(found)))
            print(f"FAILED ({why}, {sec:.0f} s)")
        else:
            runs.append((script.name, "ok", sec, len(found)))
            print(f"ok ({len(found)} lines, {sec:.0f} s)")
    command = "jaxgrav bench" + (" --quick" if args.quick else "")
    after = {"load_average": [round(x, 2) for x in os.getloadavg()]}
    with atomic_output(out, force=args.force) as tmp:
        tmp.write_text(_report(command, rows, runs, failures, before, after, others))
    print(f"wrote {out}: {len(rows)} results from {len(scripts) - len(failures)} of "
          f"{len(scripts)} scripts")
    if failures:
        for script, why, tail in failures:
            print(f"jaxgrav bench: {script} failed ({why}):\n{tail}", file=sys.stderr)
        raise SystemExit(1)
