"""Messages of the map, track and point-mass model readers (issue 19): one line naming the
file, the value and what was expected, in plain words (no Python list syntax, no library
function a command-line user cannot call)."""

import json

import jax
import numpy as np
import pytest
import xarray as xr

from jaxgrav.cli import main
from jaxgrav.datasets import load_map
from jaxgrav.fields.pointmass import paper_d
from jaxgrav.fields.pointmass_fit import load_point_masses, save_point_masses
from jaxgrav.grid_files import read_netcdf
from jaxgrav.tracks import read_track_csv


def _montecarlo_like(path, runs=8):
    """A NetCDF laid out as ``jaxgrav montecarlo --out`` writes it: one row per run, the
    runs' start positions as ``start_lat``/``start_lon`` in CF degrees along ``run``."""
    rng = np.random.default_rng(0)
    xr.Dataset(
        {"err_m": ("run", rng.uniform(100, 900, runs), {"units": "m"}),
         "score": ("run", rng.uniform(0, 5, runs)),
         "start_lat": ("run", rng.uniform(24, 25, runs), {"units": "degrees_north"}),
         "start_lon": ("run", rng.uniform(123, 124, runs), {"units": "degrees_east"})},
        coords={"run": np.arange(runs)}).to_netcdf(path)
    return path


@pytest.mark.parametrize("var", [None, "err_m"])
def test_a_table_of_points_is_not_read_as_a_map(tmp_path, clear_message, var):
    """A montecarlo file as a map: start_lat/start_lon (both along ``run``) were taken as
    the grid's axes; "holds 4 gridded variables", and ``var="err_m"`` ended in NumPy's
    "axes don't match array"."""
    path = _montecarlo_like(tmp_path / "mc.nc")
    with pytest.raises(ValueError) as info:
        read_netcdf(path, var)
    clear_message(str(info.value), path, [
        "is not a latitude/longitude grid", "latitudes 'start_lat' and longitudes 'start_lon'",
        "along one dimension, 'run' (8 values)", "a separate 1-D longitude axis"])
    with pytest.raises(ValueError, match="is not a latitude/longitude grid"):
        load_map(path, var=var)


def test_sample_refuses_a_montecarlo_file_as_its_map(tmp_path, capsys):
    mc = _montecarlo_like(tmp_path / "mc.nc")
    track = tmp_path / "t.csv"
    track.write_text("t,lat,lon\n0,24.5,123.5\n60,24.51,123.5\n")
    out = tmp_path / "o.csv"
    assert main(["sample", "--map", str(mc), "--var", "err_m", "--track", str(track),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not a latitude/longitude grid" in err, err
    assert "axes don't match" not in err and not out.exists()


def test_map_variable_messages_list_names_in_words(tmp_path, clear_message):
    path = tmp_path / "two.nc"
    z = np.zeros((3, 4))
    xr.Dataset({"z": (("lat", "lon"), z), "w": (("lat", "lon"), z), "t": ("time", [1.0])},
               coords={"lat": [0.0, 1.0, 2.0], "lon": [0.0, 1.0, 2.0, 3.0]}).to_netcdf(path)
    for var, phrases in ((None, ["holds 2 gridded variables (z, w); choose one with --var"]),
                         ("g", ["has no variable 'g'; its gridded variables are z, w"]),
                         ("t", ["(dimensions lat, lon): its dimensions are time; gridded "
                                "variables: z, w"])):
        with pytest.raises(ValueError) as info:
            read_netcdf(path, var)
        clear_message(str(info.value), path, phrases)
        assert "[" not in str(info.value) and "('" not in str(info.value)


def test_a_map_without_coordinates_names_them_in_words(tmp_path, clear_message):
    path = tmp_path / "rc.nc"
    xr.Dataset({"z": (("row", "col"), np.zeros((2, 2)))}).to_netcdf(path)
    with pytest.raises(ValueError) as info:
        read_netcdf(path)
    clear_message(str(info.value), path, [
        "has no latitude coordinate: expected one named lat, latitude or y (any case) or "
        "with CF standard_name latitude; it has z"])


@pytest.mark.parametrize(("text", "kwargs", "message"), [
    ("t,lat,lon,gravity\n0,30,130,1\n", {"required": ("t", "lat", "lon", "h")},
     "lacks column h; it has t, lat, lon, gravity; required: t, lat, lon, h (names in any "
     "case"),
    ("lat,lon\n30,130\n", {"required": ("t", "lat", "gravity")},
     "lacks columns t and gravity; it has lat, lon; required: t, lat, gravity"),
    ("t,lat,lon\n0,30,130\n", {"columns": {"gravity": "FAA"}},
     "has no column 'FAA' (asked for by --columns gravity=FAA); it has t, lat, lon"),
    ("t,LAT,Lat\n0,30,31\n", {}, "columns LAT and Lat could all be 'lat'; choose one with "
     "--columns lat=COLUMN"),
])
def test_track_column_messages_list_names_in_words(tmp_path, clear_message, text, kwargs,
                                                   message):
    path = tmp_path / "a.csv"
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        read_track_csv(path, **kwargs)
    clear_message(str(info.value), path, [message])
    assert "[" not in str(info.value), info.value


@pytest.mark.parametrize(("doc", "found"), [
    ({"version": 1}, 'it has no "format" field'),
    ({"format": "grid"}, 'its "format" is "grid"'),
    ([1, 2], "it holds [1, 2], not a JSON object"),
])
def test_a_point_mass_model_message_says_what_the_file_must_hold(tmp_path, clear_message, doc,
                                                                  found):
    """"format must be 'jaxgrav.point_masses'; got None" named save_point_masses, a Python
    function a command-line user cannot call."""
    path = tmp_path / "model.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as info:
        load_point_masses(path)
    msg = str(info.value)
    clear_message(msg, path, [
        f"is not a jaxgrav point-mass model ({found}); a point-mass model is a JSON object "
        'with "format": "jaxgrav.point_masses", "version": 1, the lists "lat", "lon", '
        '"depth", "mass" and an "offset"',
        "jaxgrav.fields.pointmass_fit.save_point_masses in Python"])
    assert "None" not in msg and "written by save_point_masses" not in msg


def test_a_point_mass_model_with_a_byte_order_mark_is_read(tmp_path):
    """A model saved by a Windows editor starts with a UTF-8 byte-order mark: it was refused
    as "is not JSON (Unexpected UTF-8 BOM ...)"."""
    path, bom = tmp_path / "model.json", tmp_path / "bom.json"
    save_point_masses(path, paper_d(), offset=5.0)
    bom.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    model, offset = load_point_masses(path)
    again, offset_again = load_point_masses(bom)
    assert offset_again == offset == 5.0
    for a, b in zip(jax.tree.leaves(model), jax.tree.leaves(again), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def _one_var_map(path, values):
    """A 3 x 3 map on lat 24..25, lon 122..123 holding ``values`` as variable ``g``."""
    xr.Dataset({"g": (("lat", "lon"), values)},
               coords={"lat": np.linspace(24, 25, 3), "lon": np.linspace(122, 123, 3)}
               ).to_netcdf(path)
    return path


@pytest.mark.parametrize(("values", "what"), [
    (np.full((3, 3), "a"), r"text, not numbers \(dtype <U1\)"),
    (np.eye(3, dtype=bool), r"true/false values \(a mask\?\), not numbers \(dtype bool\)"),
])
def test_a_map_of_text_or_a_mask_is_named(tmp_path, values, what):
    """Text was "could not convert string to float: np.str_('a')"; a true/false land mask
    was read as a field of 0 and 1."""
    path = _one_var_map(tmp_path / "m.nc", values)
    with pytest.raises(ValueError, match=rf"^variable 'g' of map '.*m.nc' holds {what}; "
                       r"expected the map's values \(e.g. mGal\)$"):
        read_netcdf(path)


def test_a_map_with_no_gridded_variable_says_so(tmp_path):
    """Was "holds 0 gridded variables (none); choose one with --var NAME": nothing to choose."""
    path = tmp_path / "m.nc"
    xr.Dataset(coords={"lat": np.linspace(24, 25, 3), "lon": np.linspace(122, 123, 3)}
               ).to_netcdf(path)
    with pytest.raises(ValueError, match=r"^map '.*m.nc' holds no variable on its latitude/"
                       r"longitude grid \(it has lat, lon\); expected a map variable along lat "
                       r"and lon, e.g. gravity\(lat, lon\)$"):
        read_netcdf(path)


def test_an_infinite_map_node_is_announced_as_missing(tmp_path):
    """An inf node became a missing node with no word (a -9999 one was announced)."""
    values = np.arange(9.0).reshape(3, 3)
    values[1, 1] = np.inf
    with pytest.warns(UserWarning, match=r"1 node\(s\) of variable 'g' hold inf"):
        got = read_netcdf(_one_var_map(tmp_path / "m.nc", values))
    assert np.isnan(got.values[1, 1]) and np.isfinite(np.delete(got.values, 4)).all()
