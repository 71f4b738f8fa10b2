"""``jaxgrav dov`` with track heights outside the layers (issue 19): a submarine at -50 m
under the shipped layers (0, 10, 20 km) was refused without saying what would take it in,
and the fix, ``--layers -50,0,10000,20000``, was itself refused by argparse ("expected one
argument": a word starting with "-" read as an option)."""

import re

import numpy as np
import pytest

from jaxgrav import datasets, dov
from jaxgrav.cli import main
from jaxgrav.cli.main import joined_negative_lists
from jaxgrav.fields import harmonics
from jaxgrav.tracks import read_track_csv, write_track_csv


def _refused(capsys, argv, message, outputs):
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err, err
    assert "\n" not in err and "Traceback" not in err, err
    assert not any(p.exists() for p in outputs)
    return err


@pytest.mark.parametrize("h, layers, fix", [
    ([-50.0, 100.0], None, "the track needs a layer at or below -50 m: give "
                           "--layers=-50,0,10000,20000 (new heights are synthesised"),
    ([-47.5, 100.0], None, "give --layers=-50,0,10000,20000 "),
    ([100.0, 25000.0], None, "a layer at or above 25000 m: give --layers=0,10000,20000,25000 "),
    ([-50.0, 25000.0], None, "at or below -50 m and at or above 25000 m: give "
                             "--layers=-50,0,10000,20000,25000 "),
    pytest.param([-50.0, 100.0], "0,1000", "give --layers=-50,0,1000 ",  # the user's own
                 marks=pytest.mark.long),  # layers, widened (synthesising them takes 9 s)
])
def test_a_height_outside_the_shipped_layers_names_the_layers_that_take_it(
        tmp_path, capsys, h, layers, fix):
    track = tmp_path / "sub.csv"
    write_track_csv(track, {"lat": [34.0, 34.01], "lon": [108.5, 108.51], "h": h})
    out = tmp_path / "o.csv"
    argv = ["dov", "--track", track, "--out", out, *(["--layers", layers] if layers else [])]
    err = _refused(capsys, argv, fix, [out])
    assert "point (lat=34.0, lon=108.5" in err or "lat=34.01" in err, err


def test_a_point_off_the_grid_gets_no_layers_advice(tmp_path, capsys):
    """Off the grid horizontally, new heights would not help: no --layers advice."""
    track = tmp_path / "off.csv"
    write_track_csv(track, {"lat": [34.0, 50.0], "lon": [108.5, 108.5], "h": [0.0, -50.0]})
    out = tmp_path / "o.csv"
    err = _refused(capsys, ["dov", "--track", track, "--out", out],
                   "1 of 2 point(s) out of range", [out])
    assert "--layers" not in err, err


def test_a_height_below_a_user_grid_asks_for_a_layer_in_the_file(tmp_path, capsys):
    """A --grid cannot be re-layered: the advice is a layer in the file, not --layers."""
    lat, lon = np.linspace(0.0, 1.0, 11), np.linspace(10.0, 11.0, 11)
    values = np.zeros((2, 2, 11, 11))
    dov.LayeredGrid.from_arrays(lat, lon, [0.0, 1000.0], values).to_netcdf(tmp_path / "l.nc")
    track = tmp_path / "sub.csv"
    write_track_csv(track, {"lat": [0.5], "lon": [10.5], "h": [-20.0]})
    out = tmp_path / "o.csv"
    _refused(capsys, ["dov", "--track", track, "--out", out, "--grid", tmp_path / "l.nc"],
             "the track needs a layer at or below -20 m: add one to --grid (a user grid "
             "cannot be re-layered with --layers)", [out])


@pytest.mark.parametrize("layers", ["0,1000", "0,500,1000", "0,1000,2000"])
def test_layers_other_than_a_user_grid_s_are_refused_by_name(tmp_path, capsys, layers):
    """Issue 19: --layers with another count of heights than the --grid's ended in NumPy's
    "operands could not be broadcast together with shapes (2,) (3,)"."""
    lat, lon = np.linspace(0.0, 1.0, 11), np.linspace(10.0, 11.0, 11)
    values = np.zeros((2, 2, 11, 11))
    grid = tmp_path / "l.nc"
    dov.LayeredGrid.from_arrays(lat, lon, [0.0, 500.0], values).to_netcdf(grid)
    track = tmp_path / "t.csv"
    write_track_csv(track, {"lat": [0.5], "lon": [10.5], "h": [20.0]})
    out = tmp_path / "o.csv"
    _refused(capsys, ["dov", "--track", track, "--out", out, "--grid", grid, "--layers", layers],
             f"--layers {layers} differs from the heights of --grid {str(grid)!r} (0, 500 m); "
             "a user grid cannot be re-layered: leave --layers out", [out])


@pytest.mark.long
def test_the_advised_layers_take_a_submarine_track_in(tmp_path, capsys):
    """The --layers the refusal names, written as a user would (a space, not '='), run and
    give the degree-360 model's deflection at -50 m (synthesised there, not extrapolated)."""
    lat, lon, h = np.array([34.0, 34.2]), np.array([108.5, 108.7]), np.array([-50.0, -20.0])
    track = tmp_path / "sub.csv"
    write_track_csv(track, {"lat": lat, "lon": lon, "h": h})
    out = tmp_path / "o.csv"
    assert main(["dov", "--track", str(track), "--out", str(out)]) == 2
    layers = re.search(r"--layers=(\S+) ", capsys.readouterr().err).group(1)
    assert layers == "-50,0,10000,20000"
    assert main(["dov", "--track", str(track), "--out", str(out), "--layers", layers]) == 0
    res = read_track_csv(out, required=("lat", "lon", "h", "xi", "eta"))
    xi, eta = harmonics.deflection(datasets.load("qinling")["coefficients"], lat, lon, h)
    np.testing.assert_allclose(res["xi"], xi, atol=0.02)
    np.testing.assert_allclose(res["eta"], eta, atol=0.02)


def test_a_list_starting_with_a_minus_is_the_option_s_value():
    # argparse took "-50,0" for an unknown option; joined before parsing, without a
    # private attribute of argparse
    assert joined_negative_lists(["dov", "--layers", "-50,0,1e4", "--force"]) == [
        "dov", "--layers=-50,0,1e4", "--force"]
    same = ["dov", "--layers=-50,0", "--x", "-5", "--y", "-a,b", "-50,0"]
    assert joined_negative_lists(same) == same  # joined already; a number; not a list
