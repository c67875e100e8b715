"""What a salvage read gave back and what it lost, said as notes (and as a dict for JSON).

A log is most often damaged when the robot failed (power lost, disk full, a killed recorder), and
that is the log its user most needs: every reader that salvages records here what it recovered
(messages per topic), what it knows it lost (per topic when an index says so) and which byte
ranges it skipped, so ``info`` and every output can say it.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class SkippedRange:
    """Bytes ``[start, end)`` of the file that could not be read, and why."""

    start: int
    end: int
    why: str

    @property
    def size(self) -> int:
        return max(self.end - self.start, 0)


@dataclass
class SalvageReport:
    """What a salvage read of one file gave back and lost."""

    #: Why a salvage was needed (e.g. "no footer or summary").
    reason: str
    recovered: Counter[str] = field(default_factory=Counter)
    lost: Counter[str] = field(default_factory=Counter)
    #: Damaged parts whose message count nobody can know (a chunk with no index after it).
    lost_unknown: int = 0
    skipped: list[SkippedRange] = field(default_factory=list)
    #: Set when the file ends inside a record: the byte where that record starts.
    cut_at: int | None = None
    #: The file's size in bytes (for the cut note).
    size: int = 0
    method: str = "by a linear scan"
    #: Damage read around without losing anything (e.g. a length field that was wrong).
    details: list[str] = field(default_factory=list)

    def skip(self, start: int, end: int, why: str) -> None:
        if end > start:
            self.skipped.append(SkippedRange(start, end, why))

    def cut(self, pos: int, why: str) -> None:
        """The file ends inside the record starting at ``pos``: skip to the end."""
        self.cut_at = pos
        self.skip(pos, self.size, why)

    @property
    def damaged(self) -> bool:
        return bool(self.skipped or self.lost or self.lost_unknown or self.cut_at is not None)

    def notes(self, unit: str = "message") -> list[str]:
        total = sum(self.recovered.values())
        notes = [f"{self.reason}: recovered {_count(total, unit)} {self.method}"
                 + (f" ({_per_topic(self.recovered)})" if self.recovered else "")]
        if self.cut_at is not None:
            notes.append(f"the file is cut short at byte {self.size}, inside the record that starts at byte "
                         f"{self.cut_at}")
        for r in self.skipped[:20]:
            notes.append(f"bytes {r.start}-{r.end} ({r.size} bytes) skipped: {r.why}")
        if len(self.skipped) > 20:
            rest = self.skipped[20:]
            notes.append(f"{len(rest)} more damaged ranges skipped ({sum(r.size for r in rest)} bytes)")
        notes.extend(self.details[:20])
        if self.lost:
            notes.append(f"lost {_count(sum(self.lost.values()), unit)} in damaged parts ({_per_topic(self.lost)})")
        if self.lost_unknown:
            notes.append(f"{self.lost_unknown} damaged part{'s' if self.lost_unknown != 1 else ''} lost "
                         f"with {unit}s of unknown count")
        return notes

    def to_dict(self) -> dict[str, Any]:
        return {
            "reason": self.reason,
            "recovered": dict(sorted(self.recovered.items())),
            "recovered_total": sum(self.recovered.values()),
            "lost": dict(sorted(self.lost.items())),
            "lost_total": sum(self.lost.values()),
            "lost_unknown_parts": self.lost_unknown,
            "skipped_bytes": [{"start": r.start, "end": r.end, "why": r.why} for r in self.skipped],
            "cut_at": self.cut_at,
            "details": list(self.details),
        }


def _count(n: int, unit: str) -> str:
    return f"{n} {unit}{'s' if n != 1 else ''}"


def _per_topic(counts: Counter[str]) -> str:
    items = sorted(counts.items())
    text = ", ".join(f"{t} {n}" for t, n in items[:12])
    return text + (f", and {len(items) - 12} more topics" if len(items) > 12 else "")


class StreamDecompressor:
    """Decompresses a chunk piece by piece (zstd, lz4, bz2 all stream; anything else is stored
    as is) and stops, keeping what came out, at the first stream error: a chunk cut short or
    damaged gives back every byte before the damage.
    """

    def __init__(self, compression: str) -> None:
        self.compression = compression
        self.failed = ""
        self.eof = False
        #: bytes fed after the end of the stream (or after it failed)
        self.unused = 0
        self._obj: Any = None
        if compression == "zstd":
            import zstandard

            self._obj = zstandard.ZstdDecompressor().decompressobj()
        elif compression == "lz4":
            import lz4.frame

            self._obj = lz4.frame.LZ4FrameDecompressor()
        elif compression == "bz2":
            import bz2

            self._obj = bz2.BZ2Decompressor()

    def feed(self, piece: bytes) -> bytes:
        if self._obj is None:
            return piece
        if self.eof or self.failed:
            self.unused += len(piece)
            return b""
        try:
            out: bytes = self._obj.decompress(piece)
        except Exception as err:  # a damaged stream: keep what came out before it
            self.failed = f"{self.compression} stream error ({type(err).__name__})"
            return b""
        self.eof = bool(self._obj.eof)
        if self.eof:
            self.unused = len(getattr(self._obj, "unused_data", b""))
        return out
