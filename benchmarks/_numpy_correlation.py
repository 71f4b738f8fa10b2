"""Plain NumPy/SciPy baseline of jaxgrav's correlation matcher, one track at a time.

This is the reference a careful researcher would write without JAX: the *same*
algorithms as :func:`jaxgrav.match.dense.match_dense` and
:func:`jaxgrav.match.correlation.match_chains`, vectorised over candidates with
NumPy for ONE track; batches are a Python loop over tracks. It is used by
``match_correlation.py`` (speed) and ``tests/test_numpy_baseline.py`` (agreement,
which keeps the comparison honest). No JAX is imported here.

Dense path (:func:`match_dense_np`)
    Same offset grid (``(2h+1)²`` offsets × rotations), same shifted tracks about the
    INS centroid, same score forms and weights, same float32 ranking of the top k
    (ties to the lower index, like ``lax.top_k``), same selection, then the same
    damped Gauss–Newton (Levenberg–Marquardt) refinement. The map is the not-a-knot
    bicubic spline, evaluated with ``scipy.interpolate.RectBivariateSpline(kx=3,
    ky=3, s=0)`` built once per map (FITPACK's interpolating spline with s=0 is the
    not-a-knot spline, identical to jaxgrav's bicubic and to SciPy's
    ``RegularGridInterpolator(method="cubic")``, and much faster to build). Without
    rotations the shifted fixes of each INS fix form a regular lat/lon lattice, which
    FITPACK evaluates in grid mode (one call per fix; ``sampling="grid"``, the
    default); with rotations, or ``sampling="points"``, every shifted fix is evaluated
    on its own, as jaxgrav does. The Jacobian of the refinement uses the spline's
    **analytic derivatives** (derivative splines ``partial_derivative(1, 0)`` and
    ``(0, 1)`` built once per map) and the chain rule through the shift and rotation,
    not finite differences; residuals and Jacobian are reused when a step is
    rejected. Points off the map give NaN, as in jaxgrav (FITPACK would clamp them).

Chain path (:func:`match_chains_np`)
    Same windows (shifted inside at the map edge), iso-value masks with the node
    allowance (¾ of the largest change to one of the 8 neighbours, edge-padded),
    padded capacity keeping the best-fitting points (float32 ranking, ties to the
    lower index) with count and overflow flag, the same step-length/direction
    compatibility, forward/backward elimination, chain counting and k-best min-sum
    dynamic programme with its exact K-rows-then-K-of-K² selection, then re-scoring,
    the ``k_best`` ranking and the nearest-to-INS selection. As a NumPy programmer
    would, elimination works on the valid candidates only and counting and the
    programme on the surviving ones (variable-size index sets; compatibility
    computed once per step and reused), where jaxgrav's fixed shapes make it work on
    all ``capacity`` slots and recompute compatibility in each of its three scans
    (the count shares the programme's since 2026-12-07).
    Padded and eliminated slots carry only infinite costs in jaxgrav, so the results
    are the same (chains with infinite cost aside). The map values are taken as
    given (the refined grid is map preparation, not matching).

Both return :class:`NpMatch`, a subset of :class:`jaxgrav.match.result.MatchResult`
with the same field names and meanings.
"""

import math
from typing import NamedTuple

import numpy as np
from scipy.interpolate import RectBivariateSpline

__all__ = ["NpMap", "NpMatch", "match_chains_np", "match_dense_np", "prepare_grid", "prepare_map"]

# WGS84, as jaxgrav.constants (checked equal in tests/test_numpy_baseline.py)
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
DEG = math.pi / 180.0
SCORES = ("absolute", "difference", "bias")


# --------------------------------------------------------------------------- geodesy
def meridian_radius(lat_deg):
    s = np.sin(np.deg2rad(lat_deg))
    return WGS84_A * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * s**2) ** 1.5


def prime_vertical_radius(lat_deg):
    s = np.sin(np.deg2rad(lat_deg))
    return WGS84_A / np.sqrt(1.0 - WGS84_E2 * s**2)


def local_offsets_m(lat, lon, lat_ref, lon_ref):
    """North/east offsets (m) of points from reference points (reference radii)."""
    north = (lat - lat_ref) * DEG * meridian_radius(lat_ref)
    dlon = np.mod(lon - lon_ref + 180.0, 360.0) - 180.0
    east = dlon * DEG * prime_vertical_radius(lat_ref) * np.cos(lat_ref * DEG)
    return north, east


# --------------------------------------------------------------------------- map
class NpMap(NamedTuple):
    """A regular lat/lon map for the baseline, with its spline built once."""

    values: np.ndarray  # (ny, nx) float64
    lat0: float
    dlat: float
    lon0: float
    dlon: float
    spline: object  # RectBivariateSpline or None
    d_lat: object  # its derivative splines d/dlat, d/dlon (per degree), or None
    d_lon: object


def prepare_map(values, lat0, dlat, lon0, dlon, spline=True):
    """Baseline map from node values and geometry (e.g. of a ``jaxgrav.Grid``).

    Parameters
    ----------
    values : array_like, shape ``(ny, nx)``
        Node values, row 0 south, column 0 west.
    lat0, dlat, lon0, dlon : float
        First node and spacing (degrees).
    spline : bool
        Build the bicubic spline (needed by the dense path only).
    """
    values = np.asarray(values, dtype=np.float64)
    ny, nx = values.shape
    sp = d_lat = d_lon = None
    if spline:
        lat = lat0 + dlat * np.arange(ny)
        lon = lon0 + dlon * np.arange(nx)
        sp = RectBivariateSpline(lat, lon, values, kx=3, ky=3, s=0)
        # derivative splines built once: ev(..., dx=1) would differentiate all the
        # coefficients at every call (~10x slower on a 289 x 289 map)
        d_lat, d_lon = sp.partial_derivative(1, 0), sp.partial_derivative(0, 1)
    return NpMap(values, float(lat0), float(dlat), float(lon0), float(dlon), sp, d_lat, d_lon)


def prepare_grid(grid, spline=True):
    """:func:`prepare_map` from a ``jaxgrav.Grid`` (reads its values and geometry only)."""
    return prepare_map(np.asarray(grid.values), grid.lat0, grid.dlat, grid.lon0, grid.dlon, spline)


def fractional_index(m, lat, lon):
    lon_w = m.lon0 + np.mod(lon - m.lon0, 360.0)
    return (lat - m.lat0) / m.dlat, (lon_w - m.lon0) / m.dlon


def _inside(m, iy, ix):
    ny, nx = m.values.shape
    eps = 8.0 * float(np.finfo(np.float64).eps) * max(ny, nx)
    return (iy >= -eps) & (iy <= ny - 1 + eps) & (ix >= -eps) & (ix <= nx - 1 + eps)


def sample_bicubic(m, lat, lon, derivatives=False):
    """Spline value (and d/dlat, d/dlon per degree) at points; NaN off the map."""
    la = lat
    lo = m.lon0 + np.mod(lon - m.lon0, 360.0)  # wrapped into the map's range
    inside = _inside(m, (la - m.lat0) / m.dlat, (lo - m.lon0) / m.dlon)
    v = np.where(inside, m.spline.ev(la, lo), np.nan)
    if not derivatives:
        return v
    d_lat = np.where(inside, m.d_lat(la, lo, grid=False), 0.0)
    d_lon = np.where(inside, m.d_lon(la, lo, grid=False), 0.0)
    return v, d_lat, d_lon


def sample_offset_grid(m, lat, lon, north_1d, east_1d):
    """Spline under every INS track shifted by a separable grid of offsets, no rotation.

    Without rotation the fix i shifted by (north_a, east_b) lies at latitude
    ``lat_c + (n_i + north_a)/m_c`` and longitude ``lon_c + (e_i + east_b)/n_c``: for
    each fix the shifted positions form a regular lat/lon grid, evaluated with FITPACK's
    grid mode (B-spline bases once per row and column) instead of point by point.
    Same points and values as :func:`sample_bicubic` on :func:`shifted_tracks`.

    Returns
    -------
    Array, shape ``(len(north_1d) * len(east_1d), N)``, offsets in meshgrid-ij order.
    """
    lat_c, lon_c, m_c, n_c, north, east = _centroid_frame(lat, lon)
    la = lat_c + (north[:, None] + north_1d[None, :]) / m_c  # (N, A)
    lo = lon_c + (east[:, None] + east_1d[None, :]) / n_c  # (N, B)
    lo = m.lon0 + np.mod(lo - m.lon0, 360.0)
    ny, nx = m.values.shape
    eps = 8.0 * float(np.finfo(np.float64).eps) * max(ny, nx)
    in_y = ((la - m.lat0) / m.dlat >= -eps) & ((la - m.lat0) / m.dlat <= ny - 1 + eps)
    in_x = ((lo - m.lon0) / m.dlon >= -eps) & ((lo - m.lon0) / m.dlon <= nx - 1 + eps)
    out = np.empty((lat.shape[0], north_1d.shape[0], east_1d.shape[0]))
    for i in range(lat.shape[0]):
        out[i] = m.spline(la[i], lo[i], grid=True)
    out[~(in_y[:, :, None] & in_x[:, None, :])] = np.nan
    return out.reshape(lat.shape[0], -1).T


# --------------------------------------------------------------------------- scores
def decreasing_weights(n, decay):
    w = np.exp(-float(decay) * np.linspace(0.0, 1.0, n))
    return w / np.sum(w)


def bias_precision(weights, noise_mgal, bias_sigma_mgal):
    w = weights / np.sum(weights)
    return (float(noise_mgal) / float(bias_sigma_mgal)) ** 2 * np.sum(w**2)


def score_track(g, m, weights, kind="bias", prior=0.0):
    """Same as :func:`jaxgrav.match.scoring.score_track` (broadcast over leading axes)."""
    if kind not in SCORES:
        raise ValueError(f"kind must be one of {SCORES}; got {kind!r}")
    bad = np.any(np.isnan(m), axis=-1)
    m = np.where(np.isnan(m), 0.0, m)
    r = g - m
    w = weights / np.sum(weights)
    if kind == "absolute":
        score = np.sum(w * r**2, axis=-1)
        bias = np.zeros_like(score)
    elif kind == "difference":
        d = np.diff(r, axis=-1)
        wd = w[:-1] / np.sum(w[:-1])
        score = np.sum(wd * d**2, axis=-1)
        bias = np.sum(w * r, axis=-1)
    else:
        bias = np.sum(w * r, axis=-1) / (1.0 + prior)
        score = np.sum(w * (r - bias[..., None]) ** 2, axis=-1) + prior * bias**2
    return np.where(bad, np.inf, score), bias


def kmin(x, k):
    """k smallest along the last axis, ascending; ranked in float32, ties to the lower index.

    The same ranking as ``jaxgrav.match.chains.kmin`` (``lax.top_k`` of −x in float32).
    """
    idx = np.argsort(x.astype(np.float32), axis=-1, kind="stable")[..., :k]
    return np.take_along_axis(x, idx, axis=-1), idx


def nearest_to_ins(topk_score, distance, selection):
    if selection == "best":
        return 0
    if selection != "nearest":
        raise ValueError(f"selection must be 'nearest' or 'best'; got {selection!r}")
    return int(np.argmin(np.where(np.isfinite(topk_score), distance, np.inf)))


class NpMatch(NamedTuple):
    """Result of one baseline match (fields as :class:`jaxgrav.match.result.MatchResult`)."""

    lat: np.ndarray
    lon: np.ndarray
    offset_north_m: float
    offset_east_m: float
    rotation_deg: float
    score: float
    bias: float
    topk_lat: np.ndarray
    topk_lon: np.ndarray
    topk_score: np.ndarray
    chosen: int
    n_candidates: np.ndarray
    work_unconstrained: float
    work_constrained: float
    work_pairs: float
    status: int
    index: np.ndarray = None  # chain path: candidate slots of the top-k chains (K, N)


# --------------------------------------------------------------------------- dense path
def _centroid_frame(lat, lon):
    lat_c, lon_c = np.mean(lat), np.mean(lon)
    m_c = meridian_radius(lat_c) * DEG
    n_c = prime_vertical_radius(lat_c) * np.cos(lat_c * DEG) * DEG
    return lat_c, lon_c, m_c, n_c, (lat - lat_c) * m_c, (lon - lon_c) * n_c


def shifted_tracks(lat, lon, d_north, d_east, rotation_rad):
    """INS track shifted and turned about its centroid: ``(lat, lon)`` of shape ``(*S, N)``."""
    lat_c, lon_c, m_c, n_c, north, east = _centroid_frame(lat, lon)
    c = np.cos(rotation_rad)[..., None]
    s = np.sin(rotation_rad)[..., None]
    rn = c * north - s * east + np.asarray(d_north)[..., None]
    re = s * north + c * east + np.asarray(d_east)[..., None]
    return lat_c + rn / m_c, lon_c + re / n_c


def match_dense_np(m, lat, lon, readings, config, sampling="auto"):
    """NumPy version of :func:`jaxgrav.match.dense.match_dense` for one track.

    Parameters
    ----------
    m : NpMap
        Map with its spline (:func:`prepare_map`).
    lat, lon, readings : array_like, shape ``(N,)``
        INS fixes (degrees) and readings (mGal).
    config : jaxgrav.match.dense.DenseConfig (or any object with the same attributes)
    sampling : {"auto", "grid", "points"}
        How the map is sampled under the candidate tracks: ``"grid"`` uses the
        separable structure of the offsets (one FITPACK grid evaluation per fix,
        :func:`sample_offset_grid`; only without rotations), ``"points"`` evaluates
        every shifted fix (as jaxgrav does); ``"auto"`` is ``"grid"`` when possible.

    Returns
    -------
    NpMatch
    """
    if config.method != "bicubic":
        raise NotImplementedError("the baseline implements the bicubic dense path only")
    lat, lon, g = (np.asarray(a, dtype=np.float64) for a in (lat, lon, readings))
    n = lat.shape[0]
    spacing = float(config.spacing_m)
    max_rot = float(config.max_rotation_deg)
    h = config.half_size
    grid_1d = np.arange(-h, h + 1) * spacing
    on, oe = (a.reshape(-1) for a in np.meshgrid(grid_1d, grid_1d, indexing="ij"))
    if config.n_rotations == 1:
        rot = np.zeros(1)
    else:
        rot = np.linspace(-1.0, 1.0, config.n_rotations) * max_rot * DEG
    d_n, d_e = np.tile(on, config.n_rotations), np.tile(oe, config.n_rotations)
    rr = np.repeat(rot, on.shape[0])
    if sampling == "auto":
        sampling = "grid" if config.n_rotations == 1 else "points"
    if sampling == "grid":
        if config.n_rotations != 1:
            raise ValueError("sampling='grid' needs n_rotations == 1")
        values = sample_offset_grid(m, lat, lon, grid_1d, grid_1d)
    elif sampling == "points":
        values = sample_bicubic(m, *shifted_tracks(lat, lon, d_n, d_e, rr))
    else:
        raise ValueError(f"sampling must be 'auto', 'grid' or 'points'; got {sampling!r}")
    w = decreasing_weights(n, config.weight_decay)
    prior = bias_precision(w, config.noise_mgal, config.bias_sigma_mgal)
    scores, biases = score_track(g, values, w, config.score, prior)
    k = min(config.k_best, scores.shape[0])
    _, top = kmin(scores, k)
    topk_score = scores[top]
    la, lo = shifted_tracks(lat, lon, d_n[top], d_e[top], rr[top])  # (k, N)
    distance = np.sum(np.hypot(*local_offsets_m(la, lo, lat, lon)), axis=-1)
    chosen = nearest_to_ins(topk_score, distance, config.selection)
    i = top[chosen]
    found = bool(np.isfinite(scores[i]))

    p = np.array([d_n[i], d_e[i], rr[i], biases[i]])
    free = np.array(
        [1.0, 1.0, 1.0 if config.n_rotations > 1 else 0.0, 1.0 if config.score == "bias" else 0.0]
    )
    step_max = np.array(
        [spacing, spacing, max_rot * DEG / max(config.n_rotations - 1, 1), np.inf]
    )
    if config.refine_steps:
        p = _refine(m, lat, lon, g, w, config.score, prior, p, free, step_max,
                    float(config.damping), config.refine_steps)
    reach = h * spacing
    p[:2] = np.clip(p[:2], -reach, reach)  # the refinement stays in the searched square
    if not found:
        p = np.zeros_like(p)
    m_lat, m_lon = shifted_tracks(lat, lon, p[0], p[1], p[2])
    final_score, final_bias = score_track(g, sample_bicubic(m, m_lat, m_lon), w, config.score,
                                          prior)
    off_n, off_e = local_offsets_m(m_lat, m_lon, lat, lon)
    edge = abs(p[0]) >= reach or abs(p[1]) >= reach
    n_off = float(scores.shape[0])
    return NpMatch(
        lat=m_lat,
        lon=m_lon,
        offset_north_m=float(np.mean(off_n)),
        offset_east_m=float(np.mean(off_e)),
        rotation_deg=float(p[2] / DEG),
        score=float(final_score) if found else np.inf,
        bias=float(p[3]) if config.score == "bias" else (float(final_bias) if found else 0.0),
        topk_lat=la,
        topk_lon=lo,
        topk_score=topk_score,
        chosen=chosen,
        n_candidates=np.full(n, scores.shape[0]),
        work_unconstrained=n_off**n,
        work_constrained=n_off,
        work_pairs=n_off * n,
        status=(0 if found else 1) | (8 if found and edge else 0),
    )


def _residual_function(m, lat, lon, g, w, kind, prior):
    """Weighted residuals of p = (north, east, rotation, bias) and their analytic Jacobian.

    The squared norm is the score of the shifted track (as jaxgrav's ``_residuals``);
    everything that does not depend on p is computed once per track.
    """
    lat_c, lon_c, m_c, n_c, north, east = _centroid_frame(lat, lon)
    sqrt_w = np.sqrt(w / np.sum(w))
    sqrt_wd = np.sqrt(w[:-1] / np.sum(w[:-1]))
    sqrt_prior = np.sqrt(prior)
    n = lat.shape[0]
    jac_bias = np.zeros((n + 1, 4))
    jac_bias[:-1, 3] = -sqrt_w
    jac_bias[-1, 3] = sqrt_prior

    def res(p, jacobian=True):
        c, s = np.cos(p[2]), np.sin(p[2])
        la = lat_c + (c * north - s * east + p[0]) / m_c
        lo = lon_c + (s * north + c * east + p[1]) / n_c
        if jacobian:
            v, v_lat, v_lon = sample_bicubic(m, la, lo, derivatives=True)
        else:
            v = sample_bicubic(m, la, lo)
        r = g - v
        if kind == "difference":
            out = sqrt_wd * np.diff(r)
        elif kind == "bias":
            out = np.append(sqrt_w * (r - p[3]), sqrt_prior * p[3])
        else:
            out = sqrt_w * r
        if not jacobian:
            return out, None
        # dr/dp = -(dM/dlat · dlat/dp + dM/dlon · dlon/dp) for p = (north, east, rotation)
        a, b = v_lat / m_c, v_lon / n_c
        jr = np.stack([-a, -b, a * (s * north + c * east) - b * (c * north - s * east),
                       np.zeros(n)], axis=1)
        if kind == "difference":
            return out, sqrt_wd[:, None] * np.diff(jr, axis=0)
        if kind == "bias":
            jac = jac_bias.copy()
            jac[:-1, :3] = sqrt_w[:, None] * jr[:, :3]
            return out, jac
        return out, sqrt_w[:, None] * jr

    return res


def _refine(m, lat, lon, g, w, kind, prior, p, free, step_max, damping, n_steps):
    """Damped Gauss–Newton as jaxgrav's ``_refine``; a step is kept only if it lowers the cost."""
    res = _residual_function(m, lat, lon, g, w, kind, prior)
    r, jac = res(p)
    cost = np.sum(r**2)
    lam = damping
    fixed = np.diag(1.0 - free) + 1e-12 * np.eye(4)
    for _ in range(n_steps):
        j = jac * free
        jtj = j.T @ j
        a = jtj + lam * np.diag(np.diag(jtj)) + fixed
        dp = -np.linalg.solve(a, j.T @ r) * free
        scale = min(1.0, float(np.min(step_max / np.maximum(np.abs(dp), 1e-30))))
        trial = p + scale * dp
        r_new, _ = res(trial, jacobian=False)
        c_new = np.sum(r_new**2)
        if np.isfinite(c_new) and c_new < cost:
            p, cost, lam = trial, c_new, lam * 0.3
            r, jac = res(p)
        else:
            lam = lam * 10.0  # p unchanged: its residuals and Jacobian are reused
    return p


# --------------------------------------------------------------------------- chain path
def iso_candidates(m, lat, lon, readings, half_size, capacity, delta, slope_factor):
    """Padded iso-value candidates, as :func:`jaxgrav.match.candidates.iso_candidates`.

    Returns a dict with lat, lon, north_m, east_m, value, mask (N, C), count,
    overflow, window_complete (N,).
    """
    ny, nx = m.values.shape
    k = int(half_size)
    s = 2 * k + 1
    if 2 * k + 1 > min(ny, nx):
        raise ValueError("window larger than the map")
    iy, ix = fractional_index(m, lat, lon)
    r = np.round(iy).astype(np.int64) - k
    col = np.round(ix).astype(np.int64) - k
    r_in = np.clip(r, 0, ny - s)
    c_in = np.clip(col, 0, nx - s)
    complete = (r == r_in) & (col == c_in)
    ar = np.arange(s)
    rows = r_in[:, None] + ar  # (N, s)
    cols = c_in[:, None] + ar
    win = m.values[rows[:, :, None], cols[:, None, :]]  # (N, s, s)
    node_lat = m.lat0 + m.dlat * rows
    node_lon = m.lon0 + m.dlon * cols
    # allowance: 3/4 of the largest change to any of the 8 neighbours (edge-padded)
    pad = np.pad(win, ((0, 0), (1, 1), (1, 1)), mode="edge")
    spread = np.zeros_like(win)
    for a in (-1, 0, 1):
        for b in (-1, 0, 1):
            np.maximum(spread, np.abs(pad[:, 1 + a : 1 + a + s, 1 + b : 1 + b + s] - win),
                       out=spread)
    tol = np.asarray(delta, dtype=np.float64)[..., None, None] + 0.75 * slope_factor * spread
    misfit = np.abs(readings[:, None, None] - win) / tol
    iso = misfit <= 1.0
    count = np.sum(iso, axis=(-2, -1))
    n = lat.shape[0]
    flat_fit = np.where(iso, misfit, np.inf).reshape(n, s * s)
    capacity = min(int(capacity), s * s)
    fit, idx = kmin(flat_fit, capacity)
    mask = np.isfinite(fit)
    rr, cc = idx // s, idx % s
    fix = np.arange(n)[:, None]
    c_lat = node_lat[fix, rr]
    c_lon = node_lon[fix, cc]
    value = win.reshape(n, s * s)[fix, idx]
    north, east = local_offsets_m(c_lat, c_lon, lat[:, None], lon[:, None])
    return dict(lat=c_lat, lon=c_lon, north_m=north, east_m=east, value=value, mask=mask,
                count=count, overflow=count > capacity, window_complete=complete)


def compatibility(step_north, step_east, north0, east0, north1, east1, step_tol_m,
                  angle_tol_deg):
    """``[j, k]``: candidate j of fix i may be followed by k of fix i+1 (as jaxgrav)."""
    sn = step_north + north1[None, :] - north0[:, None]
    se = step_east + east1[None, :] - east0[:, None]
    ins_len = math.hypot(step_north, step_east)
    ratio = min(step_tol_m / max(ins_len, 1e-9), 1.0)
    tol = min(angle_tol_deg * DEG + math.asin(ratio), math.pi)
    cos_tol = math.cos(tol)
    # |len - ins_len| <= tol and s·d >= |s||d| cos(tol), compared on squares
    len_sq = sn * sn + se * se
    ok_len = (len_sq <= (ins_len + step_tol_m) ** 2) & (
        len_sq >= max(ins_len - step_tol_m, 0.0) ** 2)
    dot = sn * step_north + se * step_east
    dir_sq = (ins_len * cos_tol) ** 2
    if ins_len <= step_tol_m:  # any direction
        ok_dir = np.ones(len_sq.shape, bool)
    elif cos_tol < 0:
        ok_dir = (dot >= 0) | (dot * dot <= len_sq * dir_sq)
    else:
        ok_dir = (dot >= 0) & (dot * dot >= len_sq * dir_sq)
    return ok_len & ok_dir


def eliminate(valid, steps, north, east, step_tol_m, angle_tol_deg):
    """Forward/backward elimination on the valid candidates only (variable-size sets).

    Parameters
    ----------
    valid : list of int arrays
        Slots of the valid candidates of each fix.
    steps : tuple of arrays
        INS steps (north, east), ``(N−1,)``.
    north, east : arrays ``(N, C)``
        Candidate offsets.

    Returns
    -------
    alive : list of int arrays
        Slots of the candidates on at least one complete chain (ascending).
    compat : list of bool arrays
        ``compat[i]`` between ``alive[i]`` and ``alive[i+1]``.
    """
    n = len(valid)
    fwd = [valid[0]]
    fwd_compat = []
    for i in range(n - 1):
        a, b = fwd[i], valid[i + 1]
        c = compatibility(steps[0][i], steps[1][i], north[i, a], east[i, a], north[i + 1, b],
                          east[i + 1, b], step_tol_m, angle_tol_deg)  # (|fwd_i|, |valid_i+1|)
        keep = np.any(c, axis=0)
        fwd.append(b[keep])
        fwd_compat.append(c[:, keep])
    alive = [None] * n
    alive_pos = [None] * n  # positions of alive[i] inside fwd[i]
    alive[-1] = fwd[-1]
    alive_pos[-1] = np.arange(fwd[-1].size)
    compat = [None] * (n - 1)
    for i in range(n - 2, -1, -1):
        c = fwd_compat[i][:, alive_pos[i + 1]]  # (|fwd_i|, |alive_i+1|)
        keep = np.flatnonzero(np.any(c, axis=1))
        alive[i] = fwd[i][keep]
        alive_pos[i] = keep
        compat[i] = c[keep]
    return alive, compat


def count_chains(compat, n0):
    """Number of complete chains through the surviving candidates (float)."""
    c = np.ones(n0)
    for m in compat:
        c = c @ m
    return float(np.sum(c))


def kbest_chains(alive, compat, unary, pair_cost, k):
    """K cheapest complete chains by k-best min-sum DP over the surviving candidates.

    The same recursion and selection as jaxgrav's ``kbest_chains`` (the K rows with the
    cheapest heads, then K of their K·K extensions, float32 ranking with ties to the
    lower slot), on the variable-size sets of surviving candidates instead of the
    padded ones: padded or eliminated slots only ever carry infinite costs there.

    Returns
    -------
    total : array ``(K,)``
        Chain costs, ascending (``inf`` for missing chains).
    index : int array ``(K, N)``
        Candidate slot of each fix along each chain (0 for missing chains).
    """
    n_fix = len(alive)
    if alive[0].size == 0:
        return np.full(k, np.inf), np.zeros((k, n_fix), dtype=np.int64)
    d = np.full((alive[0].size, k), np.inf)
    d[:, 0] = unary[0, alive[0]]
    ptrs = []
    for i in range(n_fix - 1):
        a, b = alive[i], alive[i + 1]
        pair_t = (np.where(compat[i], pair_cost(i, a, b), np.inf) + unary[i + 1, b][None, :]).T
        kk = min(k, a.size)
        _, rows = kmin(d[:, 0][None, :] + pair_t, kk)  # (|b|, kk)
        sub = d[rows] + np.take_along_axis(pair_t, rows, axis=1)[..., None]  # (|b|, kk, K)
        vals, flat = kmin(sub.reshape(b.size, kk * k), k)
        ptrs.append(np.take_along_axis(rows, flat // k, axis=1) * k + flat % k)
        d = vals
    total, best = kmin(d.reshape(-1), min(k, d.size))
    c, r = best // k, best % k
    index = np.zeros((k, n_fix), dtype=np.int64)
    kt = total.size
    index[:kt, -1] = alive[-1][c]
    for i in range(n_fix - 2, -1, -1):
        p = ptrs[i][c, r]
        c, r = p // k, p % k
        index[:kt, i] = alive[i][c]
    total = np.concatenate([total, np.full(k - kt, np.inf)])
    return total, index


def match_chains_np(m, lat, lon, readings, config):
    """NumPy version of :func:`jaxgrav.match.correlation.match_chains` for one track.

    Parameters
    ----------
    m : NpMap
        Map (node values; the spline is not needed).
    lat, lon, readings : array_like, shape ``(N,)``
    config : jaxgrav.match.correlation.ChainConfig (or same attributes)

    Returns
    -------
    NpMatch
        ``index`` holds the candidate slots of the top-k chains.
    """
    lat, lon, g = (np.asarray(a, dtype=np.float64) for a in (lat, lon, readings))
    n = lat.shape[0]
    allowance = float(config.node_allowance)
    cands = iso_candidates(m, lat, lon, g, config.half_size, config.capacity,
                           float(config.delta), allowance)
    steps = local_offsets_m(lat[1:], lon[1:], lat[:-1], lon[:-1])
    lat_m = np.mean(lat)
    dy = meridian_radius(lat_m) * m.dlat * DEG
    dx = prime_vertical_radius(lat_m) * np.cos(lat_m * DEG) * m.dlon * DEG
    step_tol = float(config.step_tol_m) + allowance * np.hypot(dy, dx)
    valid = [np.flatnonzero(row) for row in cands["mask"]]
    alive, compat = eliminate(valid, steps, cands["north_m"], cands["east_m"], step_tol,
                              float(config.angle_tol_deg))
    n_alive = np.array([a.size for a in alive], dtype=np.float64)
    work_unconstrained = float(np.prod(cands["count"].astype(np.float64)))
    work_constrained = count_chains(compat, alive[0].size) if n_alive.all() else 0.0
    work_pairs = float(np.sum(n_alive[:-1] * n_alive[1:]))

    w = decreasing_weights(n, config.weight_decay)
    value = cands["value"]
    if config.score == "absolute":
        unary = w[:, None] * (g[:, None] - value) ** 2

        def pair_cost(i, a, b):
            return np.zeros((a.size, b.size))
    else:
        unary = np.zeros(value.shape)
        dg = np.diff(g)
        wd = w[:-1] / np.sum(w[:-1])

        def pair_cost(i, a, b):
            return wd[i] * (dg[i] - (value[i + 1, b][None, :] - value[i, a][:, None])) ** 2

    k_dp = config.k_dp if config.score == "bias" else config.k_best  # as jaxgrav
    total, index = kbest_chains(alive, compat, unary, pair_cost, k_dp)

    fix = np.arange(n)[None, :]
    values = value[fix, index]  # (K_dp, N)
    rescored, bias = score_track(g, values, w, config.score)
    rescored = np.where(np.isfinite(total), rescored, np.inf)
    order = np.argsort(rescored, kind="stable")[: config.k_best]
    idx = index[order]
    topk_score = rescored[order]
    north, east = cands["north_m"][fix, idx], cands["east_m"][fix, idx]
    distance = np.sum(np.hypot(north, east), axis=1)
    chosen = nearest_to_ins(topk_score, distance, config.selection)
    found = bool(np.isfinite(topk_score[chosen]))
    topk_lat, topk_lon = cands["lat"][fix, idx], cands["lon"][fix, idx]

    # chosen candidate on the outer ring of its window?
    c_lat = cands["lat"][np.arange(n), idx[chosen]]
    c_lon = cands["lon"][np.arange(n), idx[chosen]]
    row = np.round((c_lat - m.lat0) / m.dlat)
    col = np.round((c_lon - m.lon0) / m.dlon)
    iy, ix = fractional_index(m, lat, lon)
    k = config.half_size
    edge = bool(np.any((np.abs(row - np.round(iy)) >= k) | (np.abs(col - np.round(ix)) >= k)))
    status = (
        (0 if found else 1)
        | (2 if np.any(cands["overflow"]) else 0)
        | (0 if np.all(cands["window_complete"]) else 4)
        | (8 if found and edge else 0)
    )
    return NpMatch(
        lat=topk_lat[chosen] if found else lat,
        lon=topk_lon[chosen] if found else lon,
        offset_north_m=float(np.mean(north[chosen])) if found else 0.0,
        offset_east_m=float(np.mean(east[chosen])) if found else 0.0,
        rotation_deg=0.0,
        score=float(topk_score[chosen]),
        bias=float(bias[order][chosen]),
        topk_lat=topk_lat,
        topk_lon=topk_lon,
        topk_score=topk_score,
        chosen=chosen,
        n_candidates=cands["count"],
        work_unconstrained=work_unconstrained,
        work_constrained=work_constrained,
        work_pairs=work_pairs,
        status=status,
        index=idx,
    )
