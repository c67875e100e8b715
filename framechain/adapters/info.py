"""What ``framechain info`` shows: the frame tree with per-edge rates and stamp-to-log delays,
the cameras, and a suggested chain configuration."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from framechain.adapters.collect import CLOCK_GAP_NOTE_S
from framechain.adapters.model import LoadedLog
from framechain.timeline import (
    ChainConfig,
    ChainEvidence,
    ChainFrames,
    ChainTopics,
    HopTopics,
    Timeline,
    TransformTable,
)


@dataclass(frozen=True)
class EdgeInfo:
    """One edge of the frame tree, as ``view_frames`` and ``tf2_monitor`` would describe it.

    ``delay_*_s`` are log time minus header stamp over the edge's samples (None for static
    edges, whose stamps are not times of measurement).
    """

    parent: str
    child: str
    is_static: bool
    count: int
    rate_hz: float
    first_stamp_ns: int
    last_stamp_ns: int
    delay_mean_s: float | None
    delay_p95_s: float | None
    delay_max_s: float | None
    sources: tuple[str, ...]
    #: Header stamps and log times are in different clocks (sim time, an unsynchronised sensor).
    clocks_differ: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {
            "parent": self.parent, "child": self.child, "static": self.is_static, "count": self.count,
            "rate_hz": self.rate_hz, "first_stamp_ns": self.first_stamp_ns, "last_stamp_ns": self.last_stamp_ns,
            "span_s": (self.last_stamp_ns - self.first_stamp_ns) * 1e-9, "delay_mean_s": self.delay_mean_s,
            "delay_p95_s": self.delay_p95_s, "delay_max_s": self.delay_max_s, "sources": list(self.sources),
            "clocks_differ": self.clocks_differ,
        }


def frame_tree(transforms: TransformTable) -> list[EdgeInfo]:
    """Every edge (parent, child) with its statistics, sorted by parent then child."""
    if not len(transforms):
        return []
    key = np.char.add(np.char.add(transforms.parent, "\x1f"), transforms.child)
    names, inverse = np.unique(key, return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(names.size + 1))
    out: list[EdgeInfo] = []
    for k, name in enumerate(names.tolist()):
        rows = order[bounds[k] : bounds[k + 1]]
        parent, child = name.split("\x1f")
        static = bool(transforms.is_static[rows].all())
        stamps = np.sort(transforms.stamp_ns[rows])
        n = int(rows.size)
        span = int(stamps[-1] - stamps[0])
        rate = (n - 1) / (span * 1e-9) if n > 1 and span > 0 and not static else 0.0
        differ = False
        if static:
            mean = p95 = mx = None
        else:
            delay = (transforms.log_time_ns[rows] - transforms.stamp_ns[rows]) * 1e-9
            mean, p95, mx = float(delay.mean()), float(np.percentile(delay, 95)), float(delay.max())
            differ = abs(float(np.median(delay))) > CLOCK_GAP_NOTE_S
        out.append(EdgeInfo(parent, child, static, n, rate, int(stamps[0]), int(stamps[-1]), mean, p95, mx,
                            tuple(sorted(set(transforms.source[rows].tolist()))), differ))
    return out


def tree_roots(edges: list[EdgeInfo]) -> list[str]:
    children = {e.child for e in edges}
    return sorted({e.parent for e in edges} - children)


def children_of(edges: list[EdgeInfo]) -> dict[str, list[EdgeInfo]]:
    out: dict[str, list[EdgeInfo]] = {}
    for e in edges:
        out.setdefault(e.parent, []).append(e)
    return out


def _frames(timeline: Timeline) -> set[str]:
    t = timeline.transforms
    return set(t.parent.tolist()) | set(t.child.tolist())


def _prefer(names: list[str], *words: str) -> str | None:
    for w in words:
        hit = [n for n in names if w in n.lower()]
        if hit:
            return sorted(hit)[0]
    return sorted(names)[0] if names else None


def suggest_chain(loaded: LoadedLog) -> ChainConfig:
    """A chain a user can start from: camera frame from CameraInfo, body base_link or
    base_footprint, world map if present else odom, and the topics that feed the chain."""
    tl = loaded.timeline
    frames = _frames(tl)
    kinds = loaded.decoded_topics
    cams = tl.cameras
    camera_topic: str | None = None
    camera: str | None = None
    if len(cams):
        topics = sorted(set(cams.source.tolist()))
        camera_topic = _prefer(topics, "color", "rgb", "colour")
        if camera_topic is not None:
            camera = str(cams.frame[cams.source == camera_topic][0])
    if camera is None:
        optical = [f for f in frames if "optical" in f]
        camera = _prefer(optical, "color", "rgb") or ChainFrames().camera
    if "base_link" in frames:
        body = "base_link"
    elif "base_footprint" in frames:
        body = "base_footprint"
    else:
        body = ChainFrames().body
    if "map" in frames:
        world = "map"
    elif "odom" in frames:
        world = "odom"
    else:
        roots = [_root_of(tl.transforms, body), *tree_roots(frame_tree(tl.transforms))]
        # The world is another frame than the camera and the body (a lone camera tree has no world).
        world = next((r for r in roots if r and r not in (camera, body)), ChainFrames().world)
    depth_topics = sorted(t for t, k in kinds.items() if k == "depth")
    depth_topic: str | None = None
    if depth_topics:
        d = tl.depth_frames
        same = sorted({str(s) for s in d.source[d.frame == camera].tolist()}) if len(d) else []
        depth_topic = same[0] if same else depth_topics[0]
    det_topics = sorted(t for t, k in kinds.items() if k in ("detections", "detection"))
    # Odometry feeds the chain only when its edge is one of the body's tree (a log can hold several).
    tree = _root_of(tl.transforms, body)
    tf = tl.transforms
    odom_topics = sorted(
        t for t, k in kinds.items()
        if k == "odometry" and tree is not None
        and any(_root_of(tf, str(child)) == tree for child in set(tf.child[tf.source == t].tolist()))
    )
    return ChainConfig(
        frames=ChainFrames(camera=camera, body=body, world=world),
        topics=ChainTopics(
            camera_info=camera_topic, detections=det_topics[0] if det_topics else None, depth=depth_topic,
            odometry=odom_topics[0] if odom_topics else None,
        ),
        evidence=_suggest_evidence(loaded),
    )


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


_POINT_TYPES = ("geometry_msgs/msg/PointStamped", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/TransformStamped")


def _suggest_evidence(loaded: LoadedLog) -> ChainEvidence:
    """Evidence topics guessed from names: the robot's hop points, a target, a reference."""
    points = [t.name for t in loaded.info.topics if t.msgtype in _POINT_TYPES]

    def pick(*words: str, also: tuple[str, ...] = ()) -> str | None:
        for name in sorted(points):
            low = name.lower()
            if any(w in low for w in words) and all(a in low for a in also):
                return name
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
