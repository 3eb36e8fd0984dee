"""hdrio.radiometry.grouped: per-group medians equal NumPy's to the bit, means to rounding."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hdrio.radiometry.grouped import group_edges, group_means, group_medians


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 400), st.integers(1, 30),
       st.booleans(), st.booleans())
def test_group_statistics_match_numpy(seed, size, count, ties, nans):
    rng = np.random.default_rng(seed)
    values = rng.normal(size=size) * 10.0 ** rng.integers(-20, 20)
    if ties:  # repeated values, as codes' estimates are
        values = np.round(values, 1)
    if nans and size:
        values[rng.integers(0, size, 1 + size // 50)] = np.nan
    keys = rng.integers(0, count, size)
    medians = group_medians(values, keys, count)
    order, edges = group_edges(keys, count)
    means = group_means(values, order, edges)
    for k in range(count):
        members = values[keys == k]
        # The members of group k, in their original order.
        assert np.array_equal(values[order[edges[k]:edges[k + 1]]], members, equal_nan=True)
        if members.size == 0:
            assert np.isnan(medians[k]) and np.isnan(means[k])
            continue
        # Bit for bit: the same middle values, the same half sum.
        assert np.array_equal(medians[k], np.median(members), equal_nan=True), k
        # Another summation order: within a few rounding errors of the sum's magnitude.
        scale = np.abs(members).sum() / members.size
        assert np.isnan(means[k]) == np.isnan(np.mean(members))
        if not np.isnan(means[k]):
            assert abs(means[k] - np.mean(members)) <= 8 * np.finfo(float).eps * scale, k
