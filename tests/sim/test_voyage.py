"""Routes sailed by the autopilot (sim.route) and simulated voyages (sim.voyage,
scenarios.voyage): geometry against brute force, the INS error against the model's
stated free drift, the readings against their definition, vmap against a loop."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.geodesy import eotvos, local_offsets_m
from jaxgrav.scenarios.voyage import NAVIGATION_GRADE, voyage_preset, voyage_route, voyage_scenario
from jaxgrav.sim.route import Route, great_circle, sail
from jaxgrav.sim.voyage import indicated_track

BOX = Route(jnp.array([30.0, 30.0, 30.3, 30.3]), jnp.array([130.0, 130.4, 130.4, 130.0]),
            jnp.full(4, 5.0), jnp.asarray(500.0), jnp.asarray(True))


def test_great_circle_against_the_haversine_in_numpy():
    d, b = great_circle(30.0, 130.0, 30.5, 130.7)
    p1, p2, dl = np.radians(30.0), np.radians(30.5), np.radians(0.7)
    a = np.sin((p2 - p1) / 2) ** 2 + np.cos(p1) * np.cos(p2) * np.sin(dl / 2) ** 2
    assert float(d) == pytest.approx(2 * 6371008.8 * np.arcsin(np.sqrt(a)), rel=1e-12)
    y = np.sin(dl) * np.cos(p2)
    x = np.cos(p1) * np.sin(p2) - np.sin(p1) * np.cos(p2) * np.cos(dl)
    assert float(b) == pytest.approx(np.degrees(np.arctan2(y, x)), abs=1e-10)


@pytest.mark.long  # 4-8 s: the fast tier is at its 5-minute budget
def test_sail_goes_round_the_box_at_its_speed_and_turn_radius():
    track, leg = sail(BOX, 4001, 10.0)
    step, _ = great_circle(track.lat[:-1], track.lon[:-1], track.lat[1:], track.lon[1:])
    # the sphere's great circle against the ellipsoid's dead reckoning: within 0.5 %
    np.testing.assert_allclose(np.asarray(step), 50.0, rtol=5e-3)
    np.testing.assert_allclose(np.hypot(track.v_east, track.v_north), 5.0, rtol=1e-12)
    heading = np.degrees(np.arctan2(track.v_east, track.v_north))
    turn = np.abs((np.diff(heading) + 180.0) % 360.0 - 180.0)
    assert turn.max() <= np.degrees(50.0 / 500.0) + 1e-9  # speed·dt / radius per step
    assert np.all(np.diff(np.asarray(leg)) >= 0) and int(leg[-1]) >= 5  # past the 4th corner
    # every waypoint is passed within about the turn radius
    for i in range(4):
        d, _ = great_circle(track.lat, track.lon, BOX.lat[i], BOX.lon[i])
        assert float(d.min()) < 600.0


def test_an_open_route_holds_its_course_after_the_last_waypoint():
    track, leg = sail(BOX._replace(cyclic=jnp.asarray(False)), 4001, 10.0)
    assert int(leg[-1]) == 4
    late = np.degrees(np.arctan2(track.v_east[-500:], track.v_north[-500:]))
    assert np.ptp(late) < 1e-9


@pytest.mark.long
def test_the_free_ins_error_of_the_navigation_grade_preset():
    """The issue's figures: about 2.1 km at 1 h, 11 km at 6 h and 28 km at 12 h (RMS)."""
    grid_free = lambda lat, lon: jnp.zeros_like(lat)  # noqa: E731
    sc = voyage_preset("patrol-12h")
    keys = jax.random.split(jax.random.key(0), 64)
    v = jax.jit(jax.vmap(lambda k: voyage_scenario(k, grid_free, sc)))(keys)
    r = np.hypot(v.ins_error[:, :, 0], v.ins_error[:, :, 1])
    rms = [np.sqrt(np.mean(r[:, h * 360] ** 2)) / 1e3 for h in (1, 6, 12)]
    np.testing.assert_allclose(rms, [2.1, 11.0, 28.0], rtol=0.25)
    assert sc.ins == NAVIGATION_GRADE and sc.n_steps == 4321


@pytest.mark.long
def test_voyage_readings_and_ins_track_follow_their_definitions(smooth_grid):
    sc = voyage_preset("patrol-12h", hours=2.0, region=(29.6, 30.4, 129.6, 130.4),
                       leg_m=20000.0, margin_deg=0.05)
    v = voyage_scenario(jax.random.key(3), smooth_grid, sc)
    t = v.truth
    d_n, d_e = local_offsets_m(v.ins.lat, v.ins.lon, t.lat, t.lon)
    np.testing.assert_allclose(d_n, v.ins_error[:, 0], atol=0.5)
    np.testing.assert_allclose(d_e, v.ins_error[:, 1], atol=0.5)
    np.testing.assert_allclose(v.ins.v_north - t.v_north, v.ins_error[:, 2], atol=1e-12)
    resid = (v.gravity - smooth_grid.sample(t.lat, t.lon, "bicubic") - v.ins_error[:, 12]
             + eotvos(t.lat, t.v_east, t.v_north))
    assert abs(float(jnp.mean(resid))) < 0.1
    assert float(jnp.std(resid)) == pytest.approx(1.0, rel=0.1)
    # the route stays in the region, margin kept
    assert float(t.lat.min()) > 29.6 and float(t.lon.max()) < 130.4


@pytest.mark.long
def test_voyage_route_vmap_equals_loop():
    sc = voyage_preset("transit-24h")
    keys = jax.random.split(jax.random.key(5), 3)
    batch = jax.vmap(lambda k: voyage_route(k, sc))(keys)
    for i, k in enumerate(keys):
        one = voyage_route(k, sc)
        np.testing.assert_allclose(batch.lat[i], one.lat, rtol=0, atol=1e-12)
    assert batch.lat.shape == (3, 5) and not bool(batch.cyclic[0])


def test_bad_scenarios_get_clear_errors():
    with pytest.raises(ValueError, match="preset must be one of"):
        voyage_preset("patrol-99h")
    with pytest.raises(ValueError, match="route must be 'patrol' or 'transit'"):
        voyage_preset("patrol-12h", route="loop")
    with pytest.raises(ValueError, match="n_legs must be an integer >= 2"):
        voyage_preset("patrol-12h", n_legs=1)


def test_indicated_track_is_the_truth_plus_the_error():
    track, _ = sail(BOX, 11, 10.0)
    err = jnp.zeros((11, 13)).at[:, 0].set(100.0).at[:, 3].set(0.2)
    ins = indicated_track(track, err)
    d_n, _ = local_offsets_m(ins.lat, ins.lon, track.lat, track.lon)
    np.testing.assert_allclose(d_n, 100.0, atol=0.01)
    np.testing.assert_allclose(ins.v_east - track.v_east, 0.2)
