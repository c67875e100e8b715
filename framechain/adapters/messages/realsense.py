"""The librealsense ROS 1 bag layout (written by the SDK's recorder, not by realsense-ros).

- streams live under ``/device_<d>/sensor_<s>/<Stream>_<i>/``; their frame in the Timeline is that
  prefix without the leading ``/`` (the image headers carry a bare sensor number such as ``"1"``);
- intrinsics on ``<stream>/info/camera_info`` (distortion models "Brown Conrady" and
  "Inverse Brown Conrady");
- the extrinsic on ``<stream>/tf/<ref>`` as a bare ``geometry_msgs/Transform``: it maps points of
  the reference stream into this stream (librealsense stores reference -> stream), so it becomes
  the static edge ``T_stream_reference`` (parent = stream, child = reference); the reference is
  the stream whose own extrinsic is the identity (the depth stream on a D400);
- images carry 4 trailing bytes after the pixels (parsed leniently);
- depth in ``Depth_Units`` (``<sensor>/option/Depth_Units/value``, 0.001 m by default).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from framechain.adapters.messages.rows import CameraRows, FrameRows, TransformRows

_STREAM = re.compile(r"^(/device_\d+/sensor_\d+/[A-Za-z]+_\d+)/")


@functools.lru_cache(maxsize=256)
def stream_frame(topic: str) -> str | None:
    """``/device_0/sensor_1/Color_0/info/camera_info`` -> ``device_0/sensor_1/Color_0`` (matched once per topic: it
    is asked for every message's row)."""
    m = _STREAM.match(topic)
    return m.group(1).lstrip("/") if m else None


@dataclass(frozen=True)
class StreamEdge:
    """One recorded extrinsic as the static edge ``T_parent_child`` (parent: the stream)."""

    topic: str
    parent: str
    child: str
    log_time_ns: int
    values: tuple[float, ...]  # x, y, z, qx, qy, qz, qw


def extrinsic_edges(extrinsics: Mapping[str, tuple[float, ...]]) -> tuple[list[StreamEdge], str]:
    """The streams' extrinsics (topic -> x, y, z, qx, qy, qz, qw, log time) as static edges to the
    reference stream (the one whose own extrinsic is the identity), and a note saying what was done."""
    identity: list[str] = []
    for topic, vals in extrinsics.items():
        t, q = np.asarray(vals[:3]), np.asarray(vals[3:7])
        if np.allclose(t, 0.0) and abs(abs(q[3]) - 1.0) < 1e-9:
            frame = stream_frame(topic)
            if frame:
                identity.append(frame)
    if not identity:
        return [], "librealsense layout: no stream has an identity extrinsic; extrinsics not used"
    reference = sorted(identity, key=lambda f: (0 if "/Depth_" in f else 1, f))[0]
    edges = []
    for topic, vals in sorted(extrinsics.items()):
        frame = stream_frame(topic)
        if frame is None or frame == reference:
            continue
        edges.append(StreamEdge(topic, frame, reference, int(vals[7]), tuple(vals[:7])))
    return edges, (f"librealsense layout: frames named after their streams; extrinsics on <stream>/tf/<ref> read "
                   f"as static edges stream -> {reference}")


def apply_realsense_layout(extrinsics: Mapping[str, tuple[float, ...]], transforms: TransformRows,
                           *frame_rows: FrameRows | CameraRows) -> list[str]:
    """Rename the frames of ``frame_rows`` after their streams and add the recorded ``extrinsics`` to
    ``transforms`` as static edges; the note saying what was done (none without extrinsics)."""
    for rows in frame_rows:
        rows.frame = [stream_frame(topic) or frame for frame, topic in zip(rows.frame, rows.topic, strict=True)]
    if not extrinsics:
        return []
    edges, note = extrinsic_edges(extrinsics)
    for edge in edges:
        transforms.add_edge(edge.topic, edge.log_time_ns, edge.parent, edge.child, edge.log_time_ns, edge.values,
                            static=True)
    return [note]
