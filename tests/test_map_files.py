"""The map reader (jaxgrav.grid_files.read_netcdf, jaxgrav.datasets.load_map) and the map
region a track needs (Grid.finite_region): one case per input variant of issue 19, and
hypothesis-generated small NetCDF grids."""

import dataclasses
import json
import re

import numpy as np
import pytest
import xarray as xr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import jaxgrav as jg
from jaxgrav.cli import main
from jaxgrav.datasets import load_map
from jaxgrav.tracks import write_track_csv

LAT = np.linspace(30.0, 31.0, 11)
LON = np.linspace(130.0, 131.5, 16)
FIELD = np.add.outer(100.0 * LAT, LON) + np.sin(np.add.outer(3 * LAT, 5 * LON))


def write(path, var="z", values=FIELD, lat=LAT, lon=LON, lat_name="lat", lon_name="lon",
          extra=None, dims=None, attrs=None, more=None):
    """A NetCDF file with one variable on (lat_name, lon_name) (+ ``extra`` dims first)."""
    dims = dims or (*(extra or {}), lat_name, lon_name)
    shape = [len(extra[d]) if d in (extra or {}) else
             (len(lat) if d == lat_name else len(lon)) for d in dims]
    coords = {lat_name: lat, lon_name: lon, **(extra or {})}
    values = np.asarray(values)
    values = (values.reshape(shape) if values.size == np.prod(shape)
              else np.broadcast_to(values, shape))  # extra levels repeat the field
    data = {var: (dims, values, attrs or {})}
    data.update(more or {})
    xr.Dataset(data, coords=coords).to_netcdf(path)
    return path


def node_values(grid, lat, lon):
    """The grid's values at the file's nodes, found by coordinate (no interpolation)."""
    iy = np.array([np.argmin(np.abs(grid.lat - v)) for v in lat])
    dlon = np.mod(np.subtract.outer(np.asarray(lon, float), grid.lon) + 180, 360) - 180
    ix = np.argmin(np.abs(dlon), axis=1)
    assert np.allclose(grid.lat[iy], lat, atol=1e-4)
    assert np.allclose(dlon[np.arange(len(lon)), ix], 0, atol=1e-4)
    return np.asarray(grid.values)[np.ix_(iy, ix)]


# (id, writer kwargs, expected extent (w, e, s, n) or None)
VALID = [
    ("lat-lon", {}, (130.0, 131.5, 30.0, 31.0)),
    ("latitude-longitude", {"lat_name": "latitude", "lon_name": "longitude"}, None),
    ("gmt-y-x", {"lat_name": "y", "lon_name": "x"}, None),
    ("upper-case", {"lat_name": "LAT", "lon_name": "Lon"}, None),
    ("descending-lat", {"lat": LAT[::-1], "values": FIELD[::-1]}, (130.0, 131.5, 30.0, 31.0)),
    ("descending-lon", {"lon": LON[::-1], "values": FIELD[:, ::-1]}, None),
    ("singleton-time-first", {"extra": {"time": [0.0]}}, None),
    ("singleton-band-last", {"extra": {"band": [1]}, "dims": ("lat", "lon", "band")}, None),
    ("float32-coordinates", {"lat": np.arange(30, 31.05, 0.1, dtype=np.float32)[:11],
                             "lon": (130 + 0.1 * np.arange(16)).astype(np.float32)}, None),
    ("lon-0-360", {"lon": LON + 100.0}, (230.0, 231.5, 30.0, 31.0)),
    ("regional-0-360-across-0", {"lon": np.mod(np.linspace(-0.75, 0.75, 16), 360)},
     (-0.75, 0.75, 30.0, 31.0)),
    ("units-kept", {"attrs": {"units": "mGal"}}, None),
]


@pytest.mark.parametrize(("name", "kw", "extent"), VALID, ids=[c[0] for c in VALID])
def test_valid_map_variants(tmp_path, name, kw, extent):
    path = write(tmp_path / "m.nc", **kw)
    grid = load_map(path)
    lat, lon = kw.get("lat", LAT), kw.get("lon", LON)
    values = kw.get("values", FIELD)
    np.testing.assert_allclose(node_values(grid, lat, lon), values, rtol=0, atol=1e-12)
    assert grid.values.shape == (11, 16) and grid.dlat > 0 and grid.dlon > 0
    if extent:
        np.testing.assert_allclose(grid.extent, extent, atol=1e-9)
    if name == "units-kept":
        assert grid.units == "mGal" and grid.name == "z"
    if name == "regional-0-360-across-0":  # interpolation across 0° works like any other
        v = np.asarray(grid.sample(np.array([30.5]), np.array([359.97]), strict=True))
        assert np.isfinite(v).all()


# (id, writer kwargs or raw bytes, load_map kwargs, phrases)
INVALID = [
    ("3-d-variable", {"extra": {"depth": [0.0, 10.0, 20.0]}}, {},
     ["variable 'z'", "depth: 3", "must be 2-D", "'depth'"]),
    ("repeated-lat", {"lat": np.r_[LAT[:5], LAT[4], LAT[6:]]}, {},
     ["lat must be strictly monotonic", "lat[5] = 30.4 repeats lat[4]"]),
    ("unsorted-lon", {"lon": np.r_[LON[:7], LON[8], LON[7], LON[9:]]}, {},
     ["lon must be strictly monotonic", "lon[8] = 130.7 goes back"]),
    ("non-uniform-lon", {"lon": np.r_[LON[:10], LON[10:] + 0.03]}, {},
     ["lon must be strictly monotonic and regularly spaced", "lon[9] = 130.9", "lon[10] = 131.03",
      "not the regular"]),
    ("projected", {"lat_name": "y", "lon_name": "x", "lat": 3.3e6 + 1e3 * np.arange(11),
                   "lon": 5e5 + 1e3 * np.arange(16)}, {}, ["projected", "3.3e+06"]),
    ("two-variables", {"more": {"w": (("lat", "lon"), FIELD)}}, {},
     ["holds 2 gridded variables (z, w)", "--var NAME"]),
    ("unknown-var", {}, {"var": "gravity"},
     ["has no variable 'gravity'", "its gridded variables are z"]),
    ("no-coordinates", {"lat_name": "row", "lon_name": "col"}, {}, ["has no latitude coordinate"]),
    ("csv-as-map", b"t,lat,lon,gravity\n0,30,130,1\n", {},
     ["is not a NetCDF file", "text file starting 't,lat,lon,gravity'"]),
    ("empty-file", b"", {}, ["is not a NetCDF file (it is empty)"]),
    ("nan-refused-by-default", {"values": np.where(FIELD > 3120, np.nan, FIELD)}, {},
     ["missing (NaN or fill-value) node(s) of 176", "the first at lat"]),
]


@pytest.mark.parametrize(("name", "kw", "load_kw", "phrases"), INVALID,
                         ids=[c[0] for c in INVALID])
def test_invalid_map_variants(tmp_path, clear_message, name, kw, load_kw, phrases):
    path = tmp_path / "m.nc"
    if isinstance(kw, bytes):
        path.write_bytes(kw)
    else:
        write(path, **kw)
    with pytest.raises(ValueError) as info:
        load_map(path, **load_kw)
    clear_message(str(info.value), path, phrases)


def test_curvilinear_coordinates_refused(tmp_path):
    la, lo = np.meshgrid(LAT, LON, indexing="ij")
    xr.Dataset({"z": (("j", "i"), FIELD)},
               coords={"lat": (("j", "i"), la), "lon": (("j", "i"), lo)}).to_netcdf(
        tmp_path / "c.nc")
    with pytest.raises(ValueError, match="curvilinear"):
        load_map(tmp_path / "c.nc")


def test_coordinates_found_by_cf_attributes(tmp_path):
    xr.Dataset({"z": (("r", "c"), FIELD)},
               coords={"r": ("r", LAT, {"standard_name": "latitude"}),
                       "c": ("c", LON, {"units": "degrees_east"})}).to_netcdf(tmp_path / "cf.nc")
    np.testing.assert_allclose(load_map(tmp_path / "cf.nc").values, FIELD)


@pytest.mark.parametrize(("units", "scale", "expected"), [
    ("mGal", 1.0, "mGal"), ("m s-2", 1e-5, "mGal"), ("m/s^2", 1e-5, "mGal"),
    ("m/s²", 1e-5, "mGal"), ("m s⁻²", 1e-5, "mGal"), ("m·s⁻²", 1e-5, "mGal"),
    ("uGal", 1e3, "mGal"), ("µGal", 1e3, "mGal"), ("Gal", 1e-3, "mGal"), ("gu", 10.0, "mGal"),
    ("nT", 1.0, "nT"), ("uT", 1e-3, "nT"), ("T", 1e-9, "nT"),
    ("m", 1.0, "m"), ("", 1.0, ""),  # not a gravity or magnetic unit: as it is
])
def test_map_units_are_converted_to_mgal_or_nt(tmp_path, units, scale, expected):
    """A map declared in m/s² (or µGal, µT …) is read in mGal (nT), not misread as mGal."""
    path = write(tmp_path / "u.nc", values=FIELD * scale, attrs={"units": units})
    grid = load_map(path)
    assert grid.units == expected
    np.testing.assert_allclose(np.asarray(grid.values), FIELD, rtol=1e-12)


@pytest.mark.long
def test_a_map_in_m_per_s2_matches_like_the_map_in_mgal(tmp_path, capsys):
    """The same map in m/s²: match finds the same fix as with the map in mGal."""
    ryukyu = xr.open_dataset(jg.datasets.path("ryukyu")["anomaly_2p5min"], engine="netcdf4")
    si = ryukyu.astype("float64")
    si["gravity_anomaly"] = si["gravity_anomaly"] * 1e-5
    si["gravity_anomaly"].attrs["units"] = "m s-2"
    si.to_netcdf(tmp_path / "si.nc")
    track = tmp_path / "t.csv"
    assert main(["simulate", "--map", "ryukyu", "--n", "20", "--seed", "3", "--out",
                 str(track)]) == 0
    outs = []
    for name, m in (("mgal", "ryukyu"), ("si", str(tmp_path / "si.nc"))):
        out = tmp_path / f"{name}.json"
        assert main(["match", "--map", m, "--track", str(track), "--out", str(out)]) == 0, \
            capsys.readouterr().err
        outs.append(json.loads(out.read_text()))
    a, b = outs
    np.testing.assert_allclose([b["offset_north_m"], b["offset_east_m"]],
                               [a["offset_north_m"], a["offset_east_m"]], atol=1.0)


def test_fill_values_and_nan_cells_kept_as_a_mask(tmp_path):
    ints = np.round(FIELD).astype(np.int16)
    ints[0, :3] = -32768
    xr.Dataset({"z": (("lat", "lon"), ints, {"_FillValue": np.int16(-32768)})},
               coords={"lat": LAT[::-1], "lon": LON}).to_netcdf(tmp_path / "f.nc")
    grid = load_map(tmp_path / "f.nc", allow_nan=True)
    assert grid.n_missing == 3
    v = np.asarray(grid.values)
    assert np.isnan(v[-1, :3]).all() and np.isfinite(v[:-1]).all()  # row flipped north-up
    np.testing.assert_array_equal(v[:-1], ints[::-1][:-1])


def test_uncertainty_variable(tmp_path):
    err = np.full_like(FIELD, 2.0)
    path = write(tmp_path / "e.nc", more={"err": (("lat", "lon"), err, {"units": "mGal"})})
    grid, sigma = load_map(path, error_var="err")
    np.testing.assert_allclose(grid.values, FIELD)
    np.testing.assert_allclose(sigma.values, 2.0)
    assert sigma.units == "mGal" and (sigma.lat0, sigma.lon0) == (grid.lat0, grid.lon0)
    bad = write(tmp_path / "b.nc", more={"err": (("lat", "lon"), -err)})
    with pytest.raises(ValueError, match=r"'err' .* must be >= 0 .* found -2"):
        load_map(bad, error_var="err")
    with pytest.raises(ValueError, match="no uncertainty variable"):
        load_map("ryukyu", error_var="err")


# ---------------------------------------------------------------------- regions, seams, NaN
def global_grid(step=1.0, lon0=0.0):
    lat = np.arange(-10.0, 10.0 + step / 2, step)
    lon = lon0 + np.arange(0.0, 360.0, step)
    values = np.add.outer(np.cos(np.deg2rad(3 * lat)), np.sin(np.deg2rad(lon)) * 50)
    return jg.Grid.from_arrays(lat, lon, values), lat, lon, values


def test_global_0_360_grid_for_a_track_across_greenwich():
    grid, lat, _, values = global_grid()
    tlat = np.array([0.2, 0.4, 0.6])
    tlon = np.array([-1.5, -0.25, 1.3])  # as the track reader gives 359.5 … 1.3
    region = grid.finite_region(tlat, tlon, 5000.0)
    w, e, _, _ = region.extent
    assert w < -1.5 - 0.04 and e > 1.3 + 0.04 and region.n_missing == 0
    # bilinear across the seam equals a periodic brute-force interpolation of the file
    got = np.asarray(region.sample(tlat, tlon, "bilinear", strict=True))
    iy, fy = np.divmod(tlat - lat[0], 1.0)
    ix, fx = np.divmod(np.mod(tlon, 360.0), 1.0)
    iy, ix = iy.astype(int), ix.astype(int)
    x1 = (ix + 1) % 360
    want = ((1 - fy) * ((1 - fx) * values[iy, ix] + fx * values[iy, x1])
            + fy * ((1 - fx) * values[iy + 1, ix] + fx * values[iy + 1, x1]))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    # the same track given 0–360 gives the same map; a track far from the seam keeps it
    same = grid.finite_region(tlat, np.mod(tlon, 360.0), 5000.0)
    assert (same.lon0, same.nx) == (region.lon0, region.nx)
    far = grid.finite_region(tlat, tlon + 90.0, 5000.0)  # cut, not recentred
    assert far.nx < 30 and 80 < far.lon0 < 88.5 and far.lon0 == round(far.lon0)


def test_recentred_drops_a_repeated_360_column():
    lat = np.linspace(-2, 2, 5)
    lon = np.arange(0.0, 360.5, 0.5)
    g = jg.Grid.from_arrays(lat, lon, np.broadcast_to(np.sin(np.deg2rad(lon)), (5, lon.size)))
    r = g.recentred(0.0)
    assert r.nx == 720 and r.lon0 == -180.0
    np.testing.assert_allclose(np.asarray(r.values)[0], np.sin(np.deg2rad(r.lon)), atol=1e-12)
    with pytest.raises(ValueError, match="only a global map"):
        jg.Grid.from_arrays(LAT, LON, FIELD).recentred(0.0)


def test_finite_region_keeps_nan_far_from_the_track_and_refuses_it_near(tmp_path):
    values = FIELD.copy()
    values[:, 14:] = np.nan  # "land" in the east of the map
    path = write(tmp_path / "land.nc", values=values)
    grid = load_map(path, allow_nan=True)
    assert grid.n_missing == 22
    tlat, tlon = np.array([30.3, 30.5, 30.7]), np.array([130.3, 130.4, 130.5])
    region = grid.finite_region(tlat, tlon, 5000.0, source="--map 'land.nc'")
    assert region.n_missing == 0 and region.extent[1] < 131.35
    np.testing.assert_allclose(np.asarray(region.sample(tlat, tlon, "bilinear")),
                               np.asarray(jg.Grid.from_arrays(LAT, LON, FIELD).sample(
                                   tlat, tlon, "bilinear")), atol=1e-9)
    # bicubic on the cut map: the spline's end effect is gone 6 nodes in (see pad_nodes)
    wide = load_map(write(tmp_path / "wide.nc", values=np.tile(FIELD, (3, 3)),
                          lat=30.0 + 0.1 * np.arange(33), lon=130.0 + 0.1 * np.arange(48)))
    part = wide.finite_region(tlat + 1.1, tlon + 1.6, 0.0)
    assert part is wide  # no missing node: the whole map
    holed = dataclasses.replace(wide, values=wide.values.at[0, 0].set(np.nan))
    part = holed.finite_region(tlat + 1.1, tlon + 1.6, 0.0)
    assert part.values.shape == (17, 15)
    np.testing.assert_allclose(np.asarray(part.sample(tlat + 1.1, tlon + 1.6, "bicubic")),
                               np.asarray(wide.sample(tlat + 1.1, tlon + 1.6, "bicubic")),
                               atol=1e-3)
    with pytest.raises(ValueError, match=r"--map 'land.nc' has \d+ missing \(NaN\) node\(s\) "
                                         r"among the \d+ within 30 km .* first at lat"):
        grid.finite_region(tlat, tlon, 30000.0, source="--map 'land.nc'")
    assert grid.finite_region(tlat, tlon, 30000.0, max_missing=0.5).n_missing > 0
    with pytest.raises(ValueError, match="lie outside the map"):
        grid.finite_region(tlat + 5, tlon, 0.0)


# ---------------------------------------------------------------------- hypothesis
@st.composite
def small_grids(draw):
    ny, nx = draw(st.integers(2, 6)), draw(st.integers(2, 7))
    dlat = draw(st.sampled_from([0.25, 0.5, 1.0]))
    dlon = draw(st.sampled_from([0.2, 0.5, 1.0]))
    lat0 = draw(st.integers(-80, 75))
    lon0 = draw(st.sampled_from([-178.0, -2.0, 0.0, 10.0, 178.0, 355.0]))
    lat = lat0 + dlat * np.arange(ny)
    lon = lon0 + dlon * np.arange(nx)
    if lon[-1] >= 360:  # 355 … 361 written the 0–360 way: 355 … 359, 0, 1
        lon = np.mod(lon, 360.0)
    values = np.asarray(draw(st.lists(st.floats(-500, 500, allow_nan=False), min_size=ny * nx,
                                      max_size=ny * nx))).reshape(ny, nx)
    names = draw(st.sampled_from([("lat", "lon"), ("latitude", "longitude"), ("y", "x"),
                                  ("Lat", "LONGITUDE")]))
    flip_lat, flip_lon = draw(st.booleans()), draw(st.booleans())
    singleton = draw(st.sampled_from([None, "time", "level"]))
    return lat, lon, values, names, flip_lat, flip_lon, singleton


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(small_grids())
def test_generated_grids_read_back_node_for_node(tmp_path, g):
    lat, lon, values, (ny_name, nx_name), flip_lat, flip_lon, singleton = g
    if flip_lat:
        lat, values = lat[::-1], values[::-1]
    if flip_lon:
        lon, values = lon[::-1], values[:, ::-1]
    extra = {singleton: [0.0]} if singleton else None
    path = write(tmp_path / "h.nc", values=values, lat=lat, lon=lon, lat_name=ny_name,
                 lon_name=nx_name, extra=extra)
    grid = load_map(path)
    np.testing.assert_array_equal(node_values(grid, lat, lon), values)
    assert grid.lon[-1] - grid.lon[0] < 360 and -180 <= grid.lon0 <= 360
    assert np.all(np.diff(grid.lon) > 0) and np.all(np.diff(grid.lat) > 0)


def bad_grid(g, fault):
    """A generated grid broken by ``fault``: ``(values, lat, lon, extra, phrase)``."""
    lat, lon, values, (ny_name, _), *_ = g
    extra = None
    if fault == "depth":
        extra = {"depth": [0.0, 5.0]}
        values = np.stack([values, values])
        phrase = "depth: 2"
    else:
        lat = np.r_[lat, lat[-1] + (lat[1] - lat[0])]  # at least 3 rows to break
        values = np.vstack([values, values[-1:]])
        lat = lat.copy()
        k = len(lat) - 1
        if fault == "repeat":
            lat[k] = lat[k - 1]
            phrase = f"{ny_name}[{k}] = {lat[k]:.10g} repeats"
        elif fault == "swap":
            lat[k - 1], lat[k] = lat[k], lat[k - 1]
            phrase = "goes back"
        else:
            lat[k] += 0.3 * (lat[1] - lat[0])
            phrase = "not the regular"
    return values, lat, lon, extra, phrase


GRID_FAULTS = ["repeat", "swap", "irregular", "depth"]


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(small_grids(), st.sampled_from(GRID_FAULTS))
def test_generated_bad_grids_are_refused_by_name(tmp_path, g, fault):
    values, lat, lon, extra, phrase = bad_grid(g, fault)
    path = write(tmp_path / "bad.nc", values=values, lat=lat, lon=lon, lat_name=g[3][0],
                 lon_name=g[3][1], extra=extra)
    with pytest.raises(ValueError) as info:
        load_map(path)
    msg = str(info.value)
    assert phrase in msg and str(path) in msg and "np." not in msg, msg


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(small_grids(), st.one_of(st.none(), st.sampled_from(GRID_FAULTS)))
def test_generated_grids_through_the_sample_command(tmp_path, capsys, g, fault):
    """``jaxgrav sample`` in-process on generated NetCDF grids: at the file's nodes a
    valid grid gives its node values (any axis names, order, singleton dimension, 0–360
    longitudes); a broken one exits 2 with one line naming the file, writing nothing."""
    lat, lon, values, (ny_name, nx_name), flip_lat, flip_lon, singleton = g
    out = tmp_path / "s.csv"
    out.unlink(missing_ok=True)
    if fault is None:
        la, lo = np.meshgrid(lat, lon, indexing="ij")
        want = values  # at the nodes (la, lo), whatever order the file stores them in
        if flip_lat:
            lat, values = lat[::-1], values[::-1]
        if flip_lon:
            lon, values = lon[::-1], values[:, ::-1]
        extra = {singleton: [0.0]} if singleton else None
    else:
        values, lat, lon, extra, phrase = bad_grid(g, fault)
        la, lo = np.meshgrid(lat[:2], lon[:2], indexing="ij")
    path = write(tmp_path / "g.nc", values=values, lat=lat, lon=lon, lat_name=ny_name,
                 lon_name=nx_name, extra=extra)
    write_track_csv(tmp_path / "t.csv", {"lat": la.ravel(), "lon": lo.ravel()}, force=True)
    capsys.readouterr()
    code = main(["sample", "--map", str(path), "--track", str(tmp_path / "t.csv"),
                 "--out", str(out), "--method", "bilinear"])
    if fault is not None:
        err = capsys.readouterr().err
        assert code == 2 and phrase in err and str(path) in err and err.count("\n") == 1
        assert not out.exists()
        return
    assert code == 0
    got = np.genfromtxt(out, delimiter=",", names=True)["map"]
    np.testing.assert_allclose(got, want.ravel(), atol=1e-9 * (1 + np.abs(want).max()))


MAP_COMMANDS = {"match": "r.json", "filter": "f.csv", "navigate": "n.csv",
                "suitability": "s.nc", "simulate": "t.csv", "simulate-filter": "sf.csv",
                "simulate-voyage": "v.csv"}


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(small_grids(), st.sampled_from(GRID_FAULTS), st.sampled_from(sorted(MAP_COMMANDS)))
def test_generated_bad_grids_through_every_command(tmp_path, capsys, g, fault, command):
    """Every command that reads ``--map`` refuses a generated broken grid the same way:
    exit 2, one line naming the file and what is wrong, no traceback, nothing written."""
    values, lat, lon, extra, phrase = bad_grid(g, fault)
    path = write(tmp_path / "bad.nc", values=values, lat=lat, lon=lon, lat_name=g[3][0],
                 lon_name=g[3][1], extra=extra)
    n = 40  # a valid track (every column a command may need) inside the grid
    track = tmp_path / "log_in.csv"
    write_track_csv(track, {"t": 10.0 * np.arange(n), "lat": np.full(n, lat[0]),
                            "lon": np.full(n, lon[0]), "v_east": np.zeros(n),
                            "v_north": np.zeros(n), "gravity": np.zeros(n)}, force=True)
    out = tmp_path / MAP_COMMANDS[command]
    out.unlink(missing_ok=True)
    argv = [command, "--map", str(path), "--out", str(out)]
    if command in ("match", "filter", "navigate"):
        argv += ["--track", str(track)]
    capsys.readouterr()
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2 and phrase in err and str(path) in err, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not list(tmp_path.glob(f"{out.stem}*"))


# ---------------------------------------------------------------------- through the command
def test_sample_command_reads_user_maps_and_refuses_bad_ones(tmp_path, capsys):
    write_track_csv(tmp_path / "t.csv", {"lat": [30.2, 30.4], "lon": [130.2, 130.6]})
    ok = write(tmp_path / "time.nc", extra={"time": [0.0]}, lat=LAT[::-1], values=FIELD[::-1])
    assert main(["sample", "--map", str(ok), "--track", str(tmp_path / "t.csv"),
                 "--out", str(tmp_path / "s.csv")]) == 0
    (tmp_path / "map.csv").write_text("t,lat,lon\n0,30,130\n")
    cube = write(tmp_path / "cube.nc", extra={"depth": [0.0, 1.0]})
    for bad, phrase in [(tmp_path / "map.csv", "is not a NetCDF file"), (cube, "must be 2-D")]:
        capsys.readouterr()
        assert main(["sample", "--map", str(bad), "--track", str(tmp_path / "t.csv"),
                     "--out", str(tmp_path / "x.csv")]) == 2
        err = capsys.readouterr().err
        assert phrase in err and err.count("\n") == 1 and not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("fill", [-9999.0, 99999.0, 1e30])
def test_undeclared_fill_values_read_as_missing_nodes(tmp_path, fill):
    """A grid whose gaps hold -9999 (no _FillValue attribute: converted from ASCII) was
    read as a field of -9999 mGal there (sample wrote -5194 mGal beside it, exit 0)."""
    values = FIELD.copy()
    values[4:6, 7:9] = fill
    path = write(tmp_path / "f.nc", values=values)
    expected = f"4 node.*hold {re.escape(f'{fill:g}')}"
    with pytest.warns(jg.grid_files.UndeclaredFillWarning, match=expected):
        grid = load_map(path, allow_nan=True)
    v = np.asarray(grid.values)
    assert grid.n_missing == 4 and np.isnan(v[4:6, 7:9]).all()
    np.testing.assert_array_equal(np.isnan(v).sum(), 4)


def test_a_fill_like_value_inside_the_map_range_is_data(tmp_path):
    """-9999 among values that reach below it (a bathymetry in metres) is a value."""
    values = np.linspace(-11000.0, 0.0, FIELD.size).reshape(FIELD.shape)
    values[3, 3] = -9999.0
    grid = load_map(write(tmp_path / "d.nc", values=values), allow_nan=True)
    assert grid.n_missing == 0
