"""Files a user may pass as a chain that are another kind of file: a camera calibration (Kalibr, ROS camera_info,
OpenCV), TagSLAM's configuration or camera poses, a robot.yaml. Each is named with how a chain uses it, rather than
as a chain with unknown keys."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: Keys only a chain has: with any of them the file is a chain, whatever else is wrong with it.
CHAIN_KEYS = frozenset({"frames", "topics", "evidence", "mounts"})


def not_a_chain(raw: Mapping[str, Any], name: str) -> str | None:
    """What ``raw`` (a parsed YAML mapping, the file ``name``) is when it is no chain, and how a chain uses it;
    None when it may be a chain."""
    keys = {str(k) for k in raw}
    if keys & CHAIN_KEYS:
        return None
    entries = {str(k): v for k, v in raw.items() if isinstance(v, Mapping)}
    cameras = sorted(k for k, v in entries.items() if "intrinsics" in v and ("camera_model" in v or
                                                                             "distortion_model" in v))
    if cameras:
        return (f"this is a calibration file (a Kalibr camchain of {', '.join(cameras)}), not a chain: a chain uses it "
                f"as `calibration: {{file: {name}, camera: {cameras[0]}}}`")
    if "camera_matrix" in keys or ("K" in keys and ("D" in keys or "distortion_coefficients" in keys)):
        return (f"this is a calibration file (a camera matrix and distortion), not a chain: a chain uses it as "
                f"`calibration: {{file: {name}}}`")
    if "tagslam_parameters" in keys or "bodies" in keys:
        return ("this is a TagSLAM configuration, not a chain: `framechain info LOG` beside it suggests the tag sizes "
                "and the mount (T_body_odom) it gives, as chain keys")
    poses = sorted(k for k, v in entries.items() if isinstance(v.get("pose"), Mapping))
    if poses:
        return (f"this is a file of camera poses in a rig ({', '.join(poses)}), not a chain: `framechain info LOG "
                "--chain` beside it turns them into a rig chain's mounts")
    if "state_feature" in keys or ("urdf" in keys and keys & {"joints", "arms"}):
        return "this is a robot.yaml, not a chain: pass it as `--robot` with a LeRobot dataset and `--episode N`"
    return None


__all__ = ["CHAIN_KEYS", "not_a_chain"]
