"""The collector every reader fills: per-message handlers append primitives to one row
accumulator per table (:mod:`framechain.adapters.messages.rows`), then the tables are built once.

Handlers take decoded messages with attribute access (rosbags message classes for ROS 1 and
ROS 2, protobuf messages or JSON wrapped by :func:`wrap_json` for Foxglove schemas). They never
build a table per message: a TFMessage appends its frame names, stamps and seven floats per
transform, and :meth:`Collector.build` turns the lists into arrays and adds what the chain and
the log's other sources (calibration files, URDFs, fiducials, librealsense extrinsics) bring.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.messages.depth import DepthWindowKeeper, depth_metadata, depth_table, raw_depth_pixels
from framechain.adapters.messages.fiducials import (
    FiducialRows,
    ResolvedFiducials,
    resolve_fiducials,
    tag_size_lookup,
    with_unprojected,
)
from framechain.adapters.messages.images import image_metadata, image_table
from framechain.adapters.messages.kinds import Kind
from framechain.adapters.messages.locator import FrameFetch
from framechain.adapters.messages.realsense import apply_realsense_layout
from framechain.adapters.messages.rig_topics import TopicCameras
from framechain.adapters.messages.rows import (
    CameraRows,
    FrameRows,
    JointRows,
    ObservationRows,
    PointRows,
    TransformRows,
)
from framechain.adapters.messages.stamps import NS, fox_stamp_ns, ros_stamp_ns, stamp_notes
from framechain.adapters.mounts import (
    FileCamera,
    log_urdf_edges,
    merge_file_cameras,
    merge_static_edges,
)
from framechain.config.chain import ChainConfig
from framechain.config.mount import Mount
from framechain.timeline import CameraTable, DepthFrameTable, ImageFrameTable, Timeline, TransformTable

#: Kinds whose messages become pixel observations (a depth frame's windows wait for them).
OBSERVATION_KINDS = frozenset({Kind.DETECTIONS, Kind.DETECTION, Kind.PIXEL_POINT})


class Collector:
    """Accumulates the rows of one log; :meth:`build` returns the Timeline and the notes."""

    def __init__(self, chain: ChainConfig | None = None) -> None:
        self.chain = chain
        self.roles = chain.evidence_topics() if chain else {}
        #: Pose topics and the child frame their entry names (None: the message's, else the body frame).
        self.pose_children = {p.topic: p.child for p in chain.pose_topics()} if chain else {}
        #: Static edges and camera models the chain file adds (see framechain.adapters.mounts).
        self.chain_edges: list[Mount] = []
        self.file_cameras: list[FileCamera] = []
        self.notes: list[str] = []
        self.depth_from_pose: dict[str, int] = {}  # detections whose hypothesis pose carried a depth, by topic
        # fiducials (tags, markers in images, camera-frame points): resolved once the cameras are known
        self.fiducials = _fiducial_rows(chain)
        self.marker_finders: dict[str, Any] = {}  # a markers.MarkerFinder per dictionary, made when an image is read
        self.topic_cameras = TopicCameras(chain.topic_frames() if chain else {})
        self._relabelled_obs = 0  # observations relabelled so far
        self._fiducials_resolved: tuple[int, ResolvedFiducials] | None = None
        self._obs_ids: npt.NDArray[np.int64] = np.zeros(0, dtype=np.int64)  # in append order
        self.transforms = TransformRows()
        self.cameras = CameraRows()
        self.observations = ObservationRows()
        self.joint_states = JointRows()
        self.points = PointRows()
        self.depth_frames = FrameRows()
        self.image_frames = FrameRows()  # camera images on topics.image, shown by the sinks
        self.depth_scale: dict[str, float] = {}
        self.depth_keeper = DepthWindowKeeper()
        self._kept_obs = 0  # observations handed to the keeper so far
        #: Set by a reader while it reads: decodes the detections it holds in batches (the keeper needs them).
        self.flush_observations: Callable[[], None] | None = None
        # robot descriptions and librealsense extrinsics
        self.urdf: dict[str, str] = {}
        self.rs_extrinsics: dict[str, tuple[float, ...]] = {}
        self.skipped: Counter[tuple[str, str]] = Counter()

    # -- TF -------------------------------------------------------------------------------
    def tf(self, topic: str, log_ns: int, msg: Any) -> None:
        """tf2_msgs/TFMessage or tf/tfMessage."""
        static = topic.rstrip("/").endswith("tf_static")
        n = 0
        rows = self.transforms
        parents, children, stamps, vals = rows.parent, rows.child, rows.stamp_ns, rows.values
        for ts in msg.transforms:
            h = ts.header
            st = h.stamp
            stamps.append(st.sec * NS + st.nanosec)
            parents.append(h.frame_id)
            children.append(ts.child_frame_id)
            tr = ts.transform.translation
            q = ts.transform.rotation
            vals.extend((tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w))
            n += 1
        rows.end_message(topic, log_ns, n, static=static)

    def transform_stamped(self, topic: str, log_ns: int, msg: Any) -> None:
        """geometry_msgs/TransformStamped on its own topic: one edge sample."""
        self._edge(topic, log_ns, msg.header.frame_id, msg.child_frame_id, ros_stamp_ns(msg.header.stamp),
                   msg.transform.translation, msg.transform.rotation)

    def _edge(self, topic: str, log_ns: int, parent: str, child: str, stamp: int, tr: Any, q: Any,
              *, kind: str = "tf") -> None:
        self.transforms.add_edge(topic, log_ns, parent, child, stamp, (tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w),
                                 static=topic.rstrip("/").endswith("tf_static"), kind=kind)

    def fox_transforms(self, topic: str, log_ns: int, msg: Any) -> None:
        """foxglove.FrameTransforms (protobuf or JSON)."""
        for t in msg.transforms:
            self.fox_transform(topic, log_ns, t)

    def fox_transform(self, topic: str, log_ns: int, msg: Any) -> None:
        """foxglove.FrameTransform: parent_frame_id, child_frame_id, translation, rotation."""
        self._edge(topic, log_ns, msg.parent_frame_id, msg.child_frame_id, fox_stamp_ns(msg.timestamp),
                   msg.translation, msg.rotation)

    def odometry(self, topic: str, log_ns: int, msg: Any) -> None:
        """nav_msgs/Odometry as the edge header.frame_id -> child_frame_id."""
        pose = msg.pose.pose
        self._edge(topic, log_ns, msg.header.frame_id, self._pose_child(topic, msg.child_frame_id),
                   ros_stamp_ns(msg.header.stamp), pose.position, pose.orientation, kind="odometry")

    def pose(self, topic: str, log_ns: int, msg: Any) -> None:
        """PoseStamped, PoseWithCovarianceStamped or TransformStamped on a pose topic the chain names:
        the dynamic edge header.frame_id -> child (the entry's child, the message's, or the body frame)."""
        if hasattr(msg, "transform"):  # TransformStamped
            tr, q, child = msg.transform.translation, msg.transform.rotation, msg.child_frame_id
        else:
            pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose  # with covariance, or not
            tr, q, child = pose.position, pose.orientation, ""
        self._edge(topic, log_ns, msg.header.frame_id, self._pose_child(topic, child),
                   ros_stamp_ns(msg.header.stamp), tr, q, kind="odometry")

    def _pose_child(self, topic: str, child: str) -> str:
        """The child frame of a pose sample: the chain entry's, else the message's, else the body frame."""
        named = self.pose_children.get(topic)
        if named:
            if child.strip("/") and child.strip("/") != named:
                self.skipped[(topic, f"child frame {child!r} replaced by {named!r} as the chain says")] += 1
            return named
        if child.strip("/"):
            return child
        body = self.chain.frames.body if self.chain else "base_link"
        whose = "the chain's frames.body" if self.chain else "the default frames.body"
        self.skipped[(topic, f"no child frame in the message; {body!r} ({whose}) is used")] += 1
        return body

    def rs_extrinsic(self, topic: str, log_ns: int, msg: Any) -> None:
        """librealsense ``.../<stream>/tf/<ref>``: geometry_msgs/Transform, reference -> stream."""
        tr, q = msg.translation, msg.rotation
        self.rs_extrinsics[topic] = (tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w, float(log_ns))

    def rs_depth_units(self, topic: str, log_ns: int, msg: Any) -> None:
        sensor = topic.split("/option/", maxsplit=1)[0]
        self.depth_scale[sensor] = float(msg.data)

    # -- cameras ----------------------------------------------------------------------------
    def camera_info(self, topic: str, log_ns: int, msg: Any) -> None:
        """sensor_msgs/CameraInfo (ROS 2 ``k``/``d``, ROS 1 ``K``/``D``)."""
        k = getattr(msg, "k", None)
        if k is None:
            k = msg.K
        d = getattr(msg, "d", None)
        if d is None:
            d = msg.D
        self._camera(topic, log_ns, msg.header.frame_id, ros_stamp_ns(msg.header.stamp), int(msg.width),
                     int(msg.height), msg.distortion_model, k, d)

    def fox_camera(self, topic: str, log_ns: int, msg: Any) -> None:
        """foxglove.CameraCalibration: frame_id, width, height, distortion_model, D, K."""
        self._camera(topic, log_ns, msg.frame_id, fox_stamp_ns(msg.timestamp), int(msg.width), int(msg.height),
                     msg.distortion_model, msg.K, msg.D)

    def _camera(self, topic: str, log_ns: int, frame: str, stamp: int, w: int, h: int, model: str, k: Any,
                d: Any) -> None:
        self.cameras.append(topic, log_ns, frame, stamp, w, h, model, k, d)

    # -- observations ---------------------------------------------------------------------
    def detections(self, topic: str, log_ns: int, msg: Any) -> None:
        """vision_msgs/Detection2DArray in any layout (ROS 2 >= 4, older ROS 2, ROS 1)."""
        header = msg.header
        for det in msg.detections:
            self._detection(topic, log_ns, det, header)

    def detection(self, topic: str, log_ns: int, msg: Any) -> None:
        self._detection(topic, log_ns, msg, msg.header)

    def _detection(self, topic: str, log_ns: int, det: Any, outer: Any) -> None:
        center = det.bbox.center
        position = getattr(center, "position", None)
        if position is not None:  # vision_msgs >= 4: Pose2D{position: Point2D, theta}
            u, v = position.x, position.y
        else:  # ROS 1 and older ROS 2: geometry_msgs/Pose2D{x, y, theta}
            u, v = center.x, center.y
        h = det.header
        stamp = ros_stamp_ns(h.stamp)
        if stamp == 0:
            stamp = ros_stamp_ns(outer.stamp)
        frame = h.frame_id or outer.frame_id
        ident = getattr(det, "id", None)
        if ident is None:
            ident = getattr(det, "tracking_id", "")
        label, score, depth = "", math.nan, math.nan
        results = det.results
        if len(results):
            r0 = results[0]
            hyp = getattr(r0, "hypothesis", None)
            if hyp is not None:  # vision_msgs >= 3
                label, score = str(hyp.class_id), float(hyp.score)
            else:  # ROS 1 (int64 id) and vision_msgs 2 (string id)
                label, score = str(r0.id), float(r0.score)
            z = float(r0.pose.pose.position.z)
            if math.isfinite(z) and z > 0:
                depth = z
                self.depth_from_pose[topic] = self.depth_from_pose.get(topic, 0) + 1
        self.observations.append(topic, log_ns, str(ident), stamp, frame, u, v, depth, label, score)

    def pixel_point(self, topic: str, log_ns: int, msg: Any) -> None:
        """geometry_msgs/PointStamped holding a pixel: x = u, y = v, z = depth in metres (0: none)."""
        p = msg.point
        z = float(p.z)
        self.observations.append(topic, log_ns, "", ros_stamp_ns(msg.header.stamp), msg.header.frame_id, p.x, p.y,
                                 z if math.isfinite(z) and z > 0 else math.nan, "", math.nan)

    def add_side_detections(self, rows: Mapping[str, npt.NDArray[Any]], source: str) -> None:
        """Detections from a side table (columns already checked by the caller)."""
        stamps = [int(x) for x in rows["stamp_ns"]]
        self.observations.extend(
            source, id_text=[str(x) for x in rows["obs_id"]], stamp_ns=stamps, log_time_ns=stamps,
            frame=[str(x) for x in rows["frame"]],
            uvd=np.column_stack([rows["u"], rows["v"], rows["depth_m"]]).reshape(-1).tolist(),
            label=[str(x) for x in rows["label"]], score=[float(x) for x in rows["score"]])

    # -- points -----------------------------------------------------------------------------
    def point(self, topic: str, log_ns: int, msg: Any) -> None:
        """PointStamped, PoseStamped or TransformStamped as a logged point (role from the chain)."""
        h = msg.header
        if hasattr(msg, "point"):
            p = msg.point
            vals: tuple[float, ...] = (p.x, p.y, p.z, math.nan, math.nan, math.nan, math.nan)
        elif hasattr(msg, "pose"):
            p, q = msg.pose.position, msg.pose.orientation
            vals = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
        else:
            p, q = msg.transform.translation, msg.transform.rotation
            vals = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
        self.points.append(topic, log_ns, h.frame_id, ros_stamp_ns(h.stamp), vals)

    # -- joints, descriptions ---------------------------------------------------------------
    def joint_state(self, topic: str, log_ns: int, msg: Any) -> None:
        self.joint_states.append(topic, log_ns, ros_stamp_ns(msg.header.stamp), list(msg.name), msg.position,
                                 msg.velocity, msg.effort)

    def urdf_text(self, topic: str, log_ns: int, msg: Any) -> None:
        self.urdf[topic] = str(msg.data)

    # -- depth --------------------------------------------------------------------------------
    def depth(self, topic: str, log_ns: int, msg: Any) -> None:
        """sensor_msgs/Image (16UC1, mono16, 32FC1) or CompressedImage (compressedDepth): metadata, and
        the raw pixels held briefly so the keeper cuts the windows detections need; the rest stays in the log."""
        meta = depth_metadata(msg)
        if meta is None:
            encoding = getattr(msg, "encoding", getattr(msg, "format", "?"))
            self.skipped[(topic, f"encoding {encoding!r} is not depth")] += 1
            return
        width, height, encoding = meta
        stamp = ros_stamp_ns(msg.header.stamp)
        frame = self.topic_cameras.frame(topic, msg.header.frame_id)
        self.depth_frames.append(topic, log_ns, frame, stamp, width, height, encoding)
        if encoding.startswith("compressedDepth"):
            return  # a PNG: only the whole frame decodes, so it is fetched when needed
        try:
            raw = raw_depth_pixels(msg)
        except ValueError:  # pixels shorter than the header says: the fetch reports it if a detection needs it
            return
        if self.depth_keeper.add_frame(len(self.depth_frames) - 1, frame, stamp, log_ns, raw):
            self.settle_depth(final=False)

    def settle_depth(self, *, final: bool) -> None:
        """Hand the detections read since the last call to the depth keeper and let it cut windows."""
        if self.flush_observations is not None and not final:
            self.flush_observations()
        self._relabel_observations()
        start, end = self._kept_obs, len(self.observations)
        if end > start:
            frames, stamps, logs, uvd = self.observations.pixels(start, end)
            self.depth_keeper.add_observations(frames, stamps, logs, uvd[:, 0], uvd[:, 1])
            self._kept_obs = end
        self.depth_keeper.settle(final=final)

    # -- images ---------------------------------------------------------------------------------
    def image(self, topic: str, log_ns: int, msg: Any) -> None:
        """sensor_msgs/Image (raw) or CompressedImage (JPEG, PNG): metadata only."""
        meta = image_metadata(msg)
        if meta is None:
            encoding = getattr(msg, "encoding", getattr(msg, "format", "?"))
            self.skipped[(topic, f"image encoding {encoding!r} cannot be shown (raw or JPEG/PNG expected)")] += 1
            return
        width, height, encoding = meta
        self.image_frames.append(topic, log_ns, msg.header.frame_id, ros_stamp_ns(msg.header.stamp), width, height,
                                 encoding)

    # -- dispatch -------------------------------------------------------------------------------
    def handler(self, kind: Kind, *, foxglove: bool = False) -> Callable[[str, int, Any], None] | None:
        """The handler of a kind (Foxglove schemas have their own)."""
        if foxglove:
            return {Kind.TF: self.fox_transforms, Kind.TRANSFORM: self.fox_transform,
                    Kind.CAMERA_INFO: self.fox_camera}.get(kind)
        table: dict[Kind, Callable[[str, int, Any], None]] = {
            Kind.TF: self.tf, Kind.TRANSFORM: self.transform_stamped, Kind.CAMERA_INFO: self.camera_info,
            Kind.DEPTH: self.depth, Kind.DETECTIONS: self.detections, Kind.DETECTION: self.detection,
            Kind.PIXEL_POINT: self.pixel_point, Kind.POINT: self.point, Kind.ODOMETRY: self.odometry,
            Kind.JOINT_STATE: self.joint_state, Kind.URDF: self.urdf_text, Kind.RS_EXTRINSIC: self.rs_extrinsic,
            Kind.RS_DEPTH_UNITS: self.rs_depth_units, Kind.POSE: self.pose, Kind.IMAGE: self.image,
        }
        f = self.fiducials
        fiducial_handlers: dict[Kind, Callable[[str, int, Any], None]] = {
            Kind.APRILTAGS: f.apriltags, Kind.APRILTAG_POSES: f.apriltag_poses,
            Kind.FIDUCIAL_VERTICES: f.fiducial_vertices, Kind.FIDUCIAL_TRANSFORMS: f.fiducial_transforms,
            Kind.DETECTIONS_3D: f.detections_3d, Kind.CAMERA_POINT: f.camera_point,
        }
        table.update(fiducial_handlers)
        if kind == Kind.MARKER_IMAGE and self.chain is not None:
            def handle(topic: str, log_ns: int, msg: Any) -> None:  # searched for markers, and shown
                finder = self._marker_finder(topic)
                if finder is not None:
                    finder.image(topic, log_ns, msg)
                self.image(topic, log_ns, msg)

            return handle
        return table.get(kind)

    def _marker_finder(self, topic: str) -> Any:
        """The finder of the markers searched for in ``topic`` (a rig camera's own, else the chain's)."""
        assert self.chain is not None
        own = next((c.markers for c in self.chain.cameras if c.image == topic), None)
        spec = own or self.chain.evidence.markers
        if spec is None:
            return None
        if spec.dictionary not in self.marker_finders:
            from framechain.vision.markers import MarkerFinder

            self.marker_finders[spec.dictionary] = MarkerFinder(spec.dictionary, self.fiducials)
        if own is not None and own.size_m is not None:
            self.fiducials.marker_size_of_topic[topic] = own.size_m
        return self.marker_finders[spec.dictionary]

    def _relabel_observations(self) -> None:
        """Observations appended since the last call take their rig camera's frame (by topic)."""
        if not self.topic_cameras:
            return
        rows = self.observations
        for i in range(self._relabelled_obs, len(rows)):
            rows.frame[i] = self.topic_cameras.frame(rows.topic[i], rows.frame[i])
        self._relabelled_obs = len(rows)

    def _relabel_read_tables(self) -> None:
        """Camera models, images and fiducials (not needed while reading) take their rig camera's frame."""
        if not self.topic_cameras:
            return
        for rows in (self.cameras, self.image_frames, self.fiducials):
            rows.frame = [self.topic_cameras.frame(t, f) for f, t in zip(rows.frame, rows.topic, strict=True)]
        self._relabel_observations()
        self.notes.extend(self.topic_cameras.notes())

    # -- build ------------------------------------------------------------------------------------
    def build(self, fetch: FrameFetch | None, metadata: Mapping[str, Any]) -> tuple[Timeline, list[str]]:
        """The Timeline (every table in log-time order, ties by topic then file order) and notes."""
        realsense = bool(self.rs_extrinsics) or any("/device_" in t for t in self.depth_frames.topic)
        if realsense:
            self.notes.extend(apply_realsense_layout(self.rs_extrinsics, self.transforms, self.depth_frames,
                                                     self.cameras))
        for (topic, what), count in sorted(self.skipped.items()):
            self.notes.append(f"topic {topic}: {what} ({count} message{'s' if count != 1 else ''})")
        self._relabel_read_tables()
        for topic, count in sorted(self.depth_from_pose.items()):
            self.notes.append(
                f"topic {topic}: {count} detections carry a depth in results[0].pose.pose.position.z; it is used as "
                "the z-depth in the camera frame instead of sampling the depth image"
            )
        transforms = self._transforms()
        cameras = self._cameras()
        cameras = self._add_fiducial_observations(cameras)
        observations, self._obs_ids = self.observations.table(self.notes)
        points = self.points.table(self.roles)
        joints = self.joint_states.table()
        depth = self._depth(fetch)
        images = self._images(fetch)
        meta = dict(metadata)
        if self._fiducials_resolved is not None:
            meta["fiducials"] = self._fiducial_metadata()
            # Detections that never became observations still count: replay adds them to its totals.
            rejected: Counter[str] = Counter()
            for topic_counts in meta["fiducials"]["counts"].values():
                rejected.update(topic_counts.get("rejected", {}))
            if rejected:
                meta["rejected_at_read"] = dict(sorted(rejected.items()))
        if self.urdf:
            meta["robot_description"] = dict(self.urdf)
        timeline = Timeline(transforms=transforms, cameras=cameras, observations=observations,
                            joint_states=joints, points=points, depth_frames=depth, image_frames=images,
                            metadata=meta)
        self.notes.extend(stamp_notes(timeline))
        return timeline, self.notes

    def _transforms(self) -> TransformTable:
        """The log's edges, the chain's mounts and URDF joints (they win), the log's URDF (fills gaps)."""
        table = self.transforms.table(self.notes)
        described, bad = log_urdf_edges(self.urdf)
        self.notes.extend(bad)
        if not self.chain_edges and not described:
            return table
        table, notes = merge_static_edges(table, self.chain_edges, described)
        self.notes.extend(notes)
        return table

    def _cameras(self) -> CameraTable:
        """The log's camera models, with the calibration files' in place of theirs for the same frame."""
        table = self.cameras.table(self.notes)
        if not self.file_cameras:
            return table
        table, notes = merge_file_cameras(table, self.file_cameras)
        self.notes.extend(notes)
        return table

    def _add_fiducial_observations(self, cameras: CameraTable) -> CameraTable:
        """Fiducial detections as observation rows (tag PnP, projections) with the final camera models; the
        camera table, with a camera-less model for each camera whose 3D points needed no intrinsics."""
        for finder in self.marker_finders.values():
            self.notes.extend(finder.notes())
        if not len(self.fiducials):
            return cameras
        hint = ""
        if self.chain is not None and self.chain.calibration_sources():
            hint = "the chain's calibration gives no camera with this frame; add calibration: {file:, camera:, frame:}"
        resolved = resolve_fiducials(self.fiducials, cameras, calibration_hint=hint)
        self.notes.extend(resolved.notes)
        self._fiducials_resolved = (len(self.observations), resolved)
        k = int(resolved.stamp_ns.size)
        self.observations.extend(
            resolved.source.tolist(), id_text=[""] * k, stamp_ns=resolved.stamp_ns.tolist(),
            log_time_ns=resolved.log_time_ns.tolist(), frame=resolved.camera_frame.tolist(),
            uvd=np.column_stack([resolved.u, resolved.v, resolved.depth_m]).reshape(-1).tolist(),
            label=resolved.label.tolist(), score=resolved.score.tolist())
        cameras, notes = with_unprojected(cameras, resolved)
        self.notes.extend(notes)
        return cameras

    def _fiducial_metadata(self) -> dict[str, Any]:
        """Counts per topic and the corner side table, keyed by obs_id (JSON-ready)."""
        assert self._fiducials_resolved is not None
        first, resolved = self._fiducials_resolved
        side = dict(resolved.side)
        position = np.searchsorted(resolved.detection_index, np.asarray(side.pop("detection"), dtype=np.int64))
        ids = self._obs_ids[first + position] if self._obs_ids.size else np.zeros(0, dtype=np.int64)
        return {"counts": resolved.counts, "corners": {"obs_id": ids.tolist(), **side}}

    def _images(self, fetch: FrameFetch | None) -> ImageFrameTable:
        return image_table(self.image_frames, fetch) if len(self.image_frames) else ImageFrameTable.empty()

    def _depth(self, fetch: FrameFetch | None) -> DepthFrameTable:
        if not len(self.depth_frames):
            return DepthFrameTable.empty()
        self.settle_depth(final=True)
        return depth_table(self.depth_frames, fetch, self._scale_for, self.depth_keeper)

    def _scale_for(self, topic: str) -> float:
        for sensor, scale in self.depth_scale.items():
            if topic.startswith(sensor + "/"):
                return scale
        return 0.001


def _fiducial_rows(chain: ChainConfig | None) -> FiducialRows:
    """Fiducial rows sized as the chain says: tags by ``tag_size_m``, markers by their own size or that."""
    evidence = chain.evidence if chain else None
    tag_size = evidence.tag_size_m if evidence else None
    marker_size = evidence.markers.size_m if evidence and evidence.markers else None
    return FiducialRows(size_for_tag=tag_size_lookup(tag_size),
                        size_for_marker=tag_size_lookup(marker_size if marker_size is not None else tag_size))


