"""A camera's mount from the files beside a log: TagSLAM's rig, whose odometry is of the chain's body.

TagSLAM's ``tagslam.yaml`` gives a dynamic body with ``odom_frame_id`` (the odometry's child frame, the chain's
body) and ``T_body_odom`` between the rig and that frame, applied as ``p_rig = T_body_odom p_odom``; its
``camera_poses.yaml`` gives each camera's pose in the rig (``T_rig_cam``). The camera of the chain's detections
topic (its ``tagtopic`` in the Kalibr ``cameras.yaml``) then hangs from the body at
``T_odom_cam = inv(T_body_odom) T_rig_cam``: the ``mounts:`` entry, or why the files cannot give it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from framechain.config.rig_poses import rig_camera_poses, tagslam_pose
from framechain.geometry.rotations import quat_from_rotvec, quat_to_rotvec
from framechain.geometry.transforms import compose_rows, invert_rows
from framechain.suggest.facts import BesideHint
from framechain.suggest.rig import kalibr_cameras


def tagslam_mount_hint(beside: list[tuple[str, Any]], body: str, camera: str, detections: str | None
                       ) -> BesideHint | None:
    """The mount ``body -> camera`` from a TagSLAM rig whose odometry is of ``body`` (None: no such rig beside)."""
    found = _odometry_body(beside, body)
    if found is None:
        return None
    tagslam, xyz, rotvec = found
    calibration = kalibr_cameras(beside)
    cam = next((n for n, c in (calibration[1] if calibration else {}).items()
                if detections and detections in (c.get("tagtopic"), c.get("rostopic"))), None)
    poses_file, poses = next(((n, p) for n, raw in beside if (p := rig_camera_poses(raw)) and n != tagslam),
                             ("", {}))
    direction = (f"T_body_odom in {tagslam} inverted, as TagSLAM applies it (p_body = T_body_odom p_odom, and "
                 f"{tagslam} doubts its direction: check it)")
    if cam is None or cam not in poses:
        topics = {n: c.get("tagtopic") or c.get("rostopic") for n, c in (calibration[1] if calibration else {}).items()}
        have = ", ".join(f"{n}: {topics[n]}" if topics.get(n) else n for n in sorted(poses)) or "no camera"
        what = f"{cam} (the camera of {detections})" if cam else f"the camera of {detections or 'the detections'}"
        return BesideHint(_placeholder(body, camera), f"{tagslam}'s T_body_odom places TagSLAM's rig in {body}, but "
                          f"{poses_file or 'camera_poses.yaml'} gives no pose of {what} in the rig ({have}): use "
                          "the detections of a camera it gives, or add that pose")
    t_rig_odom, q_rig_odom = np.asarray([xyz]), quat_from_rotvec(np.asarray(rotvec, dtype=float))[None, :]
    t_odom_rig, q_odom_rig = invert_rows(t_rig_odom, q_rig_odom)
    cam_xyz, cam_quat = poses[cam]
    t, q = compose_rows(t_odom_rig, q_odom_rig, np.asarray([cam_xyz]), np.asarray([cam_quat]))
    numbers = ", ".join(f"{float(v):.6f}" for v in t[0])
    turn = ", ".join(f"{float(v):.7f}" for v in quat_to_rotvec(q[0]))
    return BesideHint(f"mounts: [{{parent: {body}, child: {camera}, xyz: [{numbers}], rotvec: [{turn}]}}]",
                      f"{direction}, with {cam}'s pose in {poses_file}")


def _odometry_body(beside: list[tuple[str, Any]], body: str) -> tuple[str, list[float], list[float]] | None:
    """The TagSLAM file whose dynamic body's odometry child is ``body``, and its ``T_body_odom`` (xyz, rotvec)."""
    for name, raw in beside:
        bodies = raw.get("bodies") if isinstance(raw, Mapping) else None
        for entry in bodies if isinstance(bodies, list) else []:
            for props in entry.values() if isinstance(entry, Mapping) else []:
                if not isinstance(props, Mapping) or props.get("odom_frame_id") != body:
                    continue
                pose = tagslam_pose(props.get("T_body_odom"))
                if pose is not None:
                    return name, *pose
    return None


def _placeholder(body: str, camera: str) -> str:
    return f"mounts: [{{parent: {body}, child: {camera}, xyz: [X, Y, Z], quat_xyzw: [QX, QY, QZ, QW]}}]"


__all__ = ["tagslam_mount_hint"]
