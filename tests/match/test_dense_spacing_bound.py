"""``DenseConfig.spacing_bound_m``: the map reads chosen when compiling, the same fixes.

On ``smooth_grid`` (0.01° nodes, ~1.1 km) with ``half_size=6`` a spacing of 150 m is
read from the default 6-node block and one of 800 m from the 14-node one; a bound of
900 m drops the point-by-point path, a bound of 300 m the larger block too.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.match.dense import DenseConfig, match_dense
from jaxgrav.navigate import LooseConfig

CFG = DenseConfig(half_size=6, noise_mgal=0.5, n_rotations=3, map_error_mgal=2.0,
                  map_error_length_m=5000.0, score_model="gls", fix="posterior")
FIELDS = ("offset_north_m", "offset_east_m", "covariance_m2", "score", "bias", "status",
          "accepted", "edge_mass")


def _track(grid):
    lat = 29.9 + 0.004 * np.arange(20)
    lon = 129.9 + 0.003 * np.arange(20)
    readings = np.asarray(grid.sample(lat + 0.004, lon - 0.002, "bicubic")) + 0.3
    return lat, lon, readings


def _same(a, b):  # to rounding: another program, other fusions
    for name in FIELDS:
        np.testing.assert_allclose(np.asarray(getattr(a, name), float),
                                   np.asarray(getattr(b, name), float), rtol=1e-9, atol=1e-9,
                                   err_msg=name)


def _size(config, grid, track):
    """Lines of the printed program (every branch's equations)."""
    return len(str(jax.make_jaxpr(lambda *t: match_dense(grid, *t, config))(*track)).splitlines())


@pytest.mark.long
def test_a_bound_gives_the_same_fixes_from_a_smaller_program(smooth_grid):
    track = _track(smooth_grid)
    for bound, spacings in ((300.0, (150.0, 300.0)), (900.0, (150.0, 800.0, 900.0))):
        for spacing in spacings:
            free = dataclasses.replace(CFG, spacing_m=spacing)
            bounded = dataclasses.replace(free, spacing_bound_m=bound)
            _same(match_dense(smooth_grid, *track, bounded), match_dense(smooth_grid, *track, free))
        # fewer branches: one (no branch) under 300 m, two blocks under 900 m
        assert _size(bounded, smooth_grid, track) < _size(free, smooth_grid, track)


@pytest.mark.long
def test_a_bound_under_vmap_over_spacings(smooth_grid):
    """A spacing per track (the loosely coupled loop's case): each block as without a bound."""
    track = _track(smooth_grid)
    spacings = jnp.array([150.0, 800.0])

    def run(spacing, bound):
        return match_dense(smooth_grid, *track,
                           dataclasses.replace(CFG, spacing_m=spacing, spacing_bound_m=bound))

    both = jax.vmap(lambda s: run(s, 900.0))(spacings)
    for k, spacing in enumerate((150.0, 800.0)):
        one = match_dense(smooth_grid, *track, dataclasses.replace(CFG, spacing_m=spacing))
        _same(jax.tree.map(lambda a: a[k], both), one)  # noqa: B023


@pytest.mark.parametrize("bound", [0.0, -5.0, np.array([100.0]), "1000"])
def test_the_bound_must_be_a_positive_number(bound):
    with pytest.raises(ValueError, match="spacing_bound_m"):
        DenseConfig(spacing_bound_m=bound)


def test_the_spacing_must_not_exceed_the_bound():
    with pytest.raises(ValueError, match="must not exceed spacing_bound_m"):
        DenseConfig(spacing_m=600.0, spacing_bound_m=500.0)
    assert DenseConfig(spacing_m=500.0, spacing_bound_m=500.0).spacing_bound_m == 500.0


@pytest.mark.parametrize("bound", [0.0, jnp.array(1500.0), None])
def test_the_loops_largest_spacing_is_a_static_number(bound):
    with pytest.raises(ValueError, match="max_spacing_m"):
        LooseConfig(max_spacing_m=bound)
