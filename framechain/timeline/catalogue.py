"""The fault catalogue of DESIGN.md: the closed set of faults and the hop each one lives on.

It lives in the model room so that code below the replay (the scene generator, which must not use
the replay's maths) can name faults; :mod:`framechain.replay.catalogue` re-exports it with the
hops typed as the replay's ``HopName``.
"""

from __future__ import annotations

from enum import StrEnum


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


#: The hop (its ``HopName`` value) each fault lives on (inverted_transform may live on either
#: transform hop; latency also on camera_to_body for a moving camera).
FAULT_HOP_VALUES: dict[Fault, str] = {
    Fault.LATENCY: "body_to_world",
    Fault.AXIS_FLIP: "camera_to_body",
    Fault.MISSING_ROTATION: "camera_to_body",
    Fault.ROTATION_ERROR: "camera_to_body",
    Fault.DEPTH_SCALE: "pixel_to_camera",
    Fault.INTRINSICS: "pixel_to_camera",
    Fault.WRONG_WORLD_FRAME: "body_to_world",
    Fault.INVERTED_TRANSFORM: "camera_to_body",
    Fault.WRONG_CAMERA_FRAME: "camera_to_body",
}
