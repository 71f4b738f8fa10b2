"""What each Monte Carlo run drew, and the NetCDF attributes of every per-run variable.

Every method's run function returns, besides its metrics, the run's scenario draws
(:func:`scenario_draws`): where the true track starts and how far the INS is off it
there, so that a run can be found again, mapped, or set against the map (e.g. a
suitability map) without re-running it. :func:`variable_attrs` gives the CF ``units``
and ``long_name`` of every variable the methods return, per kind of method.
"""

from jaxgrav.geodesy import local_offsets_m
from jaxgrav.montecarlo.fix_metrics import FIX_METRIC_ATTRS

__all__ = ["DRAW_ATTRS", "scenario_draws", "variable_attrs"]

DRAW_ATTRS = {
    "start_lat": dict(units="degrees_north", long_name="latitude of the true track's start"),
    "start_lon": dict(units="degrees_east", long_name="longitude of the true track's start"),
    "ins_offset_north_m": dict(units="m", long_name="INS minus true position at the start, "
                                                    "north"),
    "ins_offset_east_m": dict(units="m", long_name="INS minus true position at the start, "
                                                   "east"),
}
"""NetCDF attributes of :func:`scenario_draws`' variables."""

_OTHER_ATTRS = {
    "readings_on_map": dict(units="1", long_name="every reading of the run is finite (1): its "
                                                 "true track read no missing map node"),
    "status": dict(units="1", long_name="status bits OR-ed over the run (see the file's "
                                        "status_bits attribute)"),
    "score": dict(units="map units squared (nats for entropy)",
                  long_name="the matcher's score of its chosen track"),
    "offset_north_m": dict(units="m", long_name="matched mean-track offset from the INS "
                                                "track, north"),
    "offset_east_m": dict(units="m", long_name="matched mean-track offset from the INS "
                                               "track, east"),
    "work_constrained": dict(units="1", long_name="candidate chains the constrained search "
                                                  "scored"),
    "rotation_deg": dict(units="degrees", long_name="matched rotation about the INS track's "
                                                    "centroid"),
    "hourly_err_m": dict(units="m", long_name="RMS radial error of the navigation solution "
                                              "in each hour"),
    "hourly_ins_err_m": dict(units="m", long_name="RMS radial error of the free INS in each "
                                                  "hour"),
    "err_series_m": dict(units="m", long_name="radial error of the navigation solution every "
                                              "series_every_s seconds"),
    "ins_err_series_m": dict(units="m", long_name="radial error of the free INS every "
                                                  "series_every_s seconds"),
    "sigma_series_m": dict(units="m", long_name="stated radial 1-sigma of the navigation "
                                                "solution every series_every_s seconds"),
    "fix_event": dict(units="1", long_name="what happened at each segment end (0 accepted, 1 "
                                           "no fix yet, 2 not matched, 3 rejected by the "
                                           "matcher, 4 rejected by the innovation gate, 5 "
                                           "rejected by the segment's shape test)"),
    "implausible_blocks": dict(units="1", long_name="blocks of 60 readings whose innovations "
                                                    "fail the filter's chi-square test "
                                                    "(p < 1e-3)"),
    "fix_time_s": dict(units="s", long_name="time of each segment end from the voyage's "
                                            "start"),
}

_VOYAGE_ATTRS = {
    "err_m": dict(units="m", long_name="RMS radial error of the navigation solution over the "
                                       "last whole hour"),
    "ins_err_m": dict(units="m", long_name="RMS radial error of the free INS over the last "
                                           "whole hour"),
    "nees": dict(units="1", long_name="mean position NEES over the voyage (2 expected)"),
}

_FILTER_ATTRS = {  # paper D's runs (scenarios.paper_d): the second hour's RMS
    "err_m": dict(units="m", long_name="RMS horizontal error of the filter's position over "
                                       "the second half of the run"),
    "ins_err_m": dict(units="m", long_name="RMS horizontal error of the INS over the second "
                                           "half of the run"),
}


def scenario_draws(truth_lat, truth_lon, ins_lat, ins_lon):
    """The draws of one run (JAX, inside the vmapped run).

    Parameters
    ----------
    truth_lat, truth_lon : Array, shape ``(T,)``
        The true track (degrees).
    ins_lat, ins_lon : Array, shape ``(T,)``
        The INS-indicated track (degrees).

    Returns
    -------
    dict of str to Array
        :data:`DRAW_ATTRS`' variables, scalars.
    """
    north, east = local_offsets_m(ins_lat[0], ins_lon[0], truth_lat[0], truth_lon[0])
    return {"start_lat": truth_lat[0], "start_lon": truth_lon[0],
            "ins_offset_north_m": north, "ins_offset_east_m": east}


def variable_attrs(kind):
    """``units``/``long_name`` of every per-run variable of a kind of method.

    Parameters
    ----------
    kind : {"matcher", "filter", "voyage"}

    Returns
    -------
    dict of str to dict
    """
    out = {**FIX_METRIC_ATTRS, **_OTHER_ATTRS, **DRAW_ATTRS}
    if kind == "voyage":
        out.update(_VOYAGE_ATTRS)
    elif kind == "filter":
        out.update(_FILTER_ATTRS)
    return out
