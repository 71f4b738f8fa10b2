"""Simulation: tracks, drift, readings, scenarios; track CSV files."""

import dataclasses

import jax
import numpy as np
import pytest
from scipy import stats

import jaxgrav as jg
from jaxgrav import datasets, sim
from jaxgrav.constants import KNOT
from jaxgrav.scenarios import MatchingScenario, matching_scenario
from jaxgrav.sim.drift import drift_sigma
from jaxgrav.tracks import read_track_csv, write_track_csv


def test_straight_track_against_geodesy():
    tr = sim.straight_track(30.0, 130.0, 10 * KNOT, 10 * KNOT, 31, 120.0)
    assert tr.lat.shape == (31,) and float(tr.t[-1]) == 3600.0
    # one hour at 10 kn north: 18520 m along the meridian
    north, east, _ = jg.geodetic_to_enu(tr.lat[-1], tr.lon[-1], 0.0, (30.0, 130.0, 0.0))
    np.testing.assert_allclose(north, 18520.0, rtol=2e-3)
    np.testing.assert_allclose(east, 18520.0, rtol=2e-3)
    np.testing.assert_allclose(tr.v_east, 10 * KNOT)


def test_turning_track_closes_a_circle():
    # 360 degrees in 360 s at 1 deg/s: back to the start
    tr = sim.turning_track(30.0, 130.0, 10.0, 0.0, 1.0, 361, 1.0)
    d = jg.geodetic_to_enu(tr.lat[-1], tr.lon[-1], 0.0, (30.0, 130.0, 0.0))
    assert np.hypot(d[0], d[1]) < 1.0
    radius = 10.0 / np.deg2rad(1.0)
    np.testing.assert_allclose(np.ptp(np.asarray(tr.lat)) * 110_850.0, 2 * radius, rtol=5e-3)


def test_rayleigh_quantile_and_drift_statistics():
    np.testing.assert_allclose(sim.rayleigh_quantile(1.0, 0.5), np.sqrt(2 * np.log(2)))
    np.testing.assert_allclose(sim.rayleigh_sigma(sim.rayleigh_quantile(3.0, 0.99), 0.99), 3.0)
    keys = jax.random.split(jax.random.key(0), 4000)
    d = jax.vmap(lambda k: sim.sample_drift(k, 1000.0))(keys)
    # Rayleigh(σ): mean σ√(π/2), 99 % quantile 3.03σ
    np.testing.assert_allclose(np.mean(d.radius_m), 1000 * np.sqrt(np.pi / 2), rtol=0.03)
    np.testing.assert_allclose(np.quantile(d.radius_m, 0.99), 3034.9, rtol=0.06)
    fixed = sim.sample_drift(jax.random.key(1), 500.0, law="fixed", growth=0.5, rotation_deg=4)
    dn, de = sim.drift_offsets(fixed, 11)
    r = np.hypot(dn, de)
    np.testing.assert_allclose([r[0], r[-1]], [500 / 1.5, 500.0])
    with pytest.raises(ValueError, match="law"):
        sim.sample_drift(jax.random.key(1), 1.0, law="gauss")


def test_drift_offsets_rotate_and_grow_linearly():
    """The offset direction turns by rotation_rad at a constant rate, ending at
    direction_rad; the radius grows linearly from radius/(1+growth) to radius."""
    n = 13
    d = sim.sample_drift(jax.random.key(5), 800.0, law="fixed", growth=0.25, rotation_deg=10.0)
    assert 0.5 < abs(np.rad2deg(float(d.rotation_rad))) <= 10.0  # a real turn to see
    dn, de = (np.asarray(a) for a in sim.drift_offsets(d, n))
    angle = np.unwrap(np.arctan2(de, dn))  # clockwise from north
    np.testing.assert_allclose(np.diff(angle), float(d.rotation_rad) / (n - 1), atol=1e-12)
    np.testing.assert_allclose(np.cos(angle[-1] - float(d.direction_rad)), 1.0, atol=1e-12)
    r = np.hypot(dn, de)
    np.testing.assert_allclose(r, np.linspace(800.0 / 1.25, 800.0, n), rtol=1e-12)
    # over many tracks: rotation uniform in ±rotation_deg, direction uniform
    many = jax.vmap(lambda k: sim.sample_drift(k, 1.0, rotation_deg=10.0))(
        jax.random.split(jax.random.key(6), 4000))
    rot = np.rad2deg(np.asarray(many.rotation_rad))
    assert np.abs(rot).max() <= 10.0
    np.testing.assert_allclose(np.std(rot), 10.0 / np.sqrt(3.0), rtol=0.05)
    assert abs(np.mean(np.exp(1j * np.asarray(many.direction_rad)))) < 0.05
    # no rotation, no growth: a constant offset (parallel tracks)
    dn0, de0 = sim.drift_offsets(sim.sample_drift(jax.random.key(5), 800.0, law="fixed"), n)
    assert np.ptp(np.asarray(dn0)) == 0.0 and np.ptp(np.asarray(de0)) == 0.0


def test_drift_sigma_grows_with_time_and_rayleigh_law_matches_scipy():
    """σ = σ0 + rate·t since the last fix; radii drawn with that σ follow SciPy's
    Rayleigh law, whose quantiles rayleigh_quantile gives (the search radius)."""
    t = np.array([0.0, 600.0, 1800.0, 3600.0])
    sigma = np.asarray(drift_sigma(t, 0.5, 100.0))
    np.testing.assert_allclose(sigma, [100.0, 400.0, 1000.0, 1900.0])  # by hand
    assert sigma.shape == (4,) and np.asarray(drift_sigma(60.0, 1.0)) == 60.0
    p = np.array([0.1, 0.5, 0.9, 0.99])
    np.testing.assert_allclose(sim.rayleigh_quantile(sigma[:, None], p),
                               stats.rayleigh.ppf(p, scale=sigma[:, None]), rtol=1e-12)
    keys = jax.random.split(jax.random.key(7), 4000)
    for s in sigma[1:]:
        r = np.asarray(jax.vmap(lambda k, s=s: sim.sample_drift(k, s).radius_m)(keys))
        assert stats.kstest(r, stats.rayleigh(scale=s).cdf).pvalue > 1e-3
        # fraction inside each quantile radius: binomial, 4 sigma
        inside = np.mean(r[:, None] <= np.asarray(sim.rayleigh_quantile(s, p)), axis=0)
        assert np.all(np.abs(inside - p) <= 4 * np.sqrt(p * (1 - p) / r.size)), inside


def test_readings_model():
    lat = np.linspace(29, 31, 21)
    lon = np.linspace(129, 131, 21)
    grid = jg.Grid.from_arrays(lat, lon, np.add.outer(lat, lon) * 0.0 + 10.0)
    tr = sim.straight_track(29.5, 129.5, 5.0, 0.0, 8, 60.0)
    g = sim.gravity_readings(jax.random.key(0), grid, tr, noise_mgal=0.0, bias_mgal=2.0)
    np.testing.assert_allclose(g, 12.0 - jg.eotvos(tr.lat, tr.v_east, tr.v_north), atol=1e-9)
    field = lambda la, lo: 0.0 * la + 1.0  # noqa: E731
    g2 = sim.gravity_readings(jax.random.key(0), field, tr, noise_mgal=1.0, eotvos_form=None)
    assert np.std(np.asarray(g2) - 1.0) > 0.1


@pytest.mark.long
def test_scenario_keeps_track_in_region_and_vmaps():
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    scen = MatchingScenario(n_fixes=20, drift_deg=0.05)
    # the map is an argument, not a constant closed over: XLA would fold its spline
    # coefficients at compile time (seconds for a 289 x 289 grid)
    runs = jax.jit(jax.vmap(matching_scenario, in_axes=(0, None, None)))(
        jax.random.split(jax.random.key(0), 64), grid, scen)
    assert runs.readings.shape == (64, 20)
    assert np.all(np.isfinite(runs.readings))
    assert np.all(np.asarray(grid.contains(runs.ins_lat, runs.ins_lon)))
    np.testing.assert_allclose(np.hypot(runs.drift_north_m, runs.drift_east_m),
                               0.05 * sim.DEG_ARC_M, rtol=1e-9)
    one = jax.jit(matching_scenario)(jax.random.split(jax.random.key(0), 64)[3], grid, scen)
    np.testing.assert_allclose(one.readings, runs.readings[3], atol=1e-9)


def test_track_csv_roundtrip_and_errors(tmp_path):
    p = tmp_path / "t.csv"
    write_track_csv(p, {"t": [0, 1, 2], "lat": [1.0, 2.0, 3.0], "gravity": [1.5, np.nan, 2.0]})
    t = read_track_csv(p, required=("t", "lat", "gravity"), allow_nan=("gravity",))
    np.testing.assert_allclose(t["lat"], [1, 2, 3])
    assert np.isnan(t["gravity"][1])
    with pytest.raises(ValueError, match=r"column 'gravity' has 1 missing"):
        read_track_csv(p, required=("t", "gravity"))
    with pytest.raises(ValueError, match=r"lacks column lon; it has "):
        read_track_csv(p, required=("t", "lon"))
    with pytest.raises(FileExistsError):
        write_track_csv(p, {"t": [0]})
    with pytest.raises(ValueError, match="equal lengths"):
        write_track_csv(tmp_path / "u.csv", {"a": [1, 2], "b": [1]})
    (tmp_path / "bad.csv").write_text("t,lat\n0,abc\n")
    with pytest.raises(ValueError, match="'abc' is not a number"):
        read_track_csv(tmp_path / "bad.csv", required=("t",))


@pytest.mark.long  # 4-8 s: the fast tier is at its 5-minute budget
def test_scenario_with_a_fixed_start_draws_the_rest_as_without():
    """``start_lat, start_lon`` fix the start (traced: one per run in a vmap); the key
    still draws the same drift and noise as the run of that key without them."""
    grid = datasets.load("ryukyu")["anomaly_2p5min"]
    scen = MatchingScenario(n_fixes=10)
    keys = jax.random.split(jax.random.key(1), 3)
    starts = np.array([[26.0, 128.0], [27.5, 129.25], [29.0, 131.0]])

    def fixed(k, la, lo):
        return matching_scenario(k, grid, dataclasses.replace(scen, start_lat=la, start_lon=lo))

    runs = jax.jit(jax.vmap(fixed))(keys, starts[:, 0], starts[:, 1])
    np.testing.assert_allclose(runs.truth.lat[:, 0], starts[:, 0])
    np.testing.assert_allclose(runs.truth.lon[:, 0], starts[:, 1])
    free = jax.jit(jax.vmap(matching_scenario, in_axes=(0, None, None)))(keys, grid, scen)
    np.testing.assert_allclose(runs.drift_north_m, free.drift_north_m)
    assert not np.allclose(free.truth.lat[:, 0], starts[:, 0])
    with pytest.raises(ValueError, match="start_lat and start_lon must both be finite"):
        MatchingScenario(start_lat=27.0)
    with pytest.raises(ValueError, match=r"start_lat must be within -90\.\.90"):
        MatchingScenario(start_lat=97.0, start_lon=129.0)
