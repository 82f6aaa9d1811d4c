"""The fused loop's recorder copy: index arrays as runs of slices (:func:`cpgsim.harness.cosim.fused.column_runs`)."""

from __future__ import annotations

import numpy as np

from cpgsim.harness.cosim.fused import column_runs


def test_runs_of_consecutive_columns():
    # by hand: 3 4 5 | 9 10 | 2 | 7
    runs = column_runs(np.array([3, 4, 5, 9, 10, 2, 7]))
    assert runs == [(slice(3, 6), slice(0, 3)), (slice(9, 11), slice(3, 5)), (slice(2, 3), slice(5, 6)),
                    (slice(7, 8), slice(6, 7))]
    assert column_runs(np.array([], dtype=int)) == []
    assert column_runs(np.arange(448) + 5) == [(slice(5, 453), slice(0, 448))]  # the hexapod's one run


def test_slice_copy_equals_the_index_array_copy():
    rng = np.random.default_rng(0)
    for _ in range(20):
        cols = rng.permutation(40)[: rng.integers(1, 40)]
        Y = rng.normal(size=(7, cols.size))
        expected, got = np.zeros((7, 40)), np.zeros((7, 40))
        expected[:, cols] = Y
        for dst, src in column_runs(cols):
            got[:, dst] = Y[:, src]
        np.testing.assert_array_equal(got, expected)
