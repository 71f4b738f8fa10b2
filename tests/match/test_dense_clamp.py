"""The dense matcher's refinement stays inside the searched square (white and GLS paths).

Constructed case: a map that is a plane (a constant north slope, exact under the
bicubic spline) and readings from a track 2 km north of the INS track, with a search
square of ±600 m and an absolute score (no bias to absorb the shift). The best lattice
offset is the square's north edge and the Gauss–Newton refinement, whose steps are
capped one by one, would walk on towards the truth; the clamp keeps the fix inside.
"""

import numpy as np
import pytest

from jaxgrav import Grid
from jaxgrav.match.dense import DenseConfig, match_dense


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
