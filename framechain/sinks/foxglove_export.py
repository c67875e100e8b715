"""The replay as Foxglove messages (protobuf), to be written beside the log's own messages.

One MCAP then opens in Foxglove with the log and the replay together:

- ``/framechain/tf`` (``foxglove.FrameTransforms``): the transforms the replay used at each
  replayed observation, ``world -> <body>@replay -> <camera>@replay`` (the recomputed chain);
- ``/framechain/annotations`` (``foxglove.ImageAnnotations``): per image time, the detection
  (pixel and tag corners), the recomputed and as-run world points projected into the image and a
  line between them coloured by the finding that explains them (:mod:`framechain.sinks.overlay`);
  stamped with the image's header stamp so Foxglove's Image panel pairs them with that image; for a
  rig, one topic per camera, ``/framechain/annotations/<camera frame>``, each with its own detections.
  Pixels are converted from OpenCV's convention ((0, 0) the centre of the top-left pixel, as framechain
  computes them) to Foxglove's ((0, 0) that pixel's top-left corner): half a pixel right and down.
  An as-run point outside the image (a large fault moves it off the picture) is not drawn: its line
  ends at the image's border, and the label there says where the point is;
- ``/framechain/calibration`` (``foxglove.CameraCalibration``, for a rig one per camera beside its
  annotations): the camera model the replay used, frame ``<camera>@replay``, at the first annotated
  time and wherever the model changes, so the annotations can be shown (and the camera placed in the
  3D panel) where the log has no image or no CameraInfo of its own;
- ``/framechain/scene`` (``foxglove.SceneUpdate``): as-run and recomputed world points and the
  error line between them, in the world frame; for a rig also a line between two cameras' points of
  one label at one instant;
- ``/framechain/findings`` (``foxglove.Log``): one message per finding.

Schemas are registered as protobuf ``FileDescriptorSet``s holding the message's file and every
file it depends on, as Foxglove and ``mcap-protobuf-support`` do.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from framechain.analysis.evidence.alignment import AlignedEvidence
from framechain.analysis.evidence.rig_layout import PairLines
from framechain.analysis.run import Run
from framechain.analysis.verdict.findings import Finding
from framechain.arrays import BoolArray, FloatArray, IntArray, rows_of
from framechain.geometry.camera import distinct_models
from framechain.replay import ReplayResult
from framechain.sinks.colors import AS_RUN_COLOR, DETECTION_COLOR, ERROR_COLOR, RECOMPUTED_COLOR
from framechain.sinks.overlay import ImageOverlay, image_overlay
from framechain.sinks.rerun_common import REPLAY_FRAME_SUFFIX
from framechain.sinks.text import FindingView
from framechain.timeline import CameraTable, PointRole, Timeline

TF_TOPIC = "/framechain/tf"
ANNOTATIONS_TOPIC = "/framechain/annotations"
CALIBRATION_TOPIC = "/framechain/calibration"
SCENE_TOPIC = "/framechain/scene"
FINDINGS_TOPIC = "/framechain/findings"
NS = 1_000_000_000
#: Foxglove's image coordinates start at the top-left corner of the top-left pixel, OpenCV's (framechain's) at
#: its centre: a pixel (u, v) of framechain is (u + 0.5, v + 0.5) in an ImageAnnotations message.
FOXGLOVE_FROM_OPENCV_PX = 0.5


@dataclass(frozen=True)
class ProtobufMessage:
    """One serialised message with its schema (matches ``framechain.adapters.formats.mcap.writer.ExtraMessage``)."""

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
    stamp = annotation_stamps(run.timeline, result, overlay)
    if run.chain.is_rig:  # one annotations topic per camera, each with that camera's observations
        for frame in run.chain.camera_frames():
            rows = np.flatnonzero(result.observations.camera_frame == frame)
            out += _annotations(result, overlay, stamp, rows, f"{ANNOTATIONS_TOPIC}/{frame.strip('/')}")
            out += _calibrations(run.timeline.cameras, result, stamp, rows, f"{CALIBRATION_TOPIC}/{frame.strip('/')}")
    else:
        everyone = np.arange(len(result.observations))
        out += _annotations(result, overlay, stamp, everyone, ANNOTATIONS_TOPIC)
        out += _calibrations(run.timeline.cameras, result, stamp, everyone, CALIBRATION_TOPIC)
    rig = run.attribution.rig if run.attribution is not None else None
    out += _scene(result, run.aligned, overlay, rig.lines if rig is not None else None)
    out += _findings(result, run.findings)
    return out


def viewing_hints(run: Run, written: Collection[str]) -> list[str]:
    """Per camera whose annotations were ``written`` (the topics the export added), which topics to open them on:
    its image topic where the log has one, and the calibration written for it where one was."""
    images = run.timeline.image_frames
    rig = run.chain.is_rig
    out = []
    for frame in run.chain.camera_frames() if rig else [run.chain.frames.camera]:
        suffix = f"/{frame.strip('/')}" if rig else ""
        if f"{ANNOTATIONS_TOPIC}{suffix}" not in written:
            continue  # no annotation of this camera in the file: nothing to open
        mine = images.source[images.frame == frame] if rig else images.source
        topics = sorted(set(mine.tolist()))
        where = f"image {', '.join(topics)}" if topics else "no image in the log"
        calibration = f"{CALIBRATION_TOPIC}{suffix}"
        out.append(f"{ANNOTATIONS_TOPIC}{suffix} on camera {frame}: {where}"
                   + (f"; calibration {calibration}" if calibration in written else ""))
    return out


def by_stamp(stamp: IntArray) -> Iterator[tuple[int, IntArray]]:
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
    for when, in_ok in by_stamp(obs.stamp_ns[ok]):  # one message per observation time
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


def annotation_stamps(timeline: Timeline, result: ReplayResult, overlay: ImageOverlay) -> IntArray:
    """Per observation, the stamp its annotations carry: its image's header stamp (so Foxglove's Image panel
    pairs them with that image), else its own."""
    obs = result.observations
    images = timeline.image_frames
    if not len(images):
        return obs.stamp_ns
    stamp: IntArray = np.where(overlay.image_row >= 0, images.stamp_ns[np.maximum(overlay.image_row, 0)], obs.stamp_ns)
    return stamp


def clip_to_image(start: FloatArray, end: FloatArray, width: IntArray,
                  height: IntArray) -> tuple[FloatArray, BoolArray]:
    """Segments ``start -> end`` (N, 2 each, OpenCV pixels) cut where they leave the image, and which were cut.

    The image spans -0.5 .. size - 0.5 (pixel centres at integers). Only a segment that starts inside the
    image and ends outside it is cut; the others (no image size, both ends inside or outside) are kept whole.
    """
    lo = np.full_like(start, -0.5)
    hi = np.stack([width, height], axis=1).astype(float) - 0.5
    with np.errstate(invalid="ignore", divide="ignore"):
        inside_start = ((start >= lo) & (start <= hi)).all(axis=1)
        outside_end = ~((end >= lo) & (end <= hi)).all(axis=1)
        step = end - start
        # per axis, the fraction of the step at which the segment reaches the border it heads for
        bound = np.where(step > 0, hi, lo)
        reach = np.where(step != 0, (bound - start) / step, np.inf)
    cut = inside_start & outside_end & (width > 0) & (height > 0) & np.isfinite(end).all(axis=1)
    fraction = np.clip(np.min(reach, axis=1), 0.0, 1.0)
    # onto the border exactly (the fraction's rounding would leave it a hair outside)
    clipped = np.where(cut[:, None], np.clip(start + fraction[:, None] * step, lo, hi), end)
    return clipped, cut


def _annotations(result: ReplayResult, overlay: ImageOverlay, stamp: IntArray, mine: IntArray,
                 topic: str) -> list[ProtobufMessage]:
    """One ImageAnnotations per image (or per observation time without an image) of the observations ``mine``
    (one camera's), on ``topic``, in Foxglove's pixel convention (see the module docstring)."""
    from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
    from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation

    schema = file_descriptor_set(ImageAnnotations)
    obs = result.observations
    shift = FOXGLOVE_FROM_OPENCV_PX
    detection, corners = overlay.detection_uv + shift, overlay.corners_px + shift
    recomputed, as_run = overlay.recomputed_uv + shift, overlay.as_run_uv + shift
    line_end, off_image = clip_to_image(overlay.recomputed_uv, overlay.as_run_uv, overlay.width, overlay.height)
    line_end = line_end + shift
    out: list[ProtobufMessage] = []
    drawn: BoolArray = np.asarray(np.isfinite(overlay.detection_uv).all(axis=1))  # 3D points w/o intrinsics: none
    used_colors = overlay.detection_colors
    for when, in_mine in by_stamp(stamp[mine]):
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
            points(PointsAnnotation.POINTS, [detection[i]], (r, g, b), 8.0)
            if np.isfinite(corners[i]).all():
                points(PointsAnnotation.LINE_LOOP, corners[i], DETECTION_COLOR, 2.0)
            for uv, color, shown in ((recomputed[i], RECOMPUTED_COLOR, True),
                                     (as_run[i], AS_RUN_COLOR, not off_image[i])):  # no dot off the picture
                if shown and np.isfinite(uv).all():
                    points(PointsAnnotation.POINTS, [uv], color, 10.0)
            if np.isfinite(recomputed[i]).all() and np.isfinite(as_run[i]).all():
                points(PointsAnnotation.LINE_LIST, [recomputed[i], line_end[i]], overlay.color, 2.0)
                text = msg.texts.add()
                _stamp(text.timestamp, when)
                text.position.x, text.position.y = (float(v) for v in line_end[i])
                where = (f" (as-run point off the image at {overlay.as_run_uv[i, 0]:.0f}, "
                         f"{overlay.as_run_uv[i, 1]:.0f})" if off_image[i] else "")
                text.text = f"{overlay.error_px[i]:.0f} px: {overlay.label()}{where}"
                text.font_size = 14.0
                _color(text.text_color, overlay.color)
        log_ns = int(obs.log_time_ns[rows].max())
        out.append(ProtobufMessage(topic, "foxglove.ImageAnnotations", schema, log_ns, int(when),
                                   msg.SerializeToString()))
    return out


#: The distortion models Foxglove's CameraCalibration knows by another name: OpenCV's fisheye (Kalibr's equidistant)
#: is Kannala-Brandt's k1..k4; ROS's rational_polynomial and plumb_bob keep theirs.
FOXGLOVE_DISTORTION = {"equidistant": "kannala_brandt", "fisheye": "kannala_brandt"}


def calibration_message(cameras: CameraTable, row: int, stamp_ns: int, frame_id: str) -> bytes:
    """Row ``row`` of the camera table as a serialised ``foxglove.CameraCalibration`` (no rectification:
    R the identity, P = [K | 0]; no distortion written as plumb_bob with zeros)."""
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration

    msg = CameraCalibration()
    msg.timestamp.FromNanoseconds(int(stamp_ns))
    msg.frame_id = frame_id
    msg.width, msg.height = int(cameras.width[row]), int(cameras.height[row])
    k = cameras.K[row]
    n = int(cameras.n_distortion[row])
    model = str(cameras.distortion_model[row])
    msg.distortion_model = FOXGLOVE_DISTORTION.get(model, model) if n else "plumb_bob"
    msg.D.extend(float(d) for d in (cameras.distortion[row, :n] if n else np.zeros(5)))
    msg.K.extend(float(v) for v in k.ravel())
    msg.R.extend(float(v) for v in np.eye(3).ravel())
    msg.P.extend(float(v) for v in np.hstack([k, np.zeros((3, 1))]).ravel())
    data: bytes = msg.SerializeToString()
    return data


def _calibrations(cameras: CameraTable, result: ReplayResult, stamp: IntArray, mine: IntArray,
                  topic: str) -> list[ProtobufMessage]:
    """The camera model each of the observations ``mine`` was replayed with, at the first annotated stamp and
    wherever the model changes (stamp order), on ``topic``: what Foxglove needs to show the annotations when
    the log has no image or CameraInfo of its own."""
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration

    obs = result.observations
    rows = mine[result.camera_row[mine] >= 0]
    rows = rows[cameras.width[result.camera_row[rows]] > 0]  # a camera-less model (3D points) has no image
    if not rows.size:
        return []
    rows = rows[np.argsort(stamp[rows], kind="stable")]
    _, model_of = distinct_models(cameras, result.camera_row[rows])
    starts = np.flatnonzero(np.r_[True, model_of[1:] != model_of[:-1]])
    schema = file_descriptor_set(CameraCalibration)
    out: list[ProtobufMessage] = []
    for i in rows[starts].tolist():
        when = int(stamp[i])
        frame = str(obs.camera_frame[i]) + REPLAY_FRAME_SUFFIX
        out.append(ProtobufMessage(topic, "foxglove.CameraCalibration", schema, int(obs.log_time_ns[i]), when,
                                   calibration_message(cameras, int(result.camera_row[i]), when, frame)))
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
    for when, in_ok in by_stamp(obs.stamp_ns[ok]):
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
    "CALIBRATION_TOPIC",
    "FINDINGS_TOPIC",
    "FOXGLOVE_FROM_OPENCV_PX",
    "SCENE_TOPIC",
    "TF_TOPIC",
    "ProtobufMessage",
    "annotation_stamps",
    "by_stamp",
    "calibration_message",
    "clip_to_image",
    "file_descriptor_set",
    "foxglove_messages",
    "viewing_hints",
]
