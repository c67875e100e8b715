"""An episode's wall-clock time, where the dataset stores one.

LeRobot's format stores none: ``timestamp`` is seconds from the episode's start and restarts at 0 each episode
(huggingface/lerobot#1893 asks for a start time). Some recorders add a per-frame column of Unix times. A
scalar feature (int64 or float64) whose name speaks of time (``time`` or ``stamp`` in it; LeRobot's own
``timestamp`` aside) and whose first value reads as a date between 2000 and 2100, in seconds, milliseconds,
microseconds or nanoseconds, is taken for one: the four ranges are a thousandfold apart, so at most one fits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from framechain.adapters.lerobot.reader import INDEX_COLUMNS, DatasetReader, EpisodeFrames

__all__ = ["wall_clock_features", "wall_clock_start_ns"]

#: 2000-01-01 and 2100-01-01 in seconds since the epoch.
_EARLIEST_S, _LATEST_S = 946_684_800, 4_102_444_800
#: Nanoseconds per unit of a Unix time column: s, ms, us, ns.
_UNITS_NS = (1_000_000_000, 1_000_000, 1_000, 1)


def wall_clock_features(reader: DatasetReader) -> list[str]:
    """The dataset's features that may hold wall-clock times (by name and type; their values decide)."""
    return [key for key, feat in reader.features.items()
            if key not in INDEX_COLUMNS and feat.dtype in ("int64", "float64") and feat.size == 1
            and ("time" in key.lower() or "stamp" in key.lower())]


def wall_clock_start_ns(frames: EpisodeFrames, features: Sequence[str]) -> tuple[str, int] | None:
    """(feature, ns since the epoch) of the episode's first row, from the first of ``features`` (read with the
    episode) whose first value is a date; None when none is."""
    for key in features:
        column = frames.columns.get(key)
        if column is None or len(column) == 0:
            continue
        first = column.reshape(len(column), -1)[0, 0]
        value = float(first)
        if not math.isfinite(value):
            continue
        for unit_ns in _UNITS_NS:
            if _EARLIEST_S <= value * unit_ns / 1e9 <= _LATEST_S:
                # integer columns stay exact: nanoseconds since the epoch are past a float's 53-bit mantissa
                exact = isinstance(first, np.integer | int)
                return key, int(first) * unit_ns if exact else round(value * unit_ns)
    return None
