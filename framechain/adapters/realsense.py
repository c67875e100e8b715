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

import re
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from framechain.adapters.collect import Collector

_STREAM = re.compile(r"^(/device_\d+/sensor_\d+/[A-Za-z]+_\d+)/")


def stream_frame(topic: str) -> str | None:
    """``/device_0/sensor_1/Color_0/info/camera_info`` -> ``device_0/sensor_1/Color_0``."""
    m = _STREAM.match(topic)
    return m.group(1).lstrip("/") if m else None


def apply_realsense_layout(col: Collector) -> None:
    """Rename frames after their streams and turn the recorded extrinsics into static edges."""
    col.depth_rows = [
        ((stream_frame(r[6]) or r[0]), *r[1:]) for r in col.depth_rows
    ]
    col.cam_rows = [
        ((stream_frame(r[6]) or r[0]), *r[1:]) for r in col.cam_rows
    ]
    if not col.rs_extrinsics:
        return
    identity: list[str] = []
    for topic, vals in col.rs_extrinsics.items():
        t, q = np.asarray(vals[:3]), np.asarray(vals[3:7])
        if np.allclose(t, 0.0) and abs(abs(q[3]) - 1.0) < 1e-9:
            frame = stream_frame(topic)
            if frame:
                identity.append(frame)
    if not identity:
        col.notes.append("librealsense layout: no stream has an identity extrinsic; extrinsics not used")
        return
    reference = sorted(identity, key=lambda f: (0 if "/Depth_" in f else 1, f))[0]
    for topic, vals in sorted(col.rs_extrinsics.items()):
        frame = stream_frame(topic)
        if frame is None or frame == reference:
            continue
        log_ns = int(vals[7])
        col.tf_parent.append(frame)
        col.tf_child.append(reference)
        col.tf_stamp.append(log_ns)
        col.tf_vals.extend(vals[:7])
        col._tf_message(topic, log_ns, 1, True)
    col.notes.append(
        f"librealsense layout: frames named after their streams; extrinsics on <stream>/tf/<ref> read as static "
        f"edges stream -> {reference}"
    )
