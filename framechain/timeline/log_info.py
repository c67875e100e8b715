"""What a log holds, as its reader found it: format, span, topics and the quirks noticed (from its index,
or a linear scan when it has none). Every reader fills one; the run carries it beside the Timeline."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

LogFormat = Literal["mcap", "rosbag1", "rosbag2", "lerobot"]


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a log: name, message type (``pkg/msg/Type`` or a Foxglove schema), count, rate."""

    name: str
    msgtype: str
    count: int
    rate_hz: float
    encoding: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name, "msgtype": self.msgtype, "count": self.count,
            "rate_hz": self.rate_hz, "encoding": self.encoding,
        }


@dataclass(frozen=True)
class LogInfo:
    """What a log holds, from its index (or a linear scan when it has none).

    ``start_ns``/``end_ns`` are log (receive) times of the first and last message. ``notes`` are
    the quirks found, one sentence each: salvaged or lost messages, header stamps in another clock
    than the log time, stamps that go backwards, rows dropped as invalid.
    """

    format: LogFormat
    path: Path
    start_ns: int
    end_ns: int
    topics: tuple[TopicInfo, ...]
    notes: tuple[str, ...] = ()
    container: str = ""  # e.g. "mcap (ros2)", "rosbag2 (sqlite3, zstd per file)"
    message_count: int = 0
    #: What a salvage read of a damaged log recovered and lost (messages per topic, bytes skipped).
    salvage: dict[str, Any] | None = None

    @property
    def duration_s(self) -> float:
        return max(self.end_ns - self.start_ns, 0) * 1e-9

    def topic(self, name: str) -> TopicInfo | None:
        return next((t for t in self.topics if t.name == name), None)

    def with_notes(self, notes: list[str] | tuple[str, ...]) -> LogInfo:
        merged = list(self.notes)
        merged.extend(n for n in notes if n not in merged)
        return LogInfo(
            format=self.format, path=self.path, start_ns=self.start_ns, end_ns=self.end_ns, topics=self.topics,
            notes=tuple(merged), container=self.container, message_count=self.message_count,
            salvage=self.salvage,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": self.format, "container": self.container, "path": str(self.path),
            "start_ns": self.start_ns, "end_ns": self.end_ns, "duration_s": self.duration_s,
            "message_count": self.message_count, "topics": [t.to_dict() for t in self.topics],
            "notes": list(self.notes),
            **({"salvage": self.salvage} if self.salvage is not None else {}),
        }


__all__ = ["LogFormat", "LogInfo", "TopicInfo"]
