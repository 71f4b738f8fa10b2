"""How long a track ``jaxgrav match`` can take in memory, by method.

``chains`` and ``entropy+iccp`` hold arrays that grow with the square of the fixes:
20 000 fixes were killed by the system at 13 GB with no word (exit 137).
:func:`check_fixes_memory` refuses such a track before anything is compiled.
"""

from jaxgrav.cli.filter_checks import memory_budget

__all__ = ["BYTES_PER_FIX_SQUARED", "check_fixes_memory"]

BYTES_PER_FIX_SQUARED = {"chains": 60.0, "entropy+iccp": 60.0}
"""Memory per squared fix (bytes) of the methods whose memory grows with the square of the
track's length: the process's peak resident memory at 1000, 2000 and 4000 fixes on the
ryukyu map fits ``a + b n + c n²`` with ``c`` = 36-37 B (chains 0.61, 0.73, 1.21 GB;
entropy+iccp 0.60, 0.76, 1.31 GB), rounded up. ``dense``, ``entropy`` and ``iccp`` grow
linearly (dense: 0.74 GB at 20 000 fixes)."""

_BASELINE_BYTES = 0.6e9  # a match of a few fixes (JAX, the map, the program)


def check_fixes_memory(method, n_fixes, where):
    """ValueError when a ``match`` of ``n_fixes`` by ``method`` needs more than 80 % of
    the machine's memory (:data:`BYTES_PER_FIX_SQUARED`; other methods pass).

    Parameters
    ----------
    method : str
        ``--method``.
    n_fixes : int
        Rows of the track.
    where : str
        The track, for the message (e.g. ``"--track 'T.csv'"``).
    """
    per, (budget, total) = BYTES_PER_FIX_SQUARED.get(method), memory_budget()
    if per is None or not budget:
        return
    need = _BASELINE_BYTES + per * float(n_fixes) ** 2
    if need <= budget:
        return
    most = int(((budget - _BASELINE_BYTES) / per) ** 0.5)
    raise ValueError(f"{where} has {n_fixes} fixes: --method {method} needs about "
                     f"{need / 1e9:.3g} GB for them (its memory grows with the square of the "
                     f"fixes), more than 80 % of this machine's {total / 1e9:.3g} GB; match "
                     f"pieces of at most {most} fixes, or use --method dense (memory linear "
                     "in the fixes)")
