"""The fault catalogue of DESIGN.md: the closed set of faults and the hop each one lives on."""

from __future__ import annotations

from enum import StrEnum

from framechain.replay.replay import HopName


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
}
