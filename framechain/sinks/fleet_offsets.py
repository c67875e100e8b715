"""The fleet's video/state time offsets: per camera, one per episode (its own motion), their spread, and which disagree.

Episodes of one recording share a camera and a recorder, so their offsets should agree: an episode
whose offset departs from the fleet's median by more than twice what it could find a latency of (its
bound: two half-widths of its 95% interval, at least 5 ms; the interval alone holds the resampling
spread, not the few milliseconds generated episodes of one recording differ by, up to 4 ms) disagrees
(a camera that was restarted, a recorder that dropped frames, a different rig). Each camera is judged
against its own median. Rendered into the fleet report from every camera of a recording fitted across its
episodes, and elsewhere from the fleet table's per-log columns ``video_camera``, ``video_offset_s``,
``video_offset_low_s``, ``video_offset_high_s`` (the chain camera's).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from framechain.analysis.egomotion.bounds import offset_bound_s
from framechain.analysis.egomotion.recording import DEPARTURE_BOUNDS, CameraRecordingFit
from framechain.sinks.document import Heading, Paragraph, Section, table

__all__ = ["OffsetRow", "OffsetSpread", "offset_sections", "video_offsets"]

OFFSET_COLUMNS = ("log", "camera", "offset", "95% interval", "within twice its bound of the median")


@dataclass(frozen=True)
class OffsetRow:
    """One log's offset (s) and interval, and whether it is within its bound of the fleet's median."""

    unit: str
    camera: str
    offset_s: float
    low_s: float
    high_s: float
    agrees: bool

    def cells(self) -> list[str]:
        return [self.unit, self.camera, f"{self.offset_s * 1e3:+.1f} ms",
                f"{self.low_s * 1e3:+.1f} .. {self.high_s * 1e3:+.1f} ms", "yes" if self.agrees else "no"]


@dataclass(frozen=True)
class OffsetSpread:
    """One camera's offset in every log that measured it, the median, the spread, and the logs that disagree."""

    camera: str
    rows: tuple[OffsetRow, ...]
    median_s: float
    std_s: float

    @property
    def disagreeing(self) -> tuple[OffsetRow, ...]:
        return tuple(r for r in self.rows if not r.agrees)

    def summary(self) -> str:
        lo, hi = min(r.offset_s for r in self.rows), max(r.offset_s for r in self.rows)
        text = (f"Camera {self.camera}, {len(self.rows)} log{'s' if len(self.rows) != 1 else ''}: median "
                f"{self.median_s * 1e3:+.1f} ms, standard deviation {self.std_s * 1e3:.1f} ms, range "
                f"{lo * 1e3:+.1f} .. {hi * 1e3:+.1f} ms. ")
        off = self.disagreeing
        if not off:
            return text + "Every log's offset is within twice its bound of the median: the offsets agree."
        names = ", ".join(r.unit for r in off[:10]) + (", ..." if len(off) > 10 else "")
        return (text + f"{len(off)} log(s) whose offset departs from the median by more than twice its bound disagree: "
                f"{names}.")


def video_offsets(table: pa.Table, recordings: Mapping[str, Sequence[CameraRecordingFit]] | None = None
                  ) -> tuple[OffsetSpread, ...]:
    """Per camera, its offset in every log: each camera of each episode of a recording fitted across its episodes
    (``recordings``, by dataset), and the fleet table's one camera per log elsewhere (none: no log has one)."""
    recordings = recordings or {}
    units: dict[tuple[str, int | None], str] = {}
    found: dict[str, dict[str, tuple[str, float, float, float]]] = {}  # camera -> log key -> (unit, offset, interval)
    columns = ("log", "episode", "unit", "key", "video_camera", "video_offset_s", "video_offset_low_s",
               "video_offset_high_s")
    rows = (table.select([c for c in columns if c in table.column_names]).to_pylist()
            if "video_offset_s" in table.column_names else [])
    for row in rows:
        units[(str(row["log"]), row["episode"])] = str(row["unit"])
        if row["video_offset_s"] is None or str(row["log"]) in recordings:
            continue
        low = row["video_offset_low_s"] if row["video_offset_low_s"] is not None else row["video_offset_s"]
        high = row["video_offset_high_s"] if row["video_offset_high_s"] is not None else row["video_offset_s"]
        found.setdefault(row["video_camera"] or "", {}).setdefault(row["key"], (
            str(row["unit"]), row["video_offset_s"], low, high))
    for log, cameras in recordings.items():
        for fit in cameras:
            for e in fit.explained:  # as the recording's median: an unexplained episode's offset is no measurement
                unit = units.get((log, e.episode), f"{log} episode {e.episode}")
                found.setdefault(e.camera, {})[unit] = (unit, e.offset_s, *e.offset_interval_s)
    return tuple(_spread(camera, list(logs.values())) for camera, logs in sorted(found.items()))


def _spread(camera: str, logs: Sequence[tuple[str, float, float, float]]) -> OffsetSpread:
    offsets = np.array([offset for _unit, offset, _low, _high in logs])
    median = float(np.median(offsets))
    # An episode may lie twice its own bound from the median (the median has an error of its own).
    rows = tuple(OffsetRow(unit, camera, offset, low, high,
                           bool(abs(offset - median) <= DEPARTURE_BOUNDS * offset_bound_s((low, high))))
                 for unit, offset, low, high in logs)
    return OffsetSpread(camera=camera, rows=rows, median_s=median,
                        std_s=float(offsets.std(ddof=1)) if offsets.size > 1 else 0.0)


def offset_sections(spreads: Sequence[OffsetSpread]) -> list[Section]:
    """The fleet report's section on the offsets, a summary and a table per camera (none when no log has one)."""
    if not spreads:
        return []
    blocks = [block for spread in spreads for block in (
        Paragraph(spread.summary()), table(OFFSET_COLUMNS, (r.cells() for r in spread.rows)))]
    return [Section(Heading("Video/state time offset per log"), tuple(blocks), compact=True)]
