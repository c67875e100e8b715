"""Fiducial detections (AprilTag, ArUco, fiducial_msgs, 3D detections) as observations.

Message handlers append primitives per detection: the tag's four pixel corners (and the
detector's centre pixel) or a 3D point in the camera frame. Once the camera models are known,
:func:`resolve_fiducials` turns them into observation rows, vectorised per camera model:

- corners with a tag size: square-marker PnP (:mod:`framechain.vision.tag_pose`); the pixel is
  the projection of the tag centre, the depth its z in the camera frame;
- corners without a tag size: a bearing only (depth NaN, sampled from depth images at replay if
  any); the pixel is the image of the tag centre (the diagonals' intersection, undistorted);
- a 3D point (apriltag_ros pose, FiducialTransform, Detection3D, PointStamped): its projection
  through the camera model and its z.

Each detection becomes one observation labelled with its tag id, or is rejected with a
:class:`FiducialRejectReason`; the counts per topic reconcile and are kept in the metadata.

Message layouts (upstream definitions):

- ``apriltag_msgs/ApriltagArrayStamped`` (ROS 1, TagSLAM): ``apriltags[]`` with ``id``,
  ``family``, ``center`` and ``corners[4]`` as ``geometry_msgs/Point``;
- ``apriltag_msgs/AprilTagDetectionArray`` (ROS 2, christianrauch/apriltag_msgs):
  ``detections[]`` with ``id``, ``family``, ``centre`` and ``corners[4]`` as
  ``apriltag_msgs/Point`` (older releases: ``float64[2] centre``, ``float64[8] corners``);
- ``apriltag_ros/AprilTagDetectionArray`` (ROS 1): ``detections[]`` with ``id[]``, ``size[]``
  and ``pose`` (``PoseWithCovarianceStamped``, the tag in the camera frame);
- ``fiducial_msgs/FiducialArray``: ``fiducials[]`` with ``fiducial_id`` and ``x0, y0 .. x3, y3``;
- ``fiducial_msgs/FiducialTransformArray``: ``transforms[]`` with ``fiducial_id`` and
  ``transform`` (the fiducial in the camera frame);
- ``vision_msgs/Detection3DArray``: ``bbox.center`` pose in the camera frame,
  ``results[0].hypothesis.class_id`` (ROS 2) or ``results[0].id`` (ROS 1).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.arrays import BoolArray, FloatArray, IntArray, StrArray
from framechain.geometry.camera import CameraModel, distinct_models
from framechain.timeline import CameraTable, normalize_frames
from framechain.vision.opencv import project, undistort_normalised
from framechain.vision.tag_pose import MAX_REPROJECTION_PX, solve_square_tags

NS = 1_000_000_000
_CORNERS = 0  # a detection given by its four pixel corners
_POINT = 1  # a detection given by a 3D point in the camera frame


class FiducialRejectReason(StrEnum):
    """Why a detection did not become an observation; stable codes in notes and metadata."""

    NO_INTRINSICS = "no_intrinsics"  # a 3D point or a sized tag in a camera with no model
    CORNERS_INVALID = "corners_invalid"  # corners or point not finite
    PNP_FAILED = "pnp_failed"  # no square-marker pose in front of the camera
    REPROJECTION_TOO_LARGE = "reprojection_too_large"  # corners do not fit a square of the given size
    BEHIND_CAMERA = "behind_camera"  # a 3D point with z <= 0
    NO_TAG_SIZE = "no_tag_size"  # a tag with no size in a camera whose other tags have one


def _stamp(stamp: Any) -> int:
    return int(stamp.sec) * NS + int(stamp.nanosec)


def tag_size_lookup(spec: float | Mapping[str, float] | None) -> Callable[[str], float]:
    """Size in metres of the tag with a given id (label); NaN where the chain gives none.

    ``spec`` is ``evidence.tag_size_m``: one number for every tag, or a mapping from tag id to
    size with an optional ``default``.
    """
    if spec is None:
        return lambda label: math.nan
    if isinstance(spec, Mapping):
        table = {str(k): float(v) for k, v in spec.items()}
        default = table.get("default", math.nan)
        return lambda label: table.get(label, default)
    size = float(spec)
    return lambda label: size


@dataclass
class FiducialRows:
    """Per-detection primitives of one log, appended by the message handlers.

    ``size_for_tag`` gives the tag size of detections read from detector messages,
    ``size_for_marker`` of markers found in images (both NaN: bearing only).
    """

    size_for_tag: Callable[[str], float] = field(default=lambda label: math.nan)
    size_for_marker: Callable[[str], float] = field(default=lambda label: math.nan)
    #: A rig camera's own marker size, by its image topic (it wins over ``size_for_marker``).
    marker_size_of_topic: dict[str, float] = field(default_factory=dict)
    stamp_ns: list[int] = field(default_factory=list)
    log_time_ns: list[int] = field(default_factory=list)
    frame: list[str] = field(default_factory=list)
    label: list[str] = field(default_factory=list)
    score: list[float] = field(default_factory=list)
    topic: list[str] = field(default_factory=list)
    geometry: list[int] = field(default_factory=list)
    size_m: list[float] = field(default_factory=list)
    corners_px: list[float] = field(default_factory=list)  # 8 per row (u0 v0 .. u3 v3), NaN for points
    centre_px: list[float] = field(default_factory=list)  # 2 per row, NaN where the detector gave none
    point_cam: list[float] = field(default_factory=list)  # 3 per row, NaN for corners

    def __len__(self) -> int:
        return len(self.stamp_ns)

    # -- appenders ---------------------------------------------------------------------------
    def add_corners(self, topic: str, log_ns: int, stamp_ns: int, frame: str, label: str,
                    corners: Sequence[float], centre: tuple[float, float] = (math.nan, math.nan), *,
                    score: float = math.nan, from_image: bool = False) -> None:
        """One tag by its four pixel corners (u0, v0, .., u3, v3) in the detector's order."""
        size = (self.marker_size_of_topic.get(topic, self.size_for_marker(label)) if from_image
                else self.size_for_tag(label))
        self._row(topic, log_ns, stamp_ns, frame, label, score, _CORNERS, size)
        self.corners_px.extend(float(c) for c in corners)
        self.centre_px.extend(centre)
        self.point_cam.extend((math.nan, math.nan, math.nan))

    def add_point(self, topic: str, log_ns: int, stamp_ns: int, frame: str, label: str, point: Any, *,
                  score: float = math.nan) -> None:
        """One detection by a 3D point (``x, y, z`` attributes) in the camera frame, metres."""
        self._row(topic, log_ns, stamp_ns, frame, label, score, _POINT, math.nan)
        self.corners_px.extend([math.nan] * 8)
        self.centre_px.extend((math.nan, math.nan))
        self.point_cam.extend((float(point.x), float(point.y), float(point.z)))

    def _row(self, topic: str, log_ns: int, stamp_ns: int, frame: str, label: str, score: float, geometry: int,
             size_m: float) -> None:
        self.stamp_ns.append(stamp_ns)
        self.log_time_ns.append(log_ns)
        self.frame.append(frame)
        self.label.append(label)
        self.score.append(score)
        self.topic.append(topic)
        self.geometry.append(geometry)
        self.size_m.append(size_m)

    # -- message handlers (topic, log time, decoded message) ------------------------------------
    def apriltags(self, topic: str, log_ns: int, msg: Any) -> None:
        """apriltag_msgs: ROS 1 ``ApriltagArrayStamped`` or ROS 2 ``AprilTagDetectionArray``."""
        header = msg.header
        stamp, frame = _stamp(header.stamp), header.frame_id
        tags = msg.apriltags if hasattr(msg, "apriltags") else msg.detections
        for tag in tags:
            centre = tag.center if hasattr(tag, "center") else tag.centre
            self.add_corners(topic, log_ns, stamp, frame, str(tag.id), _xy_flat(tag.corners), _xy_pair(centre))

    def apriltag_poses(self, topic: str, log_ns: int, msg: Any) -> None:
        """apriltag_ros ``AprilTagDetectionArray``: each tag's (or bundle's) pose in the camera frame."""
        header = msg.header
        for det in msg.detections:
            pose = det.pose
            stamp = _stamp(pose.header.stamp) or _stamp(header.stamp)
            frame = pose.header.frame_id or header.frame_id
            label = "+".join(str(int(i)) for i in det.id)  # a bundle names all its tags
            self.add_point(topic, log_ns, stamp, frame, label, pose.pose.pose.position)

    def fiducial_vertices(self, topic: str, log_ns: int, msg: Any) -> None:
        """fiducial_msgs ``FiducialArray``: vertices x0, y0 .. x3, y3 (ArUco's corner order)."""
        stamp, frame = _stamp(msg.header.stamp), msg.header.frame_id
        for f in msg.fiducials:
            corners = (f.x0, f.y0, f.x1, f.y1, f.x2, f.y2, f.x3, f.y3)
            self.add_corners(topic, log_ns, stamp, frame, str(f.fiducial_id), corners)

    def fiducial_transforms(self, topic: str, log_ns: int, msg: Any) -> None:
        """fiducial_msgs ``FiducialTransformArray``: the fiducial's translation in the camera frame."""
        stamp, frame = _stamp(msg.header.stamp), msg.header.frame_id
        for t in msg.transforms:
            self.add_point(topic, log_ns, stamp, frame, str(t.fiducial_id), t.transform.translation)

    def detections_3d(self, topic: str, log_ns: int, msg: Any) -> None:
        """vision_msgs ``Detection3DArray``: the bounding box centre in the camera frame."""
        header = msg.header
        for det in msg.detections:
            stamp = _stamp(det.header.stamp) or _stamp(header.stamp)
            frame = det.header.frame_id or header.frame_id
            label, score = "", math.nan
            if len(det.results):
                r0 = det.results[0]
                hyp = getattr(r0, "hypothesis", None)
                if hyp is not None:  # vision_msgs >= 3 (ROS 2)
                    label, score = str(hyp.class_id), float(hyp.score)
                else:  # ROS 1: int64 id
                    label, score = str(r0.id), float(r0.score)
            self.add_point(topic, log_ns, stamp, frame, label, det.bbox.center.position, score=score)

    def camera_point(self, topic: str, log_ns: int, msg: Any) -> None:
        """geometry_msgs ``PointStamped`` named as the detections: a 3D point in a camera frame."""
        self.add_point(topic, log_ns, _stamp(msg.header.stamp), msg.header.frame_id, "", msg.point)


def _xy_pair(p: Any) -> tuple[float, float]:
    if hasattr(p, "x"):
        return float(p.x), float(p.y)
    a = np.asarray(p, dtype=np.float64).reshape(-1)
    return float(a[0]), float(a[1])


def _xy_flat(corners: Any) -> list[float]:
    """Four corners as ``Point``s (x, y attributes) or a flat ``float64[8]``."""
    if len(corners) == 8 and not hasattr(corners[0], "x"):
        return [float(c) for c in corners]
    return [float(v) for p in corners for v in (p.x, p.y)]


# -- resolution into observations --------------------------------------------------------------------
@dataclass(frozen=True)
class ResolvedFiducials:
    """Observation rows from fiducial detections (kept rows only, in detection order).

    ``detection_index`` maps each kept row to its row in :class:`FiducialRows`; ``side`` holds,
    per kept corner detection, the corners, tag size, reprojection error and detector centre
    (JSON-ready columns); ``counts`` per topic: detections, observations, bearing_only and
    rejected by reason, so that ``observations + sum(rejected) == detections``.
    """

    detection_index: IntArray
    stamp_ns: IntArray
    log_time_ns: IntArray
    camera_frame: StrArray
    u: FloatArray
    v: FloatArray
    depth_m: FloatArray
    label: StrArray
    score: FloatArray
    source: StrArray
    side: dict[str, list[Any]]
    counts: dict[str, dict[str, Any]]
    notes: list[str]
    #: Cameras without a model whose 3D points are kept in normalised image coordinates (u = x/z, v = y/z):
    #: the reader gives each a camera-less model (:func:`unprojected_cameras`).
    unprojected: frozenset[str] = frozenset()


def camera_models_at(cameras: CameraTable, frame: str, stamps_ns: IntArray) -> tuple[list[CameraModel], IntArray]:
    """Distinct camera models of ``frame`` and, per stamp, which one is in force (-1: none).

    The latest camera row at or before the stamp; before the first one, the first. Rows of one
    model share it (:func:`~framechain.geometry.camera.distinct_models`: one OpenCV call each).
    """
    mine = np.flatnonzero(cameras.frame == frame)
    if mine.size == 0:
        return [], np.full(stamps_ns.shape[0], -1, dtype=np.int64)
    order = mine[np.argsort(cameras.stamp_ns[mine], kind="stable")]
    pos = np.searchsorted(cameras.stamp_ns[order], stamps_ns, side="right") - 1
    rows = order[np.clip(pos, 0, order.size - 1)]
    return distinct_models(cameras, rows)


def _diagonal_centre(norm: FloatArray) -> FloatArray:
    """Intersection of the diagonals of quads (N, 4, 2) in undistorted normalised coordinates:
    the image of a planar square's centre under a pinhole projection."""
    p0, p1, p2, p3 = norm[:, 0], norm[:, 1], norm[:, 2], norm[:, 3]
    d1, d2 = p2 - p0, p3 - p1
    denom = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    w = p1 - p0
    t = (w[:, 0] * d2[:, 1] - w[:, 1] * d2[:, 0]) / np.where(denom == 0, np.nan, denom)
    out: FloatArray = p0 + t[:, None] * d1
    return out


def resolve_fiducials(rows: FiducialRows, cameras: CameraTable, *, calibration_hint: str = "") -> ResolvedFiducials:
    """Observation rows from the detections in ``rows`` with the camera models in ``cameras``."""
    n = len(rows)
    frame = normalize_frames(rows.frame) if n else np.zeros(0, dtype=str)
    stamp = np.asarray(rows.stamp_ns, dtype=np.int64)
    geometry = np.asarray(rows.geometry, dtype=np.int64)
    size = np.asarray(rows.size_m, dtype=np.float64)
    corners = np.asarray(rows.corners_px, dtype=np.float64).reshape(-1, 4, 2)
    centre_px = np.asarray(rows.centre_px, dtype=np.float64).reshape(-1, 2)
    point = np.asarray(rows.point_cam, dtype=np.float64).reshape(-1, 3)
    u, v, depth = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    reproj = np.full(n, np.nan)
    reason = np.full(n, "", dtype=object)
    reversed_order = np.zeros(n, dtype=bool)
    is_corners = geometry == _CORNERS
    sized = is_corners & np.isfinite(size) & (size > 0)
    finite = np.where(is_corners, np.isfinite(corners).all(axis=(1, 2)), np.isfinite(point).all(axis=1))
    reason[~finite] = FiducialRejectReason.CORNERS_INVALID.value
    no_model_frames: set[str] = set()
    unprojected: set[str] = set()
    for cam in np.unique(frame).tolist():
        in_cam = frame == cam
        models, which = camera_models_at(cameras, cam, stamp[in_cam])
        idx_cam = np.flatnonzero(in_cam)
        if not models:
            needed_model, kept_unprojected = _resolve_without_model(
                idx_cam[finite[idx_cam]], sized, is_corners, point, centre_px, corners, u, v, depth, reason)
            if needed_model:
                no_model_frames.add(cam)
            if kept_unprojected:
                unprojected.add(cam)
            continue
        for k, model in enumerate(models):
            idx = idx_cam[(which == k) & finite[idx_cam]]
            _resolve_points(model, idx[~is_corners[idx]], point, u, v, depth, reason)
            _resolve_sized(model, idx[sized[idx]], corners, size, u, v, depth, reproj, reason, reversed_order)
            _resolve_bearing(model, idx[is_corners[idx] & ~sized[idx]], corners, u, v)
    # A camera's evidence is either points (tags with a size: depth from the corners) or rays (no
    # size at all); the two do not mix, so a tag without a size beside sized ones is not used.
    for cam in np.unique(frame[sized & (reason == "")]).tolist():
        reason[(frame == cam) & is_corners & ~sized & (reason == "")] = FiducialRejectReason.NO_TAG_SIZE.value
    keep = reason == ""
    topic = np.asarray(rows.topic, dtype=str) if n else np.zeros(0, dtype=str)
    labels = np.asarray(rows.label, dtype=str) if n else np.zeros(0, dtype=str)
    counts, notes = _count(topic, frame, labels, reason, keep, is_corners, sized, reversed_order, no_model_frames,
                           calibration_hint)
    kept = np.flatnonzero(keep)
    side = _side_table(kept[is_corners[kept]], corners, size, reproj, centre_px)
    return ResolvedFiducials(
        detection_index=kept.astype(np.int64), stamp_ns=stamp[kept],
        log_time_ns=np.asarray(rows.log_time_ns, dtype=np.int64)[kept], camera_frame=frame[kept], u=u[kept],
        v=v[kept], depth_m=depth[kept], label=np.asarray(rows.label, dtype=str)[kept] if n else np.zeros(0, str),
        score=np.asarray(rows.score, dtype=np.float64)[kept], source=topic[kept], side=side, counts=counts,
        notes=notes, unprojected=frozenset(unprojected),
    )


def _resolve_without_model(
    idx: IntArray, sized: BoolArray, is_corners: BoolArray, point: FloatArray, centre_px: FloatArray,
    corners: FloatArray, u: FloatArray, v: FloatArray, depth: FloatArray, reason: npt.NDArray[Any],
) -> tuple[bool, bool]:
    """Detections ``idx`` (finite) of a camera with no model: whether sized corners needed one, and whether 3D
    points were kept unprojected.

    Bearing-only corners keep the detector's centre pixel; sized corners need intrinsics for PnP. A 3D point
    in the camera frame needs none: it is kept in normalised image coordinates (x/z, y/z) with its z, for the
    camera-less model the reader adds (intrinsics would only draw it)."""
    need = idx[sized[idx]]
    reason[need] = FiducialRejectReason.NO_INTRINSICS.value
    points = idx[~is_corners[idx]]
    front = points[point[points, 2] > 0]
    reason[points[point[points, 2] <= 0]] = FiducialRejectReason.BEHIND_CAMERA.value
    if front.size:
        z = point[front, 2]
        u[front], v[front], depth[front] = point[front, 0] / z, point[front, 1] / z, z
    bearing = idx[~sized[idx] & is_corners[idx]]
    given = np.isfinite(centre_px[bearing]).all(axis=1, keepdims=True)
    centre = np.where(given, centre_px[bearing], _diagonal_centre(corners[bearing]))
    u[bearing], v[bearing] = centre[:, 0], centre[:, 1]
    return bool(need.size), bool(front.size)


def _side_table(rows: IntArray, corners: FloatArray, size: FloatArray, reproj: FloatArray, centre_px: FloatArray
                ) -> dict[str, list[Any]]:
    """The side table of the kept corner detections ``rows``: their corners, size, reprojection error and the
    detector's own centre pixel."""
    return {
        "detection": rows.tolist(),
        "corners_px": [[float(x) for x in c] for c in corners[rows].reshape(-1, 8)],
        "size_m": [_json_float(x) for x in size[rows]],
        "reprojection_px": [_json_float(x) for x in reproj[rows]],
        "detector_centre_px": [[_json_float(x) for x in c] for c in centre_px[rows]],
    }


#: The source of a camera-less model in the camera table (width and height 0: no image to bound or draw).
UNPROJECTED_SOURCE = "3D points in the camera frame, no intrinsics"


def with_unprojected(cameras: CameraTable, resolved: ResolvedFiducials) -> tuple[CameraTable, list[str]]:
    """The camera table with a camera-less model per camera whose 3D points were kept without intrinsics (K = I,
    no distortion, width and height 0: no image; the replay's hop 1 takes (x/z, y/z, z) back to the point
    exactly, and sinks draw nothing on images for it), and a note for each."""
    if not resolved.unprojected:
        return cameras, []
    stamp = int(resolved.stamp_ns.min()) if resolved.stamp_ns.size else 0
    tables = [CameraTable.from_intrinsics(f, fx=1.0, fy=1.0, cx=0.0, cy=0.0, width=0, height=0, stamp_ns=stamp,
                                          distortion_model="none", source=UNPROJECTED_SOURCE)
              for f in sorted(resolved.unprojected)]
    notes = [f"camera {f}: no intrinsics; its detections are 3D points in the camera frame and are replayed as they "
             "are (intrinsics would only draw them on images)" for f in sorted(resolved.unprojected)]
    return CameraTable.concat([cameras, *tables]), notes


def _json_float(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _resolve_points(model: CameraModel, idx: IntArray, point: FloatArray, u: FloatArray, v: FloatArray,
                    depth: FloatArray, reason: npt.NDArray[Any]) -> None:
    if idx.size == 0:
        return
    front = point[idx, 2] > 0
    reason[idx[~front]] = FiducialRejectReason.BEHIND_CAMERA.value
    ok = idx[front]
    px = project(model, point[ok])
    u[ok], v[ok], depth[ok] = px[:, 0], px[:, 1], point[ok, 2]


def _resolve_sized(model: CameraModel, idx: IntArray, corners: FloatArray, size: FloatArray, u: FloatArray,
                   v: FloatArray, depth: FloatArray, reproj: FloatArray, reason: npt.NDArray[Any],
                   reversed_order: BoolArray) -> None:
    if idx.size == 0:
        return
    poses = solve_square_tags(model, corners[idx], size[idx])
    reproj[idx] = poses.reprojection_px
    reversed_order[idx] = poses.reversed_order
    reason[idx[~poses.ok]] = FiducialRejectReason.PNP_FAILED.value
    too_far = poses.ok & ~(poses.reprojection_px <= MAX_REPROJECTION_PX)
    reason[idx[too_far]] = FiducialRejectReason.REPROJECTION_TOO_LARGE.value
    good = poses.ok & ~too_far
    px = project(model, poses.centre_cam[good])
    ok = idx[good]
    u[ok], v[ok], depth[ok] = px[:, 0], px[:, 1], poses.centre_cam[good, 2]


def _resolve_bearing(model: CameraModel, idx: IntArray, corners: FloatArray, u: FloatArray, v: FloatArray) -> None:
    if idx.size == 0:
        return
    norm = undistort_normalised(model, corners[idx].reshape(-1, 2)).reshape(-1, 4, 2)
    centre = _diagonal_centre(norm)
    px = project(model, np.column_stack([centre, np.ones(idx.size)]))
    u[idx], v[idx] = px[:, 0], px[:, 1]


def _count(topic: StrArray, frame: StrArray, labels: StrArray, reason: npt.NDArray[Any], keep: BoolArray,
           is_corners: BoolArray, sized: BoolArray, reversed_order: BoolArray, no_model_frames: set[str],
           calibration_hint: str) -> tuple[dict[str, dict[str, Any]], list[str]]:
    counts: dict[str, dict[str, Any]] = {}
    notes: list[str] = []
    for t in sorted(set(topic.tolist())):
        mine = topic == t
        rejected = Counter(str(r) for r in reason[mine & ~keep].tolist())
        bearing = int((mine & keep & is_corners & ~sized).sum())
        counts[t] = {"detections": int(mine.sum()), "observations": int((mine & keep).sum()),
                     "bearing_only": bearing, "rejected": dict(sorted(rejected.items()))}
        for why, count in sorted(rejected.items()):
            these = mine & (reason == why)
            notes.append(f"topic {t}: {count} detection{'s' if count != 1 else ''} rejected: "
                         f"{_explain(why, frame[these], labels[these], no_model_frames, calibration_hint)}")
        if bearing:
            notes.append(f"topic {t}: {bearing} tag detection{'s' if bearing != 1 else ''} without a tag size are "
                         "bearings only (set evidence.tag_size_m, or markers.size_m, for a depth from the corners)")
        flipped = int((mine & reversed_order).sum())
        if flipped:
            notes.append(f"topic {t}: {flipped} tag corner sets wind counter-clockwise on screen (the detector's "
                         "order mirrors IPPE_SQUARE's); they were matched in reverse order")
    return counts, notes


def _explain(why: str, frames: StrArray, labels: StrArray, no_model_frames: set[str], calibration_hint: str) -> str:
    if why == FiducialRejectReason.NO_TAG_SIZE:
        ids = sorted(set(labels.tolist()), key=lambda x: (len(x), x))
        shown = ", ".join(ids[:8]) + (f" and {len(ids) - 8} more" if len(ids) > 8 else "")
        return (f"no size for tag{'s' if len(ids) != 1 else ''} {shown} in evidence.tag_size_m while other tags "
                f"of camera {', '.join(sorted(set(frames.tolist())))} have one (sized tags give points, unsized "
                "ones rays; the two are not mixed): add their sizes or a `default`")
    if why == FiducialRejectReason.NO_INTRINSICS:
        cams = sorted(set(frames.tolist()) & no_model_frames) or sorted(set(frames.tolist()))
        hint = calibration_hint or "add calibration: {file: <camchain or CameraInfo yaml>, camera: <name>} " \
                                   "to the chain, or record the camera's CameraInfo"
        return f"no intrinsics for camera {', '.join(cams)} ({hint})"
    return {
        FiducialRejectReason.CORNERS_INVALID: "corners or point not finite",
        FiducialRejectReason.PNP_FAILED: "no square-marker pose in front of the camera (PnP failed)",
        FiducialRejectReason.REPROJECTION_TOO_LARGE:
            f"tag corners reproject more than {MAX_REPROJECTION_PX} px (RMS) from the detected ones: wrong tag "
            "size, wrong intrinsics or a false detection",
        FiducialRejectReason.BEHIND_CAMERA: "point not in front of the camera (z <= 0)",
    }.get(FiducialRejectReason(why), why)


def counts_reconcile(counts: Mapping[str, Mapping[str, Any]]) -> bool:
    """Whether every topic's observations plus rejections equal its detections."""
    return all(int(c["observations"]) + sum(int(x) for x in c["rejected"].values()) == int(c["detections"])
               for c in counts.values())

