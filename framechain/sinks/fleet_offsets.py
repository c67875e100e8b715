"""The fleet's video/state time offsets: one per episode (its camera's own motion), their spread, and which disagree.

Episodes of one recording share a camera and a recorder, so their offsets should agree: an episode
whose offset departs from the fleet's median by more than twice what it could find a latency of (its
bound: two half-widths of its 95% interval, at least 5 ms; the interval alone holds the resampling
spread, not the few milliseconds generated episodes of one recording differ by, up to 4 ms) disagrees
(a camera that was restarted, a recorder that dropped frames, a different rig). Rendered into the fleet
report from the fleet table's per-log columns ``video_camera``, ``video_offset_s``, ``video_offset_low_s``,
``video_offset_high_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from framechain.analysis.egomotion.bounds import offset_bound_s
from framechain.analysis.egomotion.recording import DEPARTURE_BOUNDS
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
    """Every log's offset, the median, the spread, and the logs that disagree."""

    rows: tuple[OffsetRow, ...]
    median_s: float
    std_s: float

    @property
    def disagreeing(self) -> tuple[OffsetRow, ...]:
        return tuple(r for r in self.rows if not r.agrees)

    def summary(self) -> str:
        lo, hi = min(r.offset_s for r in self.rows), max(r.offset_s for r in self.rows)
        text = (f"{len(self.rows)} logs: median {self.median_s * 1e3:+.1f} ms, standard deviation "
                f"{self.std_s * 1e3:.1f} ms, range {lo * 1e3:+.1f} .. {hi * 1e3:+.1f} ms. ")
        off = self.disagreeing
        if not off:
            return text + "Every log's offset is within twice its bound of the median: the offsets agree."
        names = ", ".join(r.unit for r in off[:10]) + (", ..." if len(off) > 10 else "")
        return (text + f"{len(off)} log(s) whose offset departs from the median by more than twice its bound disagree: "
                f"{names}.")


def video_offsets(table: pa.Table) -> OffsetSpread | None:
    """The offsets of the fleet table's logs (one per log; None when no log has one)."""
    if "video_offset_s" not in table.column_names:
        return None
    seen: dict[str, tuple[str, str, float, float, float]] = {}
    for row in table.to_pylist():
        if row["video_offset_s"] is None or row["key"] in seen:
            continue
        low = row["video_offset_low_s"] if row["video_offset_low_s"] is not None else row["video_offset_s"]
        high = row["video_offset_high_s"] if row["video_offset_high_s"] is not None else row["video_offset_s"]
        seen[row["key"]] = (row["unit"], row["video_camera"] or "", row["video_offset_s"], low, high)
    if not seen:
        return None
    offsets = np.array([v[2] for v in seen.values()])
    median = float(np.median(offsets))
    # An episode may lie twice its own bound from the median (the median has an error of its own).
    rows = tuple(OffsetRow(unit, camera, offset, low, high,
                           bool(abs(offset - median) <= DEPARTURE_BOUNDS * offset_bound_s((low, high))))
                 for unit, camera, offset, low, high in seen.values())
    return OffsetSpread(rows=rows, median_s=median, std_s=float(offsets.std(ddof=1)) if offsets.size > 1 else 0.0)


def offset_sections(spread: OffsetSpread | None) -> list[Section]:
    """The fleet report's section on the offsets (none when no log has one)."""
    if spread is None:
        return []
    return [Section(Heading("Video/state time offset per log"),
                    (Paragraph(spread.summary()), table(OFFSET_COLUMNS, (r.cells() for r in spread.rows))),
                    compact=True)]
