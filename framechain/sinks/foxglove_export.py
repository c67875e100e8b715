"""The replay as Foxglove messages (protobuf), to be written beside the log's own messages.

One MCAP then opens in Foxglove with the log and the replay together:

- ``/framechain/tf`` (``foxglove.FrameTransforms``): the transforms the replay used at each
  replayed observation, ``world -> <body>@replay -> <camera>@replay`` (the recomputed chain);
- ``/framechain/annotations`` (``foxglove.ImageAnnotations``): per image time, the detection
  (pixel and tag corners), the recomputed and as-run world points projected into the image and a
  line between them coloured by the finding that explains them (:mod:`framechain.sinks.overlay`);
  stamped with the image's header stamp so Foxglove's Image panel pairs them with that image; for a
  rig, one topic per camera, ``/framechain/annotations/<camera frame>``, each with its own detections;
- ``/framechain/scene`` (``foxglove.SceneUpdate``): as-run and recomputed world points and the
  error line between them, in the world frame; for a rig also a line between two cameras' points of
  one label at one instant;
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
from framechain.analysis.rig_layout import PairLines
from framechain.analysis.run import Run
from framechain.arrays import BoolArray, IntArray, rows_of
from framechain.replay import ReplayResult
from framechain.sinks.colors import AS_RUN_COLOR, DETECTION_COLOR, ERROR_COLOR, RECOMPUTED_COLOR
from framechain.sinks.overlay import ImageOverlay, image_overlay
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
    if run.chain.is_rig:  # one annotations topic per camera, each with that camera's observations
        for frame in run.chain.camera_frames():
            rows = np.flatnonzero(result.observations.camera_frame == frame)
            out += _annotations(run.timeline, result, overlay, rows, f"{ANNOTATIONS_TOPIC}/{frame.strip('/')}")
    else:
        out += _annotations(run.timeline, result, overlay, np.arange(len(result.observations)), ANNOTATIONS_TOPIC)
    rig = run.attribution.rig if run.attribution is not None else None
    out += _scene(result, run.aligned, overlay, rig.lines if rig is not None else None)
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
    body = frames.body + REPLAY_FRAME_SUFFIX
    out: list[ProtobufMessage] = []
    ok = np.flatnonzero(result.replayed)
    for when, in_ok in _by_stamp(obs.stamp_ns[ok]):  # one message per observation time
        rows = ok[in_ok]
        _, per_camera = np.unique(obs.camera_frame[rows], return_index=True)  # each camera of a rig once
        msg = FrameTransforms()
        used = [(result.world_from_body, frames.world, body, int(rows[0]))]
        used += [(result.body_from_cam, body, str(obs.camera_frame[i]) + REPLAY_FRAME_SUFFIX, int(i))
                 for i in rows[np.sort(per_camera)]]
        for lookup, parent, child, i in used:
            t = msg.transforms.add()
            _stamp(t.timestamp, when)
            t.parent_frame_id, t.child_frame_id = parent, child
            t.translation.x, t.translation.y, t.translation.z = (float(v) for v in lookup.translation[i])
            t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w = (float(v) for v in lookup.quat_xyzw[i])
        out.append(ProtobufMessage(TF_TOPIC, "foxglove.FrameTransforms", schema, int(obs.log_time_ns[rows].max()),
                                   int(when), msg.SerializeToString()))
    return out


def _annotations(timeline: Timeline, result: ReplayResult, overlay: ImageOverlay, mine: IntArray,
                 topic: str) -> list[ProtobufMessage]:
    """One ImageAnnotations per image (or per observation time without an image) of the observations ``mine``
    (one camera's), on ``topic``."""
    from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
    from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation

    schema = file_descriptor_set(ImageAnnotations)
    obs = result.observations
    images = timeline.image_frames
    stamp = np.where(overlay.image_row >= 0, images.stamp_ns[np.maximum(overlay.image_row, 0)]
                     if len(images) else obs.stamp_ns, obs.stamp_ns)
    out: list[ProtobufMessage] = []
    drawn: BoolArray = np.asarray(np.isfinite(overlay.detection_uv).all(axis=1))  # 3D points w/o intrinsics: none
    used_colors = overlay.detection_colors
    for when, in_mine in _by_stamp(stamp[mine]):
        rows = mine[in_mine]
        rows = rows[drawn[rows]]
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
            r, g, b = (int(c) for c in used_colors[i])  # the detector's own pixel, or framechain's estimate
            points(PointsAnnotation.POINTS, [overlay.detection_uv[i]], (r, g, b), 8.0)
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
        out.append(ProtobufMessage(topic, "foxglove.ImageAnnotations", schema, log_ns, int(when),
                                   msg.SerializeToString()))
    return out


def _scene(result: ReplayResult, evidence: AlignedEvidence, overlay: ImageOverlay,
           lines: PairLines | None = None) -> list[ProtobufMessage]:
    """As-run and recomputed world points and the line between them, one SceneUpdate per observation time (and
    a rig's same-instant comparisons, ``lines``, between the two cameras' points)."""
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
    partner = np.full((len(obs), 3), np.nan)
    if lines is not None and len(lines):
        row = rows_of(obs.obs_id, lines.obs_id)
        partner[row[row >= 0]] = lines.partner_point[row >= 0]
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
            for other, color in ((as_run[i], overlay.color), (partner[i], ERROR_COLOR)):
                if not np.isfinite(other).all():
                    continue
                line = entity.lines.add()
                line.type = LinePrimitive.LINE_LIST
                line.pose.orientation.w = 1.0
                line.thickness = 0.01
                for xyz in (result.p_world[i], other):
                    p = line.points.add()
                    p.x, p.y, p.z = (float(v) for v in xyz)
                _color(line.color, color)
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
