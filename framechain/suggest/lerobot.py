"""A robot.yaml to start from, written from what a LeRobot dataset has: ``framechain info DATASET --episode N``.

As ``framechain info LOG`` suggests a chain for a ROS log, this suggests robot.yaml for a dataset:
the state feature and its names mapped to joints, a unit guessed from the episode's values (radians,
degrees, raw servo ticks, LeRobot's -100..100 and 0-100 ranges), one arm per prefix, and a camera
per video or image feature with its size and a guessed focal length.

When the dataset's ``robot_type`` names an arm framechain bundles a URDF for
(:mod:`framechain.robot.known_arms`: SO-100, SO-101, Koch, ALOHA, LeKiwi), the file is complete: that URDF,
the state names matched to its joints under any per-arm prefix (``left_``, ``arm1_``, ``follower_``,
numbered ``arm1_j1``), and each camera on the gripper link of the arm its name mentions (a wrist
camera of one arm, else the world, or a mobile base: LeKiwi's ``x.vel``, ``y.vel``, ``theta.vel`` become
``mobile_base``), its mount a placeholder that the camera's motion measures.
:func:`generated_robot` gives it to a run without ``--robot``. Otherwise what cannot be known from
the data is a placeholder in capitals (``URDF``, ``LINK``) with a comment, as in the chain suggestion.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from framechain.adapters.lerobot.reader import DatasetError, DatasetReader, FeatureInfo
from framechain.config.mobile_base import DEFAULT_FRAME
from framechain.config.robot import GeneratedRobot
from framechain.geometry.camera import ASSUMED_FOV_DEG, focal_of_fov
from framechain.robot.kinematics import RobotModel
from framechain.robot.known_arms import (
    BASE_VELOCITIES,
    ArmJoints,
    KnownArm,
    arm_prefixes,
    known_arm,
    match_state_names,
)

__all__ = ["dataset_needs", "generated_robot", "guess_arm_units", "guess_unit", "robot_yaml_skeleton"]

#: URDFs of LeRobot's robot types framechain does not bundle.
URDF_HINTS = {"aloha": "aloha (vx300s arms)"}
#: Words of a camera name that put it on an arm's wrist.
_WRIST_WORDS = {"wrist", "gripper", "hand", "arm", "ee"}


@dataclass(frozen=True)
class _Joint:
    state: str
    joint: str | None  # None: the URDF has no joint this state could drive
    unit: str
    why_not: str = ""


@dataclass(frozen=True)
class _Arm:
    name: str
    prefix: str  # frames' prefix (arms) or "" (one URDF)
    joints: tuple[_Joint, ...]
    unit_note: str
    #: URDF joints no state drives, held at zero
    hold: tuple[str, ...] = ()

    @property
    def default_unit(self) -> str:
        """The commonest unit of the mapped joints."""
        units = [j.unit for j in self.joints if j.joint is not None] or ["deg"]
        return Counter(units).most_common(1)[0][0]


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


def guess_arm_units(names: Sequence[str], values: np.ndarray) -> tuple[list[str], str]:
    """The units of one arm's states (``values``: (T, n) columns) and the guess in words.

    The arm's joints share a unit (LeRobot records an arm in one mode), guessed from all of them; the
    gripper takes LeRobot's 0-100 unless the arm records raw ticks or radians."""
    gripper = np.array(["gripper" in n.lower() for n in names], dtype=bool)
    body = values[:, ~gripper] if (~gripper).any() else values
    finite = body[np.isfinite(body)]
    top = float(np.abs(finite).max()) if finite.size else 0.0
    if finite.size == 0:
        unit, why = "deg", "no finite values to guess from"
    elif finite.min() >= 0.0 and 400.0 < top <= 4096.0 and np.allclose(finite, np.round(finite)):
        unit, why = "ticks", f"whole numbers {finite.min():.0f}..{top:.0f}: raw servo ticks"
    elif top <= 2 * math.pi:
        unit, why = "rad", f"values within +-{top:.2f}"
    elif top > 100.5:
        unit, why = "deg", f"values reach {top:.0f}"
    elif top >= 99.5:
        unit, why = "range_m100_100", "values stop at +-100, where LeRobot clamps range_m100_100"
    else:
        unit, why = "deg", f"values within +-{top:.0f}; LeRobot's default range_m100_100 would fit too"
    units = [unit if not g or unit in ("ticks", "rad") else guess_unit(n, values[:, i])
             for i, (n, g) in enumerate(zip(names, gripper, strict=True))]
    return units, why


def robot_yaml_skeleton(path: str | Path, episode: int) -> str:
    """robot.yaml text for the dataset at ``path``, from its metadata and episode ``episode``'s values."""
    return _skeleton(DatasetReader(path), Path(path), episode)[0]


def generated_robot(path: str | Path, episode: int | None = None) -> GeneratedRobot | None:
    """robot.yaml for a dataset whose ``robot_type`` framechain bundles a URDF for (None: another arm, or no
    state name matched). ``episode`` None: the first episode."""
    reader = DatasetReader(path)
    if known_arm(reader.robot_type) is None or not reader.episodes():
        return None
    chosen = reader.episodes()[0] if episode is None else episode
    text, line = _skeleton(reader, Path(path), chosen)
    if not line:
        return None
    first = "" if episode is not None else f"episode {chosen} (no --episode given); "
    return GeneratedRobot(text=text, line=first + line, episode=chosen)


def dataset_needs(path: str | Path, *, episode: int | None, robot_given: bool) -> str:
    """One line asking for everything a run of the dataset lacks (the episode, robot.yaml, or both), and where a
    robot.yaml to start from comes from."""
    reader = DatasetReader(path)
    ids = reader.episodes()
    shown = "none" if not ids else f"{ids[0]}..{ids[-1]}" if ids == list(range(ids[0], ids[-1] + 1)) else str(ids)
    asks = ([] if episode is not None else [f"--episode N (episodes {shown})"]) + (
        [] if robot_given else ["--robot robot.yaml (URDF, joints, cameras)"])
    line = f"{path}: a LeRobot dataset needs {' and '.join(asks)}"
    if robot_given:
        return line
    robot_type = reader.robot_type
    arm = known_arm(robot_type)
    unknown = (f"its state names match no joint of the bundled {arm.title} URDF" if arm is not None else
               f"robot_type {robot_type!r} is no arm framechain bundles a URDF for" if robot_type else "no robot_type")
    example = episode if episode is not None else (ids[0] if ids else 0)
    return f"{line} ({unknown}); `framechain info {path} --episode {example}` prints a robot.yaml to start from"


def _skeleton(reader: DatasetReader, path: Path, episode: int) -> tuple[str, str]:
    """robot.yaml text, and the line saying what it assumed when the arm is known ("" otherwise)."""
    reader.episode(episode)  # a missing episode says so in one line
    state = _state_feature(reader)
    names = list(reader.names(state)) if state else []
    values, note = _values(reader, episode, state, len(names))
    robot_type = str(reader.robot_type or "")
    arm = known_arm(robot_type)
    arms = _known_arms(arm, names, values, arm.arms_in(robot_type)) if arm is not None else []
    lines = [f"# robot.yaml suggested by `framechain info` from {path} episode {episode}; edit before use",
             f"# robot_type {robot_type or 'not given'}, {reader.fps:g} fps, codebase {reader.version}"]
    if arm is None or not arms:
        arms = _generic_arms(names, values)
        lines.append("# FILL IN the CAPITALS: the URDF, and each camera's link, mount and calibrated intrinsics")
        urdf = "URDF  # the robot's URDF" + "".join(f", e.g. {h}" for k, h in URDF_HINTS.items() if k in robot_type)
    else:
        lines.append(f"# the bundled {arm.title} URDF ({arm.source}); GUESSED: the units, the bases, and each "
                     "camera's intrinsics and mount (its link and mount are measured from its motion)")
        urdf = f"{arm.urdf}  # bundled {arm.title} URDF ({arm.source})"
    if note:
        lines.append(f"# note: {note}")
    lines.append(f"state_feature: {state or 'STATE_FEATURE'}")
    lines += _arm_lines(arms, urdf, arm.bases if arm is not None else {})
    one_arm = len(arms) == 1 and not arms[0].prefix
    base = _mobile_base_lines(names, one_arm, arm.on_base if arm is not None else None)
    lines += base
    link = arm.camera_link if arm is not None and arms else "gripper_link"
    lines += _camera_lines(reader, arms, link, known=arm is not None and bool(arms),
                           fixed=DEFAULT_FRAME if base else "world")
    text = "\n".join(lines) + "\n"
    if arm is None or not arms:
        return text, ""
    mapped = sum(j.joint is not None for a in arms for j in a.joints)
    units: dict[str, str] = {}
    for a in arms:
        units.setdefault(a.default_unit, a.unit_note)
    on = f"{len(arms)} arms ({', '.join(a.prefix for a in arms)})" if len(arms) > 1 else "1 arm"
    moved = f", {len(BASE_VELOCITIES)} the mobile base's velocities" if base else ""
    return text, (f"used the bundled {arm.title} URDF and a guessed mapping ({mapped} of {len(names)} state names "
                  f"on {on}{moved}; units {'; '.join(f'{u}: {n}' for u, n in units.items())}; cameras' intrinsics "
                  "and mounts guessed)")


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


def _known_arms(arm: KnownArm, names: Sequence[str], values: np.ndarray, count: int) -> list[_Arm]:
    """The dataset's arms matched to the known arm's joints (by name, by number, else by position); ``count``: how
    many arms its robot has."""
    groups, _unmatched = match_state_names(names, arm.motors, arms=count)
    if not groups and names and len(names) % len(arm.motors) == 0:  # unnamed columns: LeRobot's order
        n = len(names) // len(arm.motors)
        prefixes = arm_prefixes(n)
        k = len(arm.motors)
        groups = [ArmJoints(p, tuple(zip(names[i * k:(i + 1) * k], arm.motors, strict=True)))
                  for i, p in enumerate(prefixes)]
    model = RobotModel.from_urdf(arm.urdf)
    out = []
    for group in groups:
        states = [s for s, _m in group.motors]
        units, why = guess_arm_units(states, values[:, [list(names).index(s) for s in states]])
        joints = []
        for (state, motor), unit in zip(group.motors, units, strict=True):
            joint = arm.joints.get(motor)
            no_limits = joint is not None and unit.startswith("range") and None in model.limits(joint)
            why_not = (arm.unmapped.get(motor, "the bundled URDF has no such joint") if joint is None else
                       f"its URDF joint {joint!r} has no limits for {unit}" if no_limits else "")
            joints.append(_Joint(state, None if why_not else joint, unit, why_not))
        driven = {j.joint for j in joints}
        hold = tuple(j for j in arm.joints.values() if j not in driven)
        prefix = (group.prefix or f"{group.name}_") if len(groups) > 1 else ""
        out.append(_Arm(group.name, prefix, tuple(joints), why, hold))
    return out


def _generic_arms(names: Sequence[str], values: np.ndarray) -> list[_Arm]:
    """An unknown arm: one arm per prefix shared by several names with the same endings, the joints named by
    what follows the prefix (to check against the URDF)."""
    stems = [n.removesuffix(".pos") for n in names]
    split = [s.split("_", 1) if "_" in s else ["", s] for s in stems]
    endings: dict[str, set[str]] = {}
    for head, rest in split:
        endings.setdefault(head, set()).add(rest)
    shared = [h for h, e in endings.items() if h and len(e) >= 2 and sum(e == o for o in endings.values()) >= 2]
    if not (len(shared) >= 2 and all(head in shared for head, _rest in split)):
        shared = [""]
    out = []
    for head in shared:
        idx = [i for i, (h, _r) in enumerate(split) if head in (h, "")]
        # Another robot's joints may differ in kind (a base in metres, a hand in radians): a unit per joint.
        joints = tuple(_Joint(names[i], split[i][1] if head else stems[i], guess_unit(names[i], values[:, i]))
                       for i in idx)
        out.append(_Arm(head or "arm", f"{head}_" if head else "", joints, "per joint, from its values"))
    return out


def _arm_lines(arms: Sequence[_Arm], urdf: str, bases: Mapping[str, tuple[tuple[float, ...], tuple[float, ...]]]
               ) -> list[str]:
    """The arms' lines: each arm's base where its rig usually has it (``bases``, by side), else side by side."""
    if len(arms) == 1 and not arms[0].prefix:
        return [f"urdf: {urdf}", *_joint_lines(arms[0], "")]
    lines = ["arms:"]
    for i, arm in enumerate(arms):
        xyz, rpy = bases.get(_SIDES.get(arm.name.lower(), ""),
                             ((0.0, _base_y(arm.name, i, len(arms)), 0.0), (0.0, 0.0, 0.0)))
        lines += [f"  {arm.name}:", f"    urdf: {urdf}", f"    prefix: {arm.prefix}",
                  f"    world_from_base: {{xyz: [{', '.join(repr(round(v, 6)) for v in xyz)}], "
                  f"rpy: [{', '.join(repr(float(v)) for v in rpy)}]}}  # GUESSED: measure the bases",
                  *_joint_lines(arm, "    ")]
    return lines


#: The side an arm's name says (``left``, ``l``, ``right``, ``r``).
_SIDES = {"left": "left", "l": "left", "right": "right", "r": "right"}


def _base_y(name: str, i: int, n: int) -> float:
    """Arms side by side 0.4 m apart along y, the left one (or the first) at +y."""
    side = {"left": 0, "right": n - 1}.get(_SIDES.get(name.lower(), ""), i)
    return 0.2 * (n - 1) - 0.4 * side


def _joint_lines(arm: _Arm, indent: str) -> list[str]:
    """``default_unit`` (the commonest, with the guess said) and the joints, each naming the URDF joint it drives."""
    mapped = [j for j in arm.joints if j.joint is not None]
    if not mapped:
        return [f"{indent}joints: {{}}  # FILL IN: state name -> URDF joint"]
    default = arm.default_unit
    lines = [f"{indent}default_unit: {default}  # guessed: {arm.unit_note}"]
    if default == "ticks":
        lines.append(f"{indent}# ticks: (value - 2048) * 2 pi / 4096; calibration: ARM.json (LeRobot's) reads them "
                     "as LeRobot does")
    lines.append(f"{indent}joints:  # state name -> the URDF joint it drives")
    for j in arm.joints:
        if j.joint is None:
            lines.append(f"{indent}  # {j.state}: not mapped ({j.why_not})")
            continue
        joint = _yaml_name(j.joint)
        lines.append(f"{indent}  {j.state}: " + (joint if j.unit == default else f"{{joint: {joint}, unit: {j.unit}}}"))
    if arm.hold:
        lines.append(f"{indent}hold:  # GUESSED: joints no state drives, held at 0")
        lines += [f"{indent}  {_yaml_name(j)}: 0.0" for j in arm.hold]
    return lines


def _yaml_name(name: str) -> str:
    return name if re.fullmatch(r"[A-Za-z_][\w.-]*", name) else f"'{name}'"


def _mobile_base_lines(names: Sequence[str], one_arm: bool,
                       on_base: tuple[tuple[float, ...], tuple[float, ...]] | None) -> list[str]:
    """``mobile_base`` when the state holds LeRobot's base velocities (LeKiwi's ``x.vel``, ``y.vel``,
    ``theta.vel``): the base's turns move every camera, and forward kinematics of the arm alone leaves them out.
    One arm stands where its robot's drawing puts it (``on_base``), else at the base's centre; several arms: their
    ``world_from_base``."""
    if not set(BASE_VELOCITIES.values()) <= set(names):
        return []
    xyz, rpy = on_base or ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    said = "GUESSED (the robot's drawing)" if on_base is not None else "GUESSED: measure it"
    pose = f"{{xyz: [{', '.join(repr(float(v)) for v in xyz)}], rpy: [{', '.join(repr(float(v)) for v in rpy)}]}}"
    place = [f"world_from_base: {pose}  # {said}: the arm on the mobile base"] if one_arm else []
    return [*place, "mobile_base:  # the base's recorded velocities move the arm in the world",
            f"  frame: {DEFAULT_FRAME}",
            *(f"  {key}: {name}" for key, name in BASE_VELOCITIES.items()),
            "  speed_unit: m/s", "  yaw_rate_unit: deg/s  # LeRobot's"]


def _camera_lines(reader: DatasetReader, arms: Sequence[_Arm], link: str, *, known: bool, fixed: str = "world"
                  ) -> list[str]:
    """One camera per video (or image) feature: its key, size and guessed intrinsics, and its mount (a camera on no
    arm's wrist on ``fixed``: the world, or a mobile base)."""
    features = [f for f in reader.features.values() if f.is_video or f.dtype == "image"]
    if not features:
        return ["cameras: {}  # the dataset has no video or image feature"]
    prefixed = len(arms) > 1 or bool(arms and arms[0].prefix)
    lines = ["cameras:"]
    for feature in features:
        name = feature.key.split(".")[-1]
        width, height = _size(feature)
        focal = focal_of_fov(width, ASSUMED_FOV_DEG)
        arm = _camera_arm(name, arms)
        parent = fixed if arm is None else f"{arm.prefix if prefixed else ''}{link}"
        mount = ("GUESSED: a placeholder; the link and mount are measured from the camera's motion" if known
                 else "FILL IN: the link (or world) and the measured mount")
        codec = feature.info.get("video.codec", "image" if feature.dtype == "image" else "?")
        lines += [f"  {name}:  # {feature.key}: {codec}, {width}x{height}",
                  f"    video_key: {feature.key}",
                  f"    intrinsics: {{fx: {focal:.1f}, fy: {focal:.1f}, cx: {(width - 1) / 2:g}, "
                  f"cy: {(height - 1) / 2:g}, width: {width}, height: {height}}}  "
                  f"# GUESSED ({ASSUMED_FOV_DEG:.0f} deg field of view): calibrate",
                  f"    mount: {{parent: {parent}, xyz: [0.0, 0.0, 0.0], rpy: [0.0, 0.0, 0.0], "
                  f"optical: true}}  # {mount}"]
    return lines


def _camera_arm(name: str, arms: Sequence[_Arm]) -> _Arm | None:
    """The arm a camera rides, from its name: the arm it names (``left_wrist``, ``arm2``), else the first arm for a
    wrist camera; None: a camera fixed in the world (``top``, ``front``)."""
    words = set(re.split(r"[^a-z0-9]+", name.lower()))
    words |= {form for w in words if w in _SIDES for form in (_SIDES[w], _SIDES[w][0])}  # either spelling of a side
    named = [a for a in arms if a.prefix and (a.name.lower() in words or name.lower().startswith(a.prefix.lower()))]
    if named:
        return named[0]
    wrist = bool(words & _WRIST_WORDS) or any(w.startswith(("wrist", "arm")) for w in words)
    return arms[0] if wrist and arms else None


def _size(feature: FeatureInfo) -> tuple[int, int]:
    """(width, height) from the feature's shape and names (channels last or first)."""
    if feature.image_size is not None:
        return feature.image_size
    dims = [d for d in feature.shape if d > 4]
    return (dims[1], dims[0]) if len(dims) >= 2 else (640, 480)
