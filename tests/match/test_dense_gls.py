"""Dense matcher with the GLS score of a correlated map error, and the fix's quality."""

import dataclasses
import json
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgrav as jg
from jaxgrav.fields.map_error import map_error, truth_field
from jaxgrav.match.dense import DenseConfig, match_dense, shifted_tracks
from jaxgrav.match.gls import track_covariance
from jaxgrav.match.sizing import config_for
from jaxgrav.match.result import STATUS
from jaxgrav.scenarios import MatchingScenario, matching_scenario

GOLDEN = pathlib.Path(__file__).with_name("dense_white_golden.json")
SCEN = MatchingScenario(region=(29.6, 30.4, 129.6, 130.4), drift_deg=0.01, n_fixes=20, dt=60.0)
FIELDS = ("lat", "lon", "score", "bias", "offset_north_m", "offset_east_m", "rotation_deg",
          "status", "topk_score")


@pytest.fixture(scope="module")
def grid():
    lat = np.linspace(29.5, 30.5, 101)
    lon = np.linspace(129.5, 130.5, 101)
    y, x = np.meshgrid(lat - 30, lon - 130, indexing="ij")
    v = (40 * np.sin(45 * x + 2) * np.cos(35 * y) + 25 * np.cos(60 * x * y + 50 * y)
         + 20 * np.sin(70 * x - 30 * y) + 15 * x)
    return jg.Grid.from_arrays(lat, lon, v, units="mGal")


def test_map_error_zero_is_todays_white_score_bit_for_bit(grid):
    gold = json.loads(GOLDEN.read_text())  # written by the matcher before map errors existed
    for name, nrot in (("plain", 1), ("rot", 3)):
        cfg = config_for("dense", grid, 1500.0, n_rotations=nrot)
        assert cfg.map_error_mgal == 0.0
        for s in range(3):
            run = matching_scenario(jax.random.key(s), grid, SCEN)
            r = match_dense(grid, run.ins_lat, run.ins_lon, run.readings, cfg)
            for f in FIELDS:
                got, want = np.asarray(getattr(r, f)), np.asarray(gold[name][s][f])
                np.testing.assert_array_equal(got, want, err_msg=f"{name} run {s} field {f}")
            assert bool(r.accepted)
