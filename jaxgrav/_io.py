"""Atomic, no-clobber output files.

Every file jaxgrav writes goes through :func:`atomic_output`: the data are written to a
temporary file in the target's directory and renamed into place only when writing
succeeded, so a crash never leaves a half-written file, and an existing file is
replaced only when the caller passes ``force=True``. The file gets the permissions an
ordinary ``open(path, "w")`` would give (``0o666`` less the user's umask), not the
temporary file's ``0o600``. A command that writes several files checks all of them
with :func:`check_outputs` before it writes any, so it never leaves some written and
others refused.
"""

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_output", "check_name", "check_outputs"]


def _umask():
    """The process's file-creation mask (read without changing it for long)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def check_outputs(paths, *, force=False, names=None, inputs=None):
    """Refuse a set of output files before any of them is written.

    Parameters
    ----------
    paths : sequence of str, Path or None
        The files a command will write (None entries are skipped).
    force : bool
        Existing files may be replaced.
    names : sequence of str, optional
        The option that names each path (``--out``, ``--truth``), for the message.
    inputs : mapping of str to str, Path or None, optional
        The files the command reads, by option (``{"--track": path}``); an output that
        is one of them is refused, ``force`` or not (None entries, and names that are
        not existing files, such as a shipped map's, are skipped).

    Raises
    ------
    FileExistsError
        If a path exists and ``force`` is false (naming every one that exists, after
        the checks below have passed for all).
    ValueError
        If two options name the same file, an output is an input, a path is an
        existing folder, or its folder cannot be made or written (a file on the way,
        no write permission).
    """
    names = [None] * len(paths) if names is None else list(names)
    seen = {Path(p).resolve(): f"the input {opt} {str(p)!r}"
            for opt, p in (inputs or {}).items() if p is not None and Path(p).is_file()}
    existing = []
    for path, name in zip(paths, names, strict=True):
        if path is None:
            continue
        label = f"{name} {str(path)!r}" if name else repr(str(path))
        check_name(Path(path), label)
        resolved = Path(path).resolve()
        if resolved in seen:
            raise ValueError(f"{label} and {seen[resolved]} are the same file; give each "
                             "output its own path, apart from the inputs")
        seen[resolved] = label
        if Path(path).is_dir():
            raise ValueError(f"{label} is a folder; expected a file path")
        _check_folder(Path(path), label)
        if os.path.lexists(path) and not force:  # a broken link too: it was replaced
            existing.append(label)
    if existing:  # every one named, in one sentence ("a, b exist(s)" was the old wording)
        listed = (existing[0] if len(existing) == 1
                  else f"{', '.join(existing[:-1])} and {existing[-1]}")
        verb, them = ("exists", "it") if len(existing) == 1 else ("exist", "them")
        raise FileExistsError(f"{listed} {verb}; pass --force to overwrite {them} "
                              "(nothing was written)")


def check_name(path, label):
    """ValueError when a name on ``path`` is longer than its file system allows (the run
    ended in "[Errno 36] File name too long", exit 1, its output not written)."""
    folder = path.absolute().parent
    while folder != folder.parent:
        try:
            if folder.exists():
                break
        except OSError:  # a name on the way is itself too long
            pass
        folder = folder.parent
    try:
        limit = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    for part in path.parts:
        size = len(os.fsencode(part))
        if size > limit:
            raise ValueError(f"{label}: the name {part[:24]!r}... is {size} bytes long, more "
                             f"than the {limit} a name may have there; give a shorter name")


def _check_folder(path, label):
    """ValueError when ``path``'s folder cannot be made or written: its nearest existing
    ancestor is a file (``track.csv/out.json``) or a folder the user may not write."""
    folder = path.absolute().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise ValueError(f"{label}: {str(folder)!r} is a file, not a folder; expected a path "
                         "in an existing or new folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{label}: the folder {str(folder)!r} is not writable; expected a "
                         "path in a folder you may write")
    try:  # access() passes root, and folders that refuse files anyway (/proc, some mounts)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:  # was the first output written, then "[Errno 2] ... '/proc/x'"
        raise ValueError(f"{label}: a file cannot be created in the folder {str(folder)!r} "
                         f"({err.strerror}); expected a path in a folder you may write") from None


@contextlib.contextmanager
def atomic_output(path, *, force=False):
    """Yield a temporary path next to ``path``; move it into place only on success.

    Parameters
    ----------
    path : str or Path
        Final output file.
    force : bool
        Replace an existing file; otherwise an existing ``path`` raises.

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``force`` is false.
    ValueError
        If ``path`` is an existing folder (``force`` or not).
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{str(path)!r} is a folder; expected a file path")
    if os.path.lexists(path) and not force:
        raise FileExistsError(f"{str(path)!r} exists; pass force=True (--force) to overwrite it")
    path.parent.mkdir(parents=True, exist_ok=True)
    # the temporary name fits wherever the name does (a 250-byte name ended in exit 1)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:64]}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
