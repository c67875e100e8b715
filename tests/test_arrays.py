"""The distinct names of a column, by hashing, equal numpy's sort-based np.unique."""

from __future__ import annotations

import numpy as np
import pytest

from framechain.arrays import distinct_names, names_and_codes


@pytest.mark.parametrize("seed", range(5))
def test_names_and_codes_equal_np_unique(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pool = np.array(["base_link", "odom", "", "camera/optical", "b", "a", "ä_frame", "base"])
    values = pool[rng.integers(0, rng.integers(1, pool.size + 1), rng.integers(0, 300))]
    names, codes = names_and_codes(values)
    expected, inverse = np.unique(values, return_inverse=True)
    assert names.tolist() == expected.tolist()
    assert names.dtype == expected.dtype
    np.testing.assert_array_equal(codes, inverse.reshape(-1))
    assert codes.dtype == np.int64
    assert distinct_names(values) == expected.tolist()
    np.testing.assert_array_equal(names[codes], values)  # each row's name back from its code
