"""One entry point for every method, one status table, and the deprecated names."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrav as jg
import jaxgrav.match as jm
from jaxgrav.match import entropy_iccp, shifted_tracks
from jaxgrav.match.combined import COMBINED_STATUS
from jaxgrav.match.entropy import ENTROPY_STATUS, EntropyConfig
from jaxgrav.match.iccp import ICCP_STATUS, IccpConfig
from jaxgrav.match.result import CORRELATION_STATUS

# the static settings and the 20-fix track of tests/match/test_entropy_iccp.py: one compile
ENT = EntropyConfig(spacing_m=200.0, half_size=4)
ICP = IccpConfig(window_m=600.0, max_step_m=300.0, contour_tol=2.0)


@pytest.fixture(scope="module")
def track(smooth_grid):
    lat = 29.85 + 0.0045 * np.arange(20)
    lon = 129.85 + 0.0035 * np.arange(20)
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), -200.0, 400.0, 0.0)
    return lat, lon, np.asarray(smooth_grid.sample(t_lat, t_lon, "bicubic"))


def test_one_method_list_and_one_status_table():
    assert jm.METHODS == ("dense", "chains", "entropy", "iccp", "entropy+iccp")
    assert sorted(jm.STATUS) == [1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192,
                               16384, 32768, 65536, 131072]
    assert jm.status_messages(0) == []
    assert jm.status_messages(1 | 128) == [jm.STATUS[1], jm.STATUS[128]]
    # the per-matcher excerpts are views of the one table
    for part in (COMBINED_STATUS, ENTROPY_STATUS, ICCP_STATUS, CORRELATION_STATUS):
        assert all(jm.STATUS[bit] == msg for bit, msg in part.items())
    with pytest.raises(ValueError, match="method must be one of"):
        jm.match_track(None, [0.0], [0.0], [0.0], method="correlation")


@pytest.mark.long
def test_match_track_runs_every_contour_method_on_one_prepared_map(smooth_grid, track):
    lat, lon, z = track
    pm = jm.prepare_map(smooth_grid)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        both = jm.match_track(pm, lat, lon, z, method="entropy+iccp", config=(ENT, ICP))
        ent = jm.match_track(pm, lat, lon, z, method="entropy", config=ENT)
    direct = jm.match_entropy_iccp(smooth_grid, lat, lon, z, ENT, ICP)
    np.testing.assert_allclose(both.lat, direct.lat, rtol=1e-12)
    np.testing.assert_allclose(ent.lat, both.topk_lat[0], rtol=1e-12)  # the coarse stage
    with pytest.raises(ValueError, match="must be a EntropyConfig"):
        jm.match_track(pm, lat, lon, z, method="entropy", config=ICP)


def test_deprecated_shims_warn_and_equal_the_new_api(smooth_grid, track):
    lat, lon, z = track
    new = jm.match_track(smooth_grid, lat, lon, z, method="entropy", config=ENT, warn=False)
    with pytest.warns(DeprecationWarning, match="match_track_b is deprecated"):
        old = jm.match_track_b(smooth_grid, lat, lon, z, method="entropy", entropy=ENT,
                               warn=False)
    for a, b in zip(new, old, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    with pytest.warns(DeprecationWarning, match="match_track_b"):
        assert entropy_iccp.match_track_b is jm.match_track_b
        entropy_iccp.match_track_b(smooth_grid, lat, lon, z, method="entropy", entropy=ENT,
                                   warn=False)
    with pytest.warns(DeprecationWarning, match="METHODS_B"):
        assert jm.METHODS_B == ("entropy", "iccp", "entropy+iccp")
    with pytest.warns(DeprecationWarning, match="ALL_STATUS_B"):
        assert entropy_iccp.ALL_STATUS_B is jm.STATUS
    with pytest.warns(DeprecationWarning, match="status_messages_b"):
        assert jm.status_messages_b(32 | 16) == jm.status_messages(32 | 16)
    with pytest.warns(DeprecationWarning, match="noise_mgal"):
        alias = jm.match_track(smooth_grid, lat, lon, z, method="entropy", config=ENT,
                               noise_mgal=1.0, warn=False)
    np.testing.assert_array_equal(np.asarray(alias.lat), np.asarray(new.lat))
    with pytest.raises(AttributeError):
        jm.NOT_A_NAME  # noqa: B018


def _crop(grid, rows):
    """``grid``'s rows ``rows`` (a slice) as a Grid of their own."""
    lat = np.asarray(grid.lat)[rows]
    return jg.Grid.from_arrays(lat, np.asarray(grid.lon), np.asarray(grid.values)[rows],
                               units=grid.units)


def test_the_search_is_sized_at_the_track_not_the_map_centre(smooth_grid):
    # a 1° map cut to its northern half moves the central latitude 0.25° north: at
    # the map's centre the east–west node spacing (and so the dense offset spacing)
    # differs; at the track's latitude it is the same map geometry either way
    north = _crop(smooth_grid, slice(50, None))
    lat = 30.2
    for method in ("dense", "chains"):
        whole = jm.config_for(method, smooth_grid, 4000.0, lat=lat)
        part = jm.config_for(method, north, 4000.0, lat=lat)
        assert whole == part
    assert jm.config_for("dense", smooth_grid, 4000.0) != jm.config_for("dense", north, 4000.0)
    assert (jm.entropy_config_for(smooth_grid, 4000.0, lat=lat)
            == jm.entropy_config_for(north, 4000.0, lat=lat))
    assert (jm.iccp_config_for(smooth_grid, 4000.0, lat=lat)
            == jm.iccp_config_for(north, 4000.0, lat=lat))


@pytest.mark.long
def test_match_track_does_not_depend_on_how_far_the_map_extends(smooth_grid):
    # the command line cuts a map with missing nodes to the track's region: the fix
    # must be the one the whole map gives (it was not: the search was sized at the
    # map's central latitude, 502.5 vs 479.5 m offsets on the ryukyu map)
    lat = 30.1 + 0.0045 * np.arange(20)
    lon = 129.85 + 0.0035 * np.arange(20)
    t_lat, t_lon = shifted_tracks(jnp.asarray(lat), jnp.asarray(lon), -200.0, 400.0, 0.0)
    z = np.asarray(smooth_grid.sample(t_lat, t_lon, "bicubic"))
    north = _crop(smooth_grid, slice(40, None))
    a, b = (jm.match_track(g, lat, lon, z, method="dense", drift_radius_m=3000.0, warn=False)
            for g in (smooth_grid, north))
    for name, x, y in zip(a._fields, a, b, strict=True):  # the lattice too: top-k, σ
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-9, atol=1e-9,
                                   err_msg=name)
