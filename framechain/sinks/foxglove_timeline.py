"""A log with no messages of its own (a LeRobot episode) as Foxglove messages: its frame tree, joints, cameras.

``framechain export`` copies a bag's or an MCAP's own messages; a dataset has none, so its timeline is
written instead, in Foxglove's schemas (protobuf, as :mod:`framechain.sinks.foxglove_export`):

- ``/tf`` (``foxglove.FrameTransforms``): the dynamic edges (forward kinematics), one message per
  stamp; ``/tf_static``: the static edges once, at the first stamp;
- ``/joint_states`` (``foxglove.JointStates``): the joints in SI units, one message per stamp;
- ``/<camera>/calibration`` (``foxglove.CameraCalibration``): each camera's model, at the first stamp;
- ``/<camera>/video`` (``foxglove.CompressedVideo``, H.264/H.265 access units) or ``/<camera>/image``
  (``foxglove.CompressedImage``, JPEG/PNG): each camera's frames, stamped with the camera's time.

``<camera>`` is the optical frame without its ``_optical_frame`` suffix. The frames come encoded from
``frames_of`` (the adapters' :func:`~framechain.adapters.lerobot.media.encoded_frames`, handed in by
the command: sinks do not read files).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from framechain.analysis.run import Run
from framechain.arrays import IntArray
from framechain.sinks.foxglove_export import ProtobufMessage, by_stamp, calibration_message, file_descriptor_set
from framechain.timeline import CameraTable, ImageFrameTable, JointStateTable, Timeline, TransformTable

__all__ = ["EncodedCamera", "FramesOf", "camera_topic", "timeline_messages"]


class EncodedCamera(Protocol):
    """A camera's frames, encoded: ``codec`` h264/h265 (access units), jpeg or png; one stamp per frame."""

    @property
    def codec(self) -> str: ...
    @property
    def stamps_ns(self) -> IntArray: ...
    @property
    def data(self) -> tuple[bytes, ...]: ...
    @property
    def notes(self) -> tuple[str, ...]: ...


#: Encodes camera ``frame``'s images of the table.
FramesOf = Callable[[ImageFrameTable, str], EncodedCamera]


def camera_topic(frame: str) -> str:
    """``/wrist`` for ``wrist_optical_frame``."""
    return "/" + frame.removesuffix("_optical_frame").removesuffix("_optical").strip("/")


def timeline_messages(run: Run, frames_of: FramesOf | None = None) -> tuple[list[ProtobufMessage], list[str]]:
    """The timeline's frame tree, joints, camera models and frames as Foxglove messages, and notes."""
    timeline = run.timeline
    start = _first_stamp(timeline)
    out = _transforms(timeline.transforms, start)
    out += _joints(timeline.joint_states)
    out += _calibrations(timeline.cameras, start)
    notes: list[str] = []
    if frames_of is not None:
        images = timeline.image_frames
        for frame in dict.fromkeys(images.frame.tolist()):
            encoded = frames_of(images, str(frame))
            out += _frames(str(frame), encoded)
            notes.extend(encoded.notes)
    return out, notes


def _first_stamp(timeline: Timeline) -> int:
    stamps = [t.stamp_ns[~t.is_static] if isinstance(t, TransformTable) else t.stamp_ns
              for t in (timeline.transforms, timeline.joint_states, timeline.image_frames)]
    found = [int(s.min()) for s in stamps if s.size]
    return min(found) if found else 0


def _transform_message(table: TransformTable, rows: Sequence[int]) -> bytes:
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    msg = FrameTransforms()
    for i in rows:
        t = msg.transforms.add()
        t.timestamp.FromNanoseconds(int(table.stamp_ns[i]))
        t.parent_frame_id, t.child_frame_id = str(table.parent[i]), str(table.child[i])
        t.translation.x, t.translation.y, t.translation.z = (float(v) for v in table.translation[i])
        t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w = (float(v) for v in table.quat_xyzw[i])
    data: bytes = msg.SerializeToString()
    return data


def _transforms(table: TransformTable, start: int) -> list[ProtobufMessage]:
    """The static edges once on /tf_static (the latest sample of each), the dynamic ones per stamp on /tf."""
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    schema = file_descriptor_set(FrameTransforms)
    out: list[ProtobufMessage] = []
    static = np.flatnonzero(table.is_static)
    if static.size:
        latest = {str(table.child[i]): int(i) for i in static[np.argsort(table.stamp_ns[static], kind="stable")]}
        shown = table.take(np.array(sorted(latest.values()), dtype=np.int64))
        shown = dataclasses.replace(shown, stamp_ns=np.full(len(shown), start, dtype=np.int64))
        out.append(ProtobufMessage("/tf_static", "foxglove.FrameTransforms", schema, start, start,
                                   _transform_message(shown, range(len(shown)))))
    dynamic = np.flatnonzero(~table.is_static)
    for stamp, rows in by_stamp(table.stamp_ns[dynamic]):
        out.append(ProtobufMessage("/tf", "foxglove.FrameTransforms", schema, stamp, stamp,
                                   _transform_message(table, dynamic[rows].tolist())))
    return out


def _joints(table: JointStateTable) -> list[ProtobufMessage]:
    from foxglove_schemas_protobuf.JointStates_pb2 import JointStates

    schema = file_descriptor_set(JointStates)
    out: list[ProtobufMessage] = []
    for stamp, rows in by_stamp(table.stamp_ns):
        msg = JointStates()
        msg.timestamp.FromNanoseconds(stamp)
        for i in rows.tolist():
            joint = msg.joints.add()
            joint.name = str(table.joint[i])
            joint.position = float(table.position[i])
            for name in ("velocity", "effort"):
                value = float(getattr(table, name)[i])
                if np.isfinite(value):
                    setattr(joint, name, value)
        out.append(ProtobufMessage("/joint_states", "foxglove.JointStates", schema, stamp, stamp,
                                   msg.SerializeToString()))
    return out


def _calibrations(cameras: CameraTable, start: int) -> list[ProtobufMessage]:
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration

    schema = file_descriptor_set(CameraCalibration)
    out: list[ProtobufMessage] = []
    for frame in dict.fromkeys(cameras.frame.tolist()):
        i = int(np.flatnonzero(cameras.frame == frame)[0])
        stamp = max(int(cameras.stamp_ns[i]), start)
        out.append(ProtobufMessage(f"{camera_topic(str(frame))}/calibration", "foxglove.CameraCalibration", schema,
                                   stamp, stamp, calibration_message(cameras, i, stamp, str(frame))))
    return out


def _frames(frame: str, encoded: EncodedCamera) -> list[ProtobufMessage]:
    """Access units as CompressedVideo, images as CompressedImage, one message per frame."""
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from foxglove_schemas_protobuf.CompressedVideo_pb2 import CompressedVideo

    video = encoded.codec in ("h264", "h265")
    kind = CompressedVideo if video else CompressedImage
    schema = file_descriptor_set(kind)
    topic = camera_topic(frame) + ("/video" if video else "/image")
    out: list[ProtobufMessage] = []
    for stamp, data in zip(encoded.stamps_ns.tolist(), encoded.data, strict=True):
        msg = kind()
        msg.timestamp.FromNanoseconds(int(stamp))
        msg.frame_id = frame
        msg.data = data
        msg.format = encoded.codec
        out.append(ProtobufMessage(topic, f"foxglove.{kind.__name__}", schema, int(stamp), int(stamp),
                                   msg.SerializeToString()))
    return out
