"""``jaxgrav match`` on a magnetic track (paper B): a CSV with a ``magnetic`` column in nT.

The map and track are those of ``tests/test_magnetic.py`` (same sizes and settings, so
the matcher compiled there is reused when both modules run in one session).
"""

import json

import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.cli import main
from jaxgrav.fields import magnetic
from jaxgrav.match import match_track, shifted_tracks
from jaxgrav.sim import DEG_ARC_M, Track, track_error_m
from jaxgrav.tracks import read_track_csv, write_track_csv

pytest.importorskip("xarray")


@pytest.mark.long
def test_match_magnetic_track_entropy_iccp(tmp_path, capsys):
    magnetic.magnetic_map((39.0, 39.5, 115.0, 115.5), 0.01,
                          main_field=False).anomaly.to_netcdf(tmp_path / "m.nc")
    # truth: 20 fixes 600 m apart heading north-east; INS 2.9 km off and turned 1.5°
    k = np.arange(20)
    lat, lon = 39.15 + 0.00382 * k, 115.15 + 0.00492 * k
    ins_lat, ins_lon = (np.asarray(a) for a in shifted_tracks(
        jnp.asarray(lat), jnp.asarray(lon), 2500.0, -1500.0, np.deg2rad(1.5)))
    grid = magnetic.read_anomaly(tmp_path / "m.nc")
    z = np.asarray(grid.sample(lat, lon, "bicubic"))
    z = z + 10.0 * np.random.default_rng(0).standard_normal(z.size)  # nT
    write_track_csv(tmp_path / "t.csv", {"t": 60.0 * k, "lat": ins_lat, "lon": ins_lon,
                                         "magnetic": z})
    out = tmp_path / "r.json"
    opts = ["--drift-radius", "0.035", "--noise", "10", "--max-rotation", "2",
            "--entropy-half-size", "8"]
    assert main(["match", "--method", "entropy+iccp", "--map", str(tmp_path / "m.nc"),
                 "--track", str(tmp_path / "t.csv"), "--out", str(out), *opts]) == 0
    r = json.loads(out.read_text())
    assert r["field"] == "magnetic" and r["method"] == "entropy+iccp"
    assert len(r["lat"]) == len(r["lon"]) == 20
    assert np.all(np.isfinite(r["lat"])) and np.all(np.isfinite(r["lon"]))
    truth = Track(lat, lat, lon, lat, lat)
    ins_err = float(track_error_m(ins_lat, ins_lon, truth))
    assert ins_err > 2000.0
    assert float(track_error_m(np.array(r["lat"]), np.array(r["lon"]), truth)) < 0.25 * ins_err
    # the CLI passes the nT readings and options through unchanged: same as the library
    cols = read_track_csv(tmp_path / "t.csv")
    lib = match_track(grid, cols["lat"], cols["lon"], cols["magnetic"], method="entropy+iccp",
                      drift_radius_m=0.035 * DEG_ARC_M, noise=10.0, max_rotation_deg=2.0,
                      entropy_half_size=8, warn=False)
    np.testing.assert_allclose(r["lat"], np.asarray(lib.lat), rtol=0, atol=1e-12)
    np.testing.assert_allclose(r["lon"], np.asarray(lib.lon), rtol=0, atol=1e-12)
    # a magnetic track cannot go to the gravity matchers
    code = main(["match", "--method", "dense", "--map", str(tmp_path / "m.nc"),
                 "--track", str(tmp_path / "t.csv"), "--out", str(tmp_path / "d.json")])
    assert code == 2 and not (tmp_path / "d.json").exists()
    assert "use entropy, iccp or entropy+iccp for a magnetic track" in capsys.readouterr().err
