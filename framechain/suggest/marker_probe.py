"""Which marker dictionary, if any, finds markers in a log's first few images (for ``info``'s hints).

A bounded look: the first :data:`PROBE_IMAGES` images of one topic, each searched with the common
dictionaries of :data:`COMMON_DICTIONARIES` (a few tens of milliseconds per image and dictionary).
It never says markers were found unless a dictionary found them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from framechain.adapters.errors import AdapterError
from framechain.errors import FramechainError

#: The dictionaries tried, most common first (ArUco 5x5 and 4x4, the 6x6 of OpenCV's board samples,
#: AprilTag 36h11, and the original ArUco).
COMMON_DICTIONARIES = ("DICT_4X4_50", "DICT_5X5_1000", "DICT_6X6_250", "DICT_APRILTAG_36h11", "DICT_ARUCO_ORIGINAL")
PROBE_IMAGES = 3


@dataclass(frozen=True)
class MarkerProbe:
    """Markers found per dictionary in the first ``images`` images of ``topic``."""

    topic: str
    images: int
    found: dict[str, int]

    @property
    def best(self) -> str | None:
        """The dictionary that found the most markers (None when none found any)."""
        name, count = max(self.found.items(), key=lambda item: item[1], default=(None, 0))
        return name if count > 0 else None

    def text(self) -> str:
        """``3 markers of DICT_5X5_1000 in the first 1 image`` or ``no markers of DICT_4X4_50, ...``."""
        first = f"the first {self.images} image{'s' if self.images != 1 else ''} of {self.topic}"
        best = self.best
        if best is None:
            return f"no markers of {', '.join(self.found)} in {first}"
        return f"{self.found[best]} markers of {best} in {first}"


def first_images(path: str | Path, topic: str, n: int = PROBE_IMAGES) -> list[Any]:
    """The first ``n`` decoded messages of ``topic`` (fewer where the log has fewer or cannot say)."""
    from framechain.adapters.api import detect
    from framechain.adapters.formats.mcap.reader import McapLog
    from framechain.adapters.formats.rosbag.reader import RosbagsLog

    fmt, target, _notes = detect(path)
    if fmt == "mcap":
        mcap = McapLog(target)
        try:
            if not mcap.indexed:  # a scan of an unindexed file is not a quick look
                return []
            times = mcap._locations(topic).log_time_ns[:n].tolist()
            return [mcap.fetch(topic, t, times[:i].count(t)) for i, t in enumerate(times)]
        finally:
            mcap.close()
    bag = RosbagsLog(target)
    try:
        if bag.salvaged is not None:
            return []
        conns = [c for c in bag.reader.connections if c.topic == topic]
        out = []
        try:
            for conn, _t, raw in bag.reader.messages(connections=conns):
                out.append(bag.decoder(conn.msgtype, topic)(raw))
                if len(out) >= n:
                    break
        except Exception:  # a damaged chunk (rosbags raises the decompressor's error): probe what came before
            return out
        return out
    finally:
        bag.close()


def probe_markers(
    path: str | Path, topic: str, dictionaries: Sequence[str] = COMMON_DICTIONARIES, n: int = PROBE_IMAGES,
) -> MarkerProbe | None:
    """Markers per dictionary in the first ``n`` images of ``topic``; None when none could be read
    (no OpenCV, an encoding markers cannot be searched in, an unreadable log)."""
    try:
        from framechain.vision.markers import dictionary_id, image_pixels
        from framechain.vision.opencv import require_cv2

        cv2 = require_cv2()
        greys = [g for g in (image_pixels(m) for m in first_images(path, topic, n)) if g is not None]
    except (FramechainError, AdapterError, OSError):
        return None
    if not greys:
        return None
    found: dict[str, int] = {}
    for name in dictionaries:
        detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(dictionary_id(name)),
                                           cv2.aruco.DetectorParameters())
        found[name] = sum(int(np.asarray(ids).size) for ids in (detector.detectMarkers(g)[1] for g in greys)
                          if ids is not None)
    return MarkerProbe(topic, len(greys), found)


__all__ = ["COMMON_DICTIONARIES", "PROBE_IMAGES", "MarkerProbe", "first_images", "probe_markers"]
