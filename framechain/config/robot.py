"""robot.yaml: the URDF, how dataset state names map to its joints (with units), the cameras.

The file (or the ``robot:`` section of CHAIN.yaml, whose paths resolve against CHAIN.yaml)::

    urdf: so101_new_calib.urdf        # relative to this file
    state_feature: observation.state  # dataset feature holding the joint-state vector
    world_frame: world                # default "world"
    world_from_base:                  # static world -> URDF root (mobile_base: base -> root); default identity
      xyz: [0.0, 0.0, 0.0]
      rpy: [0.0, 0.0, 0.0]            # or quat_xyzw: [x, y, z, w], or rotvec: [x, y, z]
    default_unit: deg                 # optional; every joint must get a unit from here or its own
    joints:                           # dataset state name -> URDF joint, unit conversion
      shoulder_pan.pos: shoulder_pan  # a bare joint name takes default_unit
      elbow_flex.pos: {joint: elbow_flex, unit: deg, sign: -1, offset: 0.0}
      gripper.pos: {joint: gripper, unit: range_0_100}
    hold:                             # optional: joints the dataset does not record, fixed (SI)
      wrist_roll: 0.0
    cameras:                          # name -> calibration file, or the calibration inline
      wrist: calib/wrist.yaml
    detections:                       # optional, one or several sources
      - table: detections.parquet     # Parquet or CSV: episode_index, frame_index | timestamp,
                                      #   camera, u, v[, depth_m, label, score]
      - feature: observation.detection.wrist   # per-frame [u, v] or [u, v, depth_m]; NaN = none
        camera: wrist
    chain:                            # optional: how to replay and attribute (as CHAIN.yaml)
      camera: wrist                   # the camera (name); default the first one
      body: base_link                 # the body frame; default the URDF root
      latency_budget_s: 0.02
      evidence: {reference_point: [0.4, 0.1, 0.02], static_target: true}   # CHAIN.yaml evidence

Units (``unit``): ``rad`` and ``m`` as recorded; ``deg``; ``mm``; ``range_0_100`` maps 0..100 to the
joint's [lower, upper] limits (LeRobot's gripper); ``range_m100_100`` maps -100..100 to [lower,
upper]; ``ticks``: raw servo counts, ``(value - zero_ticks) * 2 pi / ticks_per_turn`` (defaults 2048
and 4096, Feetech STS servos: ``{joint: shoulder_pan, unit: ticks, zero_ticks: 2011}``). The joint
position is ``sign * convert(value) + offset`` (offset in radians or metres), so a calibration that
puts the dataset's zero elsewhere than the URDF's is explicit too.

Several arms (a bimanual SO-101, ALOHA) replace ``urdf``, ``joints``, ``world_from_base``,
``default_unit``, ``hold`` and ``calibration`` with ``arms``, one entry per arm; every link and joint
of an arm is named with its ``prefix`` (default ``<arm>_``) in the frame tree, so cameras mount on
``left_gripper_link``::

    arms:
      left:
        urdf: so101_new_calib.urdf
        prefix: left_                   # default "left_"
        world_from_base: {xyz: [0.0, 0.2, 0.0], rpy: [0.0, 0.0, 0.0]}
        default_unit: ticks
        joints: {left_shoulder_pan.pos: shoulder_pan, ...}   # the URDF's own joint names
        calibration: left_follower.json # optional: LeRobot's calibration of the arm

``calibration`` (top level for one URDF, or per arm) is LeRobot's calibration JSON
(``{motor: {id, drive_mode, homing_offset, range_min, range_max}}``, a motor named as the URDF
joint or as the state name without its arm prefix and ``.pos``). Its joints are read as LeRobot
reads its Feetech servos: the servo applies ``homing_offset`` itself, so the recorded
Present_Position ticks are already homed, and ``range_min``/``range_max`` are homed ticks too.
``ticks`` then has its zero at the middle of the range and 4095 ticks per turn (LeRobot's DEGREES
mode: ``(ticks - (range_min + range_max) / 2) * 360 / 4095``); ``range_m100_100`` and
``range_0_100`` are LeRobot's normalisation of that range, read back to ticks (inverted where
``drive_mode`` is 1, as LeRobot inverts them) and turned into an angle the same way. A joint's own
``zero_ticks`` or ``ticks_per_turn`` wins.

``mobile_base`` names the state's velocities of a base that drives around (LeKiwi's ``x.vel``, ``y.vel``,
``theta.vel``): the arms then hang from the base's frame, moved per row as its velocities integrate
(:mod:`framechain.config.mobile_base`).

This module reads and checks the file only; binding it to the URDF's model (joints that exist
and move, the conversion of joint values) is the robot adapter's job
(:mod:`framechain.adapters.robot.config`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

from framechain.config import plausible
from framechain.config.calibration import CameraCalibration, load_calibration
from framechain.config.chain import (
    ChainConfig,
    ChainEvidence,
    ChainFrames,
    ChainTopics,
    parse_evidence,
)
from framechain.config.chain_cameras import latency_budget
from framechain.config.errors import RobotConfigError
from framechain.config.mobile_base import MobileBase, parse_mobile_base
from framechain.config.schema import Section, read_yaml, show

__all__ = [
    "ArmConfig",
    "DetectionSource",
    "GeneratedRobot",
    "JointMapping",
    "JointUnit",
    "MotorCalibration",
    "RobotConfig",
    "RobotConfigError",
]


class JointUnit(StrEnum):
    """How a dataset records a joint; conversion to radians or metres is explicit."""

    RAD = "rad"
    DEG = "deg"
    M = "m"
    MM = "mm"
    RANGE_0_100 = "range_0_100"
    RANGE_M100_100 = "range_m100_100"
    TICKS = "ticks"


#: Feetech STS servos: counts per turn and the count at the middle of the range.
TICKS_PER_TURN = 4096.0
ZERO_TICKS = 2048.0
#: What LeRobot's DEGREES mode divides 360 degrees by: the servo's resolution minus one (STS3215: 4096 - 1).
CALIBRATED_TICKS_PER_TURN = 4095.0


@dataclass(frozen=True)
class JointMapping:
    """One dataset state name driving one URDF joint: ``q = sign * convert(value) + offset``."""

    state: str
    joint: str
    unit: JointUnit
    sign: float = 1.0
    offset: float = 0.0
    #: unit ticks: the count at the joint's zero and the counts per turn
    zero_ticks: float = ZERO_TICKS
    ticks_per_turn: float = TICKS_PER_TURN
    #: A LeRobot calibration's (range_min, range_max) in homed ticks: range units are then LeRobot's
    #: normalisation of this range, read back to ticks (None: range units map to the joint's limits).
    ticks_range: tuple[float, float] | None = None
    #: LeRobot's drive_mode 1: its range units count the other way (1 - fraction).
    inverted: bool = False


@dataclass(frozen=True)
class MotorCalibration:
    """One motor of a LeRobot calibration JSON; ``range_min``/``range_max`` in homed ticks (the servo applies
    ``homing_offset`` itself, so it is kept for the record only)."""

    range_min: float
    range_max: float
    drive_mode: int = 0
    homing_offset: float = 0.0


@dataclass(frozen=True)
class ArmConfig:
    """One arm of several: its URDF, the prefix of its frames and joints, where its base stands."""

    name: str
    urdf: Path
    prefix: str
    world_from_base_translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    world_from_base_quat_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class DetectionSource:
    """Where detections come from: a side table (Parquet/CSV) or a per-frame dataset feature."""

    table: Path | None = None
    feature: str | None = None
    camera: str | None = None


_KEYS = {"urdf", "state_feature", "world_frame", "world_from_base", "default_unit", "joints", "hold", "cameras",
         "detections", "chain", "arms", "calibration", "mobile_base"}
_ARM_KEYS = {"urdf", "prefix", "world_from_base", "default_unit", "joints", "hold", "calibration"}
_JOINT_KEYS = {"joint", "unit", "sign", "offset", "zero_ticks", "ticks_per_turn"}


@dataclass(frozen=True)
class RobotConfig:
    """The parsed robot.yaml (see the module docstring for the schema)."""

    urdf: Path
    joints: tuple[JointMapping, ...]
    cameras: Mapping[str, CameraCalibration] = field(default_factory=dict)
    state_feature: str = "observation.state"
    world_frame: str = "world"
    world_from_base_translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    world_from_base_quat_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    hold: Mapping[str, float] = field(default_factory=dict)
    detections: tuple[DetectionSource, ...] = ()
    chain_camera: str | None = None
    chain_body: str | None = None
    latency_budget_s: float | None = None
    #: The chain's evidence, as the ``evidence`` mapping of CHAIN.yaml reads it.
    evidence: ChainEvidence | None = None
    source: str = ""
    #: Values that are plausible but unusual, one line each (the cameras' included).
    notes: tuple[str, ...] = field(default=(), compare=False)
    #: Several arms (``arms:``): joints and hold then name prefixed joints; empty for one URDF.
    arms: tuple[ArmConfig, ...] = ()
    #: A base that drives around: the arms hang from its frame (None: they stand in the world).
    mobile_base: MobileBase | None = None

    @property
    def arms_frame(self) -> str:
        """The frame the arms' bases hang from: the mobile base's, else the world."""
        return self.world_frame if self.mobile_base is None else self.mobile_base.frame

    @classmethod
    def load(cls, path: str | Path) -> RobotConfig:
        """Read robot.yaml; relative paths in it resolve against its directory."""
        p = Path(path)
        raw = read_yaml(p, error=RobotConfigError, what="robot configuration")
        return cls.from_mapping(raw if raw is not None else {}, base_dir=p.parent, source=str(p))

    @classmethod
    def from_mapping(
        cls, raw: Mapping[str, Any], *, base_dir: str | Path = ".", source: str = "robot"
    ) -> RobotConfig:
        """Parse and check a configuration mapping (e.g. ``ChainConfig.robot``)."""
        base = Path(base_dir)
        top = Section(raw, source=source, known=_KEYS, error=RobotConfigError)
        if "arms" in top:
            arms, joints, hold = _arms(top, base)
            urdf, pose = arms[0].urdf, None
        else:
            urdf = _resolve(top.name("urdf", required=True, hint="the path of the robot's URDF", what="a file name"),
                            base)
            calibration = _calibration(top, base) if "calibration" in top else None
            joints, hold, arms = _joints(top, calibration=calibration), _hold(top), ()
            pose = top.section("world_from_base", {"xyz", "rpy", "quat_xyzw", "rotvec"}).pose(
                rotation_required=False, translation=plausible.position)
        cameras = _cameras(top, base)
        world_frame = top.frame("world_frame", "world") or ""
        chain = top.section("chain", {"camera", "body", "latency_budget_s", "evidence"})
        chain_camera = chain.name("camera", what="a camera name")
        if chain_camera is not None and chain_camera not in cameras:
            chain.fail_at(chain.path("camera"), f"{chain_camera!r} is not one of the cameras {sorted(cameras)}")
        evidence = parse_evidence(chain)
        if evidence is not None and evidence.markers is not None:
            camera = cameras.get(chain_camera or next(iter(cameras), ""))
            if camera is None or camera.video_key is None:
                chain.fail("evidence.markers are searched in the chain camera's images: give that camera a video_key")
        return cls(
            urdf=urdf, joints=joints, cameras=cameras,
            state_feature=top.name("state_feature", "observation.state", what="a feature name") or "",
            world_frame=world_frame, mobile_base=parse_mobile_base(top, world_frame),
            world_from_base_translation=pose.xyz if pose else (0.0, 0.0, 0.0),
            world_from_base_quat_xyzw=pose.quat_xyzw if pose else (0.0, 0.0, 0.0, 1.0), hold=hold, arms=arms,
            detections=_detections(top, base, cameras), chain_camera=chain_camera,
            chain_body=chain.frame("body"), latency_budget_s=latency_budget(chain),
            evidence=evidence, source=source,
            notes=(*(n for cam in cameras.values() for n in cam.notes), *top.notes),
        )

    def check_names(self, names: Sequence[str]) -> None:
        """Every mapped state name is one of the dataset's ``names`` (raises, listing them)."""
        known = set(names)
        base = self.mobile_base.states if self.mobile_base is not None else ()
        missing = [s for s in (*(m.state for m in self.joints), *base) if s not in known]
        if missing:
            raise RobotConfigError(
                self.source, f"state names {missing} are not in {self.state_feature}; it has {list(names)}"
            )

    def chain_config(self, camera: str | None = None, *, root: str) -> ChainConfig:
        """The chain configuration to replay and attribute an episode with (frames, evidence, budget).

        ``camera`` defaults to ``chain.camera``, else the first camera; the body to ``chain.body``,
        else ``root`` (the URDF's root link). Its ``robot`` section points back at this file
        (``config``) when it was read from one.
        """
        name = camera or self.chain_camera or (next(iter(self.cameras)) if self.cameras else None)
        if name is None:
            raise RobotConfigError(self.source, "no cameras configured")
        if name not in self.cameras:
            raise RobotConfigError(self.source, f"no camera {name!r}; cameras are {sorted(self.cameras)}")
        frames = ChainFrames(camera=self.cameras[name].optical_frame, body=self.chain_body or root,
                             world=self.world_frame)
        if len({frames.camera, frames.body, frames.world}) < 3:
            raise RobotConfigError(self.source, f"chain: camera, body and world must be three different frames, got "
                                   f"{frames.camera!r}, {frames.body!r}, {frames.world!r}")
        robot = {"config": str(Path(self.source).resolve())} if Path(self.source).is_file() else None
        evidence = self.evidence or ChainEvidence()
        # Markers are searched in the chain camera's frames: its video (or image) feature is the image topic.
        topics = ChainTopics(image=self.cameras[name].video_key) if evidence.markers is not None else ChainTopics()
        return ChainConfig(frames=frames, evidence=evidence, topics=topics,
                           latency_budget_s=0.02 if self.latency_budget_s is None else self.latency_budget_s,
                           robot=robot, origin=Path(self.source).name, notes=self.notes)


#: What a generated robot.yaml is called in messages and fixes (it is written beside a run's outputs).
GENERATED_SOURCE = "robot.yaml (generated)"


@dataclass(frozen=True)
class GeneratedRobot:
    """robot.yaml made for a known arm, with the one line that says what it assumed."""

    text: str
    line: str
    episode: int

    def mapping(self) -> dict[str, Any]:
        """robot.yaml's keys (what a chain's inline robot section holds)."""
        import yaml

        raw: dict[str, Any] = yaml.safe_load(self.text)
        return raw

    def config(self, written_to: Path | None = None) -> RobotConfig:
        """The parsed configuration; findings' fixes name the file it is ``written_to``, else ``robot.yaml
        (generated)``."""
        return RobotConfig.from_mapping(self.mapping(), source=GENERATED_SOURCE if written_to is None
                                        else str(written_to))


def _resolve(value: str | None, base: Path) -> Path:
    p = Path(value or "").expanduser()
    return p if p.is_absolute() else base / p


def _unit(section: Section, key: str) -> JointUnit:
    value = section.get(key)
    try:
        return JointUnit(value)
    except (ValueError, TypeError):
        units = [u.value for u in JointUnit]
        section.fail_at(section.path(key), f"is an unknown unit {show(value)}; units are {units}")


def _joints(top: Section, prefix: str = "", calibration: Mapping[str, MotorCalibration] | None = None
            ) -> tuple[JointMapping, ...]:
    joints = top.section("joints", what="a mapping of dataset state names to URDF joints")
    if not joints.raw:
        top.fail_at("joints", "must map dataset state names to URDF joints")
    default_unit = _unit(top, "default_unit") if "default_unit" in top else None
    out = tuple(_joint_mapping(joints, state, spec, default_unit, prefix, calibration)
                for state, spec in joints.entries())
    seen: dict[str, str] = {}
    for m in out:
        if m.joint in seen:
            joints.fail(f"joint {m.joint!r} is driven by both {seen[m.joint]!r} and {m.state!r}")
        seen[m.joint] = m.state
    return out


def _joint_mapping(joints: Section, state: str, spec: Any, default_unit: JointUnit | None, prefix: str,
                   calibration: Mapping[str, MotorCalibration] | None) -> JointMapping:
    entry = joints.child({"joint": spec} if isinstance(spec, str) else spec, joints.path(state),
                         _JOINT_KEYS, what="a joint name or {joint, unit, sign, offset}")
    joint = entry.name("joint", required=True, what="a joint name") or ""
    if "unit" in entry:
        unit = _unit(entry, "unit")
    elif default_unit is not None:
        unit = default_unit
    else:
        entry.fail("no unit stated (give unit: rad | deg | m | mm | range_0_100 | range_m100_100, or a default_unit)")
    sign = entry.get("sign", 1.0)
    if isinstance(sign, bool) or sign not in (1, -1):
        entry.fail_at(entry.path("sign"), f"must be 1 or -1, got {show(sign)}")
    offset = entry.number("offset", 0.0, unit="rad or m", check=plausible.joint_value) or 0.0
    motor = _motor(calibration or {}, joint, state, prefix)
    given = entry.number("zero_ticks", unit="ticks")
    per_turn = entry.number("ticks_per_turn", unit="ticks", positive=True)
    if motor is None:
        return JointMapping(state, prefix + joint, unit, float(sign), offset,
                            ZERO_TICKS if given is None else given, per_turn or TICKS_PER_TURN)
    return JointMapping(state, prefix + joint, unit, float(sign), offset,
                        0.5 * (motor.range_min + motor.range_max) if given is None else given,
                        per_turn or CALIBRATED_TICKS_PER_TURN, (motor.range_min, motor.range_max),
                        motor.drive_mode == 1)


def _motor(calibration: Mapping[str, MotorCalibration], joint: str, state: str, prefix: str
           ) -> MotorCalibration | None:
    """The calibration of the motor driving ``joint``: named as the URDF joint, or as the state name without its
    arm prefix and ``.pos`` (LeRobot's motor names)."""
    motor = state.removesuffix(".pos")
    return calibration.get(joint) or calibration.get(motor.removeprefix(prefix) if prefix else motor)


def _hold(top: Section, prefix: str = "") -> dict[str, float]:
    hold = top.section("hold", what="a mapping of URDF joints to fixed positions (rad or m)")
    return {prefix + joint: hold.number_value(value, hold.path(joint), unit="rad or m", check=plausible.joint_value)
            for joint, value in hold.entries()}


def _arms(top: Section, base: Path) -> tuple[tuple[ArmConfig, ...], tuple[JointMapping, ...], dict[str, float]]:
    """``arms``: each arm's URDF, prefix, base pose, joints (prefixed) and held joints (prefixed)."""
    for key in ("urdf", "joints", "world_from_base", "default_unit", "hold", "calibration"):
        if key in top:
            top.fail_at(key, f"goes under each arm when arms are given (arms.<name>.{key})")
    section = top.section("arms", what="a mapping of arm names to {urdf, prefix, world_from_base, joints}")
    if not section.raw:
        top.fail_at("arms", "must name at least one arm")
    arms: list[ArmConfig] = []
    joints: list[JointMapping] = []
    hold: dict[str, float] = {}
    for name, spec in section.entries():
        arm = section.child(spec, section.path(name), _ARM_KEYS, what="{urdf, prefix, world_from_base, joints}")
        prefix = arm.name("prefix", f"{name}_", what="a frame prefix") or ""
        urdf = _resolve(arm.name("urdf", required=True, hint="the arm's URDF", what="a file name"), base)
        pose = arm.section("world_from_base", {"xyz", "rpy", "quat_xyzw", "rotvec"}).pose(
            rotation_required=False, translation=plausible.position)
        calibration = _calibration(arm, base) if "calibration" in arm else None
        arms.append(ArmConfig(name, urdf, prefix, pose.xyz, pose.quat_xyzw))
        joints.extend(_joints(arm, prefix, calibration))
        hold.update(_hold(arm, prefix))
    prefixes = [a.prefix for a in arms]
    if len(set(prefixes)) != len(prefixes):
        section.fail(f"arms share a prefix ({prefixes}): give each arm its own prefix")
    seen: dict[str, str] = {}
    for m in joints:
        if m.state in seen:
            section.fail(f"state {m.state!r} drives joints of two arms ({seen[m.state]!r} and {m.joint!r})")
        seen[m.state] = m.joint
    return tuple(arms), tuple(joints), hold


def _calibration(section: Section, base: Path) -> dict[str, MotorCalibration]:
    """A LeRobot calibration JSON: ``{motor: {id, drive_mode, homing_offset, range_min, range_max}}`` (one line
    per problem)."""
    import json

    path = _resolve(section.name("calibration", what="a file name"), base)
    where = section.path("calibration")
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as err:
        section.fail_at(where, f"cannot read the calibration JSON {path} ({err})")
    if not isinstance(raw, dict) or not all(isinstance(v, dict) for v in raw.values()):
        section.fail_at(where, f"{path}: expected {{motor: {{homing_offset, drive_mode, range_min, range_max}}}}")
    out: dict[str, MotorCalibration] = {}
    for motor, entry in raw.items():
        values = {key: entry.get(key, default) for key, default in
                  (("homing_offset", 0), ("drive_mode", 0), ("range_min", None), ("range_max", None))}
        for key, value in values.items():
            if isinstance(value, bool) or not isinstance(value, int | float) or not abs(value) < 1e5:
                section.fail_at(where, f"{path}: {motor}.{key} must be a number of ticks, got {show(value)}")
        if values["range_max"] <= values["range_min"]:
            section.fail_at(where, f"{path}: {motor}: range_max {show(values['range_max'])} must be above range_min "
                            f"{show(values['range_min'])}")
        if values["drive_mode"] not in (0, 1):
            section.fail_at(where, f"{path}: {motor}.drive_mode must be 0 or 1, got {show(values['drive_mode'])}")
        out[str(motor)] = MotorCalibration(float(values["range_min"]), float(values["range_max"]),
                                           int(values["drive_mode"]), float(values["homing_offset"]))
    return out


def _cameras(top: Section, base: Path) -> dict[str, CameraCalibration]:
    cameras = top.section("cameras", what="a mapping of camera names to calibration files or mappings")
    out: dict[str, CameraCalibration] = {}
    for name, spec in cameras.entries():
        if isinstance(spec, str):
            out[name] = load_calibration(spec, name=name, base_dir=base)
        elif isinstance(spec, Mapping):
            out[name] = load_calibration(spec, name=name, base_dir=base, source=top.source,
                                         where=cameras.path(name))
        else:
            cameras.fail_at(cameras.path(name), f"must be a file path or a mapping, got {show(spec)}")
    return out


def _detections(top: Section, base: Path, cameras: Mapping[str, CameraCalibration]) -> tuple[DetectionSource, ...]:
    raw = top.get("detections")
    if raw is None:
        return ()
    items = [raw] if isinstance(raw, Mapping) else raw
    if not isinstance(items, list):
        top.fail("detections must be a mapping or a list of {table} / {feature, camera}")
    out: list[DetectionSource] = []
    for i, item in enumerate(items):
        entry = top.child(item, f"detections[{i}]", {"table", "feature", "camera"},
                          what="{table: path} or {feature: name, camera: name}")
        if ("table" in entry) == ("feature" in entry):
            entry.fail("give exactly one of table or feature")
        camera = entry.name("camera", what="a camera name")
        if camera is not None and camera not in cameras:
            entry.fail(f"camera {camera!r} is not one of {sorted(cameras)}")
        if "feature" in entry:
            feature = entry.name("feature", what="a feature name")
            if camera is None:
                entry.fail(f"feature {feature!r} needs camera: <name>")
            out.append(DetectionSource(feature=feature, camera=camera))
        else:
            out.append(DetectionSource(table=_resolve(entry.name("table", what="a file name"), base), camera=camera))
    return tuple(out)
