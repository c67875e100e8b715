"""The replay as Foxglove messages (protobuf), to be written beside the log's own messages.

One MCAP then opens in Foxglove with the log and the replay together:

- ``/framechain/tf`` (``foxglove.FrameTransforms``): the transforms the replay used at each
  replayed observation, ``world -> <body>@replay -> <camera>@replay`` (the recomputed chain);
- ``/framechain/annotations`` (``foxglove.ImageAnnotations``): per image time, the detection
  (pixel and tag corners), the recomputed and as-run world points projected into the image and a
  line between them coloured by the finding that explains them (:mod:`framechain.sinks.overlay`);
  stamped with the image's header stamp so Foxglove's Image panel pairs them with that image;
- ``/framechain/scene`` (``foxglove.SceneUpdate``): as-run and recomputed world points and the
  error line between them, in the world frame;
- ``/framechain/findings`` (``foxglove.Log``): one message per finding.

Schemas are registered as protobuf ``FileDescriptorSet``s holding the message's file and every
file it depends on, as Foxglove and ``mcap-protobuf-support`` do.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from framechain.analysis.alignment import AlignedEvidence
from framechain.analysis.findings import Finding
from framechain.analysis.run import Run
from framechain.arrays import BoolArray, IntArray
from framechain.replay import ReplayResult
from framechain.sinks.overlay import (
    AS_RUN_COLOR,
    DETECTION_COLOR,
    RECOMPUTED_COLOR,
    ImageOverlay,
    image_overlay,
)
from framechain.sinks.rerun_common import REPLAY_FRAME_SUFFIX
from framechain.sinks.text import FindingView
from framechain.timeline import PointRole, Timeline

TF_TOPIC = "/framechain/tf"
ANNOTATIONS_TOPIC = "/framechain/annotations"
SCENE_TOPIC = "/framechain/scene"
FINDINGS_TOPIC = "/framechain/findings"
NS = 1_000_000_000


@dataclass(frozen=True)
class ProtobufMessage:
    """One serialised message with its schema (matches ``framechain.adapters.formats.mcap.export.ExtraMessage``)."""

    topic: str
    schema_name: str
    schema_data: bytes
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    schema_encoding: str = "protobuf"
    message_encoding: str = "protobuf"


def file_descriptor_set(message_class: Any) -> bytes:
    """The serialised ``FileDescriptorSet`` of a protobuf message class and its dependencies."""
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    out = FileDescriptorSet()
    seen: set[str] = set()

    def add(file: Any) -> None:
        for dep in file.dependencies:
            if dep.name not in seen:
                seen.add(dep.name)
                add(dep)
        file.CopyToProto(out.file.add())

    add(message_class.DESCRIPTOR.file)
    data: bytes = out.SerializeToString()
    return data


def _stamp(message: Any, ns: int) -> None:
    message.FromNanoseconds(int(ns))


def _color(target: Any, rgb: tuple[int, int, int], alpha: float = 1.0) -> None:
    target.r, target.g, target.b, target.a = rgb[0] / 255, rgb[1] / 255, rgb[2] / 255, alpha


def foxglove_messages(run: Run) -> list[ProtobufMessage]:
    """Every message the run adds (see the module docstring), in no particular order."""
    result = run.replay
    overlay = image_overlay(run.timeline, result, run.aligned, run.findings)
    out = _transforms(result)
    out += _annotations(run.timeline, result, overlay)
    out += _scene(result, run.aligned, overlay)
    out += _findings(result, run.findings)
    return out


def _by_stamp(stamp: IntArray) -> Iterator[tuple[int, IntArray]]:
    """Each distinct stamp (ascending) with the rows that have it (ascending), in one sort."""
    if not stamp.size:
        return
    order = np.argsort(stamp, kind="stable")
    stamps, starts = np.unique(stamp[order], return_index=True)
    yield from zip(stamps.tolist(), np.split(order, starts[1:]), strict=True)


def _transforms(result: ReplayResult) -> list[ProtobufMessage]:
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    schema = file_descriptor_set(FrameTransforms)
    frames = result.frames
    obs = result.observations
    body, camera = frames.body + REPLAY_FRAME_SUFFIX, frames.camera + REPLAY_FRAME_SUFFIX
    out: list[ProtobufMessage] = []
    ok = np.flatnonzero(result.replayed)
    _, first = np.unique(obs.stamp_ns[ok], return_index=True)  # one message per observation time
    for i in ok[first].tolist():
        msg = FrameTransforms()
        for lookup, parent, child in ((result.world_from_body, frames.world, body),
                                      (result.body_from_cam, body, camera)):
            t = msg.transforms.add()
            _stamp(t.timestamp, obs.stamp_ns[i])
            t.parent_frame_id, t.child_frame_id = parent, child
            t.translation.x, t.translation.y, t.translation.z = (float(v) for v in lookup.translation[i])
            t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w = (float(v) for v in lookup.quat_xyzw[i])
        out.append(ProtobufMessage(TF_TOPIC, "foxglove.FrameTransforms", schema, int(obs.log_time_ns[i]),
                                   int(obs.stamp_ns[i]), msg.SerializeToString()))
    return out


def _annotations(timeline: Timeline, result: ReplayResult, overlay: ImageOverlay) -> list[ProtobufMessage]:
    """One ImageAnnotations per image (or per observation time without an image)."""
    from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
    from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation

    schema = file_descriptor_set(ImageAnnotations)
    obs = result.observations
    images = timeline.image_frames
    stamp = np.where(overlay.image_row >= 0, images.stamp_ns[np.maximum(overlay.image_row, 0)]
                     if len(images) else obs.stamp_ns, obs.stamp_ns)
    out: list[ProtobufMessage] = []
    drawn: BoolArray = np.asarray(np.isfinite(overlay.detection_uv).all(axis=1))  # 3D points w/o intrinsics: none
    for when, at_stamp in _by_stamp(stamp):
        rows = at_stamp[drawn[at_stamp]]
        if not rows.size:
            continue
        msg = ImageAnnotations()

        def points(kind: int, uv: Any, color: tuple[int, int, int], size: float, *, msg: Any = msg,
                   when: int = when) -> None:
            ann = msg.points.add()
            _stamp(ann.timestamp, when)
            ann.type = kind
            for u, v in uv:
                p = ann.points.add()
                p.x, p.y = float(u), float(v)
            _color(ann.outline_color, color)
            ann.thickness = size

        for i in rows.tolist():
            points(PointsAnnotation.POINTS, [overlay.detection_uv[i]], DETECTION_COLOR, 8.0)
            if np.isfinite(overlay.corners_px[i]).all():
                points(PointsAnnotation.LINE_LOOP, overlay.corners_px[i], DETECTION_COLOR, 2.0)
            for uv, color in ((overlay.recomputed_uv[i], RECOMPUTED_COLOR), (overlay.as_run_uv[i], AS_RUN_COLOR)):
                if np.isfinite(uv).all():
                    points(PointsAnnotation.POINTS, [uv], color, 10.0)
            if np.isfinite(overlay.recomputed_uv[i]).all() and np.isfinite(overlay.as_run_uv[i]).all():
                points(PointsAnnotation.LINE_LIST, [overlay.recomputed_uv[i], overlay.as_run_uv[i]], overlay.color, 2.0)
                text = msg.texts.add()
                _stamp(text.timestamp, when)
                text.position.x, text.position.y = (float(v) for v in overlay.as_run_uv[i])
                text.text = f"{overlay.error_px[i]:.0f} px: {overlay.label()}"
                text.font_size = 14.0
                _color(text.text_color, overlay.color)
        log_ns = int(obs.log_time_ns[rows].max())
        out.append(ProtobufMessage(ANNOTATIONS_TOPIC, "foxglove.ImageAnnotations", schema, log_ns, int(when),
                                   msg.SerializeToString()))
    return out


def _scene(result: ReplayResult, evidence: AlignedEvidence, overlay: ImageOverlay) -> list[ProtobufMessage]:
    """As-run and recomputed world points and the line between them, one SceneUpdate per observation time."""
    from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    schema = file_descriptor_set(SceneUpdate)
    obs = result.observations
    as_run = np.full((len(obs), 3), np.nan)
    if len(evidence) == len(obs):
        for role in (PointRole.HOP_WORLD, PointRole.TARGET):
            if evidence.present(role):
                as_run = evidence.points(role)
                break
    out: list[ProtobufMessage] = []
    ok = np.flatnonzero(result.replayed & np.isfinite(result.p_world).all(axis=1))
    for when, in_ok in _by_stamp(obs.stamp_ns[ok]):
        rows = ok[in_ok]
        msg = SceneUpdate()
        entity = msg.entities.add()
        _stamp(entity.timestamp, when)
        entity.frame_id = result.frames.world
        entity.id = f"obs {int(obs.obs_id[rows[0]])}"
        entity.lifetime.FromNanoseconds(NS // 5)
        for i in rows.tolist():
            for xyz, color in ((result.p_world[i], RECOMPUTED_COLOR), (as_run[i], AS_RUN_COLOR)):
                if not np.isfinite(xyz).all():
                    continue
                sphere = entity.spheres.add()
                sphere.pose.position.x, sphere.pose.position.y, sphere.pose.position.z = (float(v) for v in xyz)
                sphere.pose.orientation.w = 1.0
                sphere.size.x = sphere.size.y = sphere.size.z = 0.04
                _color(sphere.color, color)
            if np.isfinite(as_run[i]).all():
                line = entity.lines.add()
                line.type = LinePrimitive.LINE_LIST
                line.pose.orientation.w = 1.0
                line.thickness = 0.01
                for xyz in (result.p_world[i], as_run[i]):
                    p = line.points.add()
                    p.x, p.y, p.z = (float(v) for v in xyz)
                _color(line.color, overlay.color)
        out.append(ProtobufMessage(SCENE_TOPIC, "foxglove.SceneUpdate", schema, int(obs.log_time_ns[rows].max()),
                                   int(when), msg.SerializeToString()))
    return out


def _findings(result: ReplayResult, findings: Sequence[Finding]) -> list[ProtobufMessage]:
    from foxglove_schemas_protobuf.Log_pb2 import Log

    schema = file_descriptor_set(Log)
    obs = result.observations
    when = int(obs.stamp_ns.min()) if len(obs) else 0
    log_ns = int(obs.log_time_ns.min()) if len(obs) else 0
    out: list[ProtobufMessage] = []
    for finding in findings:
        msg = Log()
        _stamp(msg.timestamp, when)
        msg.level = Log.ERROR
        msg.name = "framechain"
        msg.message = FindingView.of(finding).text()
        out.append(ProtobufMessage(FINDINGS_TOPIC, "foxglove.Log", schema, log_ns, when, msg.SerializeToString()))
    return out


__all__ = [
    "ANNOTATIONS_TOPIC",
    "FINDINGS_TOPIC",
    "SCENE_TOPIC",
    "TF_TOPIC",
    "ProtobufMessage",
    "file_descriptor_set",
    "foxglove_messages",
]
