"""The collector every reader fills: per-message handlers append primitives to lists, then the
columnar tables are built once.

Handlers take decoded messages with attribute access (rosbags message classes for ROS 1 and
ROS 2, protobuf messages or JSON wrapped by :func:`wrap_json` for Foxglove schemas). They never
build a table per message: a TFMessage appends its frame names, stamps and seven floats per
transform, and :meth:`Collector.build` turns the lists into arrays.
"""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.messages.depth import DepthWindowKeeper, make_depth_loader
from framechain.adapters.messages.fiducials import (
    FiducialRows,
    ResolvedFiducials,
    resolve_fiducials,
    tag_size_lookup,
    with_unprojected,
)
from framechain.adapters.messages.images import image_metadata, make_image_loader
from framechain.adapters.messages.kinds import Kind
from framechain.adapters.messages.locator import FrameFetch, FrameLocator
from framechain.adapters.messages.realsense import extrinsic_edges, stream_frame
from framechain.adapters.robot.mounts import (
    FileCamera,
    StaticEdge,
    log_urdf_edges,
    merge_file_cameras,
    merge_static_edges,
)
from framechain.config.chain import ChainConfig
from framechain.timeline import (
    CameraTable,
    DepthFrameTable,
    ImageFrameTable,
    JointStateTable,
    ObservationTable,
    PointTable,
    Timeline,
    TransformTable,
    normalize_frames,
)
from framechain.timeline.tables import MAX_DISTORTION_COEFFS, QUATERNION_NORM_TOLERANCE

NS = 1_000_000_000
#: Header stamps further than this from log time are pointed out (sim time, another clock).
CLOCK_GAP_NOTE_S = 10.0


def ros_stamp_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` (ROS 1 and ROS 2 as rosbags decodes both) in nanoseconds."""
    return int(stamp.sec) * NS + int(stamp.nanosec)


def fox_stamp_ns(stamp: Any) -> int:
    """``google.protobuf.Timestamp`` (or Foxglove JSON ``{sec, nsec}`` wrapped) in nanoseconds."""
    return int(stamp.seconds) * NS + int(stamp.nanos)


class _Obj:
    """Attribute access over a JSON object (Foxglove JSON encoding)."""

    __slots__ = ("_d",)

    def __init__(self, d: Mapping[str, Any]) -> None:
        self._d = d

    def __getattr__(self, name: str) -> Any:
        try:
            return wrap_json(self._d[name])
        except KeyError:
            raise AttributeError(name) from None


class _JsonStamp:
    __slots__ = ("nanos", "seconds")

    def __init__(self, d: Mapping[str, Any]) -> None:
        self.seconds = int(d.get("sec", 0))
        self.nanos = int(d.get("nsec", 0))


def wrap_json(value: Any) -> Any:
    """JSON values with attribute access; ``{sec, nsec}`` become protobuf-like timestamps."""
    if isinstance(value, dict):
        if set(value) <= {"sec", "nsec"} and value:
            return _JsonStamp(value)
        return _Obj(value)
    if isinstance(value, list):
        return [wrap_json(v) for v in value]
    return value

#: Kinds whose messages become pixel observations (a depth frame's windows wait for them).
OBSERVATION_KINDS = frozenset({Kind.DETECTIONS, Kind.DETECTION, Kind.PIXEL_POINT})


class Collector:
    """Accumulates the rows of one log; :meth:`build` returns the Timeline and the notes."""

    def __init__(self, path: str, chain: ChainConfig | None = None) -> None:
        self.path = path
        self.chain = chain
        self.roles = chain.evidence_topics() if chain else {}
        #: Pose topics and the child frame their entry names (None: the message's, else the body frame).
        self.pose_children = {p.topic: p.child for p in chain.pose_topics()} if chain else {}
        #: Static edges and camera models the chain file adds (see framechain.adapters.robot.mounts).
        self.chain_edges: list[StaticEdge] = []
        self.file_cameras: list[FileCamera] = []
        self.notes: list[str] = []
        self.depth_from_pose: dict[str, int] = {}  # detections whose hypothesis pose carried a depth, by topic
        # fiducials (tags, markers in images, camera-frame points): resolved once the cameras are known
        evidence = chain.evidence if chain else None
        marker_size = evidence.markers.size_m if evidence and evidence.markers else None
        self.fiducials = FiducialRows(
            size_for_tag=tag_size_lookup(evidence.tag_size_m if evidence else None),
            size_for_marker=tag_size_lookup(marker_size if marker_size is not None else
                                            (evidence.tag_size_m if evidence else None)),
        )
        self.marker_finder: Any = None  # a markers.MarkerFinder, made when an image topic is read
        self._fiducials_resolved: tuple[int, ResolvedFiducials] | None = None
        self._obs_ids: npt.NDArray[np.int64] = np.zeros(0, dtype=np.int64)
        # transforms: per row
        self.tf_parent: list[str] = []
        self.tf_child: list[str] = []
        self.tf_stamp: list[int] = []
        self.tf_vals: list[float] = []
        # transforms: per message (row counts expand them)
        self.tf_msg_log: list[int] = []
        self.tf_msg_rows: list[int] = []
        self.tf_msg_static: list[bool] = []
        self.tf_msg_topic: list[str] = []
        self.tf_msg_kind: list[str] = []  # "tf" or "odometry" (odometry edges yield to /tf)
        # cameras
        self.cam_rows: list[tuple[str, int, int, int, int, str, str]] = []  # frame stamp log w h model topic
        self.cam_k: list[list[float]] = []
        self.cam_d: list[list[float]] = []
        # observations
        self.obs_id_text: list[str] = []
        self.obs_stamp: list[int] = []
        self.obs_log: list[int] = []
        self.obs_frame: list[str] = []
        self.obs_uvd: list[float] = []
        self.obs_label: list[str] = []
        self.obs_score: list[float] = []
        self.obs_topic: list[str] = []
        # joint states (long form)
        self.js_stamp: list[int] = []
        self.js_log: list[int] = []
        self.js_rows: list[int] = []
        self.js_topic: list[str] = []
        self.js_name: list[str] = []
        self.js_pos: list[npt.NDArray[np.float64]] = []
        self.js_vel: list[npt.NDArray[np.float64]] = []
        self.js_eff: list[npt.NDArray[np.float64]] = []
        # points
        self.pt_frame: list[str] = []
        self.pt_stamp: list[int] = []
        self.pt_log: list[int] = []
        self.pt_vals: list[float] = []  # x y z qx qy qz qw
        self.pt_topic: list[str] = []
        # depth frames
        self.depth_rows: list[tuple[str, int, int, int, int, str, str]] = []
        self.depth_loc: list[FrameLocator] = []
        self._depth_seen: Counter[tuple[str, int]] = Counter()
        self.depth_scale: dict[str, float] = {}
        self.depth_keeper = DepthWindowKeeper()
        self._kept_obs = 0  # observations handed to the keeper so far
        #: Set by a reader while it reads: decodes the detections it holds in batches (the keeper needs them).
        self.flush_observations: Callable[[], None] | None = None
        # camera images on topics.image (metadata; bytes are fetched when a sink shows them)
        self.image_rows: list[tuple[str, int, int, int, int, str, str]] = []
        self.image_loc: list[FrameLocator] = []
        self._image_seen: Counter[tuple[str, int]] = Counter()
        # robot descriptions and librealsense extrinsics
        self.urdf: dict[str, str] = {}
        self.rs_extrinsics: dict[str, tuple[float, ...]] = {}
        self.skipped: Counter[tuple[str, str]] = Counter()

    # -- TF -------------------------------------------------------------------------------
    def tf(self, topic: str, log_ns: int, msg: Any) -> None:
        """tf2_msgs/TFMessage or tf/tfMessage."""
        static = topic.rstrip("/").endswith("tf_static")
        n = 0
        parents, children, stamps, vals = self.tf_parent, self.tf_child, self.tf_stamp, self.tf_vals
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
        self._tf_message(topic, log_ns, n, static)

    def transform_stamped(self, topic: str, log_ns: int, msg: Any) -> None:
        """geometry_msgs/TransformStamped on its own topic: one edge sample."""
        self._edge(topic, log_ns, msg.header.frame_id, msg.child_frame_id, ros_stamp_ns(msg.header.stamp),
                   msg.transform.translation, msg.transform.rotation)

    def _edge(self, topic: str, log_ns: int, parent: str, child: str, stamp: int, tr: Any, q: Any,
              *, kind: str = "tf") -> None:
        self.tf_parent.append(parent)
        self.tf_child.append(child)
        self.tf_stamp.append(stamp)
        self.tf_vals.extend((tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w))
        self._tf_message(topic, log_ns, 1, topic.rstrip("/").endswith("tf_static"), kind=kind)

    def _tf_message(self, topic: str, log_ns: int, n: int, static: bool, *, kind: str = "tf") -> None:
        self.tf_msg_log.append(log_ns)
        self.tf_msg_rows.append(n)
        self.tf_msg_static.append(static)
        self.tf_msg_topic.append(topic)
        self.tf_msg_kind.append(kind)

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

    def _apply_realsense_layout(self) -> None:
        """Rename frames after their streams and turn the recorded extrinsics into static edges."""
        self.depth_rows = [((stream_frame(r[6]) or r[0]), *r[1:]) for r in self.depth_rows]
        self.cam_rows = [((stream_frame(r[6]) or r[0]), *r[1:]) for r in self.cam_rows]
        if not self.rs_extrinsics:
            return
        edges, note = extrinsic_edges(self.rs_extrinsics)
        for edge in edges:
            self.tf_parent.append(edge.parent)
            self.tf_child.append(edge.child)
            self.tf_stamp.append(edge.log_time_ns)
            self.tf_vals.extend(edge.values)
            self._tf_message(edge.topic, edge.log_time_ns, 1, True)
        self.notes.append(note)

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
        self.cam_rows.append((frame, stamp, log_ns, w, h, model, topic))
        self.cam_k.append([float(x) for x in k])
        self.cam_d.append([float(x) for x in d])

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
        self.obs_id_text.append(str(ident))
        self.obs_stamp.append(stamp)
        self.obs_log.append(log_ns)
        self.obs_frame.append(frame)
        self.obs_uvd.extend((u, v, depth))
        self.obs_label.append(label)
        self.obs_score.append(score)
        self.obs_topic.append(topic)

    def pixel_point(self, topic: str, log_ns: int, msg: Any) -> None:
        """geometry_msgs/PointStamped holding a pixel: x = u, y = v, z = depth in metres (0: none)."""
        p = msg.point
        z = float(p.z)
        self.obs_id_text.append("")
        self.obs_stamp.append(ros_stamp_ns(msg.header.stamp))
        self.obs_log.append(log_ns)
        self.obs_frame.append(msg.header.frame_id)
        self.obs_uvd.extend((p.x, p.y, z if math.isfinite(z) and z > 0 else math.nan))
        self.obs_label.append("")
        self.obs_score.append(math.nan)
        self.obs_topic.append(topic)

    def add_side_detections(self, rows: Mapping[str, npt.NDArray[Any]], source: str) -> None:
        """Detections from a side table (columns already checked by the caller)."""
        n = len(rows["stamp_ns"])
        self.obs_id_text.extend(str(x) for x in rows["obs_id"])
        self.obs_stamp.extend(int(x) for x in rows["stamp_ns"])
        self.obs_log.extend(int(x) for x in rows["stamp_ns"])
        self.obs_frame.extend(str(x) for x in rows["frame"])
        self.obs_uvd.extend(np.column_stack([rows["u"], rows["v"], rows["depth_m"]]).reshape(-1).tolist())
        self.obs_label.extend(str(x) for x in rows["label"])
        self.obs_score.extend(float(x) for x in rows["score"])
        self.obs_topic.extend([source] * n)

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
        self.pt_frame.append(h.frame_id)
        self.pt_stamp.append(ros_stamp_ns(h.stamp))
        self.pt_log.append(log_ns)
        self.pt_vals.extend(vals)
        self.pt_topic.append(topic)

    # -- joints, descriptions ---------------------------------------------------------------
    def joint_state(self, topic: str, log_ns: int, msg: Any) -> None:
        names = list(msg.name)
        n = len(names)
        self.js_stamp.append(ros_stamp_ns(msg.header.stamp))
        self.js_log.append(log_ns)
        self.js_rows.append(n)
        self.js_topic.append(topic)
        self.js_name.extend(names)
        self.js_pos.append(_fit(msg.position, n))
        self.js_vel.append(_fit(msg.velocity, n))
        self.js_eff.append(_fit(msg.effort, n))

    def urdf_text(self, topic: str, log_ns: int, msg: Any) -> None:
        self.urdf[topic] = str(msg.data)

    # -- depth --------------------------------------------------------------------------------
    def depth(self, topic: str, log_ns: int, msg: Any) -> None:
        """sensor_msgs/Image (16UC1, mono16, 32FC1) or CompressedImage (compressedDepth): metadata, and
        the raw pixels held briefly so the keeper cuts the windows detections need; the rest stays in the log."""
        from framechain.adapters.messages.depth import depth_metadata, raw_depth_pixels

        meta = depth_metadata(msg)
        if meta is None:
            encoding = getattr(msg, "encoding", getattr(msg, "format", "?"))
            self.skipped[(topic, f"encoding {encoding!r} is not depth")] += 1
            return
        width, height, encoding = meta
        stamp = ros_stamp_ns(msg.header.stamp)
        self.depth_rows.append((msg.header.frame_id, stamp, log_ns, width, height, encoding, topic))
        self.depth_loc.append(_locate(self._depth_seen, topic, log_ns))
        if encoding.startswith("compressedDepth"):
            return  # a PNG: only the whole frame decodes, so it is fetched when needed
        try:
            raw = raw_depth_pixels(msg)
        except ValueError:  # pixels shorter than the header says: the fetch reports it if a detection needs it
            return
        if self.depth_keeper.add_frame(len(self.depth_rows) - 1, msg.header.frame_id, stamp, log_ns, raw):
            self.settle_depth(final=False)

    def settle_depth(self, *, final: bool) -> None:
        """Hand the detections read since the last call to the depth keeper and let it cut windows."""
        if self.flush_observations is not None and not final:
            self.flush_observations()
        start, end = self._kept_obs, len(self.obs_stamp)
        if end > start:
            uvd = np.asarray(self.obs_uvd[3 * start : 3 * end], dtype=np.float64).reshape(-1, 3)
            self.depth_keeper.add_observations(self.obs_frame[start:end], self.obs_stamp[start:end],
                                               self.obs_log[start:end], uvd[:, 0], uvd[:, 1])
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
        self.image_rows.append((msg.header.frame_id, ros_stamp_ns(msg.header.stamp), log_ns, width, height,
                                encoding, topic))
        self.image_loc.append(_locate(self._image_seen, topic, log_ns))

    def _images(self, fetch: FrameFetch | None) -> ImageFrameTable:
        if not self.image_rows:
            return ImageFrameTable.empty()
        n = len(self.image_rows)
        table = ImageFrameTable(**_frame_columns(self.image_rows), video_path=np.full(n, ""),
                                video_time_ns=np.zeros(n, dtype=np.int64))
        order = _canonical(table.log_time_ns, table.source)
        locators = [self.image_loc[i] for i in order.tolist()]
        encodings = [str(e) for e in table.encoding[order]]
        loader = make_image_loader(fetch, locators, encodings) if fetch is not None else None
        return replace(table.take(order), loader=loader)

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
        if kind == Kind.MARKER_IMAGE and self.chain is not None and self.chain.evidence.markers is not None:
            if self.marker_finder is None:  # here, not per message: a bad dictionary is one error
                from framechain.adapters.messages.markers import MarkerFinder

                self.marker_finder = MarkerFinder(self.chain.evidence.markers.dictionary, f)
            find: Callable[[str, int, Any], None] = self.marker_finder.image

            def handle(topic: str, log_ns: int, msg: Any) -> None:  # searched for markers, and shown
                find(topic, log_ns, msg)
                self.image(topic, log_ns, msg)

            return handle
        return table.get(kind)

    # -- build ------------------------------------------------------------------------------------
    def build(self, fetch: FrameFetch | None, metadata: Mapping[str, Any]) -> tuple[Timeline, list[str]]:
        """The Timeline (every table in log-time order, ties by topic then file order) and notes."""
        realsense = bool(self.rs_extrinsics) or any("/device_" in r[6] for r in self.depth_rows)
        if realsense:
            self._apply_realsense_layout()
        for (topic, what), count in sorted(self.skipped.items()):
            self.notes.append(f"topic {topic}: {what} ({count} message{'s' if count != 1 else ''})")
        for topic, count in sorted(self.depth_from_pose.items()):
            self.notes.append(
                f"topic {topic}: {count} detections carry a depth in results[0].pose.pose.position.z; it is used as "
                "the z-depth in the camera frame instead of sampling the depth image"
            )
        transforms = self._transforms_with_additions()
        cameras = self._cameras()
        cameras = self._add_fiducial_observations(cameras)
        observations = self._observations()
        points = self._points()
        joints = self._joints()
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
        if not self.tf_msg_rows:
            return TransformTable.empty()
        rows = np.asarray(self.tf_msg_rows, dtype=np.int64)
        vals = np.asarray(self.tf_vals, dtype=np.float64).reshape(-1, 7)
        parent = normalize_frames(self.tf_parent)
        child = normalize_frames(self.tf_child)
        stamp = np.asarray(self.tf_stamp, dtype=np.int64)
        log = np.repeat(np.asarray(self.tf_msg_log, dtype=np.int64), rows)
        static = np.repeat(np.asarray(self.tf_msg_static, dtype=bool), rows)
        topic = np.repeat(np.asarray(self.tf_msg_topic, dtype=str), rows)
        kind = np.repeat(np.asarray(self.tf_msg_kind, dtype=str), rows)
        keep = np.ones(stamp.size, dtype=bool)
        # Odometry carries an edge only where /tf does not.
        odom = kind == "odometry"
        if odom.any():
            tf_children = set(child[~odom].tolist())
            dup = odom & np.isin(child, list(tf_children))
            for t in np.unique(topic[dup]).tolist():
                sel = dup & (topic == t)
                self.notes.append(
                    f"topic {t}: odometry edge {parent[sel][0]} -> {child[sel][0]} is also on /tf; "
                    "the /tf samples are used"
                )
            keep &= ~dup
            # Two odometry topics for one child: keep the one with most samples.
            sel_odom = odom & keep
            owners: dict[str, str] = {}
            for c in np.unique(child[sel_odom]).tolist():
                ts, counts = np.unique(topic[sel_odom & (child == c)], return_counts=True)
                owners[c] = str(ts[np.argmax(counts)])
                for other in ts.tolist():
                    if other != owners[c]:
                        self.notes.append(
                            f"topic {other}: odometry for {c!r} also comes from {owners[c]}; {owners[c]} is used"
                        )
            for c, t in owners.items():
                keep &= ~(sel_odom & (child == c) & (topic != t))
        finite = np.isfinite(vals).all(axis=1)
        norm = np.linalg.norm(vals[:, 3:], axis=1)
        unit = np.abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE
        for mask, what in ((~finite, "translation or rotation NaN or Inf"),
                           (finite & ~unit, "quaternion not unit length")):
            bad = mask & keep
            if bad.any():
                for (t, p, c), count in Counter(zip(topic[bad].tolist(), parent[bad].tolist(), child[bad].tolist(),
                                                    strict=True)).items():
                    first = int(stamp[bad & (topic == t) & (parent == p) & (child == c)][0])
                    self.notes.append(
                        f"topic {t}: {count} transform{'s' if count != 1 else ''} {p} -> {c} with {what} dropped "
                        f"(first at stamp {first * 1e-9:.9f} s)"
                    )
                keep &= ~mask
        table = TransformTable(parent=parent[keep], child=child[keep], stamp_ns=stamp[keep], log_time_ns=log[keep],
                               translation=vals[keep, :3], quat_xyzw=vals[keep, 3:], is_static=static[keep],
                               source=topic[keep])
        self._note_backwards(table)
        return table.take(_canonical(table.log_time_ns, table.source))

    def _transforms_with_additions(self) -> TransformTable:
        """The log's edges, the chain's mounts and URDF joints (they win), the log's URDF (fills gaps)."""
        table = self._transforms()
        described, bad = log_urdf_edges(self.urdf)
        self.notes.extend(bad)
        if not self.chain_edges and not described:
            return table
        table, notes = merge_static_edges(table, self.chain_edges, described)
        self.notes.extend(notes)
        return table

    def _note_backwards(self, table: TransformTable) -> None:
        dyn = ~table.is_static
        if not dyn.any():
            return
        key = np.char.add(np.char.add(table.parent[dyn], "\x1f"), table.child[dyn])
        order = np.lexsort((table.log_time_ns[dyn], key))
        k, s = key[order], table.stamp_ns[dyn][order]
        back = (k[1:] == k[:-1]) & (s[1:] < s[:-1])
        if back.any():
            for name, count in Counter(k[1:][back].tolist()).items():
                p, _, c = name.partition("\x1f")  # a damaged log's names may hold the separator
                self.notes.append(
                    f"edge {p} -> {c}: header stamps go backwards {count} time{'s' if count != 1 else ''} "
                    "in log order; "
                    "samples are ordered by stamp for lookups"
                )

    def _cameras(self) -> CameraTable:
        """The log's camera models, with the calibration files' in place of theirs for the same frame."""
        table = self._log_cameras()
        if not self.file_cameras:
            return table
        table, notes = merge_file_cameras(table, self.file_cameras)
        self.notes.extend(notes)
        return table

    def _log_cameras(self) -> CameraTable:
        if not self.cam_rows:
            return CameraTable.empty()
        frame, stamp, log, w, h, model, topic = (list(c) for c in zip(*self.cam_rows, strict=True))
        kk = np.array([k if len(k) == 9 else [0.0] * 9 for k in self.cam_k], dtype=np.float64).reshape(-1, 3, 3)
        n_d = np.array([min(len(d), MAX_DISTORTION_COEFFS) for d in self.cam_d], dtype=np.int64)
        dist = np.zeros((len(self.cam_d), MAX_DISTORTION_COEFFS))
        for i, d in enumerate(self.cam_d):
            dist[i, : n_d[i]] = d[:MAX_DISTORTION_COEFFS]
        usable = np.isfinite(kk).all(axis=(1, 2)) & kk.any(axis=(1, 2)) & (kk[:, 0, 0] > 0) & (kk[:, 1, 1] > 0)
        topics = np.asarray(topic, dtype=str)
        if not usable.all():
            for t, count in Counter(topics[~usable].tolist()).items():
                self.notes.append(
                    f"topic {t}: {count} CameraInfo with K all zero or focal lengths not positive "
                    "(an uncalibrated camera) dropped"
                )
        models = np.asarray([_distortion_model_name(m) for m in model], dtype=str)
        table = CameraTable(frame=np.asarray(frame, dtype=str), stamp_ns=np.asarray(stamp, dtype=np.int64),
                            log_time_ns=np.asarray(log, dtype=np.int64), width=np.asarray(w, dtype=np.int64),
                            height=np.asarray(h, dtype=np.int64), K=np.where(usable[:, None, None], kk, np.eye(3)),
                            distortion_model=models, distortion=dist, n_distortion=n_d, source=topics).take(usable)
        return table.take(_canonical(table.log_time_ns, table.source))

    def _observations(self) -> ObservationTable:
        n = len(self.obs_stamp)
        if n == 0:
            return ObservationTable.empty()
        ids = np.full(n, -1, dtype=np.int64)
        numeric = np.array([t.strip().lstrip("-").isdigit() for t in self.obs_id_text])
        if numeric.any():
            ids[numeric] = [int(t) for t, ok in zip(self.obs_id_text, numeric, strict=True) if ok]
        if np.unique(ids[numeric]).size != int(numeric.sum()):
            self.notes.append(
                "detection ids repeat (tracking ids?); observations are numbered in log order instead"
            )
            numeric[:] = False
        start = int(ids[numeric].max()) + 1 if numeric.any() else 0
        ids[~numeric] = np.arange(start, start + int((~numeric).sum()))
        self._obs_ids = ids.copy()  # in append order: the fiducial side table refers to them
        uvd = np.asarray(self.obs_uvd, dtype=np.float64).reshape(-1, 3)
        table = ObservationTable(
            obs_id=ids, stamp_ns=np.asarray(self.obs_stamp, dtype=np.int64),
            log_time_ns=np.asarray(self.obs_log, dtype=np.int64), camera_frame=np.asarray(self.obs_frame, dtype=str),
            u=uvd[:, 0], v=uvd[:, 1], depth_m=uvd[:, 2], label=np.asarray(self.obs_label, dtype=str),
            score=np.asarray(self.obs_score, dtype=np.float64), source=np.asarray(self.obs_topic, dtype=str),
        )
        return table.take(_canonical(table.log_time_ns, table.source))

    def _add_fiducial_observations(self, cameras: CameraTable) -> CameraTable:
        """Fiducial detections as observation rows (tag PnP, projections) with the final camera models; the
        camera table, with a camera-less model for each camera whose 3D points needed no intrinsics."""
        if self.marker_finder is not None:
            self.notes.extend(self.marker_finder.notes())
        if not len(self.fiducials):
            return cameras
        hint = ""
        if self.chain is not None and self.chain.calibration:
            hint = "the chain's calibration gives no camera with this frame; add calibration: {file:, camera:, frame:}"
        resolved = resolve_fiducials(self.fiducials, cameras, calibration_hint=hint)
        self.notes.extend(resolved.notes)
        self._fiducials_resolved = (len(self.obs_stamp), resolved)
        k = int(resolved.stamp_ns.size)
        self.obs_id_text.extend([""] * k)
        self.obs_stamp.extend(resolved.stamp_ns.tolist())
        self.obs_log.extend(resolved.log_time_ns.tolist())
        self.obs_frame.extend(resolved.camera_frame.tolist())
        self.obs_uvd.extend(np.column_stack([resolved.u, resolved.v, resolved.depth_m]).reshape(-1).tolist())
        self.obs_label.extend(resolved.label.tolist())
        self.obs_score.extend(resolved.score.tolist())
        self.obs_topic.extend(resolved.source.tolist())
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

    def _points(self) -> PointTable:
        n = len(self.pt_stamp)
        if n == 0:
            return PointTable.empty()
        vals = np.asarray(self.pt_vals, dtype=np.float64).reshape(-1, 7)
        topics = np.asarray(self.pt_topic, dtype=str)
        roles = np.asarray([self.roles.get(t, "reference") for t in self.pt_topic], dtype=str)
        table = PointTable(frame=np.asarray(self.pt_frame, dtype=str),
                           stamp_ns=np.asarray(self.pt_stamp, dtype=np.int64),
                           log_time_ns=np.asarray(self.pt_log, dtype=np.int64), xyz=vals[:, :3], quat_xyzw=vals[:, 3:],
                           role=roles, obs_id=np.full(n, -1, dtype=np.int64), source=topics)
        return table.take(_canonical(table.log_time_ns, table.source))

    def _joints(self) -> JointStateTable:
        if not self.js_rows:
            return JointStateTable.empty()
        rows = np.asarray(self.js_rows, dtype=np.int64)
        table = JointStateTable(
            stamp_ns=np.repeat(np.asarray(self.js_stamp, dtype=np.int64), rows),
            log_time_ns=np.repeat(np.asarray(self.js_log, dtype=np.int64), rows),
            joint=np.asarray(self.js_name, dtype=str),
            position=np.concatenate(self.js_pos), velocity=np.concatenate(self.js_vel),
            effort=np.concatenate(self.js_eff), source=np.repeat(np.asarray(self.js_topic, dtype=str), rows),
        )
        return table.take(_canonical(table.log_time_ns, table.source))

    def _depth(self, fetch: FrameFetch | None) -> DepthFrameTable:
        if not self.depth_rows:
            return DepthFrameTable.empty()
        table = DepthFrameTable(**_frame_columns(self.depth_rows))
        order = _canonical(table.log_time_ns, table.source)
        locators = [self.depth_loc[i] for i in order.tolist()]
        scales = [self._scale_for(loc.topic) for loc in locators]
        loader = make_depth_loader(fetch, locators, scales) if fetch is not None else None
        self.settle_depth(final=True)
        windows = self.depth_keeper.lookup(order.tolist(), scales) if fetch is not None else None
        return replace(table.take(order), loader=loader, windows=windows)

    def _scale_for(self, topic: str) -> float:
        for sensor, scale in self.depth_scale.items():
            if topic.startswith(sensor + "/"):
                return scale
        return 0.001


def _locate(seen: Counter[tuple[str, int]], topic: str, log_ns: int) -> FrameLocator:
    """The locator of the next frame on ``topic`` at ``log_ns`` (its rank among equal log times)."""
    ordinal = seen[(topic, log_ns)]
    seen[(topic, log_ns)] += 1
    return FrameLocator(topic, log_ns, ordinal)


def _frame_columns(rows: list[tuple[str, int, int, int, int, str, str]]) -> dict[str, Any]:
    """The columns shared by depth and image frame tables, from their metadata rows."""
    frame, stamp, log, w, h, enc, topic = (list(c) for c in zip(*rows, strict=True))
    return {"frame": np.asarray(frame, dtype=str), "stamp_ns": np.asarray(stamp, dtype=np.int64),
            "log_time_ns": np.asarray(log, dtype=np.int64), "width": np.asarray(w, dtype=np.int64),
            "height": np.asarray(h, dtype=np.int64), "encoding": np.asarray(enc, dtype=str),
            "source": np.asarray(topic, dtype=str)}


def _fit(values: Any, n: int) -> npt.NDArray[np.float64]:
    arr = np.asarray(values, dtype=np.float64).reshape(-1)
    if arr.size == n:
        return arr
    out = np.full(n, np.nan)
    out[: min(arr.size, n)] = arr[:n]
    return out


def _canonical(log_time_ns: npt.NDArray[np.int64], source: npt.NDArray[np.str_]) -> npt.NDArray[np.intp]:
    """Stable order by log time, then topic; file order within a topic is kept."""
    return np.lexsort((source, log_time_ns))


def _distortion_model_name(model: str) -> str:
    """ROS names; librealsense's "Brown Conrady" is plumb_bob, empty is none."""
    low = model.strip().lower()
    if not low:
        return "none"
    if low in ("brown conrady", "brown_conrady", "modified brown conrady"):
        return "plumb_bob"
    if low in ("kannala_brandt", "fisheye", "equidistant"):
        return "equidistant"
    return model.strip()


def stamp_notes(timeline: Timeline) -> list[str]:
    """Point out topics whose header stamps are in another clock than their log times."""
    notes: list[str] = []
    per_topic: dict[str, list[npt.NDArray[np.int64]]] = defaultdict(list)
    tables: list[tuple[Any, npt.NDArray[np.bool_] | None]] = [
        (timeline.transforms, ~timeline.transforms.is_static), (timeline.cameras, None),
        (timeline.observations, None), (timeline.joint_states, None), (timeline.points, None),
        (timeline.depth_frames, None),
    ]
    for table, mask in tables:
        if not len(table):
            continue
        sel = np.ones(len(table), dtype=bool) if mask is None else mask
        for t in np.unique(table.source[sel]).tolist():
            rows = sel & (table.source == t)
            per_topic[t].append(np.stack([table.stamp_ns[rows], table.log_time_ns[rows]]))
    for topic, parts in sorted(per_topic.items()):
        both = np.concatenate(parts, axis=1)
        stamps, logs = both[0], both[1]
        gap_s = float(np.median(logs - stamps)) * 1e-9
        if abs(gap_s) <= CLOCK_GAP_NOTE_S or topic.endswith(".csv") or topic.endswith(".parquet"):
            continue
        stamp_s, log_s = float(np.median(stamps)) * 1e-9, float(np.median(logs)) * 1e-9
        if stamp_s < 1e8 <= log_s:
            notes.append(
                f"topic {topic}: header stamps are simulation time (about {stamp_s:.1f} s) while log times are wall "
                f"clock ({log_s:.0f} s since the epoch); lookups use the header stamps, never the log times"
            )
        elif log_s < 1e8 <= stamp_s:
            notes.append(
                f"topic {topic}: log times start near zero ({log_s:.3f} s) while header stamps are wall clock "
                f"({stamp_s:.0f} s since the epoch); lookups use the header stamps"
            )
        else:
            side = "behind" if gap_s > 0 else "ahead of"
            notes.append(
                f"topic {topic}: header stamps run {abs(gap_s):.1f} s {side} log time (another clock or a late "
                "recorder); lookups use the header stamps"
            )
    return notes
