"""Errors of the replay room, modelled on tf2's Lookup / Connectivity / Extrapolation tree."""

from __future__ import annotations

from framechain.errors import FramechainError
from framechain.timeline import format_stamp


class TransformLookupError(FramechainError):
    """A transform could not be looked up (root of the tf2-like tree)."""


class FrameGraphError(TransformLookupError):
    """The frame graph is not a tree: a frame with two parents, or a cycle."""


class ConnectivityError(TransformLookupError):
    """No path joins the two frames: an unknown frame or disconnected trees."""


class ExtrapolationError(TransformLookupError):
    """A time outside an edge's recorded span (tf2 ExtrapolationException)."""

    def __init__(self, parent: str, child: str, stamp_ns: int, first_ns: int, last_ns: int) -> None:
        self.parent = parent
        self.child = child
        self.stamp_ns = stamp_ns
        self.first_ns = first_ns
        self.last_ns = last_ns
        direction = "into the past" if stamp_ns < first_ns else "into the future"
        super().__init__(
            f"lookup at {format_stamp(stamp_ns)} s would extrapolate {direction} on edge {parent} -> {child}, "
            f"recorded from {format_stamp(first_ns)} s to {format_stamp(last_ns)} s"
        )
