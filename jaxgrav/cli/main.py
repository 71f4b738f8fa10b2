"""The ``jaxgrav`` command.

Sub-commands
------------
``demo``            the main job on the shipped data (README quick start)
``match``           match a track CSV against a map (papers A and B), write JSON
``simulate``        write a track CSV (and its truth) from a matching scenario
``filter``          gravity/INS filtering of a track CSV: UKF, EKF, Gaussian sum, PMF, PF,
                    RBPF (paper D)
``simulate-filter`` write a track CSV (and its truth) from paper D's filtering scenario
``suitability``     predicted matching precision (CRLB) and descriptors on every map node
``sample``          sample a map along a track CSV
``dov``             deflection of the vertical along a track (paper C)
``montecarlo``      Monte Carlo runs of a method over all devices; NetCDF, summary, PNG
``bench``           run every benchmark script; Markdown table of ratios
``data egm2008``    rebuild the shipped EGM2008 regional files (extra ``egm2008``)

Errors in user input are reported as one line on stderr with exit code 2; a failure
while running (anything else that goes wrong) as one line with exit code 1. ``--debug``
shows the traceback instead. ``--version`` prints the installed version. Compiled programs
are cached between calls (:mod:`jaxgrav.cli.cache`; ``--no-cache`` or
``JAXGRAV_CACHE=off`` to turn it off).
"""

import argparse
import functools
import os
import re
import sys
import traceback
import warnings
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import jax

from jaxgrav import datasets
from jaxgrav._io import check_name
from jaxgrav.cli import (
    bench,
    demo,
    dov,
    match,
    montecarlo,
    navigate,
    simulate,
    simulate_filter,
    suitability,
    voyage,
)
from jaxgrav.cli import filter as filtering
from jaxgrav.cli.cache import enable_cache
from jaxgrav.fields import egm2008
from jaxgrav.grid_files import UndeclaredFillWarning
from jaxgrav.scenarios.paper_c import paper_c_trajectory

__all__ = ["NEGATIVE_LIST", "PATH_OPTIONS", "STDIN_NAME", "build_parser", "check_map_names",
           "check_special_outputs", "expand_home", "joined_negative_lists", "main",
           "stdin_named"]


def _enable_x64():
    jax.config.update("jax_enable_x64", True)  # geodesy in float64; only the CLI flips it


def _cmd_data_egm2008(args):
    paths = egm2008.build(args.region, Path(args.out), force=args.force,
                          tracks={"paper_c": paper_c_trajectory})
    for p in paths:
        print(f"wrote {p}")


def _version():
    try:
        return version("jaxgrav")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "unknown (not installed)"


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit code 2), as every
    other bad input of the command: argparse's own prints the usage block first."""

    def error(self, message):
        """Print ``PROG: error: MESSAGE (PROG --help: the options)`` and exit with 2."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser():
    """The argument parser of the ``jaxgrav`` command."""
    p = OneLineParser(prog="jaxgrav", description=__doc__.split("\n")[0])
    p.add_argument("--version", action="version", version=f"jaxgrav {_version()}")
    p.add_argument("--debug", action="store_true",
                   help="show the Python traceback of an error instead of one line")
    p.add_argument("--no-cache", action="store_true",
                   help="do not keep compiled programs in the cache folder (default "
                        "~/.cache/jaxgrav/xla, or $JAXGRAV_CACHE_DIR; JAXGRAV_CACHE=off "
                        "turns it off too)")
    sub = p.add_subparsers(dest="command", required=True)

    demo.add_parser(sub)
    match.add_parsers(sub)
    simulate.add_parser(sub)
    voyage.add_parser(sub)
    navigate.add_parser(sub)
    dov.add_parser(sub)
    filtering.add_parser(sub)
    simulate_filter.add_parser(sub)
    suitability.add_parser(sub)
    montecarlo.add_parser(sub)
    bench.add_parser(sub)

    data = sub.add_parser("data", help="build shipped data sets")
    dsub = data.add_subparsers(dest="source", required=True)
    e = dsub.add_parser("egm2008", help="EGM2008 regional grids (needs jaxgrav[egm2008])")
    e.add_argument("--region", default="all", choices=[*egm2008.REGIONS, "all"],
                   help="ryukyu, qinling or all (default)")
    e.add_argument("--out", required=True, help="output folder")
    e.add_argument("--force", action="store_true", help="overwrite existing files")
    e.set_defaults(func=_cmd_data_egm2008)
    return p


def _one_line(message, category, filename, lineno, line=None, *, default):
    """The command's warnings about the user's files as ``warning: ...`` (one line)."""
    if issubclass(category, UndeclaredFillWarning):
        return f"warning: {message}\n"
    return default(message, category, filename, lineno, line)


NEGATIVE_LIST = re.compile(r"^-\.?\d[\d.eE+-]*(,[\d.eE+-]*)+$")
"""A comma-separated value that starts with a minus, e.g. ``-50,0,10000``."""


def joined_negative_lists(argv):
    """``--opt -50,0`` as ``--opt=-50,0``.

    argparse reads a word that starts with a minus and is not a plain number as an
    option, so ``--layers -50,0,10000`` ended in "expected one argument"; joined to its
    option it is that option's value.

    Parameters
    ----------
    argv : list of str
        The command line's words after the program's name.

    Returns
    -------
    list of str
        The same words, each :data:`NEGATIVE_LIST` after a ``--option`` (without ``=``)
        joined to it.
    """
    out = []
    for word in argv:
        if (out and NEGATIVE_LIST.match(word) and out[-1].startswith("--")
                and "=" not in out[-1]):
            out[-1] = f"{out[-1]}={word}"
        else:
            out.append(word)
    return out


PATH_OPTIONS = ("out", "truth", "track", "map", "truth_map", "grid", "dir", "point_masses")
"""The arguments (``argparse`` names) that are file or folder paths."""


def expand_home(args):
    """Path options written ``--out=~/r.json``: ``~`` made the home folder, as the shell
    does only at the start of a word (``--out ~/r.json``); it wrote into a new folder
    named ``~`` under the working one, exit 0."""
    for name in PATH_OPTIONS:
        value = getattr(args, name, None)
        if isinstance(value, str) and value.startswith("~"):
            setattr(args, name, os.path.expanduser(value))


def check_special_outputs(args):
    """ValueError when ``--out`` or ``--truth`` names an existing device, pipe or socket, or
    a path option (``--out``, ``--track``, ``--map``, ...) is an empty string.

    Outputs are written whole to a temporary file and moved into place, so ``--out
    /dev/stdout --force`` (or a FIFO) was replaced by a regular file: as root, /dev/null
    and /dev/stdout themselves. A missing path, a regular file (or a link to one) and a
    folder (the demo's ``--out``) pass.
    """
    expected = {"map": "a NetCDF file or a shipped map's name", "point_masses": "paper-d "
                "or a MODEL.json file", "truth_map": "a NetCDF file or a shipped map's name"}
    for name in PATH_OPTIONS:
        # --out '' was "--out '' is a folder" or "PosixPath('.') has an empty name", and the
        # demo wrote into the working folder; --map '' read as "map '.' is a folder"
        if getattr(args, name, None) == "":
            raise ValueError(f"--{name.replace('_', '-')} is empty; expected "
                             f"{expected.get(name, 'a path')}")
        if isinstance(getattr(args, name, None), str):  # an input's: no such file can exist
            check_name(Path(getattr(args, name)),
                       f"--{name.replace('_', '-')} {getattr(args, name)!r}")
    for name in ("out", "truth"):
        value = getattr(args, name, None)
        if value is None:
            continue
        if value == "-":  # wrote a file named '-' (--track - reads standard input)
            raise ValueError(f"--{name} - : jaxgrav writes its outputs to files, not to "
                             "standard output; give a file name (./- for a file named '-')")
        path = Path(value)
        check_name(path, f"--{name} {str(value)!r}")  # exists() raised "File name too long"
        if path.exists() and not (path.is_file() or path.is_dir()):
            raise ValueError(f"--{name} {str(value)!r} is a device, pipe or socket, not a "
                             "regular file: jaxgrav writes each output whole and then moves "
                             "it into place, which would replace it; give another path")
        # --out new/ wrote a file named 'new'; the demo's and data's --out are folders
        if str(value).endswith(("/", os.sep)) and args.command not in ("demo", "data"):
            suffix = {"match": ".json", "suitability": ".nc", "montecarlo": ".nc",
                      "bench": ".md"}.get(args.command, ".csv")
            raise ValueError(f"--{name} {str(value)!r} ends in a slash, a folder, and jaxgrav "
                             f"{args.command} writes a file there: give a file name in it, "
                             f"e.g. '{str(value).rstrip('/' + os.sep)}/NAME{suffix}'")


def check_map_names(args):
    """``--map`` / ``--truth-map`` that name no file: a shipped map's name in another case
    (``Ryukyu``) is read as that map; anything else is refused naming the shipped maps
    (was "map 'Ryukyu' does not exist", with no word of the names that work)."""
    for name in ("map", "truth_map"):
        value = getattr(args, name, None)
        if not isinstance(value, str) or Path(value).exists():
            continue
        base, colon, key = value.partition(":")
        shipped = datasets.available()
        if base.lower() in shipped:
            setattr(args, name, base.lower() + colon + key)
            keys = sorted(datasets.path(base.lower())) if key else [key]
            if key not in keys:  # was "it has ['anomaly_0p5deg', 'anomaly_2p5min']"
                raise ValueError(f"--{name.replace('_', '-')} {value!r}: the shipped dataset "
                                 f"{base.lower()!r} has no map {key!r}; expected "
                                 f"{' or '.join(f'{base.lower()}:{k}' for k in keys)}")
        else:
            raise FileNotFoundError(
                f"--{name.replace('_', '-')} {value!r} is neither a file nor a shipped map "
                f"({', '.join(shipped)}); expected the path of a NetCDF grid or a shipped "
                "map's name")


STDIN_NAME = "standard input (--track -)"
"""What messages call ``--track -`` (was ``'/dev/stdin'``, a name the user never gave)."""

_STDIN_LABELS = ("track file '/dev/stdin'", "--track '/dev/stdin'", "'/dev/stdin'")


def stdin_named(text):
    """``text`` with the standard input's file names (``track file '/dev/stdin'``,
    ``--track '/dev/stdin'``) replaced by :data:`STDIN_NAME`."""
    for label in _STDIN_LABELS:
        text = text.replace(label, STDIN_NAME)
    return text


class _StdinNamed:
    """A text stream writing to ``stream`` through :func:`stdin_named`: the command's
    errors and warnings about ``--track -`` name the standard input."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        """Write ``text`` with the standard input named."""
        return self._stream.write(stdin_named(text))

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _stdin_track(args):
    """``--track -``: the standard input (``/dev/stdin``); ValueError when it is a terminal
    (the command waited, silently, for a track typed in)."""
    if sys.stdin is not None and sys.stdin.isatty():
        raise ValueError("--track - reads the track from standard input, which is a terminal "
                         "here; pipe or redirect a file into it (e.g. jaxgrav "
                         f"{args.command} --track - ... < track.csv), or give its path")
    if Path("/dev/stdin").exists():
        args.track = "/dev/stdin"  # the usual "-": was "track file '-' does not exist"


def main(argv=None):
    """Entry point of the ``jaxgrav`` command; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(joined_negative_lists(argv))
    _enable_x64()
    enable_cache(off=args.no_cache)
    default, stderr = warnings.formatwarning, sys.stderr
    warnings.formatwarning = functools.partial(_one_line, default=default)
    try:
        if getattr(args, "track", None) == "-":
            _stdin_track(args)
            sys.stderr = _StdinNamed(stderr)
        expand_home(args)
        check_special_outputs(args)
        check_map_names(args)
        args.func(args)
    except (ValueError, FileExistsError, FileNotFoundError, ImportError) as err:
        if args.debug:
            traceback.print_exc()
        print(f"jaxgrav {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"jaxgrav {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # a run-time failure: one line, exit 1 (traceback with --debug)
        if args.debug:
            traceback.print_exc()
        print(f"jaxgrav {args.command}: failed: {type(err).__name__}: {err} (run again with "
              "--debug for the traceback)", file=sys.stderr)
        return 1
    finally:
        warnings.formatwarning, sys.stderr = default, stderr
    return 0

