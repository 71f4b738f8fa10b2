"""Running an example script at its ``--smoke`` size (shared by the example tests)."""

import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def run_example(name, *args):
    """Run ``examples/NAME --smoke ARGS`` in its own process; its standard output."""
    proc = subprocess.run([sys.executable, str(EXAMPLES / name), "--smoke", *args],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout
