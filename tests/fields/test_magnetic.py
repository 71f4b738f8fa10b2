"""Magnetic maps: IGRF total intensity, polynomial anomaly, NetCDF input."""

import datetime
import sys
from dataclasses import replace

import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.fields import magnetic
from jaxgrav.match import match_track, shifted_tracks
from jaxgrav.sim import DEG_ARC_M, Track, track_error_m

LAT = 39.0 + 0.1 * np.arange(20)
LON = 115.0 + 0.1 * np.arange(20)


def test_polynomial_anomaly_range_seed_and_shape():
    a = magnetic.polynomial_anomaly(LAT, LON, seed=3)
    v = np.asarray(a.values)
    assert v.shape == (20, 20)
    assert a.units == "nT"
    assert v.min() == pytest.approx(-1296.8, abs=1e-3)
    assert v.max() == pytest.approx(1620.0, abs=1e-3)
    again = magnetic.polynomial_anomaly(LAT, LON, seed=3)
    np.testing.assert_array_equal(v, np.asarray(again.values))
    assert not np.allclose(v, np.asarray(magnetic.polynomial_anomaly(LAT, LON, seed=4).values))
    # degree 1 is a plane: every 2x2 cell has zero mixed second difference
    plane = np.asarray(magnetic.polynomial_anomaly(LAT, LON, degree=1, value_range=(0, 1)).values,
                       float)
    np.testing.assert_allclose(np.diff(np.diff(plane, axis=0), axis=1), 0.0, atol=1e-5)
    with pytest.raises(ValueError, match="value_range"):
        magnetic.polynomial_anomaly(LAT, LON, value_range=(5.0, 1.0))
    with pytest.raises(ValueError, match="degree"):
        magnetic.polynomial_anomaly(LAT, LON, degree=0)


def test_igrf_total_intensity_matches_ppigrf():
    ppigrf = pytest.importorskip("ppigrf")
    date = datetime.datetime(2020, 1, 1)
    f = magnetic.igrf_total_intensity(LAT[:3], LON[:4], height_m=1000.0, date=date)
    be, bn, bu = ppigrf.igrf(LON[1], LAT[2], 1.0, date)
    ref = float(np.sqrt(be**2 + bn**2 + bu**2).squeeze())
    assert float(f.values[2, 1]) == pytest.approx(ref, rel=1e-6)
    assert 50_000 < ref < 60_000  # Beijing area, about 54 000 nT


def test_magnetic_map_parts_add_up():
    pytest.importorskip("ppigrf")
    m = magnetic.magnetic_map(step=0.1, map_noise_nt=5.0)
    assert m.total.values.shape == (20, 20)
    assert m.total.lat0 == 39.0 and m.total.lon0 == 115.0
    np.testing.assert_allclose(np.asarray(m.total.values),
                               np.asarray(m.main.values) + np.asarray(m.anomaly.values), rtol=1e-6)
    bare = magnetic.magnetic_map(step=0.1, main_field=False)
    np.testing.assert_allclose(np.asarray(bare.total.values), np.asarray(bare.anomaly.values))
    with pytest.raises(ValueError, match="region"):
        magnetic.magnetic_map(region=(41, 39, 115, 117), main_field=False)
    with pytest.raises(ValueError, match="step"):
        magnetic.magnetic_map(step=0.0, main_field=False)


def test_missing_ppigrf_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "ppigrf", None)
    with pytest.raises(ImportError, match=r"jaxgrav\[mag\]"):
        magnetic.igrf_total_intensity(LAT, LON)


def test_read_anomaly_netcdf(tmp_path):
    pytest.importorskip("xarray")
    a = magnetic.polynomial_anomaly(LAT, LON, seed=1)
    path = tmp_path / "anom.nc"
    a.to_netcdf(path)
    back = magnetic.read_anomaly(path)
    np.testing.assert_allclose(np.asarray(back.values), np.asarray(a.values))
    bad = tmp_path / "mgal.nc"
    replace(a, units="mGal").to_netcdf(bad)
    with pytest.raises(ValueError, match="expected nT"):
        magnetic.read_anomaly(bad)



# ---------------------------------------------------------------------- matching in nT
# A small paper-B-like map (0.5° square at 0.01°, anomaly only: no ppigrf needed), read
# back through the NetCDF reader. tests/cli/test_cli_magnetic.py builds the same map and
# track and matches through the CLI with the same settings: one compile per session.
MAG_REGION = (39.0, 39.5, 115.0, 115.5)
MAG_NOISE_NT = 10.0  # paper B's reading noise
MAG_DRIFT_DEG = 0.035  # largest INS offset (~0.03°) + margin, as examples/paper_b_entropy_iccp.py


def magnetic_track(grid, d_north_m, d_east_m, rot_deg, seed):
    """Truth: 20 fixes 600 m apart heading north-east; INS: truth shifted and turned."""
    k = np.arange(20)
    lat = 39.15 + 0.00382 * k
    lon = 115.15 + 0.00492 * k
    ins_lat, ins_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), d_north_m, d_east_m,
                                      np.deg2rad(rot_deg))
    z = np.asarray(grid.sample(lat, lon, "bicubic"))
    z = z + MAG_NOISE_NT * np.random.default_rng(seed).standard_normal(z.size)
    return lat, lon, np.asarray(ins_lat), np.asarray(ins_lon), z


@pytest.mark.long
def test_entropy_iccp_on_a_magnetic_map_beats_the_ins(tmp_path):
    pytest.importorskip("xarray")

    magnetic.magnetic_map(MAG_REGION, 0.01, main_field=False).anomaly.to_netcdf(tmp_path / "m.nc")
    grid = magnetic.read_anomaly(tmp_path / "m.nc")
    assert grid.units == "nT" and grid.values.shape == (50, 50)
    # INS offset by ~0.02-0.03° and turned by 1.5° (paper B's errors), 10 nT noise
    for d_n, d_e, rot, seed in ((2500.0, -1500.0, 1.5, 0), (-2000.0, -2000.0, -1.5, 1)):
        lat, lon, ins_lat, ins_lon, z = magnetic_track(grid, d_n, d_e, rot, seed)
        res = match_track(grid, ins_lat, ins_lon, z, method="entropy+iccp",
                          drift_radius_m=MAG_DRIFT_DEG * DEG_ARC_M, noise=MAG_NOISE_NT,
                          max_rotation_deg=2.0, entropy_half_size=8, warn=False)
        truth = Track(lat, lat, lon, lat, lat)
        ins_err = float(track_error_m(ins_lat, ins_lon, truth))
        assert ins_err > 2000.0
        assert float(track_error_m(res.lat, res.lon, truth)) < 0.25 * ins_err
        assert not int(res.status) & (1 | 32)  # finite, and the coarse stage beat the INS
