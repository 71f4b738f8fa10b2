"""Test configuration: the suite runs in float64 (DESIGN.md, Precision); shared fixtures."""

import jax
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)

import jaxgrav as jg  # noqa: E402


@pytest.fixture(scope="module")
def smooth_grid():
    """A smooth, information-rich synthetic anomaly field (mGal) on a 0.01° grid."""
    lat = np.linspace(29.5, 30.5, 101)
    lon = np.linspace(129.5, 130.5, 101)
    y, x = np.meshgrid(lat - 30, lon - 130, indexing="ij")
    v = (40 * np.sin(45 * x + 2) * np.cos(35 * y) + 25 * np.cos(60 * x * y + 50 * y)
         + 20 * np.sin(70 * x - 30 * y) + 15 * x)
    return jg.Grid.from_arrays(lat, lon, v, units="mGal")
