"""A rig chain to start from, when a log holds the detections of several cameras and the files beside it
give their calibration and their poses in the rig (Kalibr camchain or TagSLAM cameras.yaml for the
intrinsics, TagSLAM camera_poses.yaml or the camchain's ``T_cn_cnm1`` for the mounts).

Each detections topic is one camera. Its frame is its messages' header.frame_id, unless those are not
one distinct frame per topic or name another topic's camera (tagslam_quad_rig's header frames are
permuted between its topics): then each camera is named after its topic's namespace.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from framechain.adapters.model import LoadedLog
from framechain.config.chain import ChainConfig, ChainEvidence, ChainFrames
from framechain.config.chain_cameras import CalibrationSource, RigCamera
from framechain.config.mount import Mount
from framechain.config.rig_poses import rig_camera_poses
from framechain.geometry.rotations import quat_to_rotvec
from framechain.suggest.tag_sizes import tag_sizes

#: The body a rig of cameras is mounted on when the log names none (TagSLAM's ``rig_body`` if it gives one).
RIG_BODY = "rig"


def kalibr_cameras(beside: list[tuple[str, Any]]) -> tuple[str, dict[str, Mapping[str, Any]]] | None:
    """The first Kalibr camchain (or TagSLAM cameras.yaml) beside the log: its file name and cameras."""
    for name, raw in beside:
        if isinstance(raw, Mapping):
            cams = {str(k): v for k, v in raw.items()
                    if isinstance(v, Mapping) and isinstance(v.get("intrinsics"), list)}
            if cams:
                return name, cams
    return None


def rig_suggestion(loaded: LoadedLog, topics: list[str], beside: list[tuple[str, Any]], *,
                   body: str | None, world: str | None) -> tuple[ChainConfig, list[str]] | None:
    """A rig chain over the detections ``topics`` when the files beside the log calibrate every one of them and
    give their mounts (None otherwise), with comments on where its numbers came from."""
    calibration = kalibr_cameras(beside)
    if len(topics) < 2 or calibration is None:
        return None
    file, cams = calibration
    by_topic = {t: next((k for k, v in cams.items() if t in (v.get("tagtopic"), v.get("rostopic"))), None)
                for t in topics}
    if any(name is None for name in by_topic.values()):
        return None
    poses, pose_file = _poses(beside, cams)
    if not poses or any(by_topic[t] not in poses for t in topics):
        return None
    order = sorted(topics, key=lambda t: list(cams).index(str(by_topic[t])))
    frames = _camera_frames(loaded, order)
    rig_body = body or str(next((v.get("rig_body") for v in cams.values() if v.get("rig_body")), RIG_BODY))
    cameras = tuple(RigCamera(frame=frames[t], detections=t,
                              calibration=CalibrationSource(file, by_topic[t], frames[t])) for t in order)
    mounts = tuple(Mount(rig_body, frames[t], *poses[str(by_topic[t])], form="rotvec") for t in order)
    comments = [f"cameras and calibration: {file} (each detections topic is the camera whose tagtopic or rostopic "
                "it is)", f"mounts: {pose_file}, each camera's pose in the rig (T_rig_cam)"]
    if any(frames[t] != _header_frame(loaded, t) for t in order):
        comments.append("camera frames are named after their topics: the messages' header.frame_id do not name one "
                        "camera per topic")
    if world is None:
        comments.append("no pose in the log: frames.world is left out, so the cameras are compared at the same "
                        "instant in the rig's frame")
    evidence = ChainEvidence(static_target=True, tag_size_m=tag_sizes(beside))
    folder = Path(str(getattr(loaded.info, "path", ""))).parent
    config = ChainConfig(frames=ChainFrames(camera=frames[order[0]], body=rig_body, world=world or rig_body),
                         cameras=cameras, mounts=mounts, evidence=evidence, has_pose=world is not None,
                         base_dir=str(folder))
    return config, comments


def _poses(beside: list[tuple[str, Any]], cams: Mapping[str, Any]
           ) -> tuple[dict[str, tuple[tuple[float, float, float], tuple[float, float, float, float]]], str]:
    """``T_rig_cam`` per camera name from the first file beside the log that gives them."""
    for name, raw in beside:
        poses = rig_camera_poses(raw)
        if poses and set(poses) & set(cams):
            return poses, name
    return {}, ""


def _header_frame(loaded: LoadedLog, topic: str) -> str:
    obs = loaded.timeline.observations
    frames = obs.camera_frame[obs.source == topic]
    if not len(frames):
        return ""
    values, counts = np.unique(frames, return_counts=True)
    return str(values[np.argmax(counts)])


def _camera_frames(loaded: LoadedLog, topics: list[str]) -> dict[str, str]:
    """Each topic's camera frame: its header.frame_id, or its namespace when those do not name one camera each."""
    header = {t: _header_frame(loaded, t) for t in topics}
    spaces = {t: t.rstrip("/").rsplit("/", 1)[0].strip("/") or t.strip("/") for t in topics}
    distinct = len(set(header.values())) == len(topics) and all(header.values())
    crossed = any(header[t] in spaces.values() and header[t] != spaces[t] for t in topics)
    return header if distinct and not crossed else spaces


def rig_yaml_body(config: ChainConfig) -> list[str]:
    """A rig chain's keys below ``frames:`` as YAML lines, one line per camera and per mount."""
    raw = config.to_dict()
    for key in ("frames", "cameras", "mounts"):
        raw.pop(key, None)
    raw["topics"] = {k: v for k, v in raw.get("topics", {}).items() if v}
    raw["evidence"] = {k: v for k, v in raw.get("evidence", {}).items() if v not in ({}, None, False)}
    lines = yaml.safe_dump({k: v for k, v in raw.items() if v not in ({}, None)}, sort_keys=False).splitlines()
    lines.append("cameras:")
    for c in config.cameras:
        entry: dict[str, Any] = {k: v for k, v in (("frame", c.frame), ("detections", c.detections)) if v}
        if c.calibration is not None:
            entry["calibration"] = {"file": _from_cwd(config, c.calibration.file), **({"camera": c.calibration.camera}
                                                                     if c.calibration.camera else {})}
        lines.append("  - " + _flow(entry))
    lines.append("mounts:")
    for m in config.mounts:
        rotation = (quat_to_rotvec(np.asarray(m.quat_xyzw)) if m.form == "rotvec" else np.asarray(m.quat_xyzw))
        key = "rotvec" if m.form == "rotvec" else "quat_xyzw"
        lines.append("  - " + _flow({"parent": m.parent, "child": m.child,
                                     "xyz": [round(float(v), 8) + 0.0 for v in m.xyz],
                                     key: [round(float(v), 8) + 0.0 for v in rotation]}))
    return lines


def _flow(value: Mapping[str, Any]) -> str:
    return yaml.safe_dump(dict(value), default_flow_style=True, sort_keys=False, width=10_000).strip()


__all__ = ["RIG_BODY", "kalibr_cameras", "rig_suggestion", "rig_yaml_body"]


def _from_cwd(config: ChainConfig, file: str) -> str:
    """A calibration file beside the log, as a path from the working directory: the printed chain is saved
    there (``info LOG --chain > chain.yaml``), and a chain's relative paths are read from its own folder."""
    if not config.base_dir or Path(file).is_absolute():
        return file
    return os.path.relpath(Path(config.base_dir) / file)
