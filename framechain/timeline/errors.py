"""The errors of the model room: tables given inconsistent or invalid data."""

from __future__ import annotations

from framechain.errors import FramechainError

__all__ = ["InvalidCameraError", "InvalidTransformError", "TimelineError"]


class TimelineError(FramechainError):
    """A table of the model was given inconsistent or invalid data."""


class InvalidTransformError(TimelineError):
    """A transform sample is not finite or its quaternion is far from unit length."""

    def __init__(self, parent: str, child: str, stamp_ns: int, what: str, source: str = "") -> None:
        self.parent = parent
        self.child = child
        self.stamp_ns = stamp_ns
        self.what = what
        self.source = source
        where = f" on {source}" if source else ""
        super().__init__(f"transform {parent} -> {child} at stamp {stamp_ns} ns{where}: {what}")


class InvalidCameraError(TimelineError):
    """A camera model is unusable (K all zero, non-positive focal length, no size)."""

    def __init__(self, frame: str, what: str, source: str = "") -> None:
        self.frame = frame
        self.what = what
        self.source = source
        where = f" on {source}" if source else ""
        super().__init__(f"camera {frame!r}{where}: {what}")
