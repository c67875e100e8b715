"""Header stamps: ROS and Foxglove times in nanoseconds, and the topics whose header stamps are in another clock
than their log times (simulation time, a late recorder)."""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.arrays import distinct_names
from framechain.timeline import Timeline

__all__ = ["CLOCK_GAP_NOTE_S", "NS", "fox_stamp_ns", "ros_stamp_ns", "stamp_notes"]

NS = 1_000_000_000
#: Header stamps further than this from log time are pointed out (sim time, another clock).
CLOCK_GAP_NOTE_S = 10.0


def ros_stamp_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` (ROS 1 and ROS 2 as rosbags decodes both) in nanoseconds."""
    return int(stamp.sec) * NS + int(stamp.nanosec)


def fox_stamp_ns(stamp: Any) -> int:
    """``google.protobuf.Timestamp`` (or Foxglove JSON ``{sec, nsec}`` wrapped) in nanoseconds."""
    return int(stamp.seconds) * NS + int(stamp.nanos)


def stamp_notes(timeline: Timeline) -> list[str]:
    """Point out topics whose header stamps are in another clock than their log times."""
    notes: list[str] = []
    per_topic: dict[str, list[npt.NDArray[np.int64]]] = defaultdict(list)
    tables: list[tuple[Any, npt.NDArray[np.bool_] | None]] = [
        (timeline.transforms, ~timeline.transforms.is_static), (timeline.cameras, None),
        (timeline.observations, None), (timeline.joint_states, None), (timeline.points, None),
        (timeline.depth_frames, None),
    ]
    for table, mask in tables:
        if not len(table):
            continue
        sel = np.ones(len(table), dtype=bool) if mask is None else mask
        for t in distinct_names(table.source[sel]):
            rows = sel & (table.source == t)
            per_topic[t].append(np.stack([table.stamp_ns[rows], table.log_time_ns[rows]]))
    for topic, parts in sorted(per_topic.items()):
        both = np.concatenate(parts, axis=1)
        stamps, logs = both[0], both[1]
        gap_s = float(np.median(logs - stamps)) * 1e-9
        if abs(gap_s) <= CLOCK_GAP_NOTE_S or topic.endswith(".csv") or topic.endswith(".parquet"):
            continue
        stamp_s, log_s = float(np.median(stamps)) * 1e-9, float(np.median(logs)) * 1e-9
        if stamp_s < 1e8 <= log_s:
            notes.append(
                f"topic {topic}: header stamps are simulation time (about {stamp_s:.1f} s) while log times are wall "
                f"clock ({log_s:.0f} s since the epoch); lookups use the header stamps, never the log times"
            )
        elif log_s < 1e8 <= stamp_s:
            notes.append(
                f"topic {topic}: log times start near zero ({log_s:.3f} s) while header stamps are wall clock "
                f"({stamp_s:.0f} s since the epoch); lookups use the header stamps"
            )
        else:
            side = "behind" if gap_s > 0 else "ahead of"
            notes.append(
                f"topic {topic}: header stamps run {abs(gap_s):.1f} s {side} log time (another clock or a late "
                "recorder); lookups use the header stamps"
            )
    return notes
