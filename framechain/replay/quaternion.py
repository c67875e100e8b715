"""The replay's quaternion maths: one implementation, in :mod:`framechain.timeline.quaternion`.

The bottom room holds it so that the adapters (forward kinematics) and the replay (lookups) share
it; these names stay importable from here.
"""

from __future__ import annotations

from framechain.timeline.quaternion import (
    IDENTITY,
    Component,
    Quat4,
    QuatLike,
    Vec3,
    VecLike,
    compose,
    homogeneous,
    invert,
    quat_angle,
    quat_conjugate,
    quat_from_matrix,
    quat_from_rotvec,
    quat_multiply,
    quat_multiply_into,
    quat_rotate,
    quat_rotate_into,
    quat_to_rotvec,
)

__all__ = [
    "IDENTITY",
    "Component",
    "Quat4",
    "QuatLike",
    "Vec3",
    "VecLike",
    "compose",
    "homogeneous",
    "invert",
    "quat_angle",
    "quat_conjugate",
    "quat_from_matrix",
    "quat_from_rotvec",
    "quat_multiply",
    "quat_multiply_into",
    "quat_rotate",
    "quat_rotate_into",
    "quat_to_rotvec",
]
