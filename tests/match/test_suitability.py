"""Suitability maps: the CRLB against a brute-force NumPy information matrix, the
plane-map limits, off-map segments, descriptors against NumPy, bad settings, the CLI."""

import numpy as np
import pytest
import xarray as xr

from jaxgrav.cli import main
from jaxgrav.constants import DEG
from jaxgrav.datasets import load_map
from jaxgrav.geodesy import meridian_radius, prime_vertical_radius
from jaxgrav.grid import Grid
from jaxgrav.match.suitability import DESCRIPTORS, suitability


@pytest.fixture(scope="module")
def small():
    """A 40 × 40 window of the shipped 2.5′ ryukyu map."""
    g = load_map("ryukyu")
    v = np.asarray(g.values)[100:140, 120:160]
    return Grid(v, lat0=float(g.lat[100]), dlat=g.dlat, lon0=float(g.lon[120]), dlon=g.dlon,
                name=g.name, units=g.units)


def _brute_force(grid, iy, ix, heading, n, spacing, noise, sig, length):
    """The CRLB by NumPy: central-difference gradients of the map, explicit Σ⁻¹."""
    lat0, lon0 = float(grid.lat[iy]), float(grid.lon[ix])
    k = np.arange(n) * spacing
    north, east = k * np.cos(np.radians(heading)), k * np.sin(np.radians(heading))
    m0 = float(meridian_radius(lat0))
    e0 = float(prime_vertical_radius(lat0)) * np.cos(lat0 * DEG)
    lat, lon = lat0 + north / m0 / DEG, lon0 + east / e0 / DEG
    h = 1e-6  # degrees
    d_lat = (np.asarray(grid.sample(lat + h, lon, "bicubic"))
             - np.asarray(grid.sample(lat - h, lon, "bicubic"))) / 2 / h
    d_lon = (np.asarray(grid.sample(lat, lon + h, "bicubic"))
             - np.asarray(grid.sample(lat, lon - h, "bicubic"))) / 2 / h
    m = np.asarray(meridian_radius(lat))
    e = np.asarray(prime_vertical_radius(lat)) * np.cos(lat * DEG)
    g = np.stack([d_lat / (m * DEG), d_lon / (e * DEG)], -1)
    d = np.hypot(north[:, None] - north[None], east[:, None] - east[None])
    cov = noise**2 * np.eye(n) + sig**2 * (1 + d / length) * np.exp(-d / length)
    ci = np.linalg.inv(cov)
    one = np.ones(n)
    info = g.T @ ci @ g - np.outer(g.T @ ci @ one, one @ ci @ g) / (one @ ci @ one)
    return np.linalg.inv(info)


@pytest.mark.parametrize(("heading", "sig"), [(45.0, 0.0), (120.0, 3.0)])
@pytest.mark.long
def test_crlb_equals_a_numpy_information_matrix(small, heading, sig):
    s = suitability(small, heading_deg=heading, n_fixes=12, spacing_m=1500.0, noise_mgal=1.0,
                    map_error_mgal=sig, map_error_length_m=10e3)
    for iy, ix in ((10, 10), (15, 20), (22, 8)):
        ref = _brute_force(small, iy, ix, heading, 12, 1500.0, 1.0, sig, 10e3)
        np.testing.assert_allclose(s.sigma_north_m[iy, ix], np.sqrt(ref[0, 0]), rtol=1e-4)
        np.testing.assert_allclose(s.sigma_east_m[iy, ix], np.sqrt(ref[1, 1]), rtol=1e-4)
        np.testing.assert_allclose(s.precision_m[iy, ix], np.sqrt(np.trace(ref)), rtol=1e-4)
        np.testing.assert_allclose(s.corr[iy, ix], ref[0, 1] / np.sqrt(ref[0, 0] * ref[1, 1]),
                                   rtol=1e-3, atol=1e-4)


@pytest.mark.long
def test_map_error_and_noise_make_the_bound_worse(small):
    a = suitability(small, n_fixes=12, spacing_m=1500.0)
    b = suitability(small, n_fixes=12, spacing_m=1500.0, map_error_mgal=3.0)
    c = suitability(small, n_fixes=12, spacing_m=1500.0, noise_mgal=2.0)
    ok = np.isfinite(a.precision_m)
    assert np.all(b.precision_m[ok] > a.precision_m[ok])
    np.testing.assert_allclose(c.precision_m[ok], 2 * a.precision_m[ok], rtol=1e-9)


@pytest.mark.long
def test_plane_map_offset_is_confounded_with_a_free_bias():
    lat = np.arange(30) * 0.05
    lon = np.arange(30) * 0.05
    v = 40.0 * lat[:, None] + 10.0 * lon[None, :]
    g = Grid(v, lat0=20.0, dlat=0.05, lon0=120.0, dlon=0.05, name="plane", units="mGal")
    free = suitability(g, n_fixes=10, spacing_m=1000.0)
    # a constant gradient: no information (inf, or ~1e11 m from rounding of the radii)
    assert np.all(free.precision_m[:5, :5] > 1e6)
    known = suitability(g, n_fixes=10, spacing_m=1000.0, bias_prior_sigma=0.0)
    # a known bias: information along the gradient only (σ_n / (|∇| √N)), none across it
    assert np.all(known.precision_m[:5, :5] > 1e6)
    sn, se, c = (a[2, 2] for a in (known.sigma_north_m, known.sigma_east_m, known.corr))
    cov = np.array([[sn**2, c * sn * se], [c * sn * se, se**2]])
    lat = 20.0 + 2 * 0.05
    grad = np.hypot(40.0 / (float(meridian_radius(lat)) * DEG),
                    10.0 / (float(prime_vertical_radius(lat)) * np.cos(lat * DEG) * DEG))
    np.testing.assert_allclose(np.sqrt(np.linalg.eigvalsh(cov)[0]), 1.0 / (grad * np.sqrt(10)),
                               rtol=0.02)


def test_segments_leaving_the_map_are_nan(small):
    s = suitability(small, heading_deg=0.0, n_fixes=10, spacing_m=2000.0)
    ny = s.precision_m.shape[0]
    reach = int(np.ceil(9 * 2000.0 / (small.dlat * DEG * 6.37e6)))
    assert np.all(np.isnan(s.precision_m[ny - reach + 1:, :]))
    assert np.all(np.isfinite(s.precision_m[: ny - reach - 1, :]))


@pytest.mark.long
def test_descriptors_against_numpy(small):
    s = suitability(small, n_fixes=8, spacing_m=1000.0, window_cells=5)
    z = np.asarray(small.values, float)
    iy, ix = 20, 17
    win = z[iy - 2:iy + 3, ix - 2:ix + 3]
    np.testing.assert_allclose(s.descriptors["std"][iy, ix], win.std(), rtol=1e-9)
    rough = 0.5 * (np.abs(np.diff(z, axis=0))[iy - 3:iy + 2, ix - 2:ix + 3].mean()
                   + np.abs(np.diff(z, axis=1))[iy - 2:iy + 3, ix - 3:ix + 2].mean())
    np.testing.assert_allclose(s.descriptors["roughness"][iy, ix], rough, rtol=1e-9)
    assert set(s.descriptors) == set(DESCRIPTORS)
    for k in DESCRIPTORS:
        assert np.isnan(s.descriptors[k][0, 0])  # the window leaves the map
    assert 0 <= np.nanmin(s.descriptors["entropy"]) and np.nanmax(s.descriptors["entropy"]) <= (
        np.log(16) + 1e-9)


@pytest.mark.parametrize(("kwargs", "message"), [
    (dict(n_fixes=1), "n_fixes must be an integer >= 2"),
    (dict(spacing_m=0.0), "spacing_m must be a finite number > 0"),
    (dict(noise_mgal=float("nan")), "noise_mgal must be a finite number > 0"),
    (dict(map_error_mgal=-1.0), "map_error_mgal must be a finite number >= 0"),
    (dict(window_cells=4), "window_cells must be an odd integer >= 3"),
    (dict(window_cells=99), "window_cells=99 is larger than the map"),
])
def test_bad_settings(small, kwargs, message):
    with pytest.raises(ValueError, match=message):
        suitability(small, **kwargs)


@pytest.mark.long
def test_cli_writes_netcdf_and_png_and_refuses_overwrite(tmp_path, capsys):
    out = tmp_path / "suit.nc"
    assert main(["suitability", "--map", "ryukyu", "--out", str(out), "--fixes", "10",
                 "--spacing", "2000", "--map-error", "3"]) == 0
    text = capsys.readouterr().out
    assert f"wrote {out} and {out.with_suffix('.png')}" in text
    with xr.open_dataset(out) as ds:
        assert set(ds.data_vars) == {"precision_m", "sigma_north_m", "sigma_east_m", "corr",
                                     "status", *DESCRIPTORS}
        # the complete map places every segment that stays on it
        assert set(np.unique(ds["status"])) == {0, 1}
        assert ds["precision_m"].attrs["units"] == "m" and ds.attrs["map_error_mgal"] == 3.0
        assert ds["precision_m"].dims == ("lat", "lon")
    assert out.with_suffix(".png").stat().st_size > 10_000
    assert main(["suitability", "--map", "ryukyu", "--out", str(out)]) == 2
    assert "exist; pass --force" in capsys.readouterr().err  # the NetCDF and its PNG
    assert main(["suitability", "--map", "ryukyu", "--out", str(tmp_path / "b.nc"),
                 "--fixes", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--fixes must be an integer >= 2" in err
    assert not (tmp_path / "b.nc").exists()
