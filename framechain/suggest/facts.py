"""What a log holds, by role: its topics by message type, its frame graph and the paths through it, and
hints in the files beside it (a calibration, a tag size) that a suggested chain or a missing key can name."""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from framechain.adapters.messages.kinds import Kind, normalize_msgtype
from framechain.adapters.model import LoadedLog
from framechain.suggest.frame_tree import EdgeInfo, frame_tree

CORNER_DETECTION_TYPES = frozenset({
    "apriltag_msgs/ApriltagArrayStamped",
    "apriltag_msgs/AprilTagDetectionArray",
    "fiducial_msgs/FiducialArray",
})
#: Detections that carry a 3D point or pose in the camera frame (a depth of their own).
POSE_DETECTION_TYPES = frozenset({
    "apriltag_ros/AprilTagDetectionArray",
    "fiducial_msgs/FiducialTransformArray",
    "vision_msgs/Detection3DArray",
})
#: Detections in pixels (depth from the hypothesis pose when given, else from depth images).
PIXEL_DETECTION_TYPES = frozenset({"vision_msgs/Detection2DArray", "vision_msgs/Detection2D"})
DETECTION_TYPES = CORNER_DETECTION_TYPES | POSE_DETECTION_TYPES | PIXEL_DETECTION_TYPES
#: What the reader makes observations of (a decoded topic of one of these kinds holds detections).
OBSERVATION_KINDS = frozenset({
    Kind.DETECTIONS, Kind.DETECTION, Kind.PIXEL_POINT, Kind.APRILTAGS, Kind.APRILTAG_POSES,
    Kind.FIDUCIAL_VERTICES, Kind.FIDUCIAL_TRANSFORMS, Kind.DETECTIONS_3D, Kind.CAMERA_POINT, Kind.MARKER_IMAGE,
})
IMAGE_TYPES = frozenset({"sensor_msgs/Image", "sensor_msgs/CompressedImage"})
CAMERA_INFO_TYPES = frozenset({"sensor_msgs/CameraInfo", "foxglove.CameraCalibration"})
POINT_TYPES = frozenset({"geometry_msgs/PointStamped", "geometry_msgs/PoseStamped",
                          "geometry_msgs/TransformStamped"})
#: Calibration or config files beside a log larger than this are not looked into for hints.
HINT_FILE_MAX_BYTES = 512_000


# -- what the log holds ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class LogFacts:
    """The topics of a log by role, and its frame graph."""

    msgtypes: dict[str, str]  # topic -> normalised message type
    counts: dict[str, int]
    edges: list[EdgeInfo]
    frames: set[str]

    def topics_of(self, types: frozenset[str]) -> list[str]:
        return sorted(t for t, m in self.msgtypes.items() if m in types)

    def describe(self, topic: str) -> str:
        return f"{self.msgtypes.get(topic, '?')} on {topic}"


def log_facts(loaded: LoadedLog) -> LogFacts:
    topics = getattr(loaded.info, "topics", ())
    edges = frame_tree(loaded.timeline.transforms)
    tl = loaded.timeline
    frames = {e.parent for e in edges} | {e.child for e in edges}
    frames |= set(tl.cameras.frame.tolist()) | set(tl.observations.camera_frame.tolist())
    return LogFacts(
        msgtypes={t.name: normalize_msgtype(t.msgtype) for t in topics},
        counts={t.name: int(t.count) for t in topics},
        edges=edges,
        frames={f for f in frames if f},
    )


def detection_topics(loaded: LoadedLog, facts: LogFacts) -> list[str]:
    """Topics of detections: known types, what the reader decoded as detections, and the sources
    of the observations it built; the one with the most detections first."""
    kinds = loaded.decoded_topics
    topics = set(facts.topics_of(DETECTION_TYPES))
    topics |= {t for t, k in kinds.items() if k in OBSERVATION_KINDS}
    obs = loaded.timeline.observations
    topics |= {str(s) for s in obs.source.tolist() if str(s)}
    count = {t: int((obs.source == t).sum()) for t in topics}
    return sorted(topics, key=lambda t: (-count[t], -facts.counts.get(t, 0), t))


def frame_path(edges: list[EdgeInfo], start: str, goal: str) -> list[EdgeInfo] | None:
    """The edges joining two frames (either direction), or None."""
    if start == goal:
        return []
    links: dict[str, list[tuple[str, EdgeInfo]]] = {}
    for e in edges:
        links.setdefault(e.parent, []).append((e.child, e))
        links.setdefault(e.child, []).append((e.parent, e))
    came: dict[str, tuple[str, EdgeInfo] | None] = {start: None}
    queue = deque([start])
    while queue:
        frame = queue.popleft()
        for nxt, edge in links.get(frame, []):
            if nxt in came:
                continue
            came[nxt] = (frame, edge)
            if nxt == goal:
                out: list[EdgeInfo] = []
                at = goal
                while (step := came[at]) is not None:
                    out.append(step[1])
                    at = step[0]
                return out[::-1]
            queue.append(nxt)
    return None


def path_text(path: list[EdgeInfo], facts: LogFacts, *, start: str) -> str:
    """``world -> odom -> base_link (dynamic, nav_msgs/Odometry on /odom; tf2_msgs/TFMessage on /tf)``."""
    frames = [start]
    for e in path:
        frames.append(e.child if e.parent == frames[-1] else e.parent)
    kind = "static" if all(e.is_static for e in path) else "dynamic"
    sources = dict.fromkeys(facts.describe(s) if s in facts.msgtypes else s for e in path for s in e.sources)
    return f"{' -> '.join(frames)} ({kind}, {'; '.join(sources)})"


# -- hints from files beside the log ------------------------------------------------------------------
def beside_yaml(log: Path) -> list[tuple[str, Any]]:
    """Small YAML files in the log's folder (calibration, tag sizes), parsed; unreadable ones skipped."""
    folder = log if log.is_dir() else log.parent
    out: list[tuple[str, Any]] = []
    try:
        candidates = sorted(folder.glob("*.yaml")) + sorted(folder.glob("*.yml"))
    except OSError:
        return out
    for path in candidates:
        try:
            if path.name == "metadata.yaml" or path.stat().st_size > HINT_FILE_MAX_BYTES:
                continue
            out.append((path.name, yaml.safe_load(path.read_text(errors="replace").replace("%YAML:1.0", ""))))
        except (OSError, yaml.YAMLError):
            continue
    return out


#: Names of a chain file beside a log (``<log name>.chain.yaml`` too; see :func:`chain_files_beside`).
CHAIN_FILE_NAMES = ("chain.yaml", "CHAIN.yaml")


def chain_files_beside(log: Path) -> list[Path]:
    """Chain files for ``log``, most specific first: ``<log name>.chain.yaml`` (``x.bag.chain.yaml`` or
    ``x.chain.yaml``) beside it, then ``chain.yaml`` or ``CHAIN.yaml`` in its folder (a bag directory's
    own folder first, then the one holding it)."""
    folders = [log, log.parent] if log.is_dir() else [log.parent]
    named = [log.parent / f"{log.name}.chain.yaml", log.parent / f"{log.stem}.chain.yaml"]
    plain = [folder / name for folder in folders for name in CHAIN_FILE_NAMES]
    return [p for p in dict.fromkeys([*named, *plain]) if p.is_file()]


def is_chain_file(name: str) -> bool:
    return name in CHAIN_FILE_NAMES or name.endswith(".chain.yaml")


@dataclass(frozen=True)
class BesideHint:
    """A value for a chain key taken from a file beside the log, and where it was found."""

    key: str  # ``calibration: {file: cameras.yaml, camera: cam1}``
    source: str  # ``cameras.yaml beside the log: cam1's tagtopic is /t265/fisheye2/tags``

    def as_key(self) -> str:
        """The key with its source as a note, ``key  (source)`` (the form ``needs.quote_key`` reads)."""
        return f"{self.key}  ({self.source})"


def from_file(name: str, what: str) -> str:
    tail = f": `--chain {name}` uses that chain" if is_chain_file(name) else ""
    return f"{what} in {name} beside the log{tail}"


def calibration_hint(beside: list[tuple[str, Any]], detection_topic: str | None) -> BesideHint | None:
    """``calibration: {file: cameras.yaml, camera: cam0}`` when a calibration file lies beside the log
    (a Kalibr camchain: the camera whose rostopic or tagtopic is the detections' topic)."""
    for name, raw in beside:
        if not isinstance(raw, Mapping):
            continue
        cams = {str(k): v for k, v in raw.items() if isinstance(v, Mapping) and isinstance(v.get("intrinsics"), list)}
        if not cams:
            if isinstance(raw.get("camera_matrix"), Mapping):
                return BesideHint(f"calibration: {{file: {name}}}", from_file(name, "camera_matrix"))
            continue
        hit = [k for k, v in cams.items()
               if detection_topic and detection_topic in (v.get("tagtopic"), v.get("rostopic"))]
        if hit:
            entry = cams[hit[0]]
            which = "tagtopic" if entry.get("tagtopic") == detection_topic else "rostopic"
            return BesideHint(f"calibration: {{file: {name}, camera: {hit[0]}}}",
                              f"{name} beside the log: {hit[0]}'s {which} is {detection_topic}")
        first = sorted(cams)[0]
        return BesideHint(f"calibration: {{file: {name}, camera: {first}}}",
                          f"{name} beside the log holds {', '.join(sorted(cams))}, none with "
                          f"{detection_topic or 'the detections topic'} as rostopic or tagtopic: pick the "
                          "detections' camera")
    return None
