"""Deprecated names of the entropy + ICCP entry point (kept for one release).

``match_track_b(..., method=...)`` is now :func:`jaxgrav.match.match_track` with the
same ``method``; ``METHODS_B`` is part of :data:`jaxgrav.match.METHODS`;
``status_messages_b`` is :func:`jaxgrav.match.status_messages` (one status table,
:data:`jaxgrav.match.STATUS`, for every method). The combined matcher lives in
:mod:`jaxgrav.match.combined`, :func:`iccp_config_for` in :mod:`jaxgrav.match.sizing`,
the paper's experiment in :mod:`jaxgrav.scenarios.paper_b`.
"""

import warnings

from jaxgrav.match.api import match_track
from jaxgrav.match.combined import COMBINED_STATUS, match_entropy_iccp
from jaxgrav.match.result import STATUS, status_messages
from jaxgrav.match.sizing import iccp_config_for

__all__ = [
    "COMBINED_STATUS",
    "iccp_config_for",
    "match_entropy_iccp",
    "match_track_b",
    "status_messages_b",
]

_METHODS_B = ("entropy", "iccp", "entropy+iccp")
_CONSTANTS = {  # deprecated module constants: name -> (value, replacement)
    "METHODS_B": (_METHODS_B, "jaxgrav.match.METHODS"),
    "ALL_STATUS_B": (STATUS, "jaxgrav.match.STATUS"),
}


def _deprecated(old, new, stacklevel=3):
    warnings.warn(f"{old} is deprecated and will be removed in the next release; use {new}",
                  DeprecationWarning, stacklevel=stacklevel)


def __getattr__(name):
    """``METHODS_B`` and ``ALL_STATUS_B``, with a ``DeprecationWarning``."""
    if name in _CONSTANTS:
        value, new = _CONSTANTS[name]
        _deprecated(name, new)
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def match_track_b(grid, lat, lon, readings, *, method="entropy+iccp", drift_radius_m=5000.0,
                  noise=1.0, max_rotation_deg=90.0, entropy_half_size=20, entropy=None,
                  iccp=None, warn=True):
    """Deprecated: :func:`jaxgrav.match.match_track` with ``method`` entropy, iccp or entropy+iccp.

    ``entropy=``/``iccp=`` become ``config=`` (for ``entropy+iccp`` the pair
    ``(entropy, iccp)``); the other keywords are the same.
    """
    _deprecated("match_track_b", "jaxgrav.match.match_track(..., method=...)")
    if method not in _METHODS_B:
        raise ValueError(f"method must be one of {_METHODS_B}; got {method!r}")
    kw = dict(method=method, drift_radius_m=drift_radius_m, noise=noise, warn=warn)
    if method != "entropy":
        kw["max_rotation_deg"] = max_rotation_deg
    if method != "iccp":
        kw["entropy_half_size"] = entropy_half_size
    if method == "entropy":
        kw["config"] = entropy
    elif method == "iccp":
        kw["config"] = iccp
    elif entropy is not None or iccp is not None:
        kw["config"] = (entropy, iccp)
    return match_track(grid, lat, lon, readings, **kw)


def status_messages_b(status):
    """Deprecated: :func:`jaxgrav.match.status_messages` (one table for every method)."""
    _deprecated("status_messages_b", "jaxgrav.match.status_messages")
    return status_messages(status)
