"""The NumPy array types every room annotates with (one definition, imported everywhere), and the one
lookup of rows by key (an observation by its ``obs_id``)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
StrArray = npt.NDArray[np.str_]


def rows_of(keys: IntArray, wanted: npt.ArrayLike) -> IntArray:
    """The row of ``keys`` holding each of ``wanted``, -1 where none (the first such row in ``keys``' order
    when a key repeats): one stable sort and a binary search, the lookup of rows by ``obs_id``."""
    want = np.asarray(wanted, dtype=np.int64)
    out = np.full(want.shape, -1, dtype=np.int64)
    if keys.size == 0 or want.size == 0:
        return out
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    pos = np.clip(np.searchsorted(ordered, want), 0, keys.size - 1)
    hit = ordered[pos] == want
    out[hit] = order[pos[hit]]
    return out
