"""A robot.yaml to start from, written from what a LeRobot dataset has: ``framechain info DATASET --episode N``.

As ``framechain info LOG`` suggests a chain for a ROS log, this suggests robot.yaml for a dataset:
the state feature and its names mapped to joints (the name without an arm prefix and ``.pos``), a
unit guessed from the episode's values (radians, degrees, raw servo ticks, a 0-100 gripper), one
arm per prefix (``left_``/``right_``: a bimanual SO-101, ALOHA), and a camera per video or image
feature with its size and a guessed focal length. What cannot be known from the data is a
placeholder in capitals (``URDF``, ``LINK``) with a comment, as in the chain suggestion.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from framechain.adapters.lerobot.format import DatasetError, DatasetReader, FeatureInfo

__all__ = ["guess_unit", "robot_yaml_skeleton"]

#: Arm prefixes of bimanual datasets (LeRobot's bi_so100/bi_so101, ALOHA).
ARM_PREFIXES = ("left_", "right_")
#: Field of view assumed for a focal length guess.
GUESSED_FOV_DEG = 70.0
#: URDFs known for LeRobot's robot types.
URDF_HINTS = {"so101": "so101_new_calib.urdf (TheRobotStudio/SO-ARM100, Simulation/SO101)",
              "so100": "so100.urdf (TheRobotStudio/SO-ARM100, Simulation/SO100)",
              "koch": "koch.urdf", "aloha": "aloha (vx300s arms)"}


@dataclass(frozen=True)
class _Joint:
    state: str
    joint: str
    unit: str


def guess_unit(name: str, values: np.ndarray) -> str:
    """The unit a state's values look recorded in: rad, deg, ticks (0..4095 servo counts) or range_0_100."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return "deg"
    lo, hi = float(finite.min()), float(finite.max())
    if "gripper" in name.lower() and lo >= 0.0 and hi <= 100.0 and hi - lo > 2 * math.pi:
        return "range_0_100"
    if -2 * math.pi <= lo and hi <= 2 * math.pi:
        return "rad"
    if lo >= 0.0 and hi <= 4096.0 and hi > 400.0 and np.allclose(finite, np.round(finite)):
        return "ticks"
    return "deg"


def robot_yaml_skeleton(path: str | Path, episode: int) -> str:
    """robot.yaml text for the dataset at ``path``, from its metadata and episode ``episode``'s values."""
    reader = DatasetReader(path)
    reader.episode(episode)  # a missing episode says so in one line
    state = _state_feature(reader)
    names = list(reader.names(state)) if state else []
    values, note = _values(reader, episode, state, len(names))
    joints = [_Joint(n, _joint_name(n), guess_unit(n, values[:, i])) for i, n in enumerate(names)]
    robot_type = str(reader.robot_type or "")
    lines = [f"# robot.yaml suggested by `framechain info` from {Path(path)} episode {episode}; edit before use",
             f"# robot_type {robot_type or 'not given'}, {reader.fps:g} fps, codebase {reader.version}",
             "# FILL IN the CAPITALS: the URDF, and each camera's link, mount and calibrated intrinsics"]
    if note:
        lines.append(f"# note: {note}")
    lines.append(f"state_feature: {state or 'STATE_FEATURE'}")
    arms = [p for p in ARM_PREFIXES if names and any(n.startswith(p) for n in names)]
    if arms and all(n.startswith(tuple(arms)) for n in names):
        lines.append("arms:")
        for prefix in arms:
            base = "[0.0, 0.2, 0.0]" if prefix == "left_" else "[0.0, -0.2, 0.0]"
            lines += [f"  {prefix.rstrip('_')}:", f"    urdf: {_urdf(robot_type)}", f"    prefix: {prefix}",
                      f"    world_from_base: {{xyz: {base}, rpy: [0.0, 0.0, 0.0]}}  # GUESSED: measure the bases",
                      *_joint_lines([j for j in joints if j.state.startswith(prefix)], "    ")]
    else:
        lines.append(f"urdf: {_urdf(robot_type)}")
        lines += _joint_lines(joints, "")
    lines += _camera_lines(reader, arms)
    return "\n".join(lines) + "\n"


def _state_feature(reader: DatasetReader) -> str | None:
    if "observation.state" in reader.features:
        return "observation.state"
    vectors = [k for k, f in reader.features.items() if "state" in k and f.dtype.startswith(("float", "int"))]
    return vectors[0] if vectors else None


def _values(reader: DatasetReader, episode: int, state: str | None, width: int) -> tuple[np.ndarray, str]:
    """The episode's state values (T, n); NaN and a note when they cannot be read (units then guessed as deg)."""
    if state is None:
        return np.full((1, width), np.nan), "no state feature found: name it under state_feature"
    try:
        frames = reader.read(episode, [state])
    except DatasetError as err:
        return np.full((1, width), np.nan), f"units not guessed: {err}"
    return np.asarray(frames.columns[state], dtype=np.float64).reshape(len(frames), -1), ""


def _joint_name(state: str) -> str:
    name = state.removesuffix(".pos")
    for prefix in ARM_PREFIXES:
        name = name.removeprefix(prefix)
    return name


def _urdf(robot_type: str) -> str:
    hint = next((h for key, h in URDF_HINTS.items() if key in robot_type.lower()), None)
    return "URDF  # the robot's URDF" + (f", e.g. {hint}" if hint else "")


def _joint_lines(joints: Sequence[_Joint], indent: str) -> list[str]:
    """``default_unit`` (the commonest) and the joints, each naming the URDF joint it drives."""
    if not joints:
        return [f"{indent}joints: {{}}  # FILL IN: state name -> URDF joint"]
    default = Counter(j.unit for j in joints).most_common(1)[0][0]
    lines = [f"{indent}default_unit: {default}  # guessed from the values"]
    if default == "ticks":
        lines.append(f"{indent}# ticks: (value - 2048) * 2 pi / 4096; calibration: ARM.json (LeRobot's) sets each zero")
    lines.append(f"{indent}joints:  # state name -> the URDF joint it drives (check the names)")
    for j in joints:
        spec = j.joint if j.unit == default else f"{{joint: {j.joint}, unit: {j.unit}}}"
        lines.append(f"{indent}  {j.state}: {spec}")
    return lines


def _camera_lines(reader: DatasetReader, arms: Sequence[str]) -> list[str]:
    """One camera per video (or image) feature: its key, size and guessed intrinsics, its mount to fill in."""
    features = [f for f in reader.features.values() if f.is_video or f.dtype == "image"]
    if not features:
        return ["cameras: {}  # the dataset has no video or image feature"]
    lines = ["cameras:"]
    for feature in features:
        name = feature.key.split(".")[-1]
        width, height = _size(feature)
        focal = 0.5 * width / math.tan(math.radians(GUESSED_FOV_DEG / 2))
        link = "gripper_link" if "wrist" in name else "world"
        if "wrist" in name and arms:
            side = next((p for p in arms if p.rstrip("_") in name), arms[0])
            link = f"{side}gripper_link"
        codec = feature.info.get("video.codec", "image" if feature.dtype == "image" else "?")
        lines += [f"  {name}:  # {feature.key}: {codec}, {width}x{height}",
                  f"    video_key: {feature.key}",
                  f"    intrinsics: {{fx: {focal:.1f}, fy: {focal:.1f}, cx: {(width - 1) / 2:g}, "
                  f"cy: {(height - 1) / 2:g}, width: {width}, height: {height}}}  "
                  f"# GUESSED ({GUESSED_FOV_DEG:.0f} deg field of view): calibrate",
                  f"    mount: {{parent: {link}, xyz: [0.0, 0.0, 0.0], "
                  "rpy: [0.0, 0.0, 0.0], optical: true}  # FILL IN: the link (or world) and the measured mount"]
    return lines


def _size(feature: FeatureInfo) -> tuple[int, int]:
    """(width, height) from the feature's shape and names (channels last or first)."""
    names = list(feature.names or ())
    shape = list(feature.shape)
    if "height" in names and "width" in names and len(shape) == len(names):
        return shape[names.index("width")], shape[names.index("height")]
    dims = [d for d in shape if d > 4]
    return (dims[1], dims[0]) if len(dims) >= 2 else (640, 480)
