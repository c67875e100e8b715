"""The chain configuration: which frames make the chain, which topics feed it, what evidence exists.

It is the contract of ``CHAIN.yaml``; every key is checked and unknown keys are an error that
names them::

    frames: {camera: camera_color_optical_frame, body: base_link, world: map}
    topics:
      camera_info: /camera/color/camera_info
      detections: /detections
      depth: /camera/depth/image_rect_raw
    evidence:
      hops: {camera: /debug/point_camera, body: /debug/point_body, world: /debug/point_world}
      target: /grasp_target
      reference: /mocap/target
      reference_point: [2.0, 0.5, 0.4]
      static_target: true          # every label (tag id) is one static object
      ignore_labels: [7]           # labels known to move (rejected as ignored_label)
      static_window_s: 5           # each tag fitted per 5 s window: odometry drift does not pose as a fault
      tag_size_m: {default: 0.16, 100: 0.10}   # or one number: tag corners -> depth by PnP
      markers: {dictionary: DICT_5X5_1000, size_m: 0.14}  # markers searched in topics.image
    latency_budget_s: 0.02

Calibration, mounts and poses from outside the log (paths relative to the chain file)::

    calibration: {file: cameras.yaml, camera: cam0}   # or a list; camera: name, rostopic or tagtopic
    mounts:                                          # static edges T_parent_child; they win over the log's
      - {parent: base_link, child: camera_link, xyz: [0.3, 0, 0.8], rpy: [0, 0.1, 0]}  # or quat_xyzw, rotvec
    urdf: robot.urdf                                 # fixed joints become static edges
    topics:
      odometry: [/odom, {topic: /vio/pose, child: base_link}]  # Odometry, PoseStamped, PoseWithCovariance-
                                                     # Stamped or TransformStamped as dynamic edges
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from framechain.config.errors import ChainConfigError
from framechain.geometry.rotations import quat_from_rotvec, quat_from_rpy


@dataclass(frozen=True)
class ChainFrames:
    """The three frames of the chain: optical camera frame, body frame, world frame (map or odom)."""

    camera: str = "camera_optical_frame"
    body: str = "base_link"
    world: str = "map"


@dataclass(frozen=True)
class ChainTopics:
    """Where the raw inputs of the chain are recorded (None: not in this log)."""

    camera_info: str | None = None
    detections: str | None = None
    depth: str | None = None
    image: str | None = None
    #: PointStamped topic whose x, y are pixels (u, v) and z the depth in metres (0: none).
    pixel_points: str | None = None
    #: A CSV or Parquet side table of detections logged outside the bag (stamp, frame, u, v, depth).
    detections_table: str | None = None
    #: The (first) pose topic; ``topics.odometry`` may also be a list (all of them in ``poses``).
    odometry: str | None = None
    #: Every pose topic when ``topics.odometry`` is a list or names a child (see :class:`PoseTopic`).
    poses: tuple[PoseTopic, ...] = ()


@dataclass(frozen=True)
class PoseTopic:
    """A topic of poses (Odometry, PoseStamped, PoseWithCovarianceStamped, TransformStamped) read as
    the dynamic edge ``header.frame_id -> child``; ``child`` None: the message's child frame, else the
    chain's body frame."""

    topic: str
    child: str | None = None


@dataclass(frozen=True)
class CalibrationSource:
    """A camera calibration file (ROS camera_info, Kalibr camchain, OpenCV YAML) for one camera.

    ``camera`` picks the camera in a file of several (Kalibr: by name, rostopic or tagtopic);
    ``frame`` is the camera's optical frame (default: the chain's camera frame).
    """

    file: str
    camera: str | None = None
    frame: str | None = None


@dataclass(frozen=True)
class MountEdge:
    """A static edge ``T_parent_child`` the user declares (metres; rotation as ``quat_xyzw``)."""

    parent: str
    child: str
    xyz: tuple[float, float, float]
    quat_xyzw: tuple[float, float, float, float]


@dataclass(frozen=True)
class HopTopics:
    """Topics where the robot logged its own point at each hop (PointStamped)."""

    camera: str | None = None
    body: str | None = None
    world: str | None = None


@dataclass(frozen=True)
class MarkerSpec:
    """Markers to find in ``topics.image``: an OpenCV dictionary name and the side length in metres."""

    dictionary: str
    size_m: float | None = None


@dataclass(frozen=True)
class ChainEvidence:
    """The evidence a log holds beyond its raw inputs (every field optional)."""

    hops: HopTopics = field(default_factory=HopTopics)
    target: str | None = None
    reference: str | None = None
    reference_point: tuple[float, float, float] | None = None
    static_target: bool = False
    #: Labels (tag ids) of objects known to move: their observations are rejected as ``ignored_label``.
    ignore_labels: tuple[str, ...] = ()
    #: Length of the windows a static target's spread is measured over (None: the default, 5 s).
    static_window_s: float | None = None
    #: Side length of square tags in metres: one number, or tag id -> size with an optional ``default``.
    tag_size_m: float | dict[str, float] | None = None
    markers: MarkerSpec | None = None


@dataclass(frozen=True)
class ChainConfig:
    """Frames, topics and evidence of one chain, plus the latency budget in seconds."""

    frames: ChainFrames = field(default_factory=ChainFrames)
    topics: ChainTopics = field(default_factory=ChainTopics)
    evidence: ChainEvidence = field(default_factory=ChainEvidence)
    latency_budget_s: float = 0.02
    #: Free-form robot section (URDF, joint mapping, calibrations) for joint-driven chains.
    robot: Mapping[str, Any] | None = None
    calibration: tuple[CalibrationSource, ...] = ()
    mounts: tuple[MountEdge, ...] = ()
    urdf: str | None = None
    #: The directory relative paths (calibration, urdf) resolve against (None: the working directory).
    base_dir: str | None = field(default=None, compare=False)
    #: Where the configuration came from (the chain file's name), to name mounts' sources.
    origin: str = field(default="chain", compare=False)

    def to_dict(self) -> dict[str, Any]:
        """Plain dictionary, as written to CHAIN.yaml (None values dropped)."""
        raw = asdict(self)
        raw.pop("base_dir")
        raw.pop("origin")
        for key in ("calibration", "mounts"):
            if not raw[key]:
                raw.pop(key)
        if not raw["topics"]["poses"]:
            raw["topics"].pop("poses")
        if not raw["evidence"]["ignore_labels"]:
            raw["evidence"].pop("ignore_labels")
        out: dict[str, Any] = _drop_none(raw)
        return out

    def resolve(self, path: str) -> Path:
        """A path named by the chain, relative to the chain file's directory."""
        p = Path(path).expanduser()
        return p if p.is_absolute() or self.base_dir is None else Path(self.base_dir) / p

    def pose_topics(self) -> tuple[PoseTopic, ...]:
        """Every topic read as a dynamic pose edge: ``topics.poses``, plus ``topics.odometry``."""
        t = self.topics
        named = {p.topic for p in t.poses}
        extra = (PoseTopic(t.odometry),) if t.odometry and t.odometry not in named else ()
        return (*t.poses, *extra)

    def to_yaml(self) -> str:
        """The configuration as YAML text a user can edit."""
        return yaml.safe_dump(self.to_dict(), sort_keys=False)

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], *, where: str = "chain",
                  base_dir: str | Path | None = None) -> ChainConfig:
        """Parse and check a configuration; unknown keys raise :class:`ChainConfigError`.

        ``base_dir``: where relative paths (calibration files, urdf) live, normally the chain
        file's directory (None: the working directory).
        """
        if not isinstance(raw, Mapping):
            raise ChainConfigError(f"{where}: expected a mapping at the top level")
        _check_keys(raw, cls, where, internal=("base_dir", "origin"))
        evidence_raw = raw.get("evidence") or {}
        _check_keys(evidence_raw, ChainEvidence, f"{where}: evidence")
        hops_raw = evidence_raw.get("hops") or {}
        _check_keys(hops_raw, HopTopics, f"{where}: evidence.hops")
        point = evidence_raw.get("reference_point")
        if point is not None:
            numbers = isinstance(point, list | tuple) and len(point) == 3 and all(
                isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in point)
            if not numbers:
                raise ChainConfigError(
                    f"{where}: evidence.reference_point must be [x, y, z], three finite numbers in metres; "
                    f"got {point!r}")
            point = tuple(float(x) for x in point)
        frames_raw = raw.get("frames") or {}
        _check_keys(frames_raw, ChainFrames, f"{where}: frames")
        topics_raw = dict(raw.get("topics") or {})
        _check_keys(topics_raw, ChainTopics, f"{where}: topics")
        if evidence_raw.get("markers") is not None and not topics_raw.get("image"):
            raise ChainConfigError(f"{where}: evidence.markers needs topics.image (the image topic to find them in)")
        poses = _pose_topics(topics_raw.pop("odometry", None), f"{where}: topics.odometry")
        poses += _pose_topics(topics_raw.pop("poses", None), f"{where}: topics.poses")
        poses = _merge_pose_topics(poses, f"{where}: topics")
        odometry = poses[0].topic if poses else None
        if len(poses) == 1 and poses[0].child is None:
            poses = []
        urdf = raw.get("urdf")
        if urdf is not None and not (isinstance(urdf, str) and urdf.strip()):
            raise ChainConfigError(f"{where}: urdf must be a file name, got {urdf!r}")
        budget = raw.get("latency_budget_s", 0.02)
        if not isinstance(budget, int | float) or budget < 0:
            raise ChainConfigError(f"{where}: latency_budget_s must be a non-negative number of seconds")
        robot = raw.get("robot")
        if robot is not None and not isinstance(robot, Mapping):
            raise ChainConfigError(f"{where}: robot must be a mapping")
        frames = ChainFrames(**{k: str(v).lstrip("/") for k, v in frames_raw.items()})
        if len({frames.camera, frames.body, frames.world}) < 3:
            raise ChainConfigError(f"{where}: frames camera, body and world must be three different frames, got "
                                   f"{frames.camera!r}, {frames.body!r}, {frames.world!r}")
        return cls(
            frames=frames,
            topics=ChainTopics(**topics_raw, odometry=odometry, poses=tuple(poses)),
            evidence=ChainEvidence(
                hops=HopTopics(**hops_raw),
                target=evidence_raw.get("target"),
                reference=evidence_raw.get("reference"),
                reference_point=point,
                static_target=bool(evidence_raw.get("static_target", False)),
                ignore_labels=_ignore_labels(evidence_raw.get("ignore_labels"), f"{where}: evidence.ignore_labels"),
                static_window_s=_window_s(evidence_raw.get("static_window_s"), f"{where}: evidence.static_window_s"),
                tag_size_m=_tag_size(evidence_raw.get("tag_size_m"), f"{where}: evidence.tag_size_m"),
                markers=_marker_spec(evidence_raw.get("markers"), f"{where}: evidence.markers"),
            ),
            latency_budget_s=float(budget),
            robot=robot,
            calibration=_calibration_sources(raw.get("calibration"), f"{where}: calibration"),
            mounts=tuple(_mount_edge(m, f"{where}: mounts[{i}]") for i, m in enumerate(_as_list(raw.get("mounts")))),
            urdf=None if urdf is None else str(urdf),
            base_dir=None if base_dir is None else str(base_dir),
            origin=Path(where).name if where != "chain" else "chain",
        )

    @classmethod
    def from_yaml(cls, path: str | Path) -> ChainConfig:
        """Read CHAIN.yaml."""
        p = Path(path)
        try:
            raw = yaml.safe_load(p.read_text())
        except OSError as err:
            raise ChainConfigError(f"{p}: cannot read chain configuration ({err.strerror})") from err
        except yaml.YAMLError as err:
            raise ChainConfigError(f"{p}: not valid YAML ({err})") from err
        if raw is None:
            raise ChainConfigError(f"{p}: the chain configuration is empty (expected frames, topics, evidence)")
        return cls.from_dict(raw, where=str(p), base_dir=p.parent)

    def evidence_topics(self) -> dict[str, str]:
        """Topic -> role name for every evidence topic configured."""
        out: dict[str, str] = {}
        hops = self.evidence.hops
        for role, topic in (
            ("hop_camera", hops.camera), ("hop_body", hops.body), ("hop_world", hops.world),
            ("target", self.evidence.target), ("reference", self.evidence.reference),
        ):
            if topic:
                out[topic] = role
        return out


def _ignore_labels(raw: Any, where: str) -> tuple[str, ...]:
    """Labels as strings (YAML reads tag ids as numbers); a single label is accepted too."""
    if raw is None:
        return ()
    items = raw if isinstance(raw, list | tuple) else [raw]
    if not all(isinstance(x, str | int) and not isinstance(x, bool) for x in items):
        raise ChainConfigError(f"{where}: expected a list of labels (tag ids or class names), got {raw!r}")
    return tuple(str(x) for x in items)


def _window_s(raw: Any, where: str) -> float | None:
    return None if raw is None else _positive(raw, where, "number of seconds")


def _positive_size(raw: Any, where: str) -> float:
    return _positive(raw, where, "size in metres")


def _positive(raw: Any, where: str, what: str) -> float:
    if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw) or raw <= 0:
        raise ChainConfigError(f"{where}: expected a positive {what}, got {raw!r}")
    return float(raw)


def _tag_size(raw: Any, where: str) -> float | dict[str, float] | None:
    """One size, or ``{tag id: size, default: size}`` (ids as strings, as labels are)."""
    if raw is None:
        return None
    if isinstance(raw, Mapping):
        return {str(k): _positive_size(v, f"{where}.{k}") for k, v in raw.items()}
    return _positive_size(raw, where)


def _marker_spec(raw: Any, where: str) -> MarkerSpec | None:
    if raw is None:
        return None
    _check_keys(raw, MarkerSpec, where)
    name = raw.get("dictionary")
    if not isinstance(name, str) or not name.strip():
        raise ChainConfigError(f"{where}: needs dictionary: an OpenCV marker dictionary such as DICT_5X5_1000")
    size = raw.get("size_m")
    return MarkerSpec(name.strip(), None if size is None else _positive_size(size, f"{where}.size_m"))


def _check_keys(raw: Any, cls: type, where: str, *, internal: tuple[str, ...] = ()) -> None:
    if not isinstance(raw, Mapping):
        raise ChainConfigError(f"{where}: expected a mapping, got {type(raw).__name__}")
    known = {f.name for f in fields(cls)} - set(internal)
    unknown = sorted(set(raw) - known)
    if unknown:
        raise ChainConfigError(f"{where}: unknown keys {unknown}; known keys are {sorted(known)}")


def _drop_none(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, tuple | list):
        return [_drop_none(v) for v in value]
    return value


def _as_list(raw: Any) -> list[Any]:
    if raw is None:
        return []
    return list(raw) if isinstance(raw, list | tuple) else [raw]


def _pose_topics(raw: Any, where: str) -> list[PoseTopic]:
    """``/odom``, ``{topic: /pose, child: base_link}`` or a list of them."""
    out: list[PoseTopic] = []
    for i, entry in enumerate(_as_list(raw)):
        here = f"{where}[{i}]" if isinstance(raw, list | tuple) else where
        if isinstance(entry, str) and entry:
            out.append(PoseTopic(entry))
            continue
        if not isinstance(entry, Mapping) or not isinstance(entry.get("topic"), str):
            raise ChainConfigError(f"{here}: expected a topic name or {{topic: /name, child: frame}}, got {entry!r}")
        _check_keys(entry, PoseTopic, here)
        child = entry.get("child")
        out.append(PoseTopic(str(entry["topic"]), None if child is None else str(child).lstrip("/")))
    return out


def _merge_pose_topics(poses: list[PoseTopic], where: str) -> list[PoseTopic]:
    """One entry per topic (``odometry`` and ``poses`` may both name it); a named child wins."""
    merged: dict[str, PoseTopic] = {}
    for pose in poses:
        known = merged.get(pose.topic)
        if known is not None and known.child and pose.child and known.child != pose.child:
            raise ChainConfigError(f"{where}: pose topic {pose.topic} is given two children, {known.child!r} and "
                                   f"{pose.child!r}")
        if known is None or pose.child:
            merged[pose.topic] = pose
    return list(merged.values())


def _calibration_sources(raw: Any, where: str) -> tuple[CalibrationSource, ...]:
    out: list[CalibrationSource] = []
    for i, entry in enumerate(_as_list(raw)):
        here = f"{where}[{i}]" if isinstance(raw, list | tuple) else where
        fields_ = {"file": entry} if isinstance(entry, str) else entry
        _check_keys(fields_, CalibrationSource, here)
        if not isinstance(fields_.get("file"), str) or not fields_["file"].strip():
            raise ChainConfigError(f"{here}: needs file: the calibration file (relative to the chain file)")
        camera, frame = fields_.get("camera"), fields_.get("frame")
        out.append(CalibrationSource(str(fields_["file"]), None if camera is None else str(camera),
                                     None if frame is None else str(frame).lstrip("/")))
    defaulted = [i for i, c in enumerate(out) if c.frame is None]
    if len(defaulted) > 1:
        raise ChainConfigError(f"{where}[{defaulted[1]}]: give frame: (the camera's optical frame); only one entry "
                               "can default to frames.camera")
    return tuple(out)


_ROTATION_KEYS = ("quat_xyzw", "rpy", "rotvec")


def _mount_edge(raw: Any, where: str) -> MountEdge:
    """``{parent, child, xyz, quat_xyzw | rpy | rotvec}`` as ``T_parent_child``."""
    if not isinstance(raw, Mapping):
        raise ChainConfigError(f"{where}: expected {{parent, child, xyz, quat_xyzw | rpy | rotvec}}, got {raw!r}")
    known = {"parent", "child", "xyz", *_ROTATION_KEYS}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise ChainConfigError(f"{where}: unknown keys {unknown}; known keys are {sorted(known)}")
    for key in ("parent", "child"):
        if not isinstance(raw.get(key), str) or not raw[key].strip("/ "):
            raise ChainConfigError(f"{where}: needs {key}: a frame name")
    parent, child = raw["parent"].strip().lstrip("/"), raw["child"].strip().lstrip("/")
    if parent == child:
        raise ChainConfigError(f"{where}: parent and child are the same frame {parent!r}")
    given = [k for k in _ROTATION_KEYS if k in raw]
    if len(given) != 1:
        what = f"two rotations ({' and '.join(given)})" if given else "no rotation"
        raise ChainConfigError(f"{where}: {what}; give exactly one of quat_xyzw [x, y, z, w], rpy [roll, pitch, yaw] "
                               "(radians, fixed axes x-y-z as URDF) or rotvec [x, y, z] (radians)")
    xyz = _numbers(raw.get("xyz", [0.0, 0.0, 0.0]), 3, f"{where}: xyz")
    key = given[0]
    if key == "quat_xyzw":
        q = _numbers(raw[key], 4, f"{where}: quat_xyzw")
        norm = math.sqrt(sum(x * x for x in q))
        if abs(norm - 1.0) > 1e-3:
            raise ChainConfigError(f"{where}: quat_xyzw {list(q)} has norm {norm:.6g}, not 1 (the order is x, y, z, w)")
        # Renormalise only what is off by more than rounding, so that to_dict -> from_dict is exact.
        quat = tuple(x / norm for x in q) if abs(norm - 1.0) > 1e-15 else q
    elif key == "rpy":
        quat = quat_xyzw_from_rpy(*_numbers(raw[key], 3, f"{where}: rpy"))
    else:
        quat = quat_xyzw_from_rotvec(*_numbers(raw[key], 3, f"{where}: rotvec"))
    return MountEdge(parent, child, (xyz[0], xyz[1], xyz[2]), (quat[0], quat[1], quat[2], quat[3]))


def _numbers(raw: Any, n: int, where: str) -> tuple[float, ...]:
    ok = isinstance(raw, list | tuple) and len(raw) == n and all(
        isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in raw)
    if not ok:
        raise ChainConfigError(f"{where}: expected {n} finite numbers, got {raw!r}")
    return tuple(float(x) for x in raw)


def quat_xyzw_from_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """URDF/tf2 rpy (fixed axes x, y, z; radians) as a unit quaternion (timeline.quaternion's maths)."""
    x, y, z, w = quat_from_rpy(np.array([roll, pitch, yaw])).tolist()
    return (x, y, z, w)


def quat_xyzw_from_rotvec(x: float, y: float, z: float) -> tuple[float, float, float, float]:
    """Rotation vector (axis times angle, radians) as a unit quaternion (timeline.quaternion's maths)."""
    qx, qy, qz, qw = quat_from_rotvec(np.array([x, y, z])).tolist()
    return (qx, qy, qz, qw)
