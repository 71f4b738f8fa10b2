"""What ``jaxgrav match`` says of missing (NaN) map nodes in its search region.

:data:`jaxgrav.match.STATUS` bit 8192 (:data:`~jaxgrav.match.api.MASKED`) describes
both readings of missing nodes (land, survey gaps); the command's line says which one
ran, why, what it did and how many fixes met them (:func:`missing_message`), and its JSON
holds the counts (:func:`missing_counts`).
"""

import numpy as np

from jaxgrav.match.api import max_gap_fixes, missing_in_reach

__all__ = ["missing_counts", "missing_message"]


def missing_counts(grid, track, result, reach_m):
    """Missing map nodes in reach and the fixes that lie in a cell with one.

    Parameters
    ----------
    grid : Grid
        The map matched (after ``--refine``).
    track : Track
        The ``--track`` read (``lat``, ``lon``: the INS track, degrees).
    result : MatchResult
    reach_m : float
        The search reach (m), the drift radius.

    Returns
    -------
    dict
        ``missing_nodes_in_reach``, ``ins_fixes_over_missing`` (fixes of the INS track in
        a cell with a missing corner) and ``fixes_over_missing`` (of the returned track).
    """
    if not grid.n_missing:  # a complete map: no sampling (nor its compile) needed
        return dict(missing_nodes_in_reach=0, ins_fixes_over_missing=0, fixes_over_missing=0)

    def over(lat, lon):
        return int(np.isnan(np.asarray(grid.sample(lat, lon, "bilinear"))).sum())

    return dict(missing_nodes_in_reach=missing_in_reach(grid, track["lat"], track["lon"],
                                                        reach_m),
                ins_fixes_over_missing=over(track["lat"], track["lon"]),
                fixes_over_missing=over(np.asarray(result.lat), np.asarray(result.lon)))


def missing_message(args, n_fix, counts, read_as, accepted):
    """The status line of bit 8192 for this run.

    Parameters
    ----------
    args : argparse.Namespace
        ``match``'s options (``method``, ``missing``).
    n_fix : int
        Fixes of the track.
    counts : dict
        :func:`missing_counts`.
    read_as : {"land", "gaps"}
        How the matcher read them (:func:`jaxgrav.match.api.missing_reading`).
    accepted : bool
        Whether the fix was accepted (a rejected fix returns the INS track).

    Returns
    -------
    str
    """
    short = args.missing != "land" and max_gap_fixes(n_fix) == 0
    why = (f"--method {args.method} reads them so" if args.method != "dense" else
           f"{n_fix} fixes are too few to score any over gaps" if short else
           f"--missing {args.missing}" if args.missing != "auto" else
           f"--missing auto: the INS track {'crosses' if read_as == 'gaps' else 'misses'} them")
    if read_as == "gaps":
        done = "each candidate was scored on its fixes over present cells"
    else:
        done = "candidates touching them were dropped" + (
            ", the fix is the best of the rest" if accepted else "")
        if args.method == "dense":
            done += (" (if they are survey gaps, not land, the truth may lie in the dropped "
                     "part: --missing gaps)")
    fix = (f", {counts['fixes_over_missing']} on the matched track" if accepted else
           " (the fix was rejected: the INS track is returned)")
    return (f"missing (NaN) map nodes: {counts['missing_nodes_in_reach']} in the search "
            f"region; fixes in a cell with one: {counts['ins_fixes_over_missing']} of {n_fix} "
            f"on the INS track{fix}; read as {'survey gaps' if read_as == 'gaps' else 'land'} "
            f"({why}): {done}")
