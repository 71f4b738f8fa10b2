"""The block test of a filter's innovations (navigate.innovation_blocks): each block equals
a NumPy loop over the used readings with SciPy's χ² tail; traced once, vmapped as looped;
the rows flagged are the blocks' spans; a lost filter is flagged, a consistent one not."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import chi2

from jaxgrav.navigate import (
    implausible_block_count,
    implausible_rows,
    innovation_blocks,
)


def _innovations(seed, n=700, wrong=(200, 330), factor=2.5):
    rng = np.random.default_rng(seed)
    s = rng.uniform(1.0, 3.0, n)
    nu = rng.normal(0.0, 1.0, n) * s
    nu[::9] = np.nan  # no reading at these rows
    s[5::31] = 0.0  # nor here (a 1-sigma of 0: no reading used)
    nu[wrong[0]:wrong[1]] *= factor  # a stretch where the filter is lost
    return nu, s


def test_blocks_equal_a_loop_over_the_used_readings():
    nu, s = _innovations(1)
    blocks = jax.tree.map(np.asarray, innovation_blocks(nu, s, 50))
    used = np.flatnonzero(np.isfinite(nu) & (s > 0))
    starts = range(0, used.size, 50)
    assert blocks.nis.shape == (14,)  # ceil(700 / 50) slots, the rest empty
    for b, k in enumerate(starts):
        rows = used[k:k + 50]
        nis = np.sum((nu[rows] / s[rows]) ** 2)
        assert blocks.nis[b] == pytest.approx(nis, rel=1e-12)
        assert blocks.dof[b] == rows.size  # the last block takes the remainder
        assert blocks.p[b] == pytest.approx(chi2.sf(nis, rows.size), rel=1e-9, abs=1e-300)
        assert (blocks.first[b], blocks.last[b]) == (rows[0], rows[-1])
    empty = len(starts)
    assert np.all(blocks.dof[empty:] == 0) and np.all(blocks.p[empty:] == 1.0)
    assert np.all(blocks.first[empty:] == 700) and np.all(blocks.last[empty:] == -1)


def test_rows_flagged_are_the_spans_of_the_failing_blocks():
    nu, s = _innovations(2)
    flagged = implausible_rows(nu, s, block=50)
    blocks = innovation_blocks(nu, s, 50)
    expected = np.zeros(700, bool)
    for first, last, p in zip(*(np.asarray(a) for a in (blocks.first, blocks.last, blocks.p)),
                              strict=True):
        if p < 1e-3:
            expected[first:last + 1] = True
    np.testing.assert_array_equal(flagged, expected)
    assert flagged[230:300].all() and not flagged[:150].any() and not flagged[400:].any()
    assert int(implausible_block_count(nu, s, 50)) == int(np.sum(np.asarray(blocks.p) < 1e-3))
    assert not implausible_rows(np.full(4, np.nan), np.ones(4)).any()
    assert implausible_rows(np.zeros(0), np.zeros(0)).shape == (0,)


def test_a_consistent_filter_is_rarely_flagged():
    rng = np.random.default_rng(3)
    s = np.full((100, 4320), 1.5)  # 100 voyages of 12 h at a reading every 10 s
    nu = rng.normal(0.0, 1.0, s.shape) * s
    counts = np.asarray(jax.vmap(implausible_block_count)(nu, s))
    assert counts.sum() <= 40  # 7200 blocks at p = 1e-3: 7 expected


def test_traced_once_and_vmap_equals_the_loop():
    traces = []

    @jax.jit
    def count(nu, s):
        traces.append(1)
        return implausible_block_count(nu, s)

    runs = [_innovations(seed, wrong=(100 * seed, 100 * seed + 200)) for seed in range(4)]
    nu, s = (jnp.asarray(np.stack(a)) for a in zip(*runs, strict=True))
    looped = [int(count(nu[i], s[i])) for i in range(4)]
    assert len(traces) == 1  # one trace for every run of the same length
    np.testing.assert_array_equal(np.asarray(jax.vmap(count)(nu, s)), looped)
    assert min(looped) >= 1


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="block must be a whole number of readings >= 1; got 0"):
        innovation_blocks(np.ones(4), np.ones(4), 0)
    with pytest.raises(ValueError, match=r"1-D of one length; got shapes \(4,\) and \(3,\)"):
        innovation_blocks(np.ones(4), np.ones(3))
