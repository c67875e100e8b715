"""The vocabulary of DESIGN.md every room shares: the three hops of the chain, the closed set of
faults and the hop each lives on, and why an observation was not replayed.

The replay names hops and rejections, the analysis fits faults, the adapters explain rejections
(``framechain info``, "why nothing replayed") and the scene generator injects faults with maths of
its own; so this imports nothing of framechain.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum


class HopName(StrEnum):
    """The three hops of the chain (DESIGN.md)."""

    PIXEL_TO_CAMERA = "pixel_to_camera"
    CAMERA_TO_BODY = "camera_to_body"
    BODY_TO_WORLD = "body_to_world"


class Fault(StrEnum):
    """A fault of the chain; values are the ``fault`` strings of attribution.json."""

    LATENCY = "latency"
    AXIS_FLIP = "axis_flip"
    MISSING_ROTATION = "missing_rotation"
    ROTATION_ERROR = "rotation_error"
    DEPTH_SCALE = "depth_scale"
    INTRINSICS = "intrinsics"
    WRONG_WORLD_FRAME = "wrong_world_frame"
    INVERTED_TRANSFORM = "inverted_transform"
    #: another frame of the camera at the same orientation looked up (a sibling camera's optical
    #: frame, the depth frame for the colour frame): the error is the offset between the two
    WRONG_CAMERA_FRAME = "wrong_camera_frame"
    #: a camera's mount is off in position (found between the cameras of a rig)
    TRANSLATION_ERROR = "translation_error"


#: The hop each fault lives on (inverted_transform may live on either transform hop; latency also
#: on camera_to_body for a moving camera).
FAULT_HOPS: dict[Fault, HopName] = {
    Fault.LATENCY: HopName.BODY_TO_WORLD,
    Fault.AXIS_FLIP: HopName.CAMERA_TO_BODY,
    Fault.MISSING_ROTATION: HopName.CAMERA_TO_BODY,
    Fault.ROTATION_ERROR: HopName.CAMERA_TO_BODY,
    Fault.DEPTH_SCALE: HopName.PIXEL_TO_CAMERA,
    Fault.INTRINSICS: HopName.PIXEL_TO_CAMERA,
    Fault.WRONG_WORLD_FRAME: HopName.BODY_TO_WORLD,
    Fault.INVERTED_TRANSFORM: HopName.CAMERA_TO_BODY,
    Fault.WRONG_CAMERA_FRAME: HopName.CAMERA_TO_BODY,
    Fault.TRANSLATION_ERROR: HopName.CAMERA_TO_BODY,
}



class RejectReason(StrEnum):
    """Why an observation was not replayed; stable codes used in every output."""

    OTHER_CAMERA = "other_camera"  # detected in another camera (one with its own CameraInfo)
    IGNORED_LABEL = "ignored_label"  # an object the chain declares as moving (evidence.ignore_labels)
    NO_CAMERA_INFO = "no_camera_info"
    OUTSIDE_IMAGE = "outside_image"
    NO_DEPTH = "no_depth"
    DEPTH_INVALID = "depth_invalid"  # not finite or not positive
    MISSING_EDGE = "missing_edge"  # no path between the frames
    EXTRAPOLATION = "extrapolation"  # outside a transform's recorded span


@dataclass(frozen=True)
class NothingReplayed:
    """Why a replay replayed no observation: every observation's rejection, counted by reason.

    ``rejected`` holds the replay's own reasons; ``rejected_at_read`` the detections the reader could
    not turn into observations (fiducial codes such as ``no_tag_size``), which count in ``total`` too.
    """

    total: int
    rejected: Mapping[RejectReason, int] = field(default_factory=dict)
    rejected_at_read: Mapping[str, int] = field(default_factory=dict)

    def ranked(self) -> list[tuple[RejectReason | str, int]]:
        """Every reason with its count, most first (ties: the replay's reasons by code, then the reader's)."""
        merged: dict[RejectReason | str, int] = {r: n for r, n in sorted(self.rejected.items()) if n}
        for reason, n in self.rejected_at_read.items():
            key: RejectReason | str = RejectReason(reason) if reason in _REASON_CODES else reason
            merged[key] = merged.get(key, 0) + int(n)
        return sorted(merged.items(), key=lambda kv: -kv[1])

    @property
    def top(self) -> RejectReason | str | None:
        """The commonest reason (None when there was no observation at all)."""
        ranked = self.ranked()
        return ranked[0][0] if ranked else None


_REASON_CODES = frozenset(r.value for r in RejectReason)

__all__ = ["FAULT_HOPS", "Fault", "HopName", "NothingReplayed", "RejectReason"]
