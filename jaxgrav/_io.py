"""Atomic, no-clobber output files.

Every file jaxgrav writes goes through :func:`atomic_output`: the data are written to a
temporary file in the target's directory and renamed into place only when writing
succeeded, so a crash never leaves a half-written file, and an existing file is
replaced only when the caller passes ``force=True``.
"""

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_output"]


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
    """
    path = Path(path)
    if path.exists() and not force:
        raise FileExistsError(f"{str(path)!r} exists; pass force=True (--force) to overwrite it")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
