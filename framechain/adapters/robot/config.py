"""robot.yaml: the URDF, how dataset state names map to its joints (with units), the cameras.

The file (or the ``robot:`` section of CHAIN.yaml, whose paths resolve against CHAIN.yaml)::

    urdf: so101_new_calib.urdf        # relative to this file
    state_feature: observation.state  # dataset feature holding the joint-state vector
    world_frame: world                # default "world"
    world_from_base:                  # static world -> URDF root; default identity
      xyz: [0.0, 0.0, 0.0]
      rpy: [0.0, 0.0, 0.0]            # or quat_xyzw: [x, y, z, w]
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
upper]. The joint position is ``sign * convert(value) + offset`` (offset in radians or metres),
so a calibration that puts the dataset's zero elsewhere than the URDF's is explicit too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml
from scipy.spatial.transform import Rotation

from framechain.adapters.robot.kinematics import RobotModel
from framechain.arrays import FloatArray
from framechain.config.calibration import CameraCalibration, load_calibration
from framechain.config.chain import ChainConfig, ChainFrames
from framechain.config.errors import ChainConfigError
from framechain.timeline import FramechainError

__all__ = [
    "DetectionSource",
    "JointMapping",
    "JointUnit",
    "RobotConfig",
    "RobotConfigError",
]


class RobotConfigError(FramechainError):
    """robot.yaml is malformed, names unknown joints or states, or leaves a unit unstated."""

    def __init__(self, source: str, what: str) -> None:
        self.source = source
        self.what = what
        super().__init__(f"{source}: {what}")


class JointUnit(StrEnum):
    """How a dataset records a joint; conversion to radians or metres is explicit."""

    RAD = "rad"
    DEG = "deg"
    M = "m"
    MM = "mm"
    RANGE_0_100 = "range_0_100"
    RANGE_M100_100 = "range_m100_100"


@dataclass(frozen=True)
class JointMapping:
    """One dataset state name driving one URDF joint: ``q = sign * convert(value) + offset``."""

    state: str
    joint: str
    unit: JointUnit
    sign: float = 1.0
    offset: float = 0.0

    def convert(self, values: npt.ArrayLike, lower: float | None, upper: float | None) -> FloatArray:
        """Dataset values -> joint position in SI (radians or metres)."""
        x = np.asarray(values, dtype=float)
        if self.unit in (JointUnit.RAD, JointUnit.M):
            si = x
        elif self.unit is JointUnit.DEG:
            si = np.deg2rad(x)
        elif self.unit is JointUnit.MM:
            si = x * 1e-3
        else:
            if lower is None or upper is None:
                raise RobotConfigError(
                    self.state, f"unit {self.unit.value} needs joint limits, and joint {self.joint!r} has none"
                )
            frac = x / 100.0 if self.unit is JointUnit.RANGE_0_100 else (x + 100.0) / 200.0
            si = lower + frac * (upper - lower)
        out: FloatArray = self.sign * si + self.offset
        return out


@dataclass(frozen=True)
class DetectionSource:
    """Where detections come from: a side table (Parquet/CSV) or a per-frame dataset feature."""

    table: Path | None = None
    feature: str | None = None
    camera: str | None = None


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
    #: The chain's evidence, as the ``evidence`` mapping of CHAIN.yaml (checked when read).
    evidence: Mapping[str, Any] | None = None
    source: str = ""

    # ------------------------------------------------------------------------------------ reading

    @classmethod
    def load(cls, path: str | Path) -> RobotConfig:
        """Read robot.yaml; relative paths in it resolve against its directory."""
        p = Path(path)
        try:
            raw = yaml.safe_load(p.read_text())
        except OSError as err:
            raise RobotConfigError(str(p), f"cannot read robot configuration ({err.strerror})") from err
        except yaml.YAMLError as err:
            raise RobotConfigError(str(p), f"not valid YAML ({err})") from err
        return cls.from_mapping(raw or {}, base_dir=p.parent, source=str(p))

    @classmethod
    def from_mapping(
        cls, raw: Mapping[str, Any], *, base_dir: str | Path = ".", source: str = "robot"
    ) -> RobotConfig:
        """Parse and check a configuration mapping (e.g. ``ChainConfig.robot``)."""
        base = Path(base_dir)
        if not isinstance(raw, Mapping):
            raise RobotConfigError(source, "expected a mapping at the top level")
        known = {"urdf", "state_feature", "world_frame", "world_from_base", "default_unit", "joints", "hold",
                 "cameras", "detections", "chain"}
        unknown = sorted(set(raw) - known)
        if unknown:
            raise RobotConfigError(source, f"unknown keys {unknown}; known keys are {sorted(known)}")
        if "urdf" not in raw:
            raise RobotConfigError(source, "missing urdf: the path of the robot's URDF")
        urdf = _resolve(raw["urdf"], base)
        default_unit = raw.get("default_unit")
        if default_unit is not None:
            default_unit = _unit(default_unit, source, "default_unit")
        joints_raw = raw.get("joints")
        if not isinstance(joints_raw, Mapping) or not joints_raw:
            raise RobotConfigError(source, "joints must map dataset state names to URDF joints")
        joints = tuple(_joint_mapping(str(k), v, default_unit, source) for k, v in joints_raw.items())
        seen: dict[str, str] = {}
        for m in joints:
            if m.joint in seen:
                raise RobotConfigError(source, f"joint {m.joint!r} is driven by both {seen[m.joint]!r} and {m.state!r}")
            seen[m.joint] = m.state
        hold_raw = raw.get("hold") or {}
        if not isinstance(hold_raw, Mapping):
            raise RobotConfigError(source, "hold must map URDF joints to fixed positions (rad or m)")
        hold: dict[str, float] = {}
        for k, v in hold_raw.items():
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise RobotConfigError(source, f"hold.{k} must be a finite number (rad or m), got {v!r}")
            hold[str(k)] = float(v)
        translation, quat = _pose(raw.get("world_from_base") or {}, source, "world_from_base")
        cameras_raw = raw.get("cameras") or {}
        if not isinstance(cameras_raw, Mapping):
            raise RobotConfigError(source, "cameras must map camera names to calibration files or mappings")
        cameras: dict[str, CameraCalibration] = {}
        for name, spec in cameras_raw.items():
            if isinstance(spec, str | Path | Mapping):
                cameras[str(name)] = load_calibration(spec, name=str(name), base_dir=base)
            else:
                raise RobotConfigError(source, f"cameras.{name} must be a file path or a mapping")
        detections = _detections(raw.get("detections"), base, source, cameras)
        chain = raw.get("chain") or {}
        chain_keys = {"camera", "body", "latency_budget_s", "evidence"}
        if not isinstance(chain, Mapping) or set(chain) - chain_keys:
            raise RobotConfigError(source, f"chain may only give {sorted(chain_keys)}")
        chain_camera = None if chain.get("camera") is None else str(chain["camera"])
        if chain_camera is not None and chain_camera not in cameras:
            raise RobotConfigError(source, f"chain.camera {chain_camera!r} is not one of the cameras {sorted(cameras)}")
        evidence = chain.get("evidence")
        budget = chain.get("latency_budget_s")
        try:  # the same checks as CHAIN.yaml
            ChainConfig.from_dict({k: v for k, v in (("evidence", evidence), ("latency_budget_s", budget))
                                   if v is not None}, where=f"{source}: chain")
        except ChainConfigError as err:
            raise RobotConfigError(source, str(err).split(": ", 1)[-1]) from err
        return cls(
            urdf=urdf, joints=joints, cameras=cameras,
            state_feature=str(raw.get("state_feature", "observation.state")),
            world_frame=str(raw.get("world_frame", "world")).lstrip("/"),
            world_from_base_translation=translation, world_from_base_quat_xyzw=quat, hold=hold,
            detections=detections, chain_camera=chain_camera,
            chain_body=None if chain.get("body") is None else str(chain["body"]),
            latency_budget_s=None if budget is None else float(budget),
            evidence=None if evidence is None else dict(evidence), source=source,
        )

    # ------------------------------------------------------------------------------------ using

    def model(self) -> RobotModel:
        """The URDF's kinematic model, checked against the joint mapping and the camera mounts."""
        model = RobotModel.from_urdf(self.urdf)
        self.check(model)
        return model

    def check(self, model: RobotModel) -> None:
        """Every mapped or held joint exists and moves; every camera path is fully driven."""
        for m in self.joints:
            joint = model.joints.get(m.joint)
            if joint is None:
                raise RobotConfigError(self.source, f"joints.{m.state}: the URDF has no joint {m.joint!r}; "
                                       f"its moving joints are {list(model.actuated)}")
            if not joint.moves or joint.mimic is not None:
                raise RobotConfigError(self.source, f"joints.{m.state}: joint {m.joint!r} is fixed or a mimic joint")
            if m.unit in (JointUnit.RANGE_0_100, JointUnit.RANGE_M100_100) and (
                joint.lower is None or joint.upper is None
            ):
                raise RobotConfigError(self.source, f"joints.{m.state}: unit {m.unit.value} needs limits on "
                                       f"joint {m.joint!r}, which has none")
        for name in self.hold:
            if name not in model.actuated:
                raise RobotConfigError(self.source, f"hold.{name}: not a moving, non-mimic URDF joint")
        driven = {m.joint for m in self.joints} | set(self.hold)
        for cam in self.cameras.values():
            # A camera named "wrist" on an SO-101 would add a second parent to the URDF's wrist_link.
            frames = [cam.optical_frame] if cam.mount.optical else [cam.link_frame, cam.optical_frame]
            taken = [f for f in frames if model.has_link(f) or f == self.world_frame]
            if taken:
                raise RobotConfigError(self.source, f"camera {cam.name!r}: its frame {taken[0]!r} is already a link "
                                       f"of the URDF; give the camera another name (e.g. {cam.name}_cam)")
            parent = cam.mount.parent
            if parent == self.world_frame:
                continue
            if not model.has_link(parent):
                raise RobotConfigError(self.source, f"camera {cam.name!r} is mounted on {parent!r}, which is "
                                       f"neither a URDF link nor the world frame {self.world_frame!r}")
            free = [j.name for j in model.path_joints(parent) if j.moves and j.mimic is None and j.name not in driven]
            if free:
                raise RobotConfigError(
                    self.source,
                    f"camera {cam.name!r} hangs below joints {free} that no dataset state drives: map them "
                    "under joints or fix them under hold",
                )
        if self.chain_body is not None and self.chain_body != self.world_frame and not model.has_link(self.chain_body):
            raise RobotConfigError(self.source, f"chain.body {self.chain_body!r} is not a URDF link")

    def check_names(self, names: Sequence[str]) -> None:
        """Every mapped state name is one of the dataset's ``names`` (raises, listing them)."""
        known = set(names)
        missing = [m.state for m in self.joints if m.state not in known]
        if missing:
            raise RobotConfigError(
                self.source, f"state names {missing} are not in {self.state_feature}; it has {list(names)}"
            )

    def joint_positions(
        self, model: RobotModel, values: npt.ArrayLike, names: Sequence[str]
    ) -> dict[str, FloatArray]:
        """``(T, n)`` dataset state vectors with column ``names`` -> ``{joint: (T,)}`` in SI units."""
        arr = np.asarray(values, dtype=float)
        self.check_names(names)
        index = {n: i for i, n in enumerate(names)}
        out: dict[str, FloatArray] = {}
        for m in self.joints:
            lower, upper = model.limits(m.joint)
            out[m.joint] = m.convert(arr[:, index[m.state]], lower, upper)
        return out

    def chain_frames(self, camera: str | None = None, *, root: str | None = None) -> ChainFrames:
        """The chain's frames: a camera's optical frame, the body (default the URDF root), the world.

        ``root`` saves parsing the URDF when the caller has the model already.
        """
        name = camera or self.chain_camera or (next(iter(self.cameras)) if self.cameras else None)
        if name is None:
            raise RobotConfigError(self.source, "no cameras configured")
        if name not in self.cameras:
            raise RobotConfigError(self.source, f"no camera {name!r}; cameras are {sorted(self.cameras)}")
        body = self.chain_body
        if body is None:
            body = root if root is not None else RobotModel.from_urdf(self.urdf).root
        return ChainFrames(camera=self.cameras[name].optical_frame, body=body, world=self.world_frame)


    def chain_config(self, camera: str | None = None, *, root: str | None = None) -> ChainConfig:
        """The chain configuration to replay and attribute an episode with (frames, evidence, budget).

        Its ``robot`` section points back at this file (``config``) when it was read from one.
        """
        frames = self.chain_frames(camera, root=root)
        raw: dict[str, Any] = {"frames": {"camera": frames.camera, "body": frames.body, "world": frames.world}}
        if self.evidence is not None:
            raw["evidence"] = dict(self.evidence)
        if self.latency_budget_s is not None:
            raw["latency_budget_s"] = self.latency_budget_s
        if Path(self.source).is_file():
            raw["robot"] = {"config": str(Path(self.source).resolve())}
        return ChainConfig.from_dict(raw, where=f"{self.source}: chain")


def _resolve(value: Any, base: Path) -> Path:
    p = Path(str(value)).expanduser()
    return p if p.is_absolute() else base / p


def _unit(value: Any, source: str, where: str) -> JointUnit:
    try:
        return JointUnit(str(value))
    except ValueError:
        raise RobotConfigError(
            source, f"{where}: unknown unit {value!r}; units are {[u.value for u in JointUnit]}"
        ) from None


def _joint_mapping(state: str, spec: Any, default_unit: JointUnit | None, source: str) -> JointMapping:
    if isinstance(spec, str):
        spec = {"joint": spec}
    if not isinstance(spec, Mapping):
        raise RobotConfigError(source, f"joints.{state} must be a joint name or {{joint, unit, sign, offset}}")
    unknown = sorted(set(spec) - {"joint", "unit", "sign", "offset"})
    if unknown:
        raise RobotConfigError(source, f"joints.{state}: unknown keys {unknown}")
    if "joint" not in spec:
        raise RobotConfigError(source, f"joints.{state}: missing joint")
    if "unit" in spec:
        unit = _unit(spec["unit"], source, f"joints.{state}")
    elif default_unit is not None:
        unit = default_unit
    else:
        raise RobotConfigError(
            source, f"joints.{state}: no unit stated (give unit: rad | deg | m | mm | range_0_100 | "
            "range_m100_100, or a default_unit)"
        )
    sign = spec.get("sign", 1.0)
    if sign not in (1, -1, 1.0, -1.0):
        raise RobotConfigError(source, f"joints.{state}: sign must be 1 or -1, got {sign!r}")
    offset = spec.get("offset", 0.0)
    if isinstance(offset, bool) or not isinstance(offset, int | float) or not math.isfinite(offset):
        raise RobotConfigError(source, f"joints.{state}: offset must be a number (rad or m), got {offset!r}")
    return JointMapping(state, str(spec["joint"]), unit, float(sign), float(offset))


def _pose(raw: Any, source: str, where: str) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    if not isinstance(raw, Mapping) or set(raw) - {"xyz", "rpy", "quat_xyzw"}:
        raise RobotConfigError(source, f"{where} must be {{xyz, rpy | quat_xyzw}}")
    try:
        xyz = np.asarray(raw.get("xyz", [0.0, 0.0, 0.0]), dtype=float).reshape(3)
        if "rpy" in raw and "quat_xyzw" in raw:
            raise RobotConfigError(source, f"{where}: give either rpy or quat_xyzw, not both")
        if "quat_xyzw" in raw:
            q = np.asarray(raw["quat_xyzw"], dtype=float).reshape(4)
            if abs(float(np.linalg.norm(q)) - 1.0) > 1e-3:
                raise RobotConfigError(source, f"{where}.quat_xyzw is not a unit quaternion (order x, y, z, w)")
            q = q / np.linalg.norm(q)
        else:
            rpy = np.asarray(raw.get("rpy", [0.0, 0.0, 0.0]), dtype=float).reshape(3)
            q = Rotation.from_euler("xyz", rpy).as_quat()
    except (TypeError, ValueError) as err:
        raise RobotConfigError(source, f"{where}: xyz needs 3 numbers, rpy 3, quat_xyzw 4 ({err})") from None
    if not (np.isfinite(xyz).all() and np.isfinite(q).all()):
        raise RobotConfigError(source, f"{where}: values must be finite")
    return (float(xyz[0]), float(xyz[1]), float(xyz[2])), (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def _detections(
    raw: Any, base: Path, source: str, cameras: Mapping[str, CameraCalibration]
) -> tuple[DetectionSource, ...]:
    if raw is None:
        return ()
    items = [raw] if isinstance(raw, Mapping) else raw
    if not isinstance(items, list):
        raise RobotConfigError(source, "detections must be a mapping or a list of {table} / {feature, camera}")
    out: list[DetectionSource] = []
    for item in items:
        if not isinstance(item, Mapping) or set(item) - {"table", "feature", "camera"}:
            raise RobotConfigError(source, "each detections entry is {table: path} or {feature: name, camera: name}")
        if ("table" in item) == ("feature" in item):
            raise RobotConfigError(source, "each detections entry gives exactly one of table or feature")
        camera = None if item.get("camera") is None else str(item["camera"])
        if camera is not None and camera not in cameras:
            raise RobotConfigError(source, f"detections: camera {camera!r} is not one of {sorted(cameras)}")
        if "feature" in item:
            if camera is None:
                raise RobotConfigError(source, f"detections feature {item['feature']!r} needs camera: <name>")
            out.append(DetectionSource(feature=str(item["feature"]), camera=camera))
        else:
            out.append(DetectionSource(table=_resolve(item["table"], base), camera=camera))
    return tuple(out)
