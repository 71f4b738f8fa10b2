"""Tests of jaxgrav.dov: layered DOV grids and their interpolation."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from jaxgrav import dov
from jaxgrav.dov import LayeredGrid
from jaxgrav.dov.interpolate import interpolate_compiled
from jaxgrav.fields.pointmass import PointMasses, deflection

LAT = np.linspace(30.0, 31.1, 12)
LON = np.linspace(100.0, 101.3, 14)
HEIGHTS = np.array([0.0, 4000.0, 10000.0, 20000.0])


def _layers(fn, heights=HEIGHTS):
    la, lo = np.meshgrid(LAT, LON, indexing="ij")
    vals = np.stack([np.stack([fn(la, lo, hh), 2.0 * fn(la, lo, hh) - 1.0]) for hh in heights])
    return LayeredGrid.from_arrays(LAT, LON, heights, vals)


def _points(n=40, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(LAT[0], LAT[-1], n), rng.uniform(LON[0], LON[-1], n),
            rng.uniform(HEIGHTS[0], HEIGHTS[-1], n))


def _smooth(la, lo, hh):
    return np.sin(3 * la) * np.cos(2 * lo) * np.exp(-hh / 15000.0) + 0.1 * la * hh / 1e4


def test_bilinear_linear_equals_scipy_trilinear():
    layers = _layers(_smooth)
    lat, lon, h = _points(200)
    out = dov.interpolate(layers, lat, lon, h, "bilinear-linear")
    assert out.values.shape == (2, 200) and bool(out.inside.all())
    for c in range(2):
        ref = RegularGridInterpolator((HEIGHTS, LAT, LON), np.asarray(layers.values[:, c]))
        np.testing.assert_allclose(out.values[c], ref(np.c_[h, lat, lon]), rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("method", "deg_h", "deg_v"),
    [("bilinear-linear", 1, 1), ("bicubic-linear", 3, 1),
     ("bilinear-lagrange", 1, 2), ("bicubic-lagrange", 3, 2)],
)
def test_exact_on_polynomials_of_the_method_order(method, deg_h, deg_v):
    rng = np.random.default_rng(1)
    coef = rng.normal(size=(deg_h + 1, deg_h + 1, deg_v + 1))

    def poly(la, lo, hh):
        x, y, z = la - 30.5, lo - 100.6, hh / 1e4
        return sum(coef[i, j, k] * x**i * y**j * z**k for i in range(deg_h + 1)
                   for j in range(deg_h + 1) for k in range(deg_v + 1))

    layers = _layers(poly)
    lat, lon, h = _points(60)
    out = dov.interpolate(layers, lat, lon, h, method)
    np.testing.assert_allclose(out.values[0], poly(lat, lon, h), rtol=0, atol=1e-9)
    np.testing.assert_allclose(out.values[1], 2 * poly(lat, lon, h) - 1, rtol=0, atol=1e-9)


@pytest.mark.long
def test_harmonic_vertical_beats_linear_on_a_harmonic_model():
    masses = PointMasses.create(lat=[33.4, 33.7], lon=[108.3, 108.6], depth=[40e3, 60e3],
                                mass=[2e15, -3e15])
    lat = np.linspace(33.0, 34.0, 41)
    lon = np.linspace(108.0, 109.0, 41)
    layers = LayeredGrid.from_point_masses(masses, lat, lon, [0.0, 10000.0, 20000.0])
    rng = np.random.default_rng(2)
    la, lo = rng.uniform(33.2, 33.8, 30), rng.uniform(108.2, 108.8, 30)
    hh = rng.uniform(500.0, 19500.0, 30)
    ref = deflection(masses, la, lo, hh)
    truth = np.stack([np.asarray(ref.xi), np.asarray(ref.eta)])
    err = {m: np.sqrt(np.mean((np.asarray(dov.interpolate(layers, la, lo, hh, m).values)
                               - truth) ** 2)) for m in ("bicubic-linear", "bicubic-harmonic")}
    assert err["bicubic-harmonic"] < 0.2 * err["bicubic-linear"], err


@pytest.mark.long
def test_grad_forward_reverse_finite_differences():
    layers = _layers(_smooth)

    def f0(p, values, heights):
        lay = LayeredGrid(values, heights, layers.lat0, layers.dlat, layers.lon0, layers.dlon)
        out = dov.make_interpolator(lay, "bicubic-harmonic")(p[0], p[1], p[2])[0]
        return out[0] + 0.5 * out[1]

    # two compiled programs: reverse mode in all three arguments (its value also gives
    # the finite differences) and forward mode
    value_and_grad = jax.jit(jax.value_and_grad(f0, argnums=(0, 1, 2)))

    def f(*a):
        return value_and_grad(*a)[0]

    p = jnp.array([30.47, 100.61, 7300.0])
    args = (p, layers.values, layers.heights)
    rev_p, gv, rev_h = value_and_grad(*args)[1]
    fwds = jax.jit(jax.jacfwd(f0, argnums=(0, 2)))(*args)
    for argnum, rev, fwd in zip((0, 2), (rev_p, rev_h), fwds, strict=True):
        np.testing.assert_allclose(rev, fwd, rtol=1e-9, atol=1e-14)
        x = args[argnum]
        for i in range(x.shape[0]):
            step = 1e-6 * max(1.0, abs(float(x[i])))
            xp, xm = x.at[i].add(step), x.at[i].add(-step)
            a_p = list(args)
            a_m = list(args)
            a_p[argnum], a_m[argnum] = xp, xm
            fd = (f(*a_p) - f(*a_m)) / (2 * step)
            np.testing.assert_allclose(rev[i], fd, rtol=1e-5, atol=1e-9)
    # linear in values: FD exact up to rounding
    dv = jnp.zeros_like(layers.values).at[1, 0, 5, 6].set(1.0)
    fd = (f(p, layers.values + dv, layers.heights) - f(p, layers.values - dv, layers.heights)) / 2
    np.testing.assert_allclose(jnp.sum(gv * dv), fd, rtol=1e-9)


@pytest.mark.long
def test_jit_no_retrace_and_vmap_equals_loop():
    layers = _layers(_smooth)
    lat, lon, h = _points(16, seed=3)
    dov.interpolate(layers, lat, lon, h, "bicubic-lagrange")
    size = interpolate_compiled._cache_size()
    lat2, lon2, h2 = _points(16, seed=4)
    lay2 = dataclass_replace(layers, heights=layers.heights + 1.0)
    dov.interpolate(lay2, lat2, lon2, h2 + 10.0, "bicubic-lagrange")
    assert interpolate_compiled._cache_size() == size
    # prepared in one program (op by op: ~2 s)
    prepared = jax.jit(dov.make_interpolator, static_argnames="method")(layers,
                                                                        "bicubic-lagrange")
    f = jax.jit(prepared)
    batched = jax.vmap(f)(jnp.asarray(lat), jnp.asarray(lon), jnp.asarray(h))[0]
    loop = np.stack([np.asarray(f(a, b, c)[0]) for a, b, c in zip(lat, lon, h, strict=True)])
    np.testing.assert_allclose(batched, loop, rtol=1e-12, atol=1e-12)


def test_prepared_layers_are_a_pytree_value():
    """make_interpolator's result passes through jit as data: a new map, no retrace."""
    layers = _layers(_smooth)
    lat, lon, h = (jnp.asarray(x) for x in _points(30, seed=5))
    # the preparation as one program for both maps (op by op it took 2.9 s)
    make_interpolator = jax.jit(dov.make_interpolator, static_argnames="method")
    prepared = make_interpolator(layers)
    assert isinstance(prepared, dov.PreparedLayers) and prepared.method == dov.DEFAULT_METHOD
    calls = []

    @jax.jit
    def f(p, la, lo, hh):
        calls.append(1)
        return p(la, lo, hh)

    out = f(prepared, lat, lon, h)
    ref = dov.interpolate(layers, lat, lon, h)
    np.testing.assert_allclose(out.values, ref.values, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out.inside, ref.inside)
    other = _layers(lambda la, lo, hh: np.cos(la) * np.sin(lo) * (1.0 + hh / 1e4))
    out2 = f(make_interpolator(other), lat, lon, h)
    assert len(calls) == 1  # same shapes and method: no retrace
    np.testing.assert_allclose(out2.values, dov.interpolate(other, lat, lon, h).values,
                               rtol=0, atol=1e-12)
    leaves = jax.tree_util.tree_leaves(prepared)
    assert any(leaf.shape == prepared.coefficients.shape for leaf in leaves)


def dataclass_replace(obj, **kw):
    return dataclasses.replace(obj, **kw)


def test_scan_track_equals_vectorised():
    layers = _layers(_smooth)
    lat = np.linspace(30.1, 31.0, 25)
    lon = np.linspace(100.2, 101.1, 25)
    h = np.linspace(100.0, 19000.0, 25)
    vals, inside, changes = dov.scan_track(layers, lat, lon, h, "bicubic-harmonic")
    ref = dov.interpolate(layers, lat, lon, h, "bicubic-harmonic")
    np.testing.assert_allclose(vals, ref.values, rtol=1e-12, atol=1e-12)
    assert bool(inside.all()) and 1 <= int(changes) <= 25


def test_out_of_range_is_nan_or_error_never_clamped():
    layers = _layers(_smooth)
    lat = np.array([30.5, 29.0, 30.5, 30.5])
    lon = np.array([100.5, 100.5, 100.5, 100.5])
    h = np.array([5000.0, 5000.0, -1.0, 20001.0])
    out = dov.interpolate(layers, lat, lon, h, "bilinear-linear")
    assert out.inside.tolist() == [True, False, False, False]
    assert np.isfinite(out.values[:, 0]).all() and np.isnan(out.values[:, 1:]).all()
    with pytest.raises(ValueError, match=r"h=-1.0 m\) is outside"):
        dov.interpolate(layers, lat[[0, 2]], lon[:2], h[[0, 2]], strict=True)
    with pytest.raises(ValueError, match=r"lat=29\.0"):
        dov.interpolate(layers, lat[:2], lon[:2], h[:2], strict=True)
    g = jax.jit(jax.grad(lambda x: jnp.nansum(dov.make_interpolator(layers)(x, lon, h)[0])))(
        jnp.asarray(lat))
    assert np.isfinite(g).all()


def test_bad_input_errors():
    layers = _layers(_smooth)
    good = np.zeros((3, 2, LAT.size, LON.size))
    with pytest.raises(ValueError, match="method must be one of"):
        dov.interpolate(layers, 30.5, 100.5, 10.0, "nearest")
    with pytest.raises(ValueError, match="strictly ascending"):
        LayeredGrid.from_arrays(LAT, LON, [0.0, 2.0, 1.0], good)
    with pytest.raises(ValueError, match=r"shape \(layers, channels, ny, nx\)"):
        LayeredGrid.from_arrays(LAT, LON, [0.0, 1.0], good)
    bad = good.copy()
    bad[1, 0, 2, 2] = np.nan
    with pytest.raises(ValueError, match="values must be finite"):
        LayeredGrid.from_arrays(LAT, LON, [0.0, 1.0, 2.0], bad)
    with pytest.raises(ValueError, match="matching"):
        dov.interpolate(layers, [30.5, 30.6], [100.5, 100.6, 100.7], 10.0)
    with pytest.raises(ValueError, match="lat must be a latitude"):
        dov.interpolate(layers, 95.0, 100.5, 10.0)
    with pytest.raises(ValueError, match="h must be finite"):
        dov.interpolate(layers, 30.5, 100.5, np.nan)
    two = LayeredGrid.from_arrays(LAT, LON, [0.0, 1.0], good[:2])
    with pytest.raises(ValueError, match="needs at least 3 layers"):
        dov.interpolate(two, 30.5, 100.5, 0.5, "bicubic-lagrange")


def test_netcdf_round_trip_and_no_clobber(tmp_path):
    layers = _layers(_smooth)
    p = tmp_path / "layers.nc"
    layers.to_netcdf(p)
    back = LayeredGrid.from_netcdf(p)
    assert back.channels == ("xi", "eta") and back.units == "arcsec"
    np.testing.assert_allclose(back.values, layers.values)
    np.testing.assert_allclose(back.heights, HEIGHTS)
    assert (back.lat0, back.dlat, back.lon0, back.dlon) == pytest.approx(
        (layers.lat0, layers.dlat, layers.lon0, layers.dlon))
    with pytest.raises(FileExistsError):
        layers.to_netcdf(p)
    layers.to_netcdf(p, force=True)
    with pytest.raises(FileNotFoundError):
        LayeredGrid.from_netcdf(tmp_path / "missing.nc")


def test_paper_layers_and_builders():
    paper = dov.paper_c_layers()
    assert paper.values.shape == (3, 2, 181, 181) and paper.dlat == pytest.approx(0.05)
    np.testing.assert_allclose(paper.heights, [0.0, 1e4, 2e4])
    small = dov.paper_c_layers([0.0, 5000.0], spacing_arcmin=60.0, nmax=20)
    assert small.values.shape == (2, 2, 10, 10)
    with pytest.raises(ValueError, match="spacing_arcmin"):
        dov.paper_c_layers([0.0, 5000.0], spacing_arcmin=7.0)
    masses = PointMasses.create(lat=[30.5], lon=[100.6], depth=[5e3], mass=[1e14])
    pm = LayeredGrid.from_point_masses(masses, LAT[:5], LON[:6], [0.0, 1000.0])
    ref = deflection(masses, LAT[2], LON[3], 1000.0)
    np.testing.assert_allclose(pm.values[1, :, 2, 3], [ref.xi, ref.eta], rtol=1e-12)


def _wave_layers(heights, wavelength=40e3):
    """One harmonic component ``cos(k y) exp(−k h)`` near the equator (k·Δ known)."""
    lat = np.linspace(0.0, 1.0, 61)
    lon = np.linspace(10.0, 11.0, 61)
    k = 2 * np.pi / wavelength
    y = np.deg2rad(lat)[:, None] * 6378136.3 + 0.0 * lon[None, :]
    vals = np.stack([np.stack([np.cos(k * y) * np.exp(-k * hh)] * 2) for hh in heights])
    return LayeredGrid.from_arrays(lat, lon, heights, vals), k


def test_harmonic_gap_ratio_is_k_times_the_gap():
    heights = np.array([0.0, 5000.0, 30000.0])
    layers, k = _wave_layers(heights)
    np.testing.assert_allclose(dov.harmonic_gap_ratio(layers), k * np.diff(heights), rtol=0.05)
    # the shipped paper-C layers (10 km apart) are well inside the trusted range
    assert np.all(np.asarray(dov.harmonic_gap_ratio(dov.paper_c_layers())) < 0.5)


@pytest.mark.long
def test_dov_command_warns_when_a_gap_is_too_wide_for_harmonic(tmp_path, capsys):
    from jaxgrav.cli import main
    from jaxgrav.tracks import write_track_csv

    heights = np.array([0.0, 2000.0, 40000.0])  # k·Δ 0.31 and 6.0 at a 40 km wavelength
    layers, k = _wave_layers(heights)
    layers.to_netcdf(tmp_path / "layers.nc")
    write_track_csv(tmp_path / "low.csv", {"lat": [0.3, 0.6], "lon": [10.4, 10.6],
                                           "h": [500.0, 1500.0]})
    write_track_csv(tmp_path / "high.csv", {"lat": [0.3, 0.6], "lon": [10.4, 10.6],
                                            "h": [500.0, 20000.0]})
    args = ["dov", "--grid", str(tmp_path / "layers.nc"), "--track"]
    assert main([*args, str(tmp_path / "low.csv"), "--out", str(tmp_path / "a.csv")]) == 0
    assert "warning" not in capsys.readouterr().err
    assert main([*args, str(tmp_path / "high.csv"), "--out", str(tmp_path / "b.csv")]) == 0
    err = capsys.readouterr().err
    assert "1 between 2000 and 40000 m (k*gap = 6.3)" in err, err
    assert "use a --grid with layers at most about 12" in err  # not --layers: refused there
    assert "--method bicubic-linear" in err
    # the warning is deserved: the harmonic value there is far off the exact field
    out = dov.interpolate(layers, 0.6, 10.6, 20000.0).values[0]
    exact = np.cos(k * np.deg2rad(0.6) * 6378136.3) * np.exp(-k * 20000.0)
    assert abs(float(out) - exact) > 0.3
    assert main([*args, str(tmp_path / "high.csv"), "--out", str(tmp_path / "c.csv"),
                 "--method", "bicubic-linear"]) == 0
    assert "warning" not in capsys.readouterr().err
