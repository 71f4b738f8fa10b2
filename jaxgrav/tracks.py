"""Track files: CSV with a header row, one fix per line, written atomically.

A track is a ``dict`` of equal-length 1-D NumPy arrays keyed by column name,
e.g. ``t`` (s), ``lat``, ``lon`` (degrees), ``gravity`` (mGal). Empty cells read
as NaN, so that missing readings survive a round trip.
"""

import csv
from pathlib import Path

import numpy as np

from jaxgrav._io import atomic_output

__all__ = ["csv_line", "read_track_csv", "write_track_csv"]


def read_track_csv(path, required=(), optional=(), *, allow_nan=()):
    """Read a track CSV.

    Parameters
    ----------
    path : str or Path
        CSV file with a header row.
    required : sequence of str
        Columns that must be present.
    optional : sequence of str
        Columns read when present (others are read too and returned as they are).
    allow_nan : sequence of str
        Columns in which empty/NaN cells are allowed; NaN anywhere else in a
        required column is an error.

    Returns
    -------
    dict of str to numpy.ndarray
        One float64 array per column, all of the same length.

    Raises
    ------
    ValueError
        Missing columns, non-numeric cells, NaN where not allowed, or no rows.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"track file {str(path)!r} does not exist")
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise ValueError(f"track file {str(path)!r} is empty; expected a header row") from None
        rows = [r for r in reader if r and any(cell.strip() for cell in r)]
    missing = [c for c in required if c not in header]
    if missing:
        raise ValueError(
            f"track file {str(path)!r} lacks column(s) {missing}; it has {header}; "
            f"required: {list(required)}"
        )
    if not rows:
        raise ValueError(f"track file {str(path)!r} has a header but no rows")
    out = {}
    for j, name in enumerate(header):
        col = np.empty(len(rows))
        for i, r in enumerate(rows):
            cell = r[j].strip() if j < len(r) else ""
            try:
                col[i] = float(cell) if cell else np.nan
            except ValueError:
                raise ValueError(
                    f"track file {str(path)!r}, line {i + 2}, column {name!r}: "
                    f"{cell!r} is not a number"
                ) from None
        out[name] = col
    for name in required:
        bad = ~np.isfinite(out[name])
        if name not in allow_nan and bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"track file {str(path)!r}, column {name!r} has {int(bad.sum())} missing or "
                f"NaN value(s), first on line {i + 2}; this column must be complete"
            )
    return out


def write_track_csv(path, columns, *, force=False, precision=9):
    """Write equal-length columns to a CSV file atomically.

    Parameters
    ----------
    path : str or Path
        Output file; an existing file is replaced only with ``force=True``.
    columns : dict of str to array_like
        Column name → 1-D values; NaN is written as an empty cell.
    force : bool
        Overwrite an existing file.
    precision : int
        Significant digits.
    """
    arrays = {k: np.asarray(v, dtype=float).reshape(-1) for k, v in columns.items()}
    lengths = {k: a.size for k, a in arrays.items()}
    if len(set(lengths.values())) > 1:
        raise ValueError(f"columns must have equal lengths; got {lengths}")
    with atomic_output(path, force=force) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(arrays))
        for row in zip(*arrays.values(), strict=True):
            w.writerow(["" if not np.isfinite(v) else f"{v:.{precision}g}" for v in row])


def csv_line(i):
    """The file line number of data row ``i`` of a track CSV (the header is line 1)."""
    return int(i) + 2
