"""Inputs found by the tenth issue-19 hunt (2026-12-07, helper-79).

The last hunt's leftovers first: a track in the −360…0 longitude convention was refused
(maps in it were read), ``filter --sigma-pos 1e-9`` ran pmf on a grid nanometres across,
and :meth:`jaxgrav.dov.LayeredGrid.from_netcdf` read only a ``units`` attribute, in
neither km nor ft. Then the hunt's own finds (below them)."""

import json

import numpy as np
import pytest
import xarray as xr

from jaxgrav.cli import main
from jaxgrav.datasets import load_map
from jaxgrav.dov import LayeredGrid
from jaxgrav.tracks import read_track_csv

ROWS = [(29.5 + 0.0056 * i, 126.5 + 0.0068 * i) for i in range(8)]


def _track(path, header="t,lat,lon,gravity", rows=None, lon_shift=0.0):
    rows = rows if rows is not None else [f"{120 * i},{lat},{lon + lon_shift:.4f},{-10 + i}"
                                          for i, (lat, lon) in enumerate(ROWS)]
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


def _log(path, n=30, dt=2.0, gap_after=None):
    """A ``filter`` log on the shipped map: ``n`` rows every ``dt`` s heading north-east,
    a reading every row, one gap of 4 steps after row ``gap_after``."""
    t = dt * np.arange(n, dtype=float)
    if gap_after is not None:
        t[gap_after + 1:] += 4 * dt
    rows = [f"{t[i]:g},{29.5 + 1e-4 * i:.5f},{126.5 + 1e-4 * i:.5f},{-10 + 0.1 * i:.2f}"
            for i in range(n)]
    return _track(path, rows=rows)


# --- the last hunt's leftovers ----------------------------------------------------------

def test_a_track_in_the_minus_360_convention_is_read_as_maps_are(tmp_path):
    """``lon`` −233.5 (126.5° E written as −360…0, as some survey software exports) was
    refused "outside [-180, 360]" with a NMEA hint, while a map in that convention was
    read."""
    east = read_track_csv(_track(tmp_path / "e.csv"), required=("t", "lat", "lon"))
    west = read_track_csv(_track(tmp_path / "w.csv", lon_shift=-360.0),
                          required=("t", "lat", "lon"))
    np.testing.assert_allclose(west["lon"], east["lon"], atol=1e-9)
    assert west.cells["lon"][0] == "-233.5"  # passed through to outputs as written


def test_match_on_a_minus_360_track_equals_the_east_track(tmp_path):
    outs = []
    for name, shift in (("e", 0.0), ("w", -360.0)):
        track = _track(tmp_path / f"{name}.csv", lon_shift=shift)
        outs.append(tmp_path / f"{name}.json")
        assert main(["match", "--map", "ryukyu", "--track", str(track), "--out",
                     str(outs[-1])]) == 0
    east, west = (json.loads(p.read_text()) for p in outs)
    assert east["offset_north_m"] == pytest.approx(west["offset_north_m"], abs=1e-6)
    assert east["offset_east_m"] == pytest.approx(west["offset_east_m"], abs=1e-6)


def test_a_track_beyond_both_conventions_is_still_refused(tmp_path):
    track = _track(tmp_path / "t.csv", rows=["0,29.5,-200", "10,29.5,10"])
    with pytest.raises(ValueError, match="longitude -200 is outside"):
        read_track_csv(track, required=("t", "lat", "lon"))


def test_pmf_sigma_pos_the_map_cannot_resolve_is_refused(tmp_path, refused):
    """``filter --method pmf --sigma-pos 1e-9`` ran: the grid (±4 σ, fixed) was 8 nm
    across, every row at its edge, "final 1-sigma 0 m" with a 1.4 km true error, exit 0."""
    out = tmp_path / "o.csv"
    refused(["filter", "--map", "ryukyu", "--track", _log(tmp_path / "log.csv"), "--out", out,
             "--method", "pmf", "--sigma-pos", "1e-9"],
            "--sigma-pos 1e-09 m makes pmf's grid 8e-09 m across (±4 sigma, the region it "
            "searches), across which the map changes by at most 1.15e-10 mGal (its steepest "
            "slope is 0.0144 mGal/m), below a tenth of what 30 readings of --sigma-gravity 1 "
            "mGal can tell (0.0183 mGal): no cell could be told from another; expected a "
            "--sigma-pos of at least 0.16 m")
    assert not out.exists()


def test_a_tiny_max_gap_refuses_any_gap_by_name(tmp_path, refused):
    """``--max-gap 1e-9`` is kept: it says "predict through no gap", and a log with one
    is refused naming it (a log without gaps runs as with the default)."""
    refused(["filter", "--map", "ryukyu", "--track", _log(tmp_path / "log.csv", gap_after=9),
             "--out", tmp_path / "o.csv", "--max-gap", "1e-9"],
            "a gap of 10 s on lines 11-12 (t 18 -> 28 s) is longer than --max-gap 1e-09 s")


def _layers(path, key, xi_units, xi_factor, h_units, h_factor):
    lat, lon = np.linspace(0.0, 1.0, 6), np.linspace(10.0, 11.0, 6)
    values = np.stack([np.stack([np.add.outer(lat, lon) * (k + 1) * (c + 1) for c in range(2)])
                       for k in range(2)])
    xr.Dataset({name: (("height", "lat", "lon"), values[:, c] / xi_factor, {key: xi_units})
                for c, name in enumerate(("xi", "eta"))},
               coords={"height": ("height", np.array([0.0, 1000.0]) / h_factor,
                                  {key: h_units}),
                       "lat": lat, "lon": lon}).to_netcdf(path)
    return values


@pytest.mark.parametrize("key", ["units", "Units", "UNITS", "unit"])
def test_layered_grid_from_netcdf_converts_declared_units(tmp_path, key):
    """Outside the command line the layers read only ``units`` and never converted:
    µrad were taken for arcsec, heights in km for metres."""
    values = _layers(tmp_path / "g.nc", key, "urad", 0.20626480624709636, "km", 1000.0)
    layers = LayeredGrid.from_netcdf(tmp_path / "g.nc")
    assert layers.units == "arcsec"
    np.testing.assert_allclose(np.asarray(layers.heights), [0.0, 1000.0])
    np.testing.assert_allclose(np.asarray(layers.values), values, rtol=1e-12)


def test_layered_grid_keeps_channels_of_another_kind_and_refuses_odd_heights(tmp_path):
    _layers(tmp_path / "g.nc", "units", "mGal", 1.0, "m", 1.0)
    assert LayeredGrid.from_netcdf(tmp_path / "g.nc").units == "mGal"
    _layers(tmp_path / "h.nc", "units", "arcsec", 1.0, "s", 1.0)
    with pytest.raises(ValueError, match="height declares units 's'; expected layer heights"):
        LayeredGrid.from_netcdf(tmp_path / "h.nc")


# --- the hunt's own finds ---------------------------------------------------------------

@pytest.mark.parametrize("header, name, factor", [
    ("t,lat,lon,faa_mgal", "gravity", 1.0), ("t,lat,lon,free_air_anomaly_mgal", "gravity", 1.0),
    ("t,lat,lon,grav_ugal", "gravity", 1e-3), ("t,lat,lon,mag_anomaly_nt", "magnetic", 1.0),
    ("t,lat,lon,ve_kn", "v_east", 1852.0 / 3600.0),
    ("t,lat,lon,v_north_kts", "v_north", 1852.0 / 3600.0),
    ("timestamp_min,lat,lon", "t", 60.0)])
def test_a_unit_ending_on_any_alias_is_read(tmp_path, header, name, factor):
    """``faa_mgal`` (a survey's anomaly with its unit) was "needs a 'gravity' column" and
    ``ve_kn`` passed through unread: the ``name_unit`` endings knew the canonical names
    only (``gravity_mgal``), not the aliases the reader accepts (``faa``, ``ve``)."""
    track = _track(tmp_path / "t.csv", header, ["0,29.5,126.5,2", "1,29.51,126.51,4"]
                   if header.count(",") == 3 else ["0,29.5,126.5", "1,29.51,126.51"])
    got = read_track_csv(track, required=("t", "lat", "lon"), optional=(name,))
    column = -1 if name != "t" else 0
    values = [float(r.split(",")[column]) for r in track.read_text().splitlines()[1:]]
    np.testing.assert_allclose(got[name], np.asarray(values) * factor)


def _small_map(path, rows):
    """The shipped map's nodes near 29.5 N 126.5 E, ``rows`` rows of 36 columns."""
    grid = load_map("ryukyu")
    lat, lon, values = (np.asarray(a) for a in (grid.lat, grid.lon, grid.values))
    i, j = np.searchsorted(lat, 29.4), np.searchsorted(lon, 126.0)
    xr.Dataset({"z": (("lat", "lon"), values[i:i + rows, j:j + 36], {"units": "mGal"})},
               coords={"lat": lat[i:i + rows], "lon": lon[j:j + 36]}).to_netcdf(path)
    return path


def test_simulate_voyage_on_a_two_row_map_names_the_map(tmp_path, refused):
    """A 2-row map ended in the interpolator's "bicubic interpolation needs at least 4
    nodes per axis; got 2" (no option, no file), as ``sample`` and ``match`` did not."""
    grid = _small_map(tmp_path / "m.nc", 2)
    refused(["simulate-voyage", "--map", grid, "--out", tmp_path / "v.csv", "--hours", "1"],
            f"--map '{grid}' has 2 x 36 nodes (lat x lon); bicubic interpolation needs at "
            "least 4 along each axis: give a larger map")
    assert not (tmp_path / "v.csv").exists()


@pytest.mark.parametrize("command, option", [
    ("match", "--map-error"), ("filter", "--map-error"), ("navigate", "--map-error"),
    ("montecarlo", "--told-map-error")])
def test_a_told_map_error_beyond_any_map_s_is_refused(tmp_path, refused, command, option):
    """A map error told to a matcher or filter was not capped as a drawn one is (1000 map
    units): ``match --map-error 1e9`` ran, every fix rejected, "score 3.72e-19", exit 0."""
    log = _log(tmp_path / "log.csv")
    out = tmp_path / ("o.json" if command == "match" else "o.nc" if command == "montecarlo"
                      else "o.csv")
    argv = (["montecarlo", "--method", "dense", "--runs", "3"] if command == "montecarlo"
            else [command, "--track", log])
    refused([*argv, "--map", "ryukyu", "--out", out, option, "1e9"],
            f"{option}{' SIGMA' if command == 'montecarlo' else ''} must be at most 1000 (map "
            "units; a marine gravity map's error is a few mGal, a magnetic map's tens of nT); "
            "got 1e+09")
    assert not out.exists()


def _field(lat, lon):
    return (50 * np.sin(np.radians(lat) * 3) * np.cos(np.radians(lon) * 2)
            + 20 * np.sin(np.radians(lon) * 5))


@pytest.mark.parametrize("lon", [np.arange(-280.0, 80.01, 2.0),  # GFDL MOM, seam twice
                                 np.arange(20.0, 378.01, 2.0),  # rolled, from 20 E
                                 np.arange(20.0, 378.01, 2.0)[::-1],
                                 np.arange(355.0, 365.01, 0.5)])  # regional across 0 as 360
def test_a_map_stored_from_another_meridian_is_read(tmp_path, lon):
    """A global map from −280 to 80 (or 20 to 378) ended in the grid's "lon must lie
    within [-180, 360] and span at most 360 degrees; got -340.0 .. 18.0", naming no file;
    a regional 355 … 365 the same."""
    lat = np.arange(-20.0, 40.01, 2.0)
    path = tmp_path / "m.nc"
    xr.Dataset({"z": (("lat", "lon"), _field(*np.meshgrid(lat, lon, indexing="ij")),
                      {"units": "mGal"})}, coords={"lat": lat, "lon": lon}).to_netcdf(path)
    track = _track(tmp_path / "t.csv", "t,lat,lon",
                   [f"{60 * i},{10 + 0.5 * i},{v:g}" for i, v in enumerate((359.0, 0.5, 1.5))])
    out = tmp_path / "s.csv"
    assert main(["sample", "--map", str(path), "--track", str(track), "--out", str(out),
                 "--method", "bilinear"]) == 0
    got = np.loadtxt(out, delimiter=",", skiprows=1)
    # bilinear between 2-degree nodes of a field of 72-degree waves: h^2/8 |f''| < 0.2 mGal
    # (a column taken from the wrong side of the seam is off by tens of mGal)
    np.testing.assert_allclose(got[:, -1], _field(got[:, 1], got[:, 2]), atol=0.2)


def test_a_regional_map_beyond_every_convention_is_named(tmp_path, refused):
    lat, lon = np.arange(0.0, 10.01, 1.0), np.arange(-190.0, 10.01, 1.0)
    path = tmp_path / "m.nc"
    xr.Dataset({"z": (("lat", "lon"), np.zeros((lat.size, lon.size)), {"units": "mGal"})},
               coords={"lat": lat, "lon": lon}).to_netcdf(path)
    track = _track(tmp_path / "t.csv", "t,lat,lon", ["0,5,5", "60,5.1,5.1"])
    refused(["sample", "--map", path, "--track", track, "--out", tmp_path / "s.csv"],
            f"map '{path}': longitudes -190 .. 10 reach beyond -180 .. 360 degrees on a map "
            "that is not global, and no shift by 360 degrees brings them within")


@pytest.mark.parametrize("dims, flip", [(("height", "lat", "lon"), True),
                                        (("altitude", "latitude", "longitude"), False),
                                        (("Height", "y", "x"), True)])
def test_dov_layers_named_otherwise_or_stored_top_down_are_read(tmp_path, dims, flip):
    """A --grid with ``latitude``/``longitude`` (or ``altitude``) dimensions was refused
    ("missing lat, lon"), as maps are not; layers stored from the top down were refused
    as "heights must be strictly ascending"."""
    lat, lon = np.linspace(0.0, 1.0, 11), np.linspace(10.0, 11.0, 11)
    values = np.stack([np.stack([np.add.outer(lat, lon) * (k + 1) * (c + 1) for c in range(2)])
                       for k in range(3)])
    heights = np.array([0.0, 1000.0, 5000.0])
    outs = []
    for name, (d, f) in (("a", (("height", "lat", "lon"), False)), ("b", (dims, flip))):
        k = slice(None, None, -1 if f else 1)
        xr.Dataset({c: (d, values[k, i], {"units": "arcsec"}) for i, c in enumerate(("xi", "eta"))},
                   coords={d[0]: (d[0], heights[k], {"units": "m"}), d[1]: lat,
                           d[2]: lon}).to_netcdf(tmp_path / f"{name}.nc")
        outs.append(tmp_path / f"{name}.csv")
        track = _track(tmp_path / "t.csv", "lat,lon,h", ["0.5,10.5,500", "0.52,10.55,2500"])
        assert main(["dov", "--grid", str(tmp_path / f"{name}.nc"), "--track", str(track),
                     "--out", str(outs[-1])]) == 0
    assert outs[0].read_text() == outs[1].read_text()


def test_suitability_of_a_magnetic_map_is_labelled_in_nt(tmp_path):
    """``suitability`` on an nT map wrote its window std, roughness and noise as mGal (and
    titled the PNG so); they are in the map's units."""
    path = _small_map(tmp_path / "g.nc", 36)
    with xr.open_dataset(path) as ds:
        mag = ds.load()
    mag["z"].attrs["units"] = "nT"
    mag.to_netcdf(tmp_path / "m.nc")
    out = tmp_path / "s.nc"
    assert main(["suitability", "--map", str(tmp_path / "m.nc"), "--out", str(out),
                 "--fixes", "10"]) == 0
    with xr.open_dataset(out) as ds:
        assert ds["std"].attrs["units"] == "nT" and ds["slope_std"].attrs["units"] == "nT/km"
        assert ds.attrs["noise_nt"] == 1.0 and "noise_mgal" not in ds.attrs


@pytest.mark.parametrize("header, rows, lat, lon", [
    ("t,lat_deg,lat_min,lon_deg,lon_min", ["0,29,30.0,-126,30.0", "60,-0,30,-126,30.6"],
     [29.5, -0.5], [-126.5, -126.51]),
    ("t,Latitude,Latitude Minutes,Latitude Seconds,lon", ["0,29,30,36,126.5", "60,29,31,0,126.6"],
     [29.51, 29.0 + 31 / 60], [126.5, 126.6]),
    ("t,lat,N/S,lon,E/W", ["0,29.5,S,126.5,W", "60,-0.0,N,126.6,W"], [-29.5, 0.0],
     [-126.5, -126.6]),
])
def test_positions_written_in_parts_are_joined(tmp_path, header, rows, lat, lon):
    """``lat_deg, lat_min`` read the whole degrees and passed the minutes through (a track
    in 29° 30' sampled at 29°), and a ``N/S`` column after the latitude was passed through
    (35° S sampled at 35° N), exit 0."""
    got = read_track_csv(_track(tmp_path / "t.csv", header, rows), required=("t", "lat", "lon"))
    np.testing.assert_allclose(got["lat"], lat, rtol=1e-12)
    np.testing.assert_allclose(got["lon"], lon, rtol=1e-12)


def test_a_minimum_latitude_column_is_not_taken_for_minutes(tmp_path):
    track = _track(tmp_path / "t.csv", "t,lat,lat_min,lon", ["0,29.5,29,126.5", "60,29.6,29,126.6"])
    got = read_track_csv(track, required=("t", "lat", "lon"))
    np.testing.assert_allclose(got["lat"], [29.5, 29.6])


def test_a_hemisphere_column_beside_negative_positions_is_refused(tmp_path):
    track = _track(tmp_path / "t.csv", "t,lat,ns,lon", ["0,-29.5,S,126.5", "60,29.6,N,126.6"])
    with pytest.raises(ValueError, match="column 'ns' gives 'lat' a hemisphere, and the column "
                                         "has negative values too"):
        read_track_csv(track, required=("t", "lat", "lon"))


@pytest.mark.parametrize("header, height", [("h", "5000"), ("altitude_ft", "16000")])
def test_a_track_flown_far_above_the_map_is_warned_of(tmp_path, capsys, header, height):
    """An airborne survey at 5 km (``h``, or ``altitude`` in feet, which was no column)
    was sampled and matched against the sea-level map in silence."""
    rows = [f"{120 * i},{lat},{lon},{height}" for i, (lat, lon) in enumerate(ROWS)]
    track = _track(tmp_path / "t.csv", f"t,lat,lon,{header}", rows)
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out",
                 str(tmp_path / "s.csv")]) == 0
    err = capsys.readouterr().err
    assert (f"warning: column '{header}' of --track '{track}' puts the track at heights up to "
            f"{float(height) * (0.3048 if 'ft' in header else 1):g} m; the map is read at its "
            "own surface") in err


def test_a_ship_s_antenna_height_is_not_warned_of(tmp_path, capsys):
    rows = [f"{120 * i},{lat},{lon},35.2" for i, (lat, lon) in enumerate(ROWS)]
    track = _track(tmp_path / "t.csv", "t,lat,lon,alt", rows)
    assert main(["sample", "--map", "ryukyu", "--track", str(track), "--out",
                 str(tmp_path / "s.csv")]) == 0
    assert "warning" not in capsys.readouterr().err


def test_navigate_refuses_a_fix_block_longer_than_the_log(tmp_path, refused):
    """``navigate --method dense --fix-every 1e9`` printed NumPy's "Mean of empty slice"
    and failed out of memory (217 TB), exit 1."""
    dlon = 50.0 / (111_320.0 * np.cos(np.radians(29.5)))  # 5 m/s east, rows 10 s apart
    rows = [f"{10 * i},29.5,{126.5 + dlon * i:.7f},5.0,0.0,{-10 + 0.1 * i:.2f}"
            for i in range(40)]
    log = _track(tmp_path / "log.csv", "t,lat,lon,v_east,v_north,gravity", rows)
    out = tmp_path / "n.csv"
    refused(["navigate", "--map", "ryukyu", "--track", log, "--out", out, "--method", "dense",
             "--fix-every", "1e9"],
            f"--fix-every 1000000000 rows is longer than --track '{log}' (40 rows): no fix could "
            "be averaged; expected at most 40 rows a fix")
    assert not out.exists()


@pytest.mark.parametrize("lon, attrs", [(-np.linspace(126.0, 127.0, 11), {"units": "degrees_west"}),
                                        (np.linspace(126.0, 127.0, 11) - 360.0, {})])
def test_dov_layers_read_longitudes_as_maps_are(tmp_path, lon, attrs):
    """Layers in CF ``degrees_west`` were read as east (every track point "outside the
    layered grid"), as the map reader does not; also the −360…0 convention."""
    lat, east = np.linspace(0.0, 1.0, 11), np.linspace(126.0, 127.0, 11)
    field = np.add.outer(lat, east)
    values = np.stack([np.stack([field * (k + 1) * (c + 1) for c in range(2)]) for k in range(2)])
    xr.Dataset({c: (("height", "lat", "lon"), values[:, i], {"units": "arcsec"})
                for i, c in enumerate(("xi", "eta"))},
               coords={"height": ("height", [0.0, 1000.0], {"units": "m"}), "lat": lat,
                       "lon": ("lon", lon, attrs)}).to_netcdf(tmp_path / "g.nc")
    layers = LayeredGrid.from_netcdf(tmp_path / "g.nc")
    assert tuple(float(v) for v in layers.extent[:2]) == pytest.approx((126.0, 127.0))
    np.testing.assert_allclose(np.asarray(layers.values)[0, 0], field, rtol=1e-12)


@pytest.mark.parametrize("units, factor", [("arcmin", 60.0), ("arc_seconds", 3600.0)])
def test_map_coordinates_in_minutes_of_arc_are_read(tmp_path, units, factor):
    """A map whose axes declare ``arcmin`` was refused: "coordinate value 1740 is not a
    latitude/longitude in degrees (projected coordinates in metres?)"."""
    path = _small_map(tmp_path / "d.nc", 36)
    with xr.open_dataset(path) as ds:
        arc = ds.load()
    arc = arc.assign_coords(lat=("lat", arc.lat.values * factor, {"units": units}),
                            lon=("lon", arc.lon.values * factor, {"units": units}))
    arc.to_netcdf(tmp_path / "a.nc")
    track = _track(tmp_path / "t.csv")
    outs = [tmp_path / "d.csv", tmp_path / "a.csv"]
    for grid, out in zip((path, tmp_path / "a.nc"), outs, strict=True):
        assert main(["sample", "--map", str(grid), "--track", str(track), "--out",
                     str(out)]) == 0
    a, b = (np.loadtxt(p, delimiter=",", skiprows=1)[:, -1] for p in outs)
    np.testing.assert_allclose(b, a, rtol=1e-6)
