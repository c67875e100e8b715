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
      camera_offset_window_s: 1    # each camera's offset searched within +-1 s from its own motion (0.5)
      tag_size_m: {default: 0.16, 100: 0.10}   # or one number: tag corners -> depth by PnP
      markers: {dictionary: DICT_5X5_1000, size_m: 0.14}  # markers searched in topics.image
    latency_budget_s: 0.02
    tolerance_m: 0.001             # a finding that moves the error by less is a note, not a fix

Calibration, mounts and poses from outside the log (paths relative to the chain file)::

    calibration: {file: cameras.yaml, camera: cam0}   # or a list; camera: name, rostopic or tagtopic
    mounts:                                          # static edges T_parent_child; they win over the log's
      - {parent: base_link, child: camera_link, xyz: [0.3, 0, 0.8], rpy: [0, 0.1, 0]}  # or quat_xyzw, rotvec
    urdf: robot.urdf                                 # fixed joints become static edges
    topics:
      odometry: [/odom, {topic: /vio/pose, child: base_link}]  # Odometry, PoseStamped, PoseWithCovariance-
                                                     # Stamped or TransformStamped as dynamic edges

A rig of several cameras lists them under ``cameras:`` (each camera's topics decide which camera an
observation belongs to, whatever its header.frame_id says)::

    frames: {body: rig, world: arena}   # world omitted: the rig has no pose (same-instant sightings only);
                                        # world equal to body: a fixed rig
    cameras:
      - {frame: cam_sync/cam0, detections: /cam_sync/cam0/tags, calibration: {file: cameras.yaml, camera: cam0}}
      - {frame: cam_sync/cam1, detections: /cam_sync/cam1/tags, calibration: {file: cameras.yaml, camera: cam1},
         camera_info: /cam1/camera_info, image: /cam1/image_raw, depth: /cam1/depth, latency_budget_s: 0.05}
    evidence:
      static_target: true
      moving_labels: [0, 1, 2]          # move: compared only between cameras at the same instant
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import yaml

from framechain.config import plausible
from framechain.config.chain_cameras import (
    CalibrationSource,
    MarkerSpec,
    RigCamera,
    calibration_sources,
    latency_budget,
    marker_spec,
    rig_cameras,
)
from framechain.config.errors import ChainConfigError
from framechain.config.file_kinds import not_a_chain
from framechain.config.mount import Mount, chain_mounts
from framechain.config.schema import Section, as_list, dataclass_keys, finite_number, read_yaml, show

#: The error worth acting on when the chain does not say (m): a millimetre.
DEFAULT_TOLERANCE_M = 0.001


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
class HopTopics:
    """Topics where the robot logged its own point at each hop (PointStamped)."""

    camera: str | None = None
    body: str | None = None
    world: str | None = None


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
    #: Labels of objects that move but are still evidence where several cameras see them at the same instant.
    moving_labels: tuple[str, ...] = ()
    #: Length of the windows a static target's spread is measured over (None: the default, 5 s).
    static_window_s: float | None = None
    #: How far (s, either way) each camera's time offset is searched from its own motion (None: the default, 0.5 s).
    camera_offset_window_s: float | None = None
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
    #: The error worth acting on (m): a finding whose effect is smaller is a note ("no action needed"), and no
    #: bound is under the fault that moves the error by this much.
    tolerance_m: float = DEFAULT_TOLERANCE_M
    #: Free-form robot section (URDF, joint mapping, calibrations) for joint-driven chains.
    robot: Mapping[str, Any] | None = None
    calibration: tuple[CalibrationSource, ...] = ()
    mounts: tuple[Mount, ...] = ()
    urdf: str | None = None
    #: The cameras of a rig (empty: the one camera of ``frames.camera``); ``frames.camera`` is the first.
    cameras: tuple[RigCamera, ...] = ()
    #: False for a rig chain without ``frames.world``: the rig has no pose (``frames.world`` is then the
    #: body frame) and sightings are compared only between cameras at the same instant.
    has_pose: bool = True
    #: The directory relative paths (calibration, urdf) resolve against (None: the working directory).
    base_dir: str | None = field(default=None, compare=False)
    #: Where the configuration came from (the chain file's name), to name mounts' sources.
    origin: str = field(default="chain", compare=False)
    #: Values that are plausible but unusual, one line each (the outputs' notes carry them).
    notes: tuple[str, ...] = field(default=(), compare=False)

    def to_dict(self) -> dict[str, Any]:
        """Plain dictionary, as written to CHAIN.yaml (None values dropped)."""
        raw = asdict(self)
        raw.pop("base_dir")
        raw.pop("origin")
        raw.pop("notes")
        if not raw.pop("has_pose"):
            raw["frames"].pop("world")
        if raw["tolerance_m"] == DEFAULT_TOLERANCE_M:
            raw.pop("tolerance_m")
        for key in ("calibration", "mounts", "cameras"):
            if not raw[key]:
                raw.pop(key)
        for mount in raw.get("mounts", []):  # what a chain's mounts: entry has not (see framechain.config.mount)
            for key in ("optical", "source", "form"):
                mount.pop(key)
        for camera in raw.get("cameras", []):
            if camera["calibration"] is not None:
                camera["calibration"].pop("frame")
        if not raw["topics"]["poses"]:
            raw["topics"].pop("poses")
        for key in ("ignore_labels", "moving_labels"):
            if not raw["evidence"][key]:
                raw["evidence"].pop(key)
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

    @property
    def is_rig(self) -> bool:
        """Whether the chain lists several cameras under ``cameras:``."""
        return len(self.cameras) > 1

    def camera_frames(self) -> tuple[str, ...]:
        """The optical frame of every camera of the chain (the rig's, in their order; else frames.camera)."""
        return tuple(c.frame for c in self.cameras) if self.cameras else (self.frames.camera,)

    def topic_frames(self) -> dict[str, str]:
        """Topic -> camera frame for every topic a rig camera names (its messages belong to that camera)."""
        return {topic: c.frame for c in self.cameras for topic in c.topics()}

    def detection_topics(self) -> tuple[str, ...]:
        """Every detections topic: the rig cameras', else ``topics.detections``."""
        if self.cameras:
            return tuple(c.detections for c in self.cameras)
        return (self.topics.detections,) if self.topics.detections else ()

    def calibration_sources(self) -> tuple[CalibrationSource, ...]:
        """Every calibration file entry: ``calibration:`` and each rig camera's (its frame filled in)."""
        own = tuple(c.calibration for c in self.cameras if c.calibration is not None)
        return (*self.calibration, *own)

    def latency_budget_for(self, frame: str) -> float:
        """The latency budget of one camera (its own, else the chain's)."""
        own = next((c.latency_budget_s for c in self.cameras if c.frame == frame), None)
        return self.latency_budget_s if own is None else own

    def to_yaml(self) -> str:
        """The configuration as YAML text a user can edit."""
        return yaml.safe_dump(self.to_dict(), sort_keys=False)

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], *, where: str = "chain",
                  base_dir: str | Path | None = None) -> ChainConfig:
        """Parse and check a configuration; a mistake raises :class:`ChainConfigError` naming the key.

        ``where`` names the source (the chain file) in messages; ``base_dir``: where relative paths
        (calibration files, urdf) live, normally the chain file's directory (None: the working
        directory). Plausible but unusual values become :attr:`notes`.
        """
        other = not_a_chain(raw, Path(where).name) if isinstance(raw, Mapping) else None
        if other is not None:
            raise ChainConfigError(where, other)
        top = Section(raw, source=where, known=dataclass_keys(cls, "base_dir", "origin", "notes", "has_pose"),
                      error=ChainConfigError)
        topics = top.section("topics", dataclass_keys(ChainTopics))
        evidence = parse_evidence(top) or ChainEvidence()
        cameras = rig_cameras(top)
        if cameras:
            given = sorted(k for k in ("detections", "camera_info", "image", "depth") if k in topics)
            if given:
                top.fail(f"{', '.join('topics.' + g for g in given)}: a rig chain gives these per camera, under "
                         "cameras:")
        images = "image" in topics or any(c.image for c in cameras)
        if evidence.markers is not None and not images:
            top.fail("evidence.markers needs topics.image (the image topic to find them in)")
        poses = _merge_pose_topics(_pose_topics(topics, "odometry") + _pose_topics(topics, "poses"), topics)
        odometry = poses[0].topic if poses else None
        if len(poses) == 1 and poses[0].child is None:
            poses = []
        robot = top.get("robot")
        if robot is not None and not isinstance(robot, Mapping):
            top.fail_at("robot", f"must be a mapping, got {show(robot)}")
        budget = latency_budget(top)
        tolerance = top.number("tolerance_m", DEFAULT_TOLERANCE_M, minimum=0.0, unit="m", check=plausible.tolerance)
        named = {k: topics.name(k, what="a topic name") for k in dataclass_keys(ChainTopics, "odometry", "poses")}
        frames_section = top.section("frames", dataclass_keys(ChainFrames))
        return cls(
            frames=_frames(frames_section, cameras),
            topics=ChainTopics(**named, odometry=odometry, poses=tuple(poses)),
            evidence=evidence,
            latency_budget_s=0.02 if budget is None else budget,
            tolerance_m=DEFAULT_TOLERANCE_M if tolerance is None else tolerance,
            robot=robot,
            calibration=calibration_sources(top),
            mounts=chain_mounts(top),
            urdf=top.name("urdf", what="a file name"),
            cameras=cameras,
            has_pose=not cameras or "world" in frames_section,
            base_dir=None if base_dir is None else str(base_dir),
            origin=Path(where).name if where != "chain" else "chain",
            notes=tuple(top.notes),
        )

    @classmethod
    def from_yaml(cls, path: str | Path) -> ChainConfig:
        """Read CHAIN.yaml."""
        p = Path(path)
        raw = read_yaml(p, error=ChainConfigError, what="chain configuration")
        if raw is None:
            raise ChainConfigError(str(p), "the chain configuration is empty (expected frames, topics, evidence)")
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


def parse_evidence(parent: Section) -> ChainEvidence | None:
    """The ``evidence`` mapping of CHAIN.yaml (or of robot.yaml's ``chain:``); None when not given."""
    if "evidence" not in parent:
        return None
    section = parent.section("evidence", dataclass_keys(ChainEvidence))
    hops = section.section("hops", dataclass_keys(HopTopics))
    point = section.vector("reference_point", 3, what="[x, y, z], three finite numbers in metres",
                           check=plausible.position)
    both = sorted(set(_labels(section, "ignore_labels")) & set(_labels(section, "moving_labels")))
    if both:
        section.fail(f"labels {both} are both in ignore_labels (not used) and moving_labels (used when seen by "
                     "several cameras at once): keep them in one")
    return ChainEvidence(
        hops=HopTopics(**{k: hops.name(k, what="a topic name") for k in dataclass_keys(HopTopics)}),
        target=section.name("target", what="a topic name"),
        reference=section.name("reference", what="a topic name"),
        reference_point=None if point is None else (point[0], point[1], point[2]),
        static_target=section.flag("static_target", False),
        ignore_labels=_labels(section, "ignore_labels"),
        moving_labels=_labels(section, "moving_labels"),
        static_window_s=section.number("static_window_s", positive=True, unit="s", check=plausible.static_window),
        camera_offset_window_s=section.number("camera_offset_window_s", positive=True, unit="s",
                                              check=plausible.offset_window),
        tag_size_m=_tag_size(section),
        markers=marker_spec(section),
    )


def _frames(section: Section, cameras: tuple[RigCamera, ...] = ()) -> ChainFrames:
    """The chain's frames; a rig's camera is its first camera's (or one of them), its world may be its body
    (a fixed rig) or left out (no pose: the body)."""
    default = ChainFrames()
    body = section.frame("body") or default.body
    if not cameras:
        frames = ChainFrames(camera=section.frame("camera") or default.camera, body=body,
                             world=section.frame("world") or default.world)
        # world equal to body: a camera on a body that does not move (a fixed rig); the camera is its own frame.
        if frames.camera in (frames.body, frames.world):
            section.fail(f"the camera frame {frames.camera!r} must differ from body {frames.body!r} and world "
                         f"{frames.world!r} (world may equal body: a body that does not move)")
        return frames
    names = [c.frame for c in cameras]
    camera = section.frame("camera") or names[0]
    if camera not in names:
        section.fail(f"camera {camera!r} is none of the rig's cameras ({', '.join(names)})")
    world = section.frame("world") or body
    if body in names or world in names:
        section.fail(f"body {body!r} and world {world!r} must not be camera frames of the rig")
    return ChainFrames(camera=camera, body=body, world=world)


def _labels(section: Section, key: str) -> tuple[str, ...]:
    """Labels as strings (YAML reads tag ids as numbers); a single label is accepted too."""
    raw = section.get(key)
    if raw is None:
        return ()
    items = raw if isinstance(raw, list | tuple) else [raw]
    if not all(isinstance(x, str | int) and not isinstance(x, bool) for x in items):
        section.expected(key, "a list of labels (tag ids or class names)", raw)
    return tuple(str(x) for x in items)


def _tag_size(section: Section) -> float | dict[str, float] | None:
    """One size, or ``{tag id: size, default: size}`` (ids as strings, as labels are)."""
    raw = section.get("tag_size_m")
    path = section.path("tag_size_m")
    if raw is None:
        return None
    if isinstance(raw, Mapping):
        sizes = section.child(raw, path)
        return {key: sizes.number_value(value, f"{path}.{key}", positive=True, unit="m", check=plausible.tag_size)
                for key, value in sizes.entries()}
    if not finite_number(raw) or raw <= 0:
        section.expected("tag_size_m", "a positive size in metres (one number, or {tag id: size, default: size})",
                         raw)
    return section.number_value(raw, path, check=plausible.tag_size)


def _drop_none(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, tuple | list):
        return [_drop_none(v) for v in value]
    return value


def _pose_topics(topics: Section, key: str) -> list[PoseTopic]:
    """``/odom``, ``{topic: /pose, child: base_link}`` or a list of them."""
    raw = topics.get(key)
    out: list[PoseTopic] = []
    for i, entry in enumerate(as_list(raw)):
        here = f"{topics.path(key)}[{i}]" if isinstance(raw, list | tuple) else topics.path(key)
        if isinstance(entry, str) and entry.strip():
            out.append(PoseTopic(entry.strip()))
            continue
        if not isinstance(entry, Mapping) or not isinstance(entry.get("topic"), str):
            topics.expected_at(here, "a topic name or {topic: /name, child: frame}", entry)
        pose = topics.child(entry, here, dataclass_keys(PoseTopic))
        out.append(PoseTopic(pose.name("topic", required=True, what="a topic name") or "", pose.frame("child")))
    return out


def _merge_pose_topics(poses: list[PoseTopic], topics: Section) -> list[PoseTopic]:
    """One entry per topic (``odometry`` and ``poses`` may both name it); a named child wins."""
    merged: dict[str, PoseTopic] = {}
    for pose in poses:
        known = merged.get(pose.topic)
        if known is not None and known.child and pose.child and known.child != pose.child:
            topics.fail(f"pose topic {pose.topic} is given two children, {known.child!r} and {pose.child!r}")
        if known is None or pose.child:
            merged[pose.topic] = pose
    return list(merged.values())
