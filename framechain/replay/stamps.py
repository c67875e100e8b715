"""Matching times: the nearest sample of a sorted stamp array, vectorised."""

from __future__ import annotations

import numpy as np

from framechain.arrays import IntArray


def nearest(sorted_stamps: IntArray, queries: IntArray) -> IntArray:
    """Index of the stamp nearest each query (ties go to the earlier one); ``sorted_stamps`` non-empty."""
    right = np.clip(np.searchsorted(sorted_stamps, queries), 0, sorted_stamps.size - 1)
    left = np.clip(right - 1, 0, sorted_stamps.size - 1)
    out: IntArray = np.where(np.abs(sorted_stamps[left] - queries) <= np.abs(sorted_stamps[right] - queries),
                             left, right)
    return out
