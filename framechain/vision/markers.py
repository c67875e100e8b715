"""Markers found in logged images: ArUco / AprilTag dictionaries with OpenCV's ArucoDetector.

With ``topics.image`` and ``evidence.markers: {dictionary: DICT_5X5_1000, size_m: 0.14}`` in the
chain, each image on that topic (``sensor_msgs/Image`` mono8, rgb8, bgr8, rgba8, bgra8, or
``CompressedImage`` JPEG/PNG) is searched for markers; each marker becomes a detection with
its four corners (ArUco's order: clockwise from the top-left seen from the front), resolved into
an observation like any tag corners (:mod:`framechain.adapters.messages.fiducials`).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from framechain.config.errors import ChainConfigError
from framechain.vision.opencv import require_cv2

_CHANNELS = {"mono8": 1, "8uc1": 1, "rgb8": 3, "bgr8": 3, "8uc3": 3, "rgba8": 4, "bgra8": 4, "8uc4": 4}


def dictionary_id(name: str, where: str = "chain") -> int:
    """OpenCV's id of a predefined dictionary: ``DICT_5X5_1000``, ``5x5_1000``, ``DICT_APRILTAG_36h11``
    (``where``: the chain file, to start the error with)."""
    cv2 = require_cv2()
    key = name.strip().upper()
    if not key.startswith("DICT_"):
        key = f"DICT_{key}"
    known = sorted({d.upper() for d in dir(cv2.aruco) if d.startswith("DICT_")})
    if key not in known:
        raise ChainConfigError(where, f"evidence.markers.dictionary {name!r} is not an OpenCV dictionary; "
                               f"known: {', '.join(known)}")
    return int(getattr(cv2.aruco, next(d for d in dir(cv2.aruco) if d.upper() == key)))


def image_pixels(msg: Any) -> npt.NDArray[np.uint8] | None:
    """Grey (H, W) uint8 pixels of an Image or CompressedImage; None for encodings not handled."""
    cv2 = require_cv2()
    fmt = getattr(msg, "format", None)
    if fmt is not None and not hasattr(msg, "encoding"):
        if "compressedDepth" in fmt:
            return None
        data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
        grey = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
        return None if grey is None else np.asarray(grey, dtype=np.uint8)
    encoding = str(msg.encoding).lower()
    channels = _CHANNELS.get(encoding)
    if channels is None:
        return None
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if raw.size < h * step or step < w * channels:
        return None
    rows = raw[: h * step].reshape(h, step)[:, : w * channels]
    if channels == 1:
        return np.ascontiguousarray(rows)
    pix = rows.reshape(h, w, channels)
    code = {("rgb8", 3): cv2.COLOR_RGB2GRAY, ("rgba8", 4): cv2.COLOR_RGBA2GRAY, ("bgra8", 4): cv2.COLOR_BGRA2GRAY}
    conversion = code.get((encoding, channels), cv2.COLOR_BGR2GRAY if channels == 3 else cv2.COLOR_BGRA2GRAY)
    return np.asarray(cv2.cvtColor(pix, conversion), dtype=np.uint8)


class CornerRows(Protocol):
    """Where found markers go: the fiducial rows of the log being read
    (:class:`framechain.adapters.messages.fiducials.FiducialRows`)."""

    def add_corners(self, topic: str, log_ns: int, stamp_ns: int, frame: str, label: str, corners: list[float], *,
                    from_image: bool = False) -> None: ...


class MarkerFinder:
    """Finds markers of one dictionary in images and appends them to the log's fiducial rows."""

    def __init__(self, dictionary: str, rows: CornerRows) -> None:
        cv2 = require_cv2()
        self.dictionary = dictionary
        self.rows = rows
        params = cv2.aruco.DetectorParameters()
        # The default leaves corners on whole pixels; PnP depth needs sub-pixel corners.
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self.detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(dictionary_id(dictionary)), params)
        self.unreadable: dict[str, int] = {}
        self.images: dict[str, int] = {}

    def image(self, topic: str, log_ns: int, msg: Any) -> None:
        """Handler for one Image or CompressedImage of the chain's image topic."""
        grey = image_pixels(msg)
        if grey is None:
            self.unreadable[topic] = self.unreadable.get(topic, 0) + 1
            return
        header = msg.header
        stamp = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
        self.search(topic, log_ns, stamp, header.frame_id, grey)

    def search(self, topic: str, log_ns: int, stamp_ns: int, frame: str, grey: npt.NDArray[np.uint8]) -> None:
        """Find the markers in one grey image (a decoded message, a video frame) taken at ``stamp_ns`` by ``frame``."""
        self.images[topic] = self.images.get(topic, 0) + 1
        corners, ids, _ = self.detector.detectMarkers(grey)
        if ids is None:
            return
        for marker_id, quad in zip(np.asarray(ids).reshape(-1).tolist(), corners, strict=True):
            # ArUco reports corners on the pixel grid whose centre of the top-left pixel is (0, 0).
            flat = np.asarray(quad, dtype=np.float64).reshape(-1).tolist()
            self.rows.add_corners(topic, log_ns, stamp_ns, frame, str(int(marker_id)), flat, from_image=True)

    def notes(self) -> list[str]:
        out = [f"topic {t}: {n} image{'s' if n != 1 else ''} in an encoding markers cannot be searched in "
               "(expected mono8, rgb8, bgr8, rgba8, bgra8, or JPEG/PNG); skipped"
               for t, n in sorted(self.unreadable.items())]
        out.extend(f"topic {t}: {n} image{'s' if n != 1 else ''} searched for {self.dictionary} markers"
                   for t, n in sorted(self.images.items()))
        return out
