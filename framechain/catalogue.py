"""The fault catalogue of DESIGN.md: the three hops of the chain, the closed set of faults, and the
hop each fault lives on.

A vocabulary every room shares (the replay names hops, the analysis fits faults, the scene
generator injects them with maths of its own), so it imports nothing of framechain.
"""

from __future__ import annotations

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
}

__all__ = ["FAULT_HOPS", "Fault", "HopName"]
