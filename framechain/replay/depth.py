"""Depth at an observation's pixel: the nearest depth frame in time, a robust window median."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray, IntArray
from framechain.replay.stamps import nearest
from framechain.timeline import DepthFrameTable, normalize_frame


@dataclass(frozen=True)
class DepthSamples:
    """Per observation: depth in metres (NaN: none), the frame used (-1: none) and its stamp."""

    depth_m: FloatArray
    frame_index: IntArray
    stamp_ns: IntArray


def sample_depth(
    frames: DepthFrameTable,
    camera_frame: str,
    stamps_ns: IntArray,
    u: FloatArray,
    v: FloatArray,
    *,
    max_gap_ns: int,
    window: int = 5,
) -> DepthSamples:
    """Median of the valid depths (finite, > 0) in a ``window`` x ``window`` box around each pixel.

    The depth frame is the one of ``camera_frame`` (registered depth) nearest in header stamp,
    within ``max_gap_ns``. Frames are decoded lazily, once each, and only where an observation
    needs them; the window medians of all observations on one frame are computed together.
    """
    n = stamps_ns.shape[0]
    depth = np.full(n, np.nan)
    index = np.full(n, -1, dtype=np.int64)
    stamp = np.zeros(n, dtype=np.int64)
    mine = np.flatnonzero(frames.frame == normalize_frame(camera_frame))
    if mine.size == 0 or n == 0:
        return DepthSamples(depth, index, stamp)
    order = mine[np.argsort(frames.stamp_ns[mine], kind="stable")]
    frame_stamps = frames.stamp_ns[order]
    pick = nearest(frame_stamps, stamps_ns)
    near = np.abs(frame_stamps[pick] - stamps_ns) <= max_gap_ns
    index[near] = order[pick[near]]
    stamp[near] = frame_stamps[pick[near]]
    half = window // 2
    offsets = np.arange(-half, half + 1)
    # Observations grouped by frame in one sort; their windows come in one call (kept at read time, or
    # cut from their frames, each loaded once), then the medians of every observation are computed together.
    used = np.flatnonzero(near)
    if used.size == 0:
        return DepthSamples(depth, index, stamp)
    used = used[np.argsort(index[used], kind="stable")]
    rows_used = index[used]
    centre_rows = np.rint(v[used]).astype(np.int64)
    centre_cols = np.rint(u[used]).astype(np.int64)
    windows = frames.load_windows(rows_used, centre_rows, centre_cols, half)
    rows = centre_rows[:, None] + offsets[None, :]
    cols = centre_cols[:, None] + offsets[None, :]
    # Window pixels outside the image do not exist: they must not repeat the border pixels.
    rows_in = (rows >= 0) & (rows < frames.height[rows_used][:, None])
    cols_in = (cols >= 0) & (cols < frames.width[rows_used][:, None])
    inside = rows_in[:, :, None] & cols_in[:, None, :]
    patch = windows.reshape(used.size, -1).astype(np.float64)
    good = inside.reshape(used.size, -1) & np.isfinite(patch) & (patch > 0)
    valid = good.any(axis=1)
    depth[used[valid]] = _median_of_good(patch[valid], good[valid])
    return DepthSamples(depth, index, stamp)


def _median_of_good(values: FloatArray, good: npt.NDArray[np.bool_]) -> FloatArray:
    """Row-wise median of the ``good`` entries (each row has one at least), as ``np.nanmedian`` gives it.

    np.nanmedian on a few rows takes numpy's masked-array path, about 0.6 ms a call: a sort with
    the bad entries last and the middle one or two picked is the same median at a fraction.
    """
    ordered = np.sort(np.where(good, values, np.inf), axis=1)
    count = good.sum(axis=1)
    rows = np.arange(values.shape[0])
    low = ordered[rows, (count - 1) // 2]
    high = ordered[rows, count // 2]
    median: FloatArray = 0.5 * (low + high)
    return median
