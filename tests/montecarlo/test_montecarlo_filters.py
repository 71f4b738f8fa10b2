"""The paper-D filters in the Monte Carlo registry: tiny runs, and the ``montecarlo`` command.

Each method compiles a whole simulated run (~20 s of CPU), so the quick suite runs
``ukf`` and ``rbpf`` only (through the runner and the command); ``ekf``, ``gsf``,
``pmf``, ``pf`` and the guarded ``ukf-guard``, ``gsf-guard`` run with ``JAXGRAV_SLOW=1`` (their
filters are tested quickly in ``test_cli_filter.py`` and ``test_guard.py``).
"""

import os

import jax
import numpy as np
import pytest
import xarray as xr

from jaxgrav import montecarlo
from jaxgrav.cli import main
from jaxgrav.fields.map_error import map_error
from jaxgrav.fields.pointmass import PointMasses
from jaxgrav.montecarlo import methods as montecarlo_methods
from jaxgrav.montecarlo.draws import DRAW_ATTRS
from jaxgrav.montecarlo.filter_runs import filter_builder
from jaxgrav.scenarios import FilterScenario
from jaxgrav.sim import DEG_ARC_M

FILTERS = ("ukf", "rbpf", "ekf", "gsf", "pmf", "pf", "ukf-guard", "gsf-guard")
slow = pytest.mark.skipif(
    os.environ.get("JAXGRAV_SLOW") != "1", reason="slow: set JAXGRAV_SLOW=1 to run"
)
N_FIXES = 31  # 5 min at 10 s: compiles like the full 2 h run, runs in no time


def test_filters_are_registered_with_paper_d_defaults():
    for kind in FILTERS:
        assert kind in montecarlo_methods.BUILDERS
    assert set(montecarlo_methods.FILTER_METHODS) == set(FILTERS)
    spec = montecarlo_methods.build("ukf")
    field, scen = spec.args
    assert isinstance(field, PointMasses) and isinstance(scen, FilterScenario)
    assert (scen.dt, scen.reading_every, scen.n_steps) == (10.0, 1, 721)
    assert (scen.pos_error, scen.noise_mgal, scen.geometry) == (2000.0, 1.0, "mixed")
    assert spec.settings["field"] == "paper-d point masses"
    assert "no_reading" not in spec.status_bits.values()
    assert spec.status_bits[2] == "off_map" and spec.status_bits[32] == "grid_edge"
    # --drift is the initial position error (degrees of arc), --noise the reading noise
    spec = montecarlo_methods.build("pmf", drift_deg=0.01, noise=2.0, n_fixes=100)
    scen = spec.args[1]
    assert scen.pos_error == pytest.approx(0.01 * DEG_ARC_M)
    assert (scen.noise_mgal, scen.n_steps) == (2.0, 100)
    with pytest.raises(ValueError, match="fixes must be at least 5"):
        montecarlo_methods.build("ekf", n_fixes=3)


@pytest.mark.parametrize("kind", ["ukf", "rbpf", *(pytest.param(k, marks=slow)
                                                   for k in FILTERS[2:])])
@pytest.mark.long
def test_every_filter_runs_in_the_monte_carlo_runner(kind):
    spec = montecarlo_methods.build(kind, n_fixes=N_FIXES)
    r = montecarlo.run(spec.fn, jax.random.key(1), 2, chunk=2, args=spec.args, progress=False)
    assert set(r) == {*montecarlo_methods.METRICS, "nees", "bound_m", "readings_on_map",
                      "implausible_blocks", *DRAW_ATTRS}
    assert r["implausible_blocks"].shape == (2,) and np.all(r["implausible_blocks"] >= 0)
    for k in ("ins_err_m", "err_m", "nees", "bound_m"):
        assert r[k].shape == (2,) and np.all(np.isfinite(r[k])) and np.all(r[k] > 0), (k, r)
    assert r["status"].dtype == np.int32
    assert np.all(r["bound_m"] < r["ins_err_m"])  # the PCRLB: below the INS's own error
    # 2 km start, 0.2 m/s: the INS stays near 2 km over 5 min; no filter explodes
    assert np.all((r["ins_err_m"] > 1500) & (r["ins_err_m"] < 2500))
    assert np.all(r["err_m"] < 2.0 * r["ins_err_m"])
    assert np.all(r["nees"] < 50)


@pytest.mark.long
def test_montecarlo_command_with_a_filter(tmp_path, capsys):
    out = tmp_path / "ukf.nc"
    assert main(["montecarlo", "--method", "ukf", "--runs", "2", "--chunk", "2", "--seed", "1",
                 "--fixes", str(N_FIXES), "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    for s in ("paper D: UKF", "INS error (m)", "error / INS", "PCRLB (m)",
              "(RMS error / RMS bound ", f"wrote {out}"):
        assert s in text
    with xr.open_dataset(out) as ds:
        assert ds.sizes["run"] == 2 and ds["nees"].dims == ("run",)
        assert ds["bound_m"].attrs["units"] == "m" and "Cramer-Rao" in ds["bound_m"].attrs[
            "long_name"]
        assert "RMS" in ds["err_m"].attrs["long_name"]  # not a matcher's mean error
        assert "second half" in ds["ins_err_m"].attrs["long_name"]
        assert ds.attrs["setting_field"] == "paper-d point masses"
        assert ds.attrs["setting_n_steps"] == N_FIXES
        spec = montecarlo_methods.build("ukf", n_fixes=N_FIXES)
        lib = montecarlo.run(spec.fn, jax.random.key(1), 2, chunk=2, args=spec.args,
                             progress=False)
        np.testing.assert_array_equal(ds["err_m"].values, lib["err_m"])


def test_filters_on_a_map_start_far_enough_inside():
    """With a map: straight random tracks (as ``paper_d_ukf.py --map ryukyu``) whose
    starts leave room for the 36 km track, 3 x the 2 km initial error and 10 km."""
    grid = montecarlo_methods.default_grid()  # 24-36 N, 124-136 E
    spec = montecarlo_methods.build("pmf", grid)
    field, scen = spec.args
    assert field is grid and scen.geometry == "random" and scen.n_steps == 721
    margin = 5.0 * 10.0 * 720 + 3 * 2000.0 + 10e3
    dlat = margin / DEG_ARC_M
    dlon = dlat / np.cos(np.radians(36.0))  # narrowest degree of longitude on the map
    np.testing.assert_allclose(scen.region, (24 + dlat, 36 - dlat, 124 + dlon, 136 - dlon),
                               atol=1e-9)
    assert spec.settings["field"] == "grid gravity_anomaly"
    assert "over the map gravity_anomaly" in spec.settings["description"]


@pytest.mark.parametrize(("kind", "told"), [("ukf", "state order 2"), ("pmf", "state order 1"),
                                            ("rbpf", "state order 2")])
@pytest.mark.long
def test_filter_builder_with_map_error(kind, told):
    """map_error=: readings from map + a drawn error per run; the filters are told by default
    (the matched SOGM state for the Kalman filters, a per-cell FOGM for pmf);
    map_error=None is today's spec."""
    grid = montecarlo_methods.default_grid()
    assert len(filter_builder(grid, kind=kind, n_fixes=N_FIXES).args) == 2
    spec = filter_builder(grid, kind=kind, n_fixes=N_FIXES, map_error=map_error(3.0, 10e3))
    assert spec.settings["map_error_told"] == told
    assert spec.settings["map_error"] == "markov2 sigma 3 mGal, L 10000 m"
    told_args = spec.args[3]
    assert float(told_args.white_var) == 0
    if kind != "pmf":
        assert float(told_args.state.length_m) == 10e3 and told_args.state.order == 2
    else:
        assert float(told_args.state.length_m) == 20e3 and told_args.state.order == 1
    white = filter_builder(grid, kind=kind, n_fixes=N_FIXES, map_error=map_error(3.0, 10e3),
                           map_error_told="white")
    assert white.args[3].state is None and float(white.args[3].white_var) == 9.0
    r = montecarlo.run(spec.fn, jax.random.key(1), 2, chunk=2, args=spec.args, progress=False)
    for k in ("ins_err_m", "err_m", "nees"):
        assert np.all(np.isfinite(r[k])) and np.all(r[k] > 0), (k, r)
