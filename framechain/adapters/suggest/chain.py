"""What a chain needs, what a log has, and a chain to start from.

A chain replays when the log (plus the chain's own files: calibration, mounts, urdf) gives each
piece: a camera frame, intrinsics for it, detections, a depth for each detection (depth images,
a depth in the message, or a tag size for PnP), a path camera -> body (the mount) and a path
body -> world (the pose). Attribution needs evidence on top. :func:`chain_needs` checks each piece
and names, for a missing one, the exact chain key that supplies it; :func:`suggest` proposes a
chain that names only frames the log has (a missing frame is a marked placeholder, never an
invented name); :func:`why_nothing_replayed` says in one line why a replay has nothing to show.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from framechain.adapters.messages.kinds import POSE_TYPES, Kind, normalize_msgtype
from framechain.adapters.model import LoadedLog
from framechain.adapters.suggest.frame_tree import EdgeInfo, frame_tree, tree_roots
from framechain.adapters.suggest.marker_probe import MarkerProbe, probe_markers
from framechain.config.chain import ChainConfig, ChainEvidence, ChainFrames, ChainTopics, HopTopics
from framechain.timeline import TransformTable

__all__ = [
    "ChainNeed",
    "NeedStatus",
    "SuggestedChain",
    "chain_needs",
    "quote_key",
    "suggest",
    "suggest_chain",
    "why_nothing_replayed",
]

#: Detections with 2D corners: a depth comes from PnP with ``evidence.tag_size_m``.
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
_POINT_TYPES = frozenset({"geometry_msgs/PointStamped", "geometry_msgs/PoseStamped",
                          "geometry_msgs/TransformStamped"})
#: Calibration or config files beside a log larger than this are not looked into for hints.
_HINT_FILE_MAX_BYTES = 512_000


class NeedStatus(StrEnum):
    FOUND = "found"
    MISSING = "missing"
    NONE = "none"  # optional for replay (evidence): attribution needs it


@dataclass(frozen=True)
class ChainNeed:
    """One piece of the chain: found (and where) or missing (and the chain key that supplies it)."""

    piece: str  # camera frame | intrinsics | detections | depth | mount | pose | evidence
    status: NeedStatus
    detail: str
    #: What to add to CHAIN.yaml (a YAML fragment with placeholders in capitals); "" when found.
    key: str = ""

    @property
    def found(self) -> bool:
        return self.status == NeedStatus.FOUND

    def fix(self) -> str:
        """The key as prose: ``add `evidence.tag_size_m: 0.16` (the tags' edge)``; "" when found."""
        return f"add {quote_key(self.key)}" if self.key else ""

    def line(self) -> str:
        """``depth: missing (no depth images, no tag size: add `evidence.tag_size_m: 0.16`)``."""
        fix = f": {self.fix()}" if self.key else ""
        return f"{self.piece}: {self.status.value} ({self.detail}{fix})"

    def to_dict(self) -> dict[str, Any]:
        return {"piece": self.piece, "status": self.status.value, "detail": self.detail, "key": self.key}


def quote_key(key: str) -> str:
    """``a: 1  (why); or b: 2`` as ```a: 1` (why); or `b: 2```: keys in backticks, notes outside."""
    parts = []
    for part in key.split("; "):
        lead = "or " if part.startswith("or ") else ""
        text, _, note = part.removeprefix("or ").partition("  (")
        parts.append(f"{lead}`{text.strip()}`" + (f" ({note}" if note else ""))
    return "; ".join(parts)


#: The pieces a replay cannot do without (evidence is for attribution).
REPLAY_PIECES = ("camera frame", "intrinsics", "detections", "depth", "mount", "pose")


@dataclass(frozen=True)
class SuggestedChain:
    """A chain to start from; ``placeholders`` maps a frame slot the log cannot fill to why."""

    config: ChainConfig
    placeholders: Mapping[str, str] = field(default_factory=dict)
    needs: tuple[ChainNeed, ...] = ()

    @property
    def ready(self) -> bool:
        """Every piece a replay needs is in the log."""
        return all(n.found for n in self.needs if n.piece in REPLAY_PIECES)

    def missing(self) -> list[ChainNeed]:
        return [n for n in self.needs if n.status != NeedStatus.FOUND]

    def to_yaml(self, *, source: str = "") -> str:
        """CHAIN.yaml text: placeholder frames and missing keys as marked comments to fill in."""
        raw = self.config.to_dict()
        frames = raw.pop("frames")
        head = [f"# chain suggested by `framechain info` from {source}; edit before use" if source
                else "# chain suggested by `framechain info`; edit before use"]
        if not self.ready:
            head.append("# NOT READY: this log lacks pieces of the chain (the FILL IN comments below)")
        lines = ["frames:"]
        for slot in ("camera", "body", "world"):
            if slot in self.placeholders:
                lines.append(f"  # {slot}: FILL IN  # placeholder: {self.placeholders[slot]}")
            else:
                lines.append(f"  {slot}: {_scalar(frames[slot])}")
        todo = [n for n in self.missing() if n.key]
        evidence = raw.get("evidence") or {}
        for name in [k for k, v in evidence.items() if v in (None, False, [], {})]:
            # An unset key the FILL IN comments ask for is left out, not written beside them as false.
            if any(f"evidence.{name}" in n.key for n in todo):
                del evidence[name]
        if "evidence" in raw and not evidence:
            del raw["evidence"]
        body = yaml.safe_dump(raw, sort_keys=False).rstrip("\n")
        tail = []
        if todo:
            tail.append("# FILL IN what the log lacks: add these keys, replacing the CAPITALS")
            tail.append("# (`evidence.tag_size_m: 0.16` is `tag_size_m: 0.16` under `evidence:`):")
            for need in todo:
                tail.append(f"#   {need.piece}: {need.detail}")
                tail.extend(f"#     {line}" for line in need.key.split("; "))
        return "\n".join([*head, *lines, body, *tail]) + "\n"


def _scalar(value: str) -> str:
    return yaml.safe_dump(value, default_flow_style=True).removesuffix("\n...\n").strip()


# -- what the log holds ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class _LogFacts:
    """The topics of a log by role, and its frame graph."""

    msgtypes: dict[str, str]  # topic -> normalised message type
    counts: dict[str, int]
    edges: list[EdgeInfo]
    frames: set[str]

    def topics_of(self, types: frozenset[str]) -> list[str]:
        return sorted(t for t, m in self.msgtypes.items() if m in types)

    def describe(self, topic: str) -> str:
        return f"{self.msgtypes.get(topic, '?')} on {topic}"


def _facts(loaded: LoadedLog) -> _LogFacts:
    topics = getattr(loaded.info, "topics", ())
    edges = frame_tree(loaded.timeline.transforms)
    tl = loaded.timeline
    frames = {e.parent for e in edges} | {e.child for e in edges}
    frames |= set(tl.cameras.frame.tolist()) | set(tl.observations.camera_frame.tolist())
    return _LogFacts(
        msgtypes={t.name: normalize_msgtype(t.msgtype) for t in topics},
        counts={t.name: int(t.count) for t in topics},
        edges=edges,
        frames={f for f in frames if f},
    )


def _detection_topics(loaded: LoadedLog, facts: _LogFacts) -> list[str]:
    """Topics of detections: known types, what the reader decoded as detections, and the sources
    of the observations it built; the one with the most detections first."""
    kinds = loaded.decoded_topics
    topics = set(facts.topics_of(DETECTION_TYPES))
    topics |= {t for t, k in kinds.items() if k in OBSERVATION_KINDS}
    obs = loaded.timeline.observations
    topics |= {str(s) for s in obs.source.tolist() if str(s)}
    count = {t: int((obs.source == t).sum()) for t in topics}
    return sorted(topics, key=lambda t: (-count[t], -facts.counts.get(t, 0), t))


def _path(edges: list[EdgeInfo], start: str, goal: str) -> list[EdgeInfo] | None:
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


def _path_text(path: list[EdgeInfo], facts: _LogFacts, *, start: str) -> str:
    """``world -> odom -> base_link (dynamic, nav_msgs/Odometry on /odom; tf2_msgs/TFMessage on /tf)``."""
    frames = [start]
    for e in path:
        frames.append(e.child if e.parent == frames[-1] else e.parent)
    kind = "static" if all(e.is_static for e in path) else "dynamic"
    sources = dict.fromkeys(facts.describe(s) if s in facts.msgtypes else s for e in path for s in e.sources)
    return f"{' -> '.join(frames)} ({kind}, {'; '.join(sources)})"


# -- hints from files beside the log ------------------------------------------------------------------
def _beside_yaml(log: Path) -> list[tuple[str, Any]]:
    """Small YAML files in the log's folder (calibration, tag sizes), parsed; unreadable ones skipped."""
    folder = log if log.is_dir() else log.parent
    out: list[tuple[str, Any]] = []
    try:
        candidates = sorted(folder.glob("*.yaml")) + sorted(folder.glob("*.yml"))
    except OSError:
        return out
    for path in candidates:
        try:
            if path.name == "metadata.yaml" or path.stat().st_size > _HINT_FILE_MAX_BYTES:
                continue
            out.append((path.name, yaml.safe_load(path.read_text(errors="replace").replace("%YAML:1.0", ""))))
        except (OSError, yaml.YAMLError):
            continue
    return out


def _calibration_hint(beside: list[tuple[str, Any]], detection_topic: str | None) -> str | None:
    """``calibration: {file: cameras.yaml, camera: cam0}`` when a Kalibr file beside the log names the
    detections' camera (by rostopic or tagtopic)."""
    for name, raw in beside:
        if not isinstance(raw, Mapping):
            continue
        cams = {str(k): v for k, v in raw.items() if isinstance(v, Mapping) and isinstance(v.get("intrinsics"), list)}
        if not cams:
            if isinstance(raw.get("camera_matrix"), Mapping):
                return f"calibration: {{file: {name}}}"
            continue
        hit = [k for k, v in cams.items()
               if detection_topic and detection_topic in (v.get("tagtopic"), v.get("rostopic"))]
        return f"calibration: {{file: {name}, camera: {(hit or sorted(cams))[0]}}}"
    return None


def _tag_size_hint(beside: list[tuple[str, Any]]) -> float | None:
    """A default tag size written in a config beside the log (TagSLAM's ``default_tag_size``)."""

    def find(value: Any, depth: int = 0) -> float | None:
        if depth > 6:
            return None
        if isinstance(value, Mapping):
            for key in ("default_tag_size", "tag_size", "tag_size_m"):
                size = value.get(key)
                if isinstance(size, int | float) and not isinstance(size, bool) and 0 < size < 10:
                    return float(size)
            for v in value.values():
                if (hit := find(v, depth + 1)) is not None:
                    return hit
        elif isinstance(value, list):
            for v in value:
                if (hit := find(v, depth + 1)) is not None:
                    return hit
        return None

    for _, raw in beside:
        if (size := find(raw)) is not None:
            return size
    return None


# -- the suggestion ---------------------------------------------------------------------------------------
def _prefer(names: Sequence[str], *words: str) -> str | None:
    for w in words:
        hit = [n for n in names if w in n.lower()]
        if hit:
            return sorted(hit, key=lambda n: (len(n), n))[0]
    return sorted(names)[0] if names else None


def _root_of(transforms: TransformTable, frame: str) -> str | None:
    """The root of the tree ``frame`` belongs to (None when the frame is in no edge)."""
    parent = dict(zip(transforms.child.tolist(), transforms.parent.tolist(), strict=True))
    if frame not in parent and frame not in set(parent.values()):
        return None
    seen = {frame}
    while frame in parent and parent[frame] not in seen:
        frame = parent[frame]
        seen.add(frame)
    return frame


def suggest(loaded: LoadedLog) -> SuggestedChain:
    """A chain a user can start from, naming only frames the log has, and what it still needs.

    Camera: the frame of the detections (the topic with the most), else a CameraInfo's (colour
    first), else an optical frame of the frame tree. Body: base_link, base_footprint, another
    ``base`` frame, else the child of a pose topic's edge. World: map, odom, else the root of the
    body's tree. Detections, depth, CameraInfo and pose topics follow those frames.
    """
    tl = loaded.timeline
    facts = _facts(loaded)
    placeholders: dict[str, str] = {}
    detections = _detection_topics(loaded, facts)
    obs = tl.observations
    det_topic = detections[0] if detections else None
    camera: str | None = None
    if det_topic is not None:
        frames = obs.camera_frame[obs.source == det_topic]
        if len(frames):
            values, n = np.unique(frames, return_counts=True)
            camera = str(values[np.argmax(n)])
    cams = tl.cameras
    camera_topic: str | None = None
    if camera is None and len(cams):
        camera_topic = _prefer(sorted(set(cams.source.tolist())), "color", "rgb", "colour")
        if camera_topic is not None:
            camera = str(cams.frame[cams.source == camera_topic][0])
    elif camera is not None and len(cams):
        mine = sorted(set(cams.source[cams.frame == camera].tolist()))
        camera_topic = mine[0] if mine else None
    if camera is None:
        optical = [f for f in facts.frames if "optical" in f]
        camera = _prefer(optical, "color", "rgb")
    if camera is None:
        placeholders["camera"] = ("no camera frame in this log (no detections, CameraInfo or *_optical frame): "
                                  "name the optical frame of your camera")
    tf = tl.transforms
    pose_edges = [e for e in facts.edges if not e.is_static and any(facts.msgtypes.get(s) in POSE_TYPES
                                                                      for s in e.sources)]
    base = [f for f in facts.frames if "base" in f.lower() and f != camera]
    body: str | None
    if "base_link" in facts.frames:
        body = "base_link"
    elif "base_footprint" in facts.frames:
        body = "base_footprint"
    elif base:
        body = _prefer(base, "base")
    elif pose_edges:
        body = sorted(pose_edges, key=lambda e: (-e.count, e.child))[0].child
    else:
        body = None
        placeholders["body"] = ("no body frame in this log (base_link, base_footprint, or the child of a pose "
                                "topic): name it and add mounts: (camera -> body) or urdf:")
    world: str | None = None
    if "map" in facts.frames:
        world = "map"
    elif "odom" in facts.frames:
        world = "odom"
    elif body is not None:
        roots = [_root_of(tf, body), *tree_roots(facts.edges)]
        world = next((r for r in roots if r and r not in (camera, body)), None)
    if world is None:
        placeholders["world"] = ("no world frame in this log (map, odom, or the root of the body's tree): "
                                 "name it and add topics.odometry:")
    defaults = ChainFrames()
    frames = ChainFrames(camera=camera or defaults.camera, body=body or defaults.body, world=world or defaults.world)
    if len({frames.camera, frames.body, frames.world}) < 3:  # a placeholder default met a real name
        frames = ChainFrames(camera=camera or "CAMERA_FRAME", body=body or "BODY_FRAME", world=world or "WORLD_FRAME")
    depth_topic: str | None = None
    depth_topics = sorted(t for t, k in loaded.decoded_topics.items() if k == "depth")
    if depth_topics:
        d = tl.depth_frames
        same = sorted({str(s) for s in d.source[d.frame == frames.camera].tolist()}) if len(d) else []
        depth_topic = same[0] if same else depth_topics[0]
    # Odometry feeds the chain only when its edge is one of the body's tree (a log can hold several).
    tree = _root_of(tf, frames.body) if body is not None else None
    odom_topics = sorted(
        t for t, k in loaded.decoded_topics.items()
        if k == "odometry" and tree is not None
        and any(_root_of(tf, str(child)) == tree for child in set(tf.child[tf.source == t].tolist()))
    )
    config = ChainConfig(
        frames=frames,
        topics=ChainTopics(camera_info=camera_topic, detections=det_topic, depth=depth_topic,
                           odometry=odom_topics[0] if odom_topics else None),
        evidence=_suggest_evidence(loaded),
    )
    needs = chain_needs(loaded, config, placeholders=placeholders)
    return SuggestedChain(config=config, placeholders=placeholders, needs=tuple(needs))


def suggest_chain(loaded: LoadedLog) -> ChainConfig:
    """The suggested chain configuration alone (see :func:`suggest`)."""
    return suggest(loaded).config


def _suggest_evidence(loaded: LoadedLog) -> ChainEvidence:
    """Evidence topics guessed from names: the robot's hop points, a target, a reference."""
    points = [t.name for t in getattr(loaded.info, "topics", ()) if normalize_msgtype(t.msgtype) in _POINT_TYPES]

    def pick(*words: str, also: tuple[str, ...] = ()) -> str | None:
        for name in sorted(points):
            low = name.lower()
            if any(w in low for w in words) and all(a in low for a in also):
                return str(name)
        return None

    hops = HopTopics(
        camera=pick("camera", "cam", also=("point",)),
        body=pick("body", "base", also=("point",)),
        world=pick("world", "map", also=("point",)),
    )
    return ChainEvidence(
        hops=hops,
        target=pick("target", "goal", "grasp"),
        reference=pick("mocap", "reference", "ground_truth", "groundtruth", "vicon", "optitrack"),
    )


# -- what the chain needs -------------------------------------------------------------------------------
def chain_needs(
    loaded: LoadedLog, chain: ChainConfig, *, placeholders: Mapping[str, str] | None = None,
) -> list[ChainNeed]:
    """Each piece of ``chain`` checked against the log (read with or without that chain)."""
    holes = dict(placeholders or {})
    facts = _facts(loaded)
    frames = chain.frames
    path = Path(str(getattr(loaded.info, "path", "")))
    beside = _beside_yaml(path) if str(path) not in ("", ".") else []
    needs: list[ChainNeed] = []
    needs.append(_camera_need(frames.camera, holes, facts, loaded))
    detections, det_need = _detections_need(chain, loaded, facts)
    needs.append(_intrinsics_need(chain, holes, facts, loaded, beside, detections))
    needs.append(det_need)
    needs.append(_depth_need(chain, loaded, facts, beside, detections))
    needs.append(_mount_need(frames, holes, facts))
    needs.append(_pose_need(chain, holes, facts))
    needs.append(_evidence_need(chain, detections, facts))
    return needs


def _camera_need(camera: str, holes: Mapping[str, str], facts: _LogFacts, loaded: LoadedLog) -> ChainNeed:
    if "camera" in holes:
        return ChainNeed("camera frame", NeedStatus.MISSING, holes["camera"], "frames: {camera: CAMERA_OPTICAL_FRAME}")
    if camera not in facts.frames:
        return ChainNeed("camera frame", NeedStatus.MISSING, f"{camera} is in no transform, CameraInfo or detection "
                         "of the log", "frames: {camera: CAMERA_OPTICAL_FRAME}")
    tl = loaded.timeline
    where = sorted({str(s) for s in tl.observations.source[tl.observations.camera_frame == camera].tolist()})
    if where:
        return ChainNeed("camera frame", NeedStatus.FOUND, f"{camera} (header.frame_id of {', '.join(where)})")
    cams = sorted({str(s) for s in tl.cameras.source[tl.cameras.frame == camera].tolist()})
    return ChainNeed("camera frame", NeedStatus.FOUND, f"{camera}" + (f" (from {', '.join(cams)})" if cams else ""))


def _detections_need(chain: ChainConfig, loaded: LoadedLog, facts: _LogFacts) -> tuple[str | None, ChainNeed]:
    """The detections topic the chain replays, and its need."""
    t = chain.topics
    obs = loaded.timeline.observations
    named = t.detections or t.pixel_points
    markers = chain.evidence.markers
    if named is None and t.detections_table:
        n = len(obs)
        return None, ChainNeed("detections", NeedStatus.FOUND if n else NeedStatus.MISSING,
                               f"{n} detections from the table {t.detections_table}",
                               "" if n else "topics.detections_table: DETECTIONS.parquet")
    if named is None and t.image and markers:
        n = int((obs.source == t.image).sum()) if len(obs) else 0
        if t.image not in facts.msgtypes:
            return t.image, ChainNeed("detections", NeedStatus.MISSING, f"the chain's topics.image {t.image} is not in "
                                      "the log", f"topics.image: {_image_choice(facts)}")
        n_images = _count(facts.counts.get(t.image, 0), 'image')
        if n == 0:  # searched and found none: a wrong dictionary, or no marker in view
            probe = _probe(loaded, t.image)
            best = probe.best if probe is not None else None
            seen = f"; {probe.text()}" if probe is not None else ""
            key = (f"evidence.markers: {{dictionary: {best}, size_m: {markers.size_m or 'MARKER_EDGE_M'}}}"
                   if best is not None and best != markers.dictionary else
                   "evidence.markers.dictionary: another dictionary (the printed markers' family), or topics.image: "
                   "a topic that sees the markers")
            return t.image, ChainNeed("detections", NeedStatus.MISSING, f"0 markers found in {n_images} of {t.image} "
                                      f"with {markers.dictionary}{seen}", key)
        return t.image, ChainNeed("detections", NeedStatus.FOUND, f"markers in the images of {t.image} "
                                  f"({n_images}, {_count(n, 'marker')})")
    candidates = _detection_topics(loaded, facts)
    if named is None:
        images = facts.topics_of(IMAGE_TYPES)
        images = [i for i in images if "depth" not in i.lower()]
        key = "topics.detections: DETECTIONS_TOPIC"
        probe = _probe(loaded, images[0]) if images else None
        if probe is not None and probe.best is not None:  # only a dictionary that found markers is suggested
            key += (f"; or topics.image: {images[0]}; evidence.markers: {{dictionary: {probe.best}, "
                    f"size_m: MARKER_SIZE_M}}  ({probe.text()})")
        elif probe is not None:
            key += f"  ({probe.text()})"
        return None, ChainNeed("detections", NeedStatus.MISSING, "no detections topic in the log "
                               "(vision_msgs, AprilTag or fiducial detections)" if not candidates else
                               f"the chain names none (the log has {', '.join(candidates)})",
                               key if not candidates else f"topics.detections: {candidates[0]}")
    if named not in facts.msgtypes and len(obs) == 0:
        also = f" (detection topics in the log: {', '.join(candidates)})" if candidates else ""
        return named, ChainNeed("detections", NeedStatus.MISSING, f"the chain names {named}, which the log lacks{also}",
                                f"topics.detections: {candidates[0] if candidates else 'DETECTIONS_TOPIC'}")
    n_obs = int((obs.source == named).sum()) if len(obs) else 0
    n_msg = facts.counts.get(named, 0)
    others = [c for c in candidates if c != named]
    also = f"; also {', '.join(others)}" if others else ""
    if n_obs == 0 and len(obs) == 0:
        return named, ChainNeed("detections", NeedStatus.MISSING,
                                f"{facts.describe(named)} has {n_msg} messages but no detection was read from them",
                                f"topics.detections: {others[0] if others else 'DETECTIONS_TOPIC'}")
    return named, ChainNeed("detections", NeedStatus.FOUND,
                            f"{facts.describe(named)}: {n_msg} messages, {n_obs or len(obs)} detections{also}")


def _probe(loaded: LoadedLog, topic: str) -> MarkerProbe | None:
    """The common dictionaries tried on the first images of ``topic`` (None: no log file, unreadable)."""
    path = str(getattr(loaded.info, "path", ""))
    return probe_markers(path, topic) if path not in ("", ".") else None


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _image_choice(facts: _LogFacts) -> str:
    images = [i for i in facts.topics_of(IMAGE_TYPES) if "depth" not in i.lower()]
    return images[0] if images else "IMAGE_TOPIC"


def _intrinsics_need(
    chain: ChainConfig, holes: Mapping[str, str], facts: _LogFacts, loaded: LoadedLog,
    beside: list[tuple[str, Any]], detections: str | None,
) -> ChainNeed:
    camera = chain.frames.camera
    cams = loaded.timeline.cameras
    hint = _calibration_hint(beside, detections) or "calibration: {file: CAMERAS.yaml, camera: NAME}"
    if "camera" not in holes and len(cams) and (cams.frame == camera).any():
        i = int(np.flatnonzero(cams.frame == camera)[0])
        return ChainNeed("intrinsics", NeedStatus.FOUND,
                         f"{cams.source[i]} ({int(cams.width[i])}x{int(cams.height[i])}, {cams.distortion_model[i]})")
    infos = facts.topics_of(CAMERA_INFO_TYPES)
    if infos:
        other = sorted({str(f) for f in cams.frame.tolist()}) if len(cams) else []
        detail = (f"no CameraInfo for {camera}; the log's ({', '.join(infos)}) are for "
                  f"{', '.join(other) or 'other frames'}")
        return ChainNeed("intrinsics", NeedStatus.MISSING, detail, f"{hint}  (or topics.camera_info: TOPIC)")
    return ChainNeed("intrinsics", NeedStatus.MISSING, "no CameraInfo in the log",
                     f"{hint}  (ROS camera_info, Kalibr or OpenCV YAML)")


def _depth_need(
    chain: ChainConfig, loaded: LoadedLog, facts: _LogFacts, beside: list[tuple[str, Any]], detections: str | None,
) -> ChainNeed:
    tl = loaded.timeline
    if chain.topics.depth:
        if chain.topics.depth in facts.msgtypes:
            return ChainNeed("depth", NeedStatus.FOUND, f"depth images on {chain.topics.depth} "
                             f"({facts.counts.get(chain.topics.depth, 0)} frames)")
        return ChainNeed("depth", NeedStatus.MISSING, f"the chain names depth topic {chain.topics.depth}, which the "
                         "log lacks", "topics.depth: DEPTH_IMAGE_TOPIC")
    msgtype = facts.msgtypes.get(detections or "", "")
    if msgtype in POSE_DETECTION_TYPES:
        return ChainNeed("depth", NeedStatus.FOUND, f"the detections of {detections} carry a 3D position")
    tag_size = chain.evidence.tag_size_m
    markers = chain.evidence.markers
    if tag_size is not None and (msgtype in CORNER_DETECTION_TYPES or detections is None):
        return ChainNeed("depth", NeedStatus.FOUND, f"tag corners and evidence.tag_size_m {tag_size} (PnP)")
    if markers is not None and detections == chain.topics.image:
        if markers.size_m is not None:
            return ChainNeed("depth", NeedStatus.FOUND, f"marker corners and evidence.markers size_m {markers.size_m} "
                             "(PnP)")
        return ChainNeed("depth", NeedStatus.MISSING, "markers without a size give bearings only",
                         f"evidence.markers: {{dictionary: {markers.dictionary}, size_m: MARKER_EDGE_M}}")
    obs = tl.observations
    mine = obs.depth_m[obs.source == detections] if detections and len(obs) else obs.depth_m[:0]
    if mine.size and np.isfinite(mine).any():
        share = float(np.isfinite(mine).mean())
        return ChainNeed("depth", NeedStatus.FOUND, f"a depth in the detections themselves ({share:.0%} of them)")
    if msgtype in CORNER_DETECTION_TYPES:
        size = _tag_size_hint(beside)
        size_text = f"{size:g}" if size is not None else "TAG_EDGE_M"
        return ChainNeed("depth", NeedStatus.MISSING, "tag corners but no tag size (AprilTag/ArUco corners give a "
                         "depth by PnP)", f"evidence.tag_size_m: {size_text}")
    depth_images = [t for t in facts.topics_of(IMAGE_TYPES) if "depth" in t.lower()]
    if depth_images:
        return ChainNeed("depth", NeedStatus.MISSING, f"depth images on {depth_images[0]} but the chain names none",
                         f"topics.depth: {depth_images[0]}")
    return ChainNeed("depth", NeedStatus.MISSING, "no depth images, no depth in the detections, no tag size",
                     "topics.depth: DEPTH_IMAGE_TOPIC; or evidence.tag_size_m: TAG_EDGE_M  (fiducial corners)")


def _mount_key(body: str, camera: str) -> str:
    return (f"mounts: [{{parent: {body}, child: {camera}, xyz: [X, Y, Z], quat_xyzw: [QX, QY, QZ, QW]}}]; "
            "or urdf: ROBOT.urdf")


def _mount_need(frames: ChainFrames, holes: Mapping[str, str], facts: _LogFacts) -> ChainNeed:
    body = "BODY_FRAME" if "body" in holes else frames.body
    camera = "CAMERA_OPTICAL_FRAME" if "camera" in holes else frames.camera
    if "camera" in holes or "body" in holes:
        return ChainNeed("mount", NeedStatus.MISSING, "no camera -> body path without both frames",
                         _mount_key(body, camera))
    path = _path(facts.edges, frames.body, frames.camera)
    if path is None:
        return ChainNeed("mount", NeedStatus.MISSING, f"no path from the camera frame {frames.camera} to the body "
                         f"{frames.body}", _mount_key(body, camera))
    return ChainNeed("mount", NeedStatus.FOUND, _path_text(path, facts, start=frames.body))


def _pose_need(chain: ChainConfig, holes: Mapping[str, str], facts: _LogFacts) -> ChainNeed:
    frames = chain.frames
    poses = facts.topics_of(POSE_TYPES)
    key = f"topics.odometry: {poses[0] if poses else 'POSE_TOPIC'}  (Odometry, PoseStamped, ... as world -> body)"
    named = [p.topic for p in chain.pose_topics()]
    lacking = [p for p in named if p not in facts.msgtypes]
    if lacking:
        return ChainNeed("pose", NeedStatus.MISSING, f"the chain names pose topic {', '.join(lacking)}, which the "
                         "log lacks", key)
    if "body" in holes or "world" in holes:
        return ChainNeed("pose", NeedStatus.MISSING, "no body -> world path without both frames", key)
    path = _path(facts.edges, frames.world, frames.body)
    if path is None:
        return ChainNeed("pose", NeedStatus.MISSING, f"no path from the body {frames.body} to the world "
                         f"{frames.world}", key)
    return ChainNeed("pose", NeedStatus.FOUND, _path_text(path, facts, start=frames.world))


def _evidence_need(chain: ChainConfig, detections: str | None, facts: _LogFacts) -> ChainNeed:
    ev = chain.evidence
    have = [f"{role} {topic}" for topic, role in chain.evidence_topics().items()]
    if ev.reference_point is not None:
        have.append("reference_point")
    if ev.static_target:
        have.append("static_target")
    if have:
        return ChainNeed("evidence", NeedStatus.FOUND, ", ".join(have))
    tags = facts.msgtypes.get(detections or "", "") in CORNER_DETECTION_TYPES | POSE_DETECTION_TYPES
    first = "evidence.static_target: true  (the tags do not move)" if tags else \
        "evidence.static_target: true  (the detected object does not move)"
    return ChainNeed("evidence", NeedStatus.NONE, "attribution needs evidence: the robot's own points, a target, "
                     "a reference or a static target",
                     f"{first}; or evidence.reference: TOPIC; or evidence.reference_point: [X, Y, Z]; "
                     "or evidence.hops: {camera: TOPIC, body: TOPIC, world: TOPIC}")


# -- why a replay has nothing ---------------------------------------------------------------------------
#: What to add for each rejection reason of the replay (framechain.replay.RejectReason values), when the
#: needs do not say it more precisely.
_REJECTION_FIX = {
    "no_camera_info": "calibration: {file: CAMERAS.yaml, camera: NAME}; or topics.camera_info: TOPIC",
    "outside_image": "calibration: {file: CAMERAS.yaml, camera: NAME}  (the intrinsics of this image size: the "
                     "pixels fall outside the image)",
    "no_depth": "topics.depth: DEPTH_IMAGE_TOPIC; or evidence.tag_size_m: TAG_EDGE_M",
    "depth_invalid": "topics.depth: DEPTH_IMAGE_TOPIC  (a depth image with valid pixels at the detections)",
    "missing_edge": "mounts: [{parent: BODY, child: CAMERA, xyz: [X, Y, Z], quat_xyzw: [QX, QY, QZ, QW]}]; "
                    "or urdf: ROBOT.urdf; or topics.odometry: POSE_TOPIC",
}


def why_nothing_replayed(loaded: LoadedLog, chain: ChainConfig, counts: Mapping[str, Any]) -> str | None:
    """One line: why no observation was replayed and what to add; None when something was."""
    if int(counts.get("replayed", 0)):
        return None
    needs = {n.piece: n for n in chain_needs(loaded, chain)}
    total = int(counts.get("total", 0))
    if total == 0:
        det = needs["detections"]
        if det.found:
            return f"0 observations: {det.detail}, but none reached the replay"
        return f"0 observations: {det.detail}: {det.fix()}"
    rejected = {str(k): int(v) for k, v in dict(counts.get("rejected", {})).items()}
    by_count = sorted(rejected.items(), key=lambda kv: -kv[1])
    listed = ", ".join(f"{reason} {n}" for reason, n in by_count)
    top = by_count[0][0] if by_count else ""
    fix = f"add {quote_key(_REJECTION_FIX[top])}" if top in _REJECTION_FIX else \
        "see `framechain info LOG --chain CHAIN.yaml`"
    if top == "other_camera":
        obs = loaded.timeline.observations
        theirs = sorted({str(f) for f in obs.camera_frame.tolist()} - {chain.frames.camera})
        fix = f"set `frames.camera` to the detections' frame ({', '.join(theirs) or 'their header.frame_id'})"
    elif top == "ignored_label":
        fix = "every detection's label is in `evidence.ignore_labels`: keep the static ones out of it"
    elif top == "extrapolation":
        fix = ("check the stamps: the transforms do not cover the detections' stamps (another clock? "
               "`framechain info` notes say)")
    piece = {"no_camera_info": "intrinsics", "outside_image": "intrinsics", "no_depth": "depth",
             "depth_invalid": "depth"}.get(top)
    if top == "missing_edge":
        piece = next((p for p in ("mount", "pose") if not needs[p].found), None)
    if piece is not None and not needs[piece].found and needs[piece].key:
        fix = needs[piece].fix()
    source = needs["detections"].detail.split(":", 1)[0]
    return f"0 of {total} observations replayed ({source}); all rejected: {listed}: {fix}"
