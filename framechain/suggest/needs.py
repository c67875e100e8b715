"""What a chain needs and whether the log has it: each piece (camera frame, intrinsics, detections,
depth, mount, pose, evidence) found, and where, or missing with the chain key that supplies it."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from framechain.adapters.messages.kinds import POSE_TYPES
from framechain.adapters.model import LoadedLog
from framechain.config.chain import ChainConfig, ChainFrames
from framechain.config.chain_cameras import MarkerSpec
from framechain.suggest.facts import (
    CAMERA_INFO_TYPES,
    CORNER_DETECTION_TYPES,
    IMAGE_TYPES,
    POSE_DETECTION_TYPES,
    LogFacts,
    beside_yaml,
    calibration_hint,
    detection_topics,
    frame_path,
    log_facts,
    path_text,
)
from framechain.suggest.marker_probe import MarkerProbe, probe_markers
from framechain.suggest.mount_hints import tagslam_mount_hint
from framechain.suggest.tag_sizes import same_sizes, tag_size_hint, tag_sizes
from framechain.suggest.typos import did_you_mean, or_list


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
#: What a suggested chain names a frame the log cannot give (capitals, as every placeholder of a key).
PLACEHOLDER_FRAMES = {"camera": "CAMERA_OPTICAL_FRAME", "body": "BODY_FRAME", "world": "WORLD_FRAME"}


# -- what the chain needs -------------------------------------------------------------------------------
def chain_needs(
    loaded: LoadedLog, chain: ChainConfig, *, placeholders: Mapping[str, str] | None = None,
) -> list[ChainNeed]:
    """Each piece of ``chain`` checked against the log (read with or without that chain)."""
    if getattr(loaded.info, "format", "") == "lerobot":
        return _dataset_needs(loaded, chain)
    holes = dict(placeholders or {})
    facts = log_facts(loaded)
    if chain.cameras:
        return rig_needs(loaded, chain, facts)
    frames = chain.frames
    path = Path(str(getattr(loaded.info, "path", "")))
    beside = beside_yaml(path) if str(path) not in ("", ".") else []
    needs: list[ChainNeed] = []
    needs.append(_camera_need(frames.camera, holes, facts, loaded))
    detections, det_need = _detections_need(chain, loaded, facts)
    needs.append(_intrinsics_need(chain, holes, facts, loaded, beside, detections))
    needs.append(det_need)
    needs.append(_depth_need(chain, loaded, facts, beside, detections))
    needs.append(_mount_need(frames, holes, facts, beside, detections))
    needs.append(_pose_need(chain, holes, facts))
    needs.append(_evidence_need(chain, detections, facts))
    return needs


def _dataset_needs(loaded: LoadedLog, chain: ChainConfig) -> list[ChainNeed]:
    """A LeRobot episode's pieces: every key named is one robot.yaml has (a dataset has no topics)."""
    tl = loaded.timeline
    meta = tl.metadata
    cameras: Mapping[str, Any] = meta.get("cameras") or {}
    name = next((n for n, c in cameras.items() if c.get("frame") == chain.frames.camera), "CAMERA")
    where = "  (in robot.yaml)"
    found, missing, none = NeedStatus.FOUND, NeedStatus.MISSING, NeedStatus.NONE
    needs = [ChainNeed("camera frame", found, f"{chain.frames.camera} (robot.yaml camera {name})")]
    has_model = bool((tl.cameras.frame == chain.frames.camera).any())
    needs.append(ChainNeed("intrinsics", found, f"robot.yaml camera {name}") if has_model else ChainNeed(
        "intrinsics", missing, f"camera {name} has no intrinsics",
        f"cameras.{name}.intrinsics: {{fx: FX, fy: FY, cx: CX, cy: CY, width: W, height: H}}{where}"))
    videos = {n: c.get("video_key") for n, c in cameras.items() if c.get("video_file")}
    obs = tl.observations
    mine = obs.camera_frame == chain.frames.camera
    if mine.any():
        sources = sorted({str(s) for s in obs.source[mine].tolist()})
        needs.append(ChainNeed("detections", found, f"{int(mine.sum())} in {', '.join(sources)}"))
    else:
        key = (f"detections: [{{table: DETECTIONS.parquet}}]{where}; or detections: [{{feature: FEATURE, camera: "
               f"{name}}}]{where}; or chain.evidence.markers: {{dictionary: DICT_5X5_1000, size_m: MARKER_M}}{where}")
        if videos:
            shown = ", ".join(f"{n} ({k})" for n, k in videos.items())
            needs.append(ChainNeed("detections", none, f"no detections; the motion of cameras {shown} in their video "
                                   "is evidence of its own (offset, mount, link)", key))
        elif lost := lost_videos(meta):
            needs.append(ChainNeed("detections", missing, f"no detections, and {lost}", key))
        else:
            needs.append(ChainNeed("detections", missing, "no detections and no camera video", key))
    depth = bool(np.isfinite(obs.depth_m[mine]).any()) or bool((tl.depth_frames.frame == chain.frames.camera).any())
    needs.append(ChainNeed("depth", found, "in the detections or a depth feature") if depth or not mine.any() else
                 ChainNeed("depth", missing, "the detections have no depth",
                           f"cameras.{name}.depth: {{feature: DEPTH_FEATURE, scale_m: 0.001}}{where}; or "
                           f"chain.evidence.markers.size_m: MARKER_M{where}"))
    parent = cameras.get(name, {}).get("parent", "?")
    needs.append(ChainNeed("mount", found, f"{chain.frames.camera} on {parent} (robot.yaml)"))
    needs.append(ChainNeed("pose", found, f"forward kinematics of {meta.get('state_feature', 'the joint states')}"))
    evidence = chain.evidence
    if evidence.static_target or evidence.reference_point is not None:
        needs.append(ChainNeed("evidence", found, "static target" if evidence.static_target else "reference point"))
    else:
        needs.append(ChainNeed("evidence", none, "attribution needs evidence beside the cameras' own motion: a static "
                               "target or a reference", "chain.evidence.static_target: true  (in robot.yaml; the "
                               f"detected object does not move); or chain.evidence.reference_point: [X, Y, Z]{where}"))
    return needs


def lost_videos(metadata: Mapping[str, Any]) -> str:
    """The cameras of a LeRobot episode whose video info.json points to is not on disk, as a clause ("" for none)."""
    cameras: Mapping[str, Any] = metadata.get("cameras") or {}
    lost = [(name, c) for name, c in cameras.items() if isinstance(c, Mapping) and c.get("video_missing")]
    return "; ".join(f"camera {name}'s video is missing: {c['video_missing']} (where info.json's video_path and "
                     f"video_key {c.get('video_key')} point)" for name, c in lost)


def _camera_need(camera: str, holes: Mapping[str, str], facts: LogFacts, loaded: LoadedLog) -> ChainNeed:
    if "camera" in holes:
        return ChainNeed("camera frame", NeedStatus.MISSING, holes["camera"],
                         f"frames: {{camera: {PLACEHOLDER_FRAMES['camera']}}}")
    if camera not in facts.frames:
        close = did_you_mean(camera, facts.frames)
        meant = close[0] if close else "CAMERA_OPTICAL_FRAME"
        return ChainNeed("camera frame", NeedStatus.MISSING, f"{camera} is in no transform, CameraInfo or detection "
                         f"of the log{_did_you_mean(close)}", f"frames: {{camera: {meant}}}")
    tl = loaded.timeline
    where = sorted({str(s) for s in tl.observations.source[tl.observations.camera_frame == camera].tolist()})
    # A frame only the detections name is found, but nothing connects it yet: the mount must (it is the real gap).
    in_tree = any(camera in (e.parent, e.child) for e in facts.edges)
    unlinked = "" if in_tree else "; no transform of the log names it: the mount must connect it to the body"
    if where:
        return ChainNeed("camera frame", NeedStatus.FOUND, f"{camera} (header.frame_id of {', '.join(where)}"
                         f"{unlinked})")
    cams = sorted({str(s) for s in tl.cameras.source[tl.cameras.frame == camera].tolist()})
    return ChainNeed("camera frame", NeedStatus.FOUND, f"{camera}" + (f" (from {', '.join(cams)})" if cams else ""))


def _detections_need(chain: ChainConfig, loaded: LoadedLog, facts: LogFacts) -> tuple[str | None, ChainNeed]:
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
        return t.image, _markers_need(t.image, markers, loaded, facts)
    candidates = detection_topics(loaded, facts)
    if named is None:
        return None, _unnamed_detections_need(loaded, facts, candidates)
    return named, _named_detections_need(named, loaded, facts, candidates)


def _markers_need(image: str, markers: MarkerSpec, loaded: LoadedLog, facts: LogFacts) -> ChainNeed:
    """Detections from markers searched in the images of ``image``."""
    obs = loaded.timeline.observations
    n = int((obs.source == image).sum()) if len(obs) else 0
    if image not in facts.msgtypes:
        return ChainNeed("detections", NeedStatus.MISSING, f"the chain's topics.image {image} is not in the log",
                         f"topics.image: {_image_choice(facts)}")
    n_images = _count(facts.counts.get(image, 0), 'image')
    if n == 0:  # searched and found none: a wrong dictionary, or no marker in view
        probe = _probe(loaded, image)
        best = probe.best if probe is not None else None
        seen = f"; {probe.text()}" if probe is not None else ""
        key = (f"evidence.markers: {{dictionary: {best}, size_m: {markers.size_m or 'MARKER_EDGE_M'}}}"
               if best is not None and best != markers.dictionary else
               "evidence.markers.dictionary: another dictionary (the printed markers' family), or topics.image: "
               "a topic that sees the markers")
        return ChainNeed("detections", NeedStatus.MISSING, f"0 markers found in {n_images} of {image} "
                         f"with {markers.dictionary}{seen}", key)
    return ChainNeed("detections", NeedStatus.FOUND, f"markers in the images of {image} ({n_images}, "
                     f"{_count(n, 'marker')})")


def _unnamed_detections_need(loaded: LoadedLog, facts: LogFacts, candidates: list[str]) -> ChainNeed:
    """The chain names no detections topic: the log's own (``candidates``), or markers in its first image topic."""
    images = facts.topics_of(IMAGE_TYPES)
    images = [i for i in images if "depth" not in i.lower()]
    key = "topics.detections: DETECTIONS_TOPIC"
    probe = _probe(loaded, images[0]) if images else None
    if probe is not None and probe.best is not None:  # only a dictionary that found markers is suggested
        key += (f"; or topics.image: {images[0]}; evidence.markers: {{dictionary: {probe.best}, "
                f"size_m: MARKER_SIZE_M}}  ({probe.text()})")
    elif probe is not None:
        key += f"  ({probe.text()})"
    return ChainNeed("detections", NeedStatus.MISSING, "no detections topic in the log "
                     "(vision_msgs, AprilTag or fiducial detections)" if not candidates else
                     f"the chain names none (the log has {', '.join(candidates)})",
                     key if not candidates else f"topics.detections: {candidates[0]}")


def _named_detections_need(named: str, loaded: LoadedLog, facts: LogFacts, candidates: list[str]) -> ChainNeed:
    """The detections topic the chain names: in the log or not, with detections or not."""
    obs = loaded.timeline.observations
    if named not in facts.msgtypes and len(obs) == 0:
        close = did_you_mean(named, candidates) or did_you_mean(named, facts.msgtypes)
        also = (f"; did you mean {or_list(close)}?" if close else
                f" (detection topics in the log: {', '.join(candidates)})" if candidates else "")
        best = close[0] if close else candidates[0] if candidates else "DETECTIONS_TOPIC"
        return ChainNeed("detections", NeedStatus.MISSING, f"the chain names {named}, which the log lacks{also}",
                         f"topics.detections: {best}")
    n_obs = int((obs.source == named).sum()) if len(obs) else 0
    n_msg = facts.counts.get(named, 0)
    others = [c for c in candidates if c != named]
    also = f"; also {', '.join(others)}" if others else ""
    read = _read_counts(loaded, named)
    if n_obs == 0 and read is not None and read["detections"]:
        # Detections were read and all rejected at read (no intrinsics for PnP, say): the topic is right; the
        # piece that is missing says what to add.
        why = ", ".join(f"{reason} {n}" for reason, n in sorted(read["rejected"].items()))
        return ChainNeed("detections", NeedStatus.FOUND, f"{facts.describe(named)}: {n_msg} messages, "
                         f"{read['detections']} detections, none usable (rejected at read: {why}){also}")
    if n_obs == 0 and len(obs) == 0:
        key = (f"topics.detections: {others[0]}" if others else
               "topics.detections: DETECTIONS_TOPIC  (a topic whose messages hold detections)")
        return ChainNeed("detections", NeedStatus.MISSING,
                         f"{facts.describe(named)} has {n_msg} messages but no detection in them", key)
    return ChainNeed("detections", NeedStatus.FOUND,
                     f"{facts.describe(named)}: {n_msg} messages, {n_obs or len(obs)} detections{also}")


def _read_counts(loaded: LoadedLog, topic: str) -> Mapping[str, Any] | None:
    """The reader's counts of a fiducial topic (detections, observations, rejected by reason), if it has them."""
    fiducials = loaded.timeline.metadata.get("fiducials")
    counts = fiducials.get("counts", {}).get(topic) if isinstance(fiducials, Mapping) else None
    return counts if isinstance(counts, Mapping) else None


def _of(topic: str | None) -> str:
    return f" of {topic}" if topic else ""


def _probe(loaded: LoadedLog, topic: str) -> MarkerProbe | None:
    """The common dictionaries tried on the first images of ``topic`` (None: no log file, unreadable)."""
    path = str(getattr(loaded.info, "path", ""))
    return probe_markers(path, topic) if path not in ("", ".") else None


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _image_choice(facts: LogFacts) -> str:
    images = [i for i in facts.topics_of(IMAGE_TYPES) if "depth" not in i.lower()]
    return images[0] if images else "IMAGE_TOPIC"


def _intrinsics_need(
    chain: ChainConfig, holes: Mapping[str, str], facts: LogFacts, loaded: LoadedLog,
    beside: list[tuple[str, Any]], detections: str | None,
) -> ChainNeed:
    camera = chain.frames.camera
    cams = loaded.timeline.cameras
    hint = calibration_hint(beside, detections)
    key = hint.as_key() if hint is not None else \
        "calibration: {file: CAMERAS.yaml, camera: NAME}  (ROS camera_info, Kalibr or OpenCV YAML)"

    if "camera" not in holes and len(cams) and (cams.frame == camera).any():
        mine = np.flatnonzero(cams.frame == camera)
        imaged = mine[cams.width[mine] > 0]
        if not imaged.size:  # only the reader's camera-less model: the detections are 3D camera-frame points
            return ChainNeed("intrinsics", NeedStatus.FOUND, f"not needed: the detections{_of(detections)} are 3D "
                             "points in the camera frame (intrinsics would only draw them on images)")
        i = int(imaged[0])
        return ChainNeed("intrinsics", NeedStatus.FOUND,
                         f"{cams.source[i]} ({int(cams.width[i])}x{int(cams.height[i])}, {cams.distortion_model[i]})")
    infos = facts.topics_of(CAMERA_INFO_TYPES)
    if infos:
        other = sorted({str(f) for f in cams.frame.tolist()}) if len(cams) else []
        detail = (f"no CameraInfo for {camera}; the log's ({', '.join(infos)}) are for "
                  f"{', '.join(other) or 'other frames'}")
        return ChainNeed("intrinsics", NeedStatus.MISSING, detail, f"{key}; or topics.camera_info: TOPIC")
    return ChainNeed("intrinsics", NeedStatus.MISSING, "no CameraInfo in the log", key)


def _depth_need(
    chain: ChainConfig, loaded: LoadedLog, facts: LogFacts, beside: list[tuple[str, Any]], detections: str | None,
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
    if tag_size is not None and (msgtype in CORNER_DETECTION_TYPES or not msgtype):  # none named, or not in the log
        others = [(name, raw) for name, raw in beside if name != chain.origin]  # not the chain being checked
        beside_sizes = tag_size_hint(others)
        if beside_sizes is not None and not same_sizes(tag_size, tag_sizes(others)):
            # A tag declared at the wrong size looks like a moving tag: name the sizes the files give.
            return ChainNeed("depth", NeedStatus.FOUND, f"tag corners and evidence.tag_size_m {tag_size} (PnP), but "
                             "the sizes beside the log differ", beside_sizes.as_key())
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
        size = tag_size_hint(beside)
        return ChainNeed("depth", NeedStatus.MISSING, "tag corners but no tag size (AprilTag/ArUco corners give a "
                         "depth by PnP)", size.as_key() if size is not None else
                         "evidence.tag_size_m: TAG_EDGE_M  (the printed tags' edge in metres)")
    depth_images = [t for t in facts.topics_of(IMAGE_TYPES) if "depth" in t.lower()]
    if depth_images:
        return ChainNeed("depth", NeedStatus.MISSING, f"depth images on {depth_images[0]} but the chain names none",
                         f"topics.depth: {depth_images[0]}")
    return ChainNeed("depth", NeedStatus.MISSING, "no depth images, no depth in the detections, no tag size",
                     "topics.depth: DEPTH_IMAGE_TOPIC; or evidence.tag_size_m: TAG_EDGE_M  (fiducial corners)")


def rig_needs(loaded: LoadedLog, chain: ChainConfig, facts: LogFacts) -> list[ChainNeed]:
    """Each piece of a rig chain, checked for every camera (the chain's calibration files and mounts count as
    found: the log may have been read without them)."""
    frames = chain.frames
    cams = chain.cameras
    obs = loaded.timeline.observations
    mounted = {m.child for m in chain.mounts}
    calibrated = {c.frame for c in cams if c.calibration is not None} | set(loaded.timeline.cameras.frame.tolist())
    lacking_topics = [c.detections for c in cams if c.detections not in facts.msgtypes]
    counts = ", ".join(f"{c.frame} {int((obs.source == c.detections).sum())}" for c in cams)
    sized = chain.evidence.tag_size_m is not None or any(c.depth for c in cams)
    unmounted = [c.frame for c in cams if c.frame not in mounted and frame_path(facts.edges, frames.body, c.frame)
                 is None]
    uncalibrated = [c.frame for c in cams if c.frame not in calibrated]
    needs = [
        ChainNeed("camera frame", NeedStatus.FOUND, f"{len(cams)} cameras: {', '.join(c.frame for c in cams)} "
                  "(each the camera of its detections topic)"),
        _rig_need("intrinsics", uncalibrated, "every camera's calibration", "calibration: {file: CAMERAS.yaml, "
                  "camera: NAME} under each camera"),
        _rig_need("detections", lacking_topics, f"detections per camera: {counts}", "detections: TOPIC under each "
                  "camera (the log's topics)"),
        ChainNeed("depth", NeedStatus.FOUND if sized else NeedStatus.MISSING,
                  "tag sizes (depth by PnP)" if sized else "no tag size and no depth topic",
                  "" if sized else "evidence.tag_size_m: TAG_EDGE_M"),
        _rig_need("mount", unmounted, f"every camera mounted on {frames.body}",
                  f"mounts: [{{parent: {frames.body}, child: CAMERA, xyz: [X, Y, Z], rotvec: [RX, RY, RZ]}}]"),
    ]
    if chain.has_pose:
        needs.append(_pose_need(chain, {}, facts))
    else:
        needs.append(ChainNeed("pose", NeedStatus.FOUND, f"none: {frames.body} has no pose, its cameras are "
                               "compared at the same instant in its frame"))
    needs.append(_evidence_need(chain, cams[0].detections, facts) if not chain.evidence.moving_labels else
                 ChainNeed("evidence", NeedStatus.FOUND, "labels seen by several cameras at once"))
    return needs


def _rig_need(piece: str, lacking: list[str], found: str, key: str) -> ChainNeed:
    if lacking:
        return ChainNeed(piece, NeedStatus.MISSING, f"not for {', '.join(lacking)}", key)
    return ChainNeed(piece, NeedStatus.FOUND, found)


def _did_you_mean(close: list[str]) -> str:
    return f"; did you mean {or_list(close)}?" if close else ""


def _mount_key(body: str, camera: str) -> str:
    return (f"mounts: [{{parent: {body}, child: {camera}, xyz: [X, Y, Z], quat_xyzw: [QX, QY, QZ, QW]}}]; "
            "or urdf: ROBOT.urdf")


def _mount_need(frames: ChainFrames, holes: Mapping[str, str], facts: LogFacts, beside: list[tuple[str, Any]],
                detections: str | None) -> ChainNeed:
    body = PLACEHOLDER_FRAMES["body"] if "body" in holes else frames.body
    camera = PLACEHOLDER_FRAMES["camera"] if "camera" in holes else frames.camera
    if "camera" in holes or "body" in holes:
        return ChainNeed("mount", NeedStatus.MISSING, "no camera -> body path without both frames",
                         _mount_key(body, camera))
    path = frame_path(facts.edges, frames.body, frames.camera)
    if path is None and frames.body not in facts.frames and (close := did_you_mean(frames.body, facts.frames)):
        return ChainNeed("mount", NeedStatus.MISSING, f"the body {frames.body} is in no transform of the log"
                         f"{_did_you_mean(close)}", f"frames: {{body: {close[0]}}}")
    if path is None:
        hint = tagslam_mount_hint(beside, body, camera, detections)
        return ChainNeed("mount", NeedStatus.MISSING, f"no path from the camera frame {frames.camera} to the body "
                         f"{frames.body}", _mount_key(body, camera) if hint is None else
                         f"{hint.as_key()}; or urdf: ROBOT.urdf")
    return ChainNeed("mount", NeedStatus.FOUND, path_text(path, facts, start=frames.body))


def _pose_need(chain: ChainConfig, holes: Mapping[str, str], facts: LogFacts) -> ChainNeed:
    frames = chain.frames
    poses = facts.topics_of(POSE_TYPES)
    key = f"topics.odometry: {poses[0] if poses else 'POSE_TOPIC'}  (Odometry, PoseStamped, ... as world -> body)"
    named = [p.topic for p in chain.pose_topics()]
    lacking = [p for p in named if p not in facts.msgtypes]
    if lacking:
        close = did_you_mean(lacking[0], poses)
        mean = f"; did you mean {or_list(close)}?" if close else ""
        if close:
            key = f"topics.odometry: {close[0]}  (Odometry, PoseStamped, ... as world -> body)"
        return ChainNeed("pose", NeedStatus.MISSING, f"the chain names pose topic {', '.join(lacking)}, which the "
                         f"log lacks{mean}", key)
    if "body" in holes or "world" in holes:
        return ChainNeed("pose", NeedStatus.MISSING, "no body -> world path without both frames", key)
    path = frame_path(facts.edges, frames.world, frames.body)
    if path is None and frames.world not in facts.frames and (close := did_you_mean(frames.world, facts.frames)):
        return ChainNeed("pose", NeedStatus.MISSING, f"the world {frames.world} is in no transform of the log"
                         f"{_did_you_mean(close)}", f"frames: {{world: {close[0]}}}")
    if path is None:
        return ChainNeed("pose", NeedStatus.MISSING, f"no path from the body {frames.body} to the world "
                         f"{frames.world}", key)
    return ChainNeed("pose", NeedStatus.FOUND, path_text(path, facts, start=frames.world))


def _evidence_need(chain: ChainConfig, detections: str | None, facts: LogFacts) -> ChainNeed:
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

