"""The point-mass filter's cell values on a map: the separable lattice path equals
point-by-point sampling (interior, map edge, missing nodes, adaptive wide cells)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import datasets
from jaxgrav import filters as fl
from jaxgrav.filters.pmf_cells import cell_values, lattice_block
from jaxgrav.grid import Grid
from jaxgrav.prepared import prepare_map

GRID = datasets.load("ryukyu")["anomaly_2p5min"]  # 24–36°N, 124–136°E, 2.5′


def _cells(n, cell_m, centre=(130.0, -250.0)):
    offsets = (np.arange(n) - (n - 1) / 2) * cell_m
    return jnp.meshgrid(jnp.asarray(centre[0] + offsets), jnp.asarray(centre[1] + offsets),
                        indexing="ij")


@pytest.mark.parametrize(("n", "cell_m", "lat", "lon", "hole"), [
    (15, 400.0, 30.3, 129.7, True),     # interior
    (15, 3200.0, 27.1, 131.2, True),    # an adaptive grid's widest cells (45 km)
    (21, 300.0, 24.02, 135.97, True),   # across the south-east corner: partly off the map
    (21, 300.0, 35.99, 124.01, False),  # across the north-west corner (longitudes wrap west)
])
def test_lattice_cells_equal_pointwise(n, cell_m, lat, lon, hole):
    values = np.asarray(GRID.values).copy()
    iy, ix = int((lat - GRID.lat0) / GRID.dlat), int((lon - GRID.lon0) / GRID.dlon)
    if hole:
        values[iy + 1, ix + 1] = np.nan  # a missing node among the cells
    field = prepare_map(Grid(jnp.asarray(values), GRID.lat0, GRID.dlat, GRID.lon0, GRID.dlon))
    dn, de = _cells(n, cell_m)
    step = fl.Step(*(jnp.asarray(v) for v in (lat, lon, 0.0, 1.0)))
    span = (n - 1) * cell_m
    assert lattice_block(field.grid, span) is not None
    fast = jax.jit(lambda f, s: cell_values(f, s, dn, de, fl.gravity_measurement, span))
    slow = jax.jit(lambda f, s: cell_values(f, s, dn, de, fl.gravity_measurement))
    v, ref = np.asarray(fast(field, step)), np.asarray(slow(field, step))
    np.testing.assert_array_equal(np.isnan(v), np.isnan(ref))
    assert np.isnan(ref).any() and np.isfinite(ref).sum() > n  # off-map or missing, and present
    ok = np.isfinite(ref)
    np.testing.assert_allclose(v[ok], ref[ok], rtol=0, atol=1e-9)


def test_lattice_block_bounds():
    # 2.5' rows are 4.6 km, columns 3.8 km at 36°N: a 12 km grid needs 4 cells + 3
    assert lattice_block(GRID, 12000.0) == 7
    assert lattice_block(GRID, None) is None
    assert lattice_block(GRID, 1e6) is None  # larger than the map
    world = Grid(jnp.zeros((10, 144)), -45.0, 10.0, 0.0, 2.5)
    assert lattice_block(world, 1000.0) is None  # global in longitude: the seam
