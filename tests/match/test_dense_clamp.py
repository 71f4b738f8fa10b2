"""The dense matcher's searched region (square or disc) and the integrity test against it.

Constructed case: a map that is a plane (a constant north slope, exact under the
bicubic spline) and readings from a track 2 km north of the INS track, with a search
square of ±600 m and an absolute score (no bias to absorb the shift). The best lattice
offset is the square's north edge and the Gauss–Newton refinement, whose steps are
capped one by one, would walk on towards the truth; the clamp keeps the fix inside.
With ``region="disc"`` the same holds for the disc, and a fix that does not narrow the
disc's own spread is rejected by ``max_sigma_ratio``.
"""

import dataclasses

import numpy as np
import pytest

from jaxgrav import Grid
from jaxgrav.fields.map_error import map_error as map_error_model
from jaxgrav.match.dense import DenseConfig, match_dense
from jaxgrav.match.sizing import WHITE_INTEGRITY, config_for


@pytest.mark.parametrize("map_error_mgal", [0.0, 2.0])
@pytest.mark.long
def test_refinement_is_clamped_to_the_searched_square(map_error_mgal):
    lat = np.linspace(29.0, 31.0, 41)
    lon = np.linspace(129.0, 131.0, 41)
    slope = 2e-3  # mGal/m north
    values = np.repeat((slope * (lat - 30.0) * 110946.0)[:, None], lon.size, 1)
    grid = Grid.from_arrays(lat, lon, values, units="mGal")
    ins_lat = 29.9 + 0.002 * np.arange(10)
    ins_lon = 129.9 + 0.002 * np.arange(10)
    shift_deg = 2000.0 / 110946.0
    readings = np.asarray(grid.sample(ins_lat + shift_deg, ins_lon))
    cfg = DenseConfig(spacing_m=200.0, half_size=3, score="absolute", refine_steps=8,
                      map_error_mgal=map_error_mgal, map_error_length_m=5000.0)
    r = match_dense(grid, ins_lat, ins_lon, readings, cfg)
    reach = cfg.half_size * cfg.spacing_m
    assert float(r.offset_north_m) <= reach + 1.0
    assert float(r.offset_north_m) >= reach - 50.0  # it did go to the edge
    assert abs(float(r.offset_east_m)) <= reach + 1.0
    assert int(r.status) & 8  # the edge flag says the fix may be beyond the square


@pytest.mark.long
def test_disc_region_searches_and_clamps_inside_the_disc():
    """A truth 2 km north-east: inside the ±600 m square's corner reach, outside the disc."""
    lat = np.linspace(29.0, 31.0, 41)
    lon = np.linspace(129.0, 131.0, 41)
    slope = 2e-3  # mGal/m, towards the north-east
    y = (lat - 30.0)[:, None] * 110946.0
    x = (lon - 130.0)[None, :] * 110946.0 * np.cos(np.radians(30.0))
    grid = Grid.from_arrays(lat, lon, slope * (y + x) / np.sqrt(2.0), units="mGal")
    ins_lat = 29.9 + 0.002 * np.arange(10)
    ins_lon = 129.9 + 0.002 * np.arange(10)
    d = 2000.0 / np.sqrt(2.0)
    readings = np.asarray(grid.sample(ins_lat + d / 110946.0,
                                      ins_lon + d / (110946.0 * np.cos(np.radians(ins_lat)))))
    reach = 600.0
    for region in ("square", "disc"):
        cfg = DenseConfig(spacing_m=200.0, half_size=3, score="absolute", region=region)
        r = match_dense(grid, ins_lat, ins_lon, readings, cfg)
        north, east = float(r.offset_north_m), float(r.offset_east_m)
        assert int(r.status) & 8  # at the edge of the searched region
        if region == "square":  # the corner, √2 × the reach away
            assert north > reach - 50.0 and east > reach - 50.0
        else:  # on the disc's rim, towards the truth
            assert np.hypot(north, east) <= reach + 1.0
            assert np.hypot(north, east) >= reach - 50.0
            assert abs(north - east) < 100.0
            top_n = (np.asarray(r.topk_lat) - ins_lat) * 110946.0
            assert np.all(np.abs(top_n) <= reach + 1.0)


def test_region_is_checked_and_sized_configs_search_the_disc():
    from jaxgrav.match.sizing import config_for

    with pytest.raises(ValueError, match="region must be 'square' or 'disc'; got 'circle'"):
        DenseConfig(region="circle")
    lat = np.linspace(29.0, 31.0, 41)
    grid = Grid.from_arrays(lat, lat + 100.0, np.zeros((41, 41)), units="mGal")
    assert config_for("dense", grid, 4000.0).region == "disc"
    assert config_for("dense", grid, 4000.0, region="square").region == "square"
    with pytest.raises(ValueError, match="region must be 'disc' or 'square'; got 'round'"):
        config_for("chains", grid, 4000.0, region="round")


def test_region_mask_and_sigma_are_the_lattice_s_own():
    from jaxgrav.match.integrity import region_mask, region_sigma, region_spread

    d = np.arange(-5, 6) * 300.0
    on, oe = (a.reshape(-1) for a in np.meshgrid(d, d, indexing="ij"))
    r2 = on**2 + oe**2
    inside, ring = region_mask(5, "disc")
    np.testing.assert_array_equal(inside, r2 <= 1500.0**2)
    np.testing.assert_array_equal(ring, inside & (r2 > 1200.0**2))
    assert inside[np.flatnonzero((on == 1500.0) & (oe == 0.0))].all()  # the rim's axis nodes
    square, edge = region_mask(5, "square")
    assert square.all() and edge.sum() == 40
    for mask in (square, inside):
        ref = np.sqrt(np.mean(on[mask] ** 2) + 300.0**2 / 12)
        np.testing.assert_allclose(region_sigma(on, oe, 300.0, mask), ref, rtol=1e-12)
    # the continuous limits: R/√3 for the square, R/2 for the disc
    np.testing.assert_allclose(region_sigma(on, oe, 300.0, square), 1650.0 / np.sqrt(3),
                               rtol=0.01)
    np.testing.assert_allclose(region_sigma(on, oe, 300.0, inside), 1500.0 / 2, rtol=0.05)
    for region, mask in (("square", square), ("disc", inside)):  # a configuration's own
        cfg = DenseConfig(spacing_m=300.0, half_size=5, region=region)
        np.testing.assert_allclose(region_spread(cfg), region_sigma(on, oe, 300.0, mask),
                                   rtol=1e-12)
    # offsets that could not be scored are not part of the prior
    half = inside & (on >= 0)
    assert region_sigma(on, oe, 300.0, half) != region_sigma(on, oe, 300.0, inside)
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="max_sigma_ratio must be >= 0"):
            DenseConfig(max_sigma_ratio=bad)


@pytest.mark.long
def test_an_uninformative_fix_is_rejected_by_the_sigma_ratio():
    """A flat map: every offset fits alike, the posterior is the searched disc itself."""
    lat = np.linspace(29.0, 31.0, 41)
    lon = np.linspace(129.0, 131.0, 41)
    grid = Grid.from_arrays(lat, lon, np.zeros((41, 41)), units="mGal")
    ins_lat = 29.9 + 0.002 * np.arange(10)
    ins_lon = 129.9 + 0.002 * np.arange(10)
    readings = np.random.default_rng(0).normal(0.0, 1.0, 10)
    base = DenseConfig(spacing_m=200.0, half_size=5, region="disc", fix="posterior",
                       map_error_mgal=2.0, map_error_length_m=5000.0, score_model="gls")
    kept = match_dense(grid, ins_lat, ins_lon, readings, base)
    assert bool(kept.accepted)
    ratio = dataclasses.replace(base, max_sigma_ratio=0.9)
    r = match_dense(grid, ins_lat, ins_lon, readings, ratio)
    assert not bool(r.accepted) and int(r.status) & 512
    np.testing.assert_allclose(r.lat, ins_lat)  # the INS track kept


def test_config_for_without_a_map_error_rejects_an_uninformative_fix():
    """``config_for`` gives the white-noise matcher the informativeness test too: white
    readings on a flat map were ``accepted`` with a σ as wide as the search."""
    lat = np.linspace(29.0, 31.0, 41)
    lon = np.linspace(129.0, 131.0, 41)
    grid = Grid.from_arrays(lat, lon, np.full((41, 41), 10.0), units="mGal")
    ins_lat = 29.9 + 0.002 * np.arange(30)
    ins_lon = 129.9 + 0.002 * np.arange(30)
    readings = 10.0 + np.random.default_rng(0).normal(0.0, 1.0, 30)
    for map_error in (None, map_error_model(0.0, 10e3)):
        cfg = config_for("dense", grid, 3000.0, map_error=map_error)
        assert cfg.max_sigma_ratio == WHITE_INTEGRITY["max_sigma_ratio"]
        assert cfg.fix == "best" and cfg.score_model == "white"  # paper A's fix otherwise
        r = match_dense(grid, ins_lat, ins_lon, readings, cfg)
        assert not bool(r.accepted) and int(r.status) & 512
        np.testing.assert_allclose(r.lat, ins_lat)
