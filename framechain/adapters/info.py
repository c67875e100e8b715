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
        roots = tree_roots(frame_tree(tl.transforms))
        world = roots[0] if roots else ChainFrames().world
    depth_topics = sorted(t for t, k in kinds.items() if k == "depth")
    depth_topic: str | None = None
    if depth_topics:
        d = tl.depth_frames
        same = sorted({str(s) for s in d.source[d.frame == camera].tolist()}) if len(d) else []
        depth_topic = same[0] if same else depth_topics[0]
    det_topics = sorted(t for t, k in kinds.items() if k in ("detections", "detection"))
    odom_topics = sorted(
        t for t, k in kinds.items() if k == "odometry" and t in set(tl.transforms.source.tolist())
    )
    return ChainConfig(
        frames=ChainFrames(camera=camera, body=body, world=world),
        topics=ChainTopics(
            camera_info=camera_topic, detections=det_topics[0] if det_topics else None, depth=depth_topic,
            odometry=odom_topics[0] if odom_topics else None,
        ),
        evidence=ChainEvidence(),
    )
