"""Each camera's pose in its rig, from a calibration file of several cameras (TagSLAM's
``camera_poses.yaml``, a Kalibr camchain): what a rig chain's ``mounts:`` are suggested from."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from framechain.arrays import FloatArray
from framechain.config.schema import finite_number
from framechain.geometry.rotations import quat_from_matrix, quat_from_rotvec

__all__ = ["rig_camera_poses", "tagslam_pose"]


def rig_camera_poses(raw: Any) -> dict[str, tuple[tuple[float, float, float], tuple[float, float, float, float]]]:
    """Each camera's pose in its rig, ``T_rig_cam`` as (xyz, quat_xyzw), from a parsed calibration file of several
    cameras (empty when it gives none):

    - TagSLAM's ``camera_poses.yaml``: ``camN: {pose: {position: {x, y, z}, rotation: {x, y, z}}}``, the
      rotation a rotation vector (radians); TagSLAM's ``T_rig_cam`` (points of the camera into the rig);
    - a Kalibr camchain: ``camN: {T_cn_cnm1: 4x4}`` maps points of camera N-1 into camera N; the rig is the
      first camera (``T_rig_cam0`` the identity) and ``T_rig_camN = T_rig_camN-1 inv(T_cn_cnm1)``.
    """
    if not isinstance(raw, Mapping):
        return {}
    entries = [(str(k), v) for k, v in raw.items() if isinstance(v, Mapping)]
    out: dict[str, tuple[tuple[float, float, float], tuple[float, float, float, float]]] = {}
    for name, entry in entries:
        pose = tagslam_pose(entry.get("pose"))
        if pose is not None:
            (x, y, z), rotvec = pose
            out[name] = ((x, y, z), _quat_of_rotvec(np.asarray(rotvec, dtype=float)))
    if out:
        return out
    chained = [(name, e.get("T_cn_cnm1")) for name, e in entries if isinstance(e.get("intrinsics"), list)]
    if len(chained) < 2 or any(not _is_matrix(m) for _, m in chained[1:]):
        return {}
    rig_from_cam = np.eye(4)
    for i, (name, matrix) in enumerate(chained):
        if i:
            rig_from_cam = rig_from_cam @ np.linalg.inv(np.asarray(matrix, dtype=float))
        t = rig_from_cam[:3, 3]
        out[name] = ((float(t[0]), float(t[1]), float(t[2])), _quat_of_matrix(rig_from_cam[:3, :3]))
    return out


def tagslam_pose(value: Any) -> tuple[list[float], list[float]] | None:
    """TagSLAM's ``{position: {x, y, z}, rotation: {x, y, z}}`` (metres, a rotation vector in radians) as
    (xyz, rotvec); None when it is not one, or a value is not a finite number."""
    if not isinstance(value, Mapping):
        return None
    position, rotation = value.get("position"), value.get("rotation")
    if not (isinstance(position, Mapping) and isinstance(rotation, Mapping)):
        return None
    values = [position.get(a) for a in "xyz"] + [rotation.get(a) for a in "xyz"]
    if not all(finite_number(v) for v in values):
        return None
    numbers: list[float] = np.asarray(values, dtype=float).tolist()
    return numbers[:3], numbers[3:]


def _is_matrix(value: Any) -> bool:
    return (isinstance(value, list) and len(value) == 4
            and all(isinstance(r, list) and len(r) == 4 and all(finite_number(x) for x in r) for r in value))


def _quat_of_rotvec(rotvec: FloatArray) -> tuple[float, float, float, float]:
    q = quat_from_rotvec(rotvec)
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def _quat_of_matrix(matrix: FloatArray) -> tuple[float, float, float, float]:
    q = quat_from_matrix(matrix)
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
