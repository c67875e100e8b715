"""A chain to start from: :func:`suggest` proposes one that names only frames the log has (a missing
frame is a marked placeholder, never an invented name), with what it still needs."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from framechain.adapters.messages.kinds import POSE_TYPES, normalize_msgtype
from framechain.adapters.model import LoadedLog
from framechain.arrays import rows_of
from framechain.config.chain import ChainConfig, ChainEvidence, ChainFrames, ChainTopics, HopTopics
from framechain.suggest.facts import POINT_TYPES, LogFacts, beside_yaml, detection_topics, log_facts
from framechain.suggest.frame_tree import tree_roots
from framechain.suggest.needs import PLACEHOLDER_FRAMES, REPLAY_PIECES, ChainNeed, NeedStatus, chain_needs
from framechain.suggest.rig import rig_suggestion, rig_yaml_body
from framechain.timeline import LogInfo, ObservationTable, TransformTable


@dataclass(frozen=True)
class SuggestedChain:
    """A chain to start from; ``placeholders`` maps a frame slot the log cannot fill to why."""

    config: ChainConfig
    placeholders: Mapping[str, str] = field(default_factory=dict)
    needs: tuple[ChainNeed, ...] = ()
    #: Where the suggestion's numbers came from, one comment line each (a rig's calibration files).
    comments: tuple[str, ...] = ()

    @property
    def ready(self) -> bool:
        """Every piece a replay needs is in the log."""
        return all(n.found for n in self.needs if n.piece in REPLAY_PIECES)

    def missing(self) -> list[ChainNeed]:
        return [n for n in self.needs if n.status != NeedStatus.FOUND]

    def frames_text(self) -> str:
        """``CAMERA_OPTICAL_FRAME (FILL IN) -> base_link -> odom``: the chain's frames, placeholders marked."""
        frames = self.config.frames
        return " -> ".join(f"{getattr(frames, slot)} (FILL IN)" if slot in self.placeholders
                           else getattr(frames, slot) for slot in ("camera", "body", "world"))

    def incomplete_line(self) -> str | None:
        """One line saying the chain is incomplete and what is missing (None: ready to replay)."""
        if self.ready:
            return None
        lacking = [n.piece for n in self.missing() if n.piece in REPLAY_PIECES]
        return (f"the suggested chain is incomplete: this log lacks {', '.join(lacking)}; "
                "`framechain info LOG --chain > chain.yaml` writes it with FILL IN comments naming the keys to add")

    def to_yaml(self, *, source: str = "") -> str:
        """CHAIN.yaml text: placeholder frames and missing keys as marked comments to fill in."""
        raw = self.config.to_dict()
        frames = raw.pop("frames")
        head = [f"# chain suggested by `framechain info` from {source}; edit before use" if source
                else "# chain suggested by `framechain info`; edit before use"]
        if not self.ready:
            head.append("# NOT READY: this log lacks pieces of the chain (the FILL IN comments below)")
        head.extend(f"# {c}" for c in self.comments)
        lines = ["frames:"]
        slots = ("camera", "body", "world") if not self.config.cameras else tuple(s for s in ("body", "world")
                                                                                  if s in frames)
        for slot in slots:
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
        body = ("\n".join(rig_yaml_body(self.config)) if self.config.cameras else
                yaml.safe_dump(raw, sort_keys=False).rstrip("\n"))
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
    ``base`` frame, else the child of a pose topic's edge. World: map, odom, a frame named world, else the
    root of the body's tree. Detections, depth, CameraInfo and pose topics follow those frames.
    """
    facts = log_facts(loaded)
    placeholders: dict[str, str] = {}
    detections = detection_topics(loaded, facts)
    det_topic = detections[0] if detections else None
    camera, camera_topic = _camera(loaded, facts, det_topic)
    if camera is None:
        placeholders["camera"] = ("no camera frame in this log (no detections, CameraInfo or *_optical frame): "
                                  "name the optical frame of your camera")
    body = _body(facts, camera)
    if body is None:
        placeholders["body"] = ("no body frame in this log (base_link, base_footprint, or the child of a pose "
                                "topic): name it and add mounts: (camera -> body) or urdf:")
    world = _world(loaded.timeline.transforms, facts, camera, body)
    if world is None:
        placeholders["world"] = ("no world frame in this log (map, odom, world, or the root of the body's tree): "
                                 "name it and add topics.odometry:")
    # A slot the log cannot fill holds a name in capitals, as the keys to add do: never a real-looking
    # frame (camera_optical_frame, base_link, map) the log does not have.
    frames = ChainFrames(camera=camera or PLACEHOLDER_FRAMES["camera"], body=body or PLACEHOLDER_FRAMES["body"],
                         world=world or PLACEHOLDER_FRAMES["world"])
    config = ChainConfig(
        frames=frames,
        topics=ChainTopics(camera_info=camera_topic, detections=det_topic, depth=_depth_topic(loaded, frames.camera),
                           odometry=_odometry_topic(loaded, frames.body) if body is not None else None),
        evidence=evidence_from_names(loaded.info),
    )
    if len(detections) > 1 and body is None:  # several cameras of a rig the files beside the log calibrate
        path = Path(str(getattr(loaded.info, "path", "")))
        rig = rig_suggestion(loaded, detections, beside_yaml(path) if str(path) not in ("", ".") else [], body=None,
                             world=None)
        if rig is not None:
            return SuggestedChain(config=rig[0], needs=tuple(chain_needs(loaded, rig[0])), comments=tuple(rig[1]))
    needs = chain_needs(loaded, config, placeholders=placeholders)
    return SuggestedChain(config=config, placeholders=placeholders, needs=tuple(needs))


def _camera(loaded: LoadedLog, facts: LogFacts, det_topic: str | None) -> tuple[str | None, str | None]:
    """The camera frame and its CameraInfo topic (None: the log has neither)."""
    obs = loaded.timeline.observations
    cams = loaded.timeline.cameras
    camera: str | None = None
    if det_topic is not None:
        frames = obs.camera_frame[obs.source == det_topic]
        if len(frames):
            values, n = np.unique(frames, return_counts=True)
            camera = str(values[np.argmax(n)])
    camera_topic: str | None = None
    if camera is None and len(cams):
        camera_topic = _prefer(sorted(set(cams.source.tolist())), "color", "rgb", "colour")
        if camera_topic is not None:
            camera = str(cams.frame[cams.source == camera_topic][0])
    elif camera is not None and len(cams):
        mine = sorted(set(cams.source[cams.frame == camera].tolist()))
        camera_topic = mine[0] if mine else None
    if camera is None:
        camera = _prefer([f for f in facts.frames if "optical" in f], "color", "rgb")
    return camera, camera_topic


def _body(facts: LogFacts, camera: str | None) -> str | None:
    """base_link, base_footprint, another ``base`` frame, else the child of a pose topic's edge; never the
    camera frame."""
    frames = facts.frames - {camera}
    for name in ("base_link", "base_footprint"):
        if name in frames:
            return name
    base = [f for f in frames if "base" in f.lower()]
    if base:
        return _prefer(base, "base")
    pose_edges = [e for e in facts.edges if not e.is_static and e.child != camera
                  and any(facts.msgtypes.get(s) in POSE_TYPES for s in e.sources)]
    if pose_edges:
        return sorted(pose_edges, key=lambda e: (-e.count, e.child))[0].child
    return None


def _world(tf: TransformTable, facts: LogFacts, camera: str | None, body: str | None) -> str | None:
    """map, odom, a frame named world, else the root of the body's tree; never the camera or the body frame (a
    pose topic ``world -> odom`` makes odom the body: its world is then world, not odom again)."""
    taken = {camera, body}
    for name in ("map", "odom", "world"):
        if name in facts.frames and name not in taken:
            return name
    if body is None:
        return None
    roots = [_root_of(tf, body), *tree_roots(facts.edges)]
    return next((r for r in roots if r and r not in taken), None)


def _depth_topic(loaded: LoadedLog, camera: str) -> str | None:
    """The depth topic of the camera's frame, else the first the reader decoded."""
    depth_topics = sorted(t for t, k in loaded.decoded_topics.items() if k == "depth")
    if not depth_topics:
        return None
    d = loaded.timeline.depth_frames
    same = sorted({str(s) for s in d.source[d.frame == camera].tolist()}) if len(d) else []
    return same[0] if same else depth_topics[0]


def _odometry_topic(loaded: LoadedLog, body: str) -> str | None:
    """Odometry feeds the chain only when its edge is one of the body's tree (a log can hold several)."""
    tf = loaded.timeline.transforms
    tree = _root_of(tf, body)
    odom_topics = sorted(
        t for t, k in loaded.decoded_topics.items()
        if k == "odometry" and tree is not None
        and any(_root_of(tf, str(child)) == tree for child in set(tf.child[tf.source == t].tolist()))
    )
    return odom_topics[0] if odom_topics else None


def suggest_chain(loaded: LoadedLog) -> ChainConfig:
    """The suggested chain configuration alone (see :func:`suggest`)."""
    return suggest(loaded).config


def evidence_from_names(info: LogInfo | None) -> ChainEvidence:
    """Evidence topics guessed from names: the robot's hop points, a target, a reference."""
    points = [t.name for t in getattr(info, "topics", ()) if normalize_msgtype(t.msgtype) in POINT_TYPES]

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


def evidence_roles(info: LogInfo) -> dict[str, str]:
    """The point topics a suggested chain reads as evidence, with their roles (from their names alone,
    so that they are read in the same pass as the rest of a log whose chain is suggested)."""
    return ChainConfig(evidence=evidence_from_names(info)).evidence_topics()


def as_suggested(loaded: LoadedLog, config: ChainConfig) -> LoadedLog:
    """The log as its suggested chain reads it, from the one read without a chain (with
    :func:`evidence_roles`): only the detections of the chain's detections topic. Another topic's
    detections are not this chain's to replay, nor are the reader's rejections and notes about them."""
    obs = loaded.timeline.observations
    topic = config.topics.detections
    if topic is None or not len(obs) or bool((obs.source == topic).all()):
        return loaded
    dropped = {str(t) for t in np.unique(obs.source).tolist()} - {topic}
    kept = obs.take(obs.source == topic)

    def about_kept(notes: Sequence[str]) -> list[str]:
        return [n for n in notes if not any(n.startswith(f"topic {t}:") for t in dropped)]

    meta = dict(loaded.timeline.metadata)
    meta["notes"] = about_kept(meta.get("notes", []))
    fiducials = meta.pop("fiducials", None)
    meta.pop("rejected_at_read", None)
    if isinstance(fiducials, Mapping):
        kept, meta = _kept_fiducials(kept, fiducials, topic, meta)
    return LoadedLog(timeline=loaded.timeline.replace(observations=kept, metadata=meta),
                     info=replace(loaded.info, notes=tuple(about_kept(loaded.info.notes))),
                     decoded_topics=loaded.decoded_topics)


def _kept_fiducials(
    kept: ObservationTable, fiducials: Mapping[str, Any], topic: str, meta: dict[str, Any],
) -> tuple[ObservationTable, dict[str, Any]]:
    """The fiducial side table and counts of the kept topic; its tags numbered from 0 in log order, as a read
    of that topic alone numbers them (the reader numbers fiducial observations, the detector does not)."""
    counts = {t: c for t, c in dict(fiducials.get("counts", {})).items() if t == topic}
    corners = dict(fiducials.get("corners", {}))
    if topic in counts:
        renumbered = np.argsort(np.argsort(kept.obs_id, kind="stable"), kind="stable").astype(np.int64)
        ids = np.asarray(corners.get("obs_id", []), dtype=np.int64)
        row = rows_of(kept.obs_id, ids)
        rows = np.flatnonzero(row >= 0).tolist()
        corners = {k: [v[i] for i in rows] if isinstance(v, list) and len(v) == ids.size else v
                   for k, v in corners.items()}
        corners["obs_id"] = renumbered[row[row >= 0]].tolist()
        kept = replace(kept, obs_id=renumbered)
    meta["fiducials"] = {**fiducials, "counts": counts, "corners": corners}
    rejected: Counter[str] = Counter()
    for topic_counts in counts.values():
        rejected.update(topic_counts.get("rejected", {}))
    if rejected:
        meta["rejected_at_read"] = dict(sorted(rejected.items()))
    return kept, meta
