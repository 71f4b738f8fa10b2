"""Magnetic maps: IGRF total intensity, polynomial anomaly, NetCDF input."""

import datetime
import sys

import numpy as np
import pytest

from jaxgrav.fields import magnetic

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
    from dataclasses import replace

    replace(a, units="mGal").to_netcdf(bad)
    with pytest.raises(ValueError, match="expected nT"):
        magnetic.read_anomaly(bad)
