"""The dense matcher's no-harm test (``DenseConfig.max_p_worse``, status 131072).

A fix is rejected, and the INS track kept, when under its own Gaussian ``N(fix, C)``
the truth is more likely than ``max_p_worse`` to lie nearer the INS track than the fix
(:func:`~jaxgrav.match.integrity.p_worse_than_ins`, the entropy+ICCP matcher's rule).
``config_for`` sets it (0.3) with a map error only.
"""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav.fields.map_error import map_error
from jaxgrav.match import shifted_tracks
from jaxgrav.match.combined import NOT_BETTER
from jaxgrav.match.dense import DenseConfig, match_dense
from jaxgrav.match.integrity import p_worse_than_ins
from jaxgrav.match.result import CORRELATION_STATUS
from jaxgrav.match.sizing import MAP_ERROR_INTEGRITY, WHITE_INTEGRITY, config_for


def test_max_p_worse_is_validated_and_set_with_a_map_error_only(smooth_grid):
    for bad in (-0.1, 0.6, float("nan"), -float("inf")):
        with pytest.raises(ValueError, match="max_p_worse must be in"):
            DenseConfig(max_p_worse=bad)
    assert DenseConfig().max_p_worse == np.inf and DenseConfig(max_p_worse=0.5).max_p_worse
    told = config_for("dense", smooth_grid, 3000.0, map_error=map_error(3.0, 1e4))
    for k, v in MAP_ERROR_INTEGRITY.items():
        assert getattr(told, k) == v
    assert MAP_ERROR_INTEGRITY["max_p_worse"] == 0.3
    white = config_for("dense", smooth_grid, 3000.0)
    assert white.max_p_worse == np.inf and "max_p_worse" not in WHITE_INTEGRITY
    assert NOT_BETTER in CORRELATION_STATUS


@pytest.mark.long  # one compile of the dense matcher; the thresholds are traced
def test_a_fix_not_shown_better_than_the_ins_track_is_rejected(smooth_grid):
    """Readings from a track 150 m off the INS track, told a 6 mGal map error: the fix
    moves a little with a σ of hundreds of m, so the truth may well be nearer the INS
    track; the same readings told no map error give a fix many σ from it."""
    n = 20
    lat = jnp.asarray(29.85 + 0.0045 * np.arange(n))
    lon = jnp.asarray(129.85 + 0.0035 * np.arange(n))
    t_lat, t_lon = shifted_tracks(lat, lon, 150.0, -100.0, 0.0)
    z = smooth_grid.sample(t_lat, t_lon, "bicubic")
    z = jnp.asarray(z + 0.5 * np.random.default_rng(4).normal(size=n))
    base = DenseConfig(spacing_m=200.0, half_size=6, region="disc", fix="posterior",
                       noise_mgal=0.5, map_error_mgal=6.0, map_error_length_m=2000.0,
                       score_model="gls")
    ps = []
    for cfg in (base, dataclasses.replace(base, map_error_mgal=0.0)):
        kept = match_dense(smooth_grid, lat, lon, z, cfg)
        assert bool(kept.accepted), int(kept.status)
        p = float(p_worse_than_ins(jnp.stack([kept.offset_north_m, kept.offset_east_m]),
                                   kept.covariance_m2))
        ps.append(p)
        below = dataclasses.replace(cfg, max_p_worse=max(p - 0.02, 0.0))
        above = dataclasses.replace(cfg, max_p_worse=min(p + 0.02, 0.5))
        r = match_dense(smooth_grid, lat, lon, z, above)  # the same fix: the test decides
        assert bool(r.accepted) and not int(r.status) & NOT_BETTER
        np.testing.assert_array_equal(np.asarray(r.lat), np.asarray(kept.lat))
        r = match_dense(smooth_grid, lat, lon, z, below)
        if p >= 0.02:
            assert not bool(r.accepted) and int(r.status) & NOT_BETTER, (p, int(r.status))
            np.testing.assert_array_equal(np.asarray(r.lat), np.asarray(lat))
    # told the map error the fix is not shown better; told none, it is (many σ out)
    assert ps[0] > 0.05 and ps[1] < ps[0], ps
