"""What the adapters return: a log read into the Timeline model, with what the log holds (LogInfo)."""

from __future__ import annotations

from dataclasses import dataclass, field

from framechain.timeline import LogInfo, Timeline


@dataclass(frozen=True)
class LoadedLog:
    """A log read into the Timeline model, with what the log holds and what was noticed."""

    timeline: Timeline
    info: LogInfo
    #: topic -> message kind for every topic that was decoded.
    decoded_topics: dict[str, str] = field(default_factory=dict)
