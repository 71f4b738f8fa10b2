"""Sanity of readings before a run, and of a fit after it: one place for the commands.

Before ``match``, ``filter`` and ``navigate`` run, :func:`check_readings` compares the
readings column with what the map predicts at the INS positions and the stated noise,
and refuses (one line naming the file, the column, what the data look like and what
fixes it) readings that cannot be anomalies in the map's units:

* fill values (−9999, 99999, …, ±1e20 and beyond);
* absolute gravity instead of an anomaly (about 979 800 mGal, or 9.8 m/s²);
* other units: a spread 100 × smaller or larger than the map's along the track (m/s²
  or µGal for mGal, µT or pT for nT);
* a level far from the map's (a total field instead of an anomaly, another datum);
* single readings far outside what the map and the noise allow.

:func:`check_positions` (:mod:`jaxgrav.cli.positions`, exported here) refuses an INS
log whose positions jump: a move between two rows that the velocity columns do not
explain (a position reset, a glitch), which the filters' continuous error model cannot
represent.

After a run, :func:`fit_check` (matchers: the fix's χ² per degree of freedom) and
:func:`innovation_check` (filters: the normalised innovations) test the fit against the
stated noise and return a warning when it is statistically implausible (p < 10⁻³): the
result is then not trustworthy as stated (a wrong map, unit, noise, or an untold map
error). :func:`implausible_rows` (the rule of
:mod:`jaxgrav.navigate.innovation_blocks`, exported here, which the voyage Monte Carlo
methods count per run) flags the rows of the blocks of readings whose innovations fail.
"""

import math

import numpy as np
from scipy.special import chdtrc

from jaxgrav.cli.positions import check_positions
from jaxgrav.match.result import P_IMPLAUSIBLE, fit_p_value
from jaxgrav.navigate.innovation_blocks import INNOVATION_BLOCK, implausible_rows
from jaxgrav.tracks import csv_line

__all__ = ["FILL_VALUES", "GAP_STEPS", "INNOVATION_BLOCK", "P_IMPLAUSIBLE", "check_positions",
           "check_readings", "fit_check", "implausible_rows", "innovation_check",
           "time_gap_warning"]

FILL_VALUES = (-9999.0, 9999.0, -99999.0, 99999.0, -999999.0, 999999.0, -32767.0, 32767.0,
               -32768.0)
"""Common fill values of geophysical files, refused as readings (and ``|v| ≥ 1e20``)."""

_UNIT_HINTS = {
    "mGal": "m/s² (× 1e5 gives mGal), µGal (× 1e-3 gives mGal) or Gal (× 1e3)",
    "nT": "µT (× 1e3 gives nT), pT (× 1e-3) or gauss (× 1e5)",
}
_SPREAD_FACTOR = 100.0  # readings' spread this far from the map's: other units
_LEVEL_SPREADS = 20.0  # level or single readings this many allowed spreads away: refused
_LEVEL_FLOOR = 300.0  # a level offset below this (mGal, nT) may be a gravimeter's bias or datum


def _iqr(a):
    q75, q25 = np.percentile(a, [75, 25])
    return float(q75 - q25)


def check_readings(readings, expected, noise, *, column, where, unit="mGal", correction=0.0,
                   missing_skipped=True, line=csv_line, noise_option="--noise"):
    """Refuse readings that cannot be anomalies of the map (see the module notes).

    Parameters
    ----------
    readings : array_like, shape ``(N,)``
        The readings column (NaN: no reading).
    expected : array_like, shape ``(N,)``
        The map at the INS positions (NaN off the map).
    noise : float
        The stated reading noise (1-σ, in ``unit``).
    column : str
        The column's name, for messages.
    where : str
        The file, for messages (e.g. ``"--track 'T.csv'"``).
    unit : {"mGal", "nT"}
    correction : array_like, shape ``(N,)`` or float
        Added to the readings before they are compared with the map (the Eötvös
        correction of raw readings); fill values are looked for before it.
    missing_skipped : bool
        The command skips an empty cell (filters); False: it needs every reading
        (matchers), and the messages say to remove the row.
    line : callable
        Row index → the file's line number (a reader's ``TrackTable.line``).
    noise_option : str
        The option that stated ``noise``, for messages (``filter``: ``--sigma-gravity``).

    Raises
    ------
    ValueError
        One line: what the readings look like and which option or change fixes it.
    """
    z = np.asarray(readings, float)
    e = np.asarray(expected, float)
    ok = np.isfinite(z)
    fix = ("leave the cell empty (the reading is skipped)" if missing_skipped else
           "remove the row (matching needs a reading at every fix)")
    if not missing_skipped and not ok.all():  # the matcher's "readings has NaN at fix 5"
        i = int(np.flatnonzero(~ok)[0])
        raise ValueError(f"{where}: column {column!r} has {int((~ok).sum())} empty, NaN or inf "
                         f"cell(s), first on line {line(i)}; {fix}")
    fill = ok & (np.isin(z, FILL_VALUES) | (np.abs(z) >= 1e20))
    if fill.any():
        i = int(np.flatnonzero(fill)[0])
        raise ValueError(
            f"{where}: column {column!r} has {int(fill.sum())} fill value(s) ({z[i]:g} on line "
            f"{line(i)}); {fix}")
    raw = z
    z = z + np.broadcast_to(np.asarray(correction, float), z.shape)
    both = ok & np.isfinite(e) & np.isfinite(z)
    if both.sum() < 3:
        return
    zb, eb = z[both], e[both]
    raw_level = float(np.median(raw[both]))
    allowed = max(_iqr(eb), 3.0 * float(noise), 1e-12)
    # absolute gravity in m/s² sits near 9.8 with a spread of mGal/1e5; an anomaly of
    # ~9.8 mGal (spread of mGal) is not it
    si = 9.6 < abs(raw_level) < 9.9 and _iqr(raw[both]) < allowed / _SPREAD_FACTOR
    if unit == "mGal" and (9.6e5 < abs(raw_level) < 9.9e5 or si):
        scale = "mGal" if abs(raw_level) > 1e3 else "m/s²"
        raise ValueError(
            f"{where}: column {column!r} looks like absolute gravity (median "
            f"{raw_level:.6g}, in {scale}?), not an anomaly; subtract normal gravity (and "
            "give mGal)")
    spread = _iqr(zb)
    # the raw readings' spread too: a correction in mGal added to readings in m/s² hides it
    small = min(spread, _iqr(raw[both]))
    if np.ptp(raw[both]) == 0:  # was "varies by 0 ... are the readings in other units?"
        raise ValueError(
            f"{where}: column {column!r} holds one value, {raw_level:g}, in all {int(both.sum())}"
            f" readings on the map, where the map varies by {_iqr(eb):.3g} {unit} along the "
            "track: a placeholder column? expected the sensor's readings")
    if small < allowed / _SPREAD_FACTOR and small >= _iqr(eb) / _SPREAD_FACTOR:
        # the readings vary as the map does: it is the noise that dwarfs them (--noise 1e30
        # was met with "are the readings in other units?")
        raise ValueError(
            f"{noise_option} {float(noise):g} {unit} is implausibly large: column {column!r} of "
            f"{where} varies by only {small:.3g} {unit} (interquartile range; the map by "
            f"{_iqr(eb):.3g} {unit} along the track), where readings with that noise would "
            f"vary by about {1.35 * float(noise):.3g} {unit}; give the sensor's noise, 1-sigma, "
            f"in {unit}")
    for value, bad in ((small, small < allowed / _SPREAD_FACTOR),
                       (spread, spread > allowed * _SPREAD_FACTOR)):
        if bad:
            raise ValueError(
                f"{where}: column {column!r} varies by {value:.3g} (interquartile range) "
                f"where the map varies by {_iqr(eb):.3g} {unit} along the track and the noise "
                f"is {float(noise):g} {unit}: a factor {value / allowed:.2g}; are the readings "
                f"in other units, e.g. {_UNIT_HINTS.get(unit, 'another unit')}?")
    level = float(np.median(zb))
    offset = level - float(np.median(eb))
    if abs(offset) > max(_LEVEL_SPREADS * allowed, _LEVEL_FLOOR):
        raise ValueError(
            f"{where}: column {column!r} sits {offset:+.4g} {unit} from the map along the "
            f"track (medians {level:.4g} and {float(np.median(eb)):.4g}), far more than the "
            f"map's spread {_iqr(eb):.3g} {unit}; " + _level_cause(z, raw, both, eb, unit))
    dev = np.abs((zb - eb) - float(np.median(zb - eb)))
    far = dev > _LEVEL_SPREADS * max(allowed, spread)
    if far.any():
        rows = np.flatnonzero(both)[far]
        raise ValueError(
            f"{where}: {rows.size} reading(s) in column {column!r} lie far outside what the "
            f"map and the noise allow ({z[rows[0]]:g} on line {line(int(rows[0]))}, "
            f"{dev[far][0]:.3g} {unit} from the rest): fill values or spikes? {fix[0].upper()}"
            f"{fix[1:]}")


GAP_STEPS = 10.0
"""A step between fixes longer than this many times the track's median step is a gap
that :func:`time_gap_warning` names."""


def time_gap_warning(t, *, where, line=csv_line):
    """A warning (for match's status messages) when a track's times have a gap (a step longer than
    :data:`GAP_STEPS` times the median step), else None.

    The matchers fit one INS offset (and, ICCP, a rotation) to the whole track, which
    holds only while the INS error barely changes; across a long gap it drifts on, and a
    track with a 10 h gap among 2-minute fixes was matched as if continuous (exit 0).
    """
    step = np.diff(np.asarray(t, float))
    if step.size < 2 or not np.median(step) > 0:
        return None
    long = np.flatnonzero(step > GAP_STEPS * np.median(step))
    if not long.size:
        return None
    i = int(long[np.argmax(step[long])])
    return (f"{where} has {long.size} gap(s) in time, the longest {step[i]:g} s "
            f"between lines {line(i)} and {line(i + 1)}, where its fixes are {np.median(step):g} "
            "s apart: the match fits one INS offset to the whole track, as if the INS error "
            "did not change across the gap; match the parts on either side separately")


def _level_cause(z, raw, both, expected, unit):
    """The likely cause of readings far from the map: the Eötvös correction, or a datum."""
    corr = z[both] - raw[both]
    raw_offset = float(np.median(raw[both]) - np.median(expected))
    if np.any(corr != 0) and abs(raw_offset) < 0.5 * abs(float(np.median(z[both] - expected))):
        return (f"the Eötvös correction from the velocity columns (median "
                f"{float(np.median(corr)):+.4g} {unit}) moved them there: check v_east and "
                "v_north (m/s), or give --eotvos-corrected if the readings are corrected")
    return "is it a total field or another datum instead of the map's anomaly?"


def fit_check(chi2_per_dof, dof, noise, *, what="the fix"):
    """Is a matcher's fit consistent with the stated noise (and map error)?

    Parameters
    ----------
    chi2_per_dof : float
        The fix's χ² over its degrees of freedom (``MatchResult.chi2_per_dof``).
    dof : int
        Its degrees of freedom.
    noise : float
        The stated reading noise, for the message.
    what : str

    Returns
    -------
    p_value : float
        ``P(χ²(dof) ≥ observed)``; NaN when not computable.
    warning : str or None
        One line when ``p_value < P_IMPLAUSIBLE``.
    """
    c = float(chi2_per_dof)
    p = fit_p_value(c, dof)
    if not p < P_IMPLAUSIBLE:
        return p, None
    return p, (f"{what} fits the readings far worse than the stated noise allows (χ² per "
               f"degree of freedom {c:.3g} over {dof}, p = {p:.1e}); the readings' errors are "
               f"larger than {float(noise):g}: state the map's error (--map-error), a larger "
               "--noise, or check the map and the units; the stated uncertainty is not "
               "trustworthy")


def innovation_check(innovation, innovation_sigma, noise_option="--sigma-gravity"):
    """Are a filter's innovations consistent with their predicted variance?

    Parameters
    ----------
    innovation, innovation_sigma : array_like, shape ``(N,)``
        Reading minus prediction and its predicted 1-σ (NaN where no reading was used).
    noise_option : str
        The command's reading-noise option, named in the warning's advice.

    Returns
    -------
    mean_nis : float
        Mean normalised innovation squared over the readings used (1 expected).
    p_value : float
        ``P(χ²(K) ≥ K · mean_nis)`` for ``K`` readings (NaN without readings).
    warning : str or None
        One line when ``p_value < P_IMPLAUSIBLE``.
    """
    _, z2 = _used_nis(innovation, innovation_sigma)
    k = z2.size
    if k == 0:
        return float("nan"), float("nan"), None
    nis = float(np.mean(z2))
    p = float(chdtrc(k, nis * k))
    if p >= P_IMPLAUSIBLE:
        return nis, p, None
    return nis, p, (f"the innovations are {math.sqrt(nis):.3g} × larger than the filter "
                    f"predicts (mean NIS {nis:.3g} over {k} readings, p = {p:.1e}): the "
                    "readings do not fit the map as stated; state the map's error "
                    f"(--map-error), a larger {noise_option}, or check the map and the "
                    "units; the stated 1-sigma is not trustworthy")


def _used_nis(innovation, innovation_sigma):
    """Rows with a usable innovation and their normalised innovations squared."""
    nu = np.asarray(innovation, float)
    s = np.asarray(innovation_sigma, float)
    used = np.flatnonzero(np.isfinite(nu) & np.isfinite(s) & (s > 0))
    return used, (nu[used] / s[used]) ** 2
