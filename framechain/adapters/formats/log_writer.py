"""``write_log``: a Timeline written back as a robot log with the real writers.

Containers: ``mcap-ros2`` (mcap_ros2's writer), ``mcap-ros1`` (mcap_ros1's writer), ``rosbag1``,
``rosbag2-sqlite`` and ``rosbag2-mcap`` (rosbags' writers). Messages are built as rosbags message
objects and serialised by rosbags (CDR or ROS 1), so every container carries the same bytes of
meaning. Mapping, table by table:

- transforms -> ``/tf`` and ``/tf_static`` (tf2_msgs/TFMessage), consecutive rows with equal
  stamp, log time and static flag in one message;
- cameras -> sensor_msgs/CameraInfo on ``chain.topics.camera_info``;
- observations -> vision_msgs/Detection2DArray on ``chain.topics.detections`` (ROS 2 layout,
  ``bbox.center.position``; ``Detection2D.id = str(obs_id)``; label and score in
  ``results[0].hypothesis``; a known depth in ``results[0].pose.pose.position.z``), consecutive
  rows with equal stamp, log time and camera frame in one message;
- depth_frames -> sensor_msgs/Image on ``chain.topics.depth``, 16UC1 millimetres or 32FC1 metres;
- points -> geometry_msgs/PointStamped (PoseStamped when every row of the topic has a rotation)
  on the evidence topic of each role;
- joint_states -> sensor_msgs/JointState on ``/joint_states``;
- ``metadata["robot_description"]`` -> std_msgs/String per topic.

Each message's log time is the table's ``log_time_ns``; messages are written in log-time order
(ties: by topic, then row order), the order :func:`open_log` returns rows in.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.errors import AdapterError
from framechain.adapters.formats.mcap.writer import write_mcap_ros1, write_mcap_ros2
from framechain.adapters.formats.msgdefs import OutMessage, typestore
from framechain.adapters.formats.rosbag.writer import write_rosbag1, write_rosbag2
from framechain.config.chain import ChainConfig
from framechain.timeline import PointTable, Timeline

CONTAINERS = ("mcap-ros2", "mcap-ros1", "rosbag1", "rosbag2-sqlite", "rosbag2-mcap")
DEFAULT_TOPICS = {
    "camera_info": "/camera/camera_info", "detections": "/detections", "depth": "/camera/depth/image_raw",
    "image": "/camera/color/image_raw",
}
NS = 1_000_000_000


def canonical_order(timeline: Timeline) -> Timeline:
    """Every table in the order :func:`open_log` returns rows: log time, then topic, then row order."""
    changes: dict[str, Any] = {}
    for name in ("transforms", "cameras", "observations", "joint_states", "points", "depth_frames", "image_frames"):
        table: Any = getattr(timeline, name)
        changes[name] = table.take(np.lexsort((table.source, table.log_time_ns))) if len(table) else table
    return timeline.replace(**changes)


def _groups(keys: list[npt.NDArray[Any]]) -> list[npt.NDArray[np.intp]]:
    """Runs of consecutive rows with equal keys."""
    n = keys[0].shape[0]
    if n == 0:
        return []
    change = np.zeros(n, dtype=bool)
    change[0] = True
    for k in keys:
        change[1:] |= k[1:] != k[:-1]
    starts = np.flatnonzero(change)
    return np.split(np.arange(n), starts[1:])


class _Builder:
    """rosbags message objects for one ROS version."""

    def __init__(self, ros1: bool) -> None:
        self.ros1 = ros1
        self.ts = typestore(ros1=ros1)
        self.T = self.ts.types
        self.seq = 0

    def time(self, ns: int) -> Any:
        sec, nsec = divmod(int(ns), NS)
        return self.T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)

    def header(self, stamp_ns: int, frame: str) -> Any:
        H = self.T["std_msgs/msg/Header"]
        if self.ros1:
            self.seq += 1
            return H(seq=self.seq, stamp=self.time(stamp_ns), frame_id=frame)
        return H(stamp=self.time(stamp_ns), frame_id=frame)

    def vec(self, x: float, y: float, z: float) -> Any:
        return self.T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    def point(self, x: float, y: float, z: float) -> Any:
        return self.T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))

    def quat(self, q: npt.NDArray[np.float64]) -> Any:
        return self.T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def tf_message(self, rows: list[tuple[str, str, int, npt.NDArray[np.float64], npt.NDArray[np.float64]]]) -> Any:
        T = self.T
        out = []
        for parent, child, stamp, t, q in rows:
            out.append(T["geometry_msgs/msg/TransformStamped"](
                header=self.header(stamp, parent), child_frame_id=child,
                transform=T["geometry_msgs/msg/Transform"](translation=self.vec(*t), rotation=self.quat(q)),
            ))
        return T["tf2_msgs/msg/TFMessage"](transforms=out)

    def camera_info(self, frame: str, stamp: int, w: int, h: int, K: npt.NDArray[np.float64], model: str,
                    d: npt.NDArray[np.float64]) -> Any:
        k = np.asarray(K, dtype=np.float64).reshape(9)
        r = np.eye(3).reshape(9)
        p = np.zeros((3, 4))
        p[:, :3] = np.asarray(K).reshape(3, 3)
        roi = self.T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        fields: dict[str, Any] = {"header": self.header(stamp, frame), "height": int(h), "width": int(w),
                                  "distortion_model": "" if model == "none" else model,
                                  "binning_x": 0, "binning_y": 0, "roi": roi}
        if self.ros1:
            fields.update(D=np.asarray(d, dtype=np.float64), K=k, R=r, P=p.reshape(12))
        else:
            fields.update(d=np.asarray(d, dtype=np.float64), k=k, r=r, p=p.reshape(12))
        return self.T["sensor_msgs/msg/CameraInfo"](**fields)

    def detections(self, stamp: int, frame: str, rows: list[tuple[int, float, float, float, str, float]]) -> Any:
        T = self.T
        dets = []
        for obs_id, u, v, depth, label, score in rows:
            results = []
            if label or not math.isnan(score) or not math.isnan(depth):
                pose = T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=T["geometry_msgs/msg/Pose"](
                        position=self.point(0.0, 0.0, depth if math.isfinite(depth) else 0.0),
                        orientation=self.quat(np.array([0.0, 0.0, 0.0, 1.0])),
                    ),
                    covariance=np.zeros(36),
                )
                results.append(T["vision_msgs/msg/ObjectHypothesisWithPose"](
                    hypothesis=T["vision_msgs/msg/ObjectHypothesis"](class_id=label, score=float(score)), pose=pose,
                ))
            bbox = T["vision_msgs/msg/BoundingBox2D"](
                center=T["vision_msgs/msg/Pose2D"](position=T["vision_msgs/msg/Point2D"](x=float(u), y=float(v)),
                                                   theta=0.0),
                size_x=0.0, size_y=0.0,
            )
            dets.append(T["vision_msgs/msg/Detection2D"](header=self.header(stamp, frame), results=results,
                                                         bbox=bbox, id=str(obs_id)))
        return T["vision_msgs/msg/Detection2DArray"](header=self.header(stamp, frame), detections=dets)

    def image(self, frame: str, stamp: int, depth_m: npt.NDArray[np.float32], encoding: str) -> Any:
        h, w = depth_m.shape
        if encoding == "16UC1":
            mm = np.where(np.isfinite(depth_m) & (depth_m > 0), np.rint(depth_m.astype(np.float64) * 1000.0), 0)
            data = np.clip(mm, 0, 65535).astype("<u2")
            step = w * 2
        elif encoding == "32FC1":
            data = np.asarray(depth_m, dtype="<f4")
            step = w * 4
        else:
            raise AdapterError("write_log", f"depth encoding {encoding!r} is not 16UC1 or 32FC1")
        return self.T["sensor_msgs/msg/Image"](
            header=self.header(stamp, frame), height=int(h), width=int(w), encoding=encoding, is_bigendian=0,
            step=step, data=np.frombuffer(data.tobytes(), dtype=np.uint8),
        )

    def camera_image(self, frame: str, stamp: int, w: int, h: int, encoding: str, data: bytes) -> Any:
        """A raw image (packed rows, little-endian) as sensor_msgs/Image, JPEG/PNG as CompressedImage."""
        from framechain.timeline.frames import RAW_IMAGE_ENCODINGS

        payload = np.frombuffer(data, dtype=np.uint8)
        if encoding in RAW_IMAGE_ENCODINGS:
            channels, dtype = RAW_IMAGE_ENCODINGS[encoding]
            return self.T["sensor_msgs/msg/Image"](
                header=self.header(stamp, frame), height=h, width=w, encoding=encoding, is_bigendian=0,
                step=w * channels * np.dtype(dtype).itemsize, data=payload,
            )
        return self.T["sensor_msgs/msg/CompressedImage"](header=self.header(stamp, frame), format=encoding,
                                                          data=payload)

    def point_stamped(self, frame: str, stamp: int, xyz: npt.NDArray[np.float64]) -> Any:
        return self.T["geometry_msgs/msg/PointStamped"](header=self.header(stamp, frame), point=self.point(*xyz))

    def pose_stamped(self, frame: str, stamp: int, xyz: npt.NDArray[np.float64], q: npt.NDArray[np.float64]) -> Any:
        T = self.T
        return T["geometry_msgs/msg/PoseStamped"](
            header=self.header(stamp, frame), pose=T["geometry_msgs/msg/Pose"](position=self.point(*xyz),
                                                                              orientation=self.quat(q)),
        )

    def joint_state(self, stamp: int, names: list[str], pos: npt.NDArray[np.float64], vel: npt.NDArray[np.float64],
                    eff: npt.NDArray[np.float64]) -> Any:
        def arr(a: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            return np.zeros(0) if np.isnan(a).all() else np.asarray(a, dtype=np.float64)

        return self.T["sensor_msgs/msg/JointState"](header=self.header(stamp, ""), name=names,
                                                     position=np.asarray(pos, dtype=np.float64), velocity=arr(vel),
                                                     effort=arr(eff))

    def string(self, text: str) -> Any:
        return self.T["std_msgs/msg/String"](data=text)


def _messages(timeline: Timeline, chain: ChainConfig, b: _Builder, depth_encoding: str) -> list[OutMessage]:
    out: list[OutMessage] = []
    tf = timeline.transforms
    for g in _groups([tf.stamp_ns, tf.log_time_ns, tf.is_static]):
        tf_rows = [(str(tf.parent[i]), str(tf.child[i]), int(tf.stamp_ns[i]), tf.translation[i], tf.quat_xyzw[i])
                   for i in g.tolist()]
        topic = "/tf_static" if bool(tf.is_static[g[0]]) else "/tf"
        out.append(OutMessage(int(tf.log_time_ns[g[0]]), topic, "tf2_msgs/msg/TFMessage", b.tf_message(tf_rows)))
    cams = timeline.cameras
    cam_topic = chain.topics.camera_info or DEFAULT_TOPICS["camera_info"]
    for i in range(len(cams)):
        msg = b.camera_info(str(cams.frame[i]), int(cams.stamp_ns[i]), int(cams.width[i]), int(cams.height[i]),
                            cams.K[i], str(cams.distortion_model[i]), cams.distortion[i, : int(cams.n_distortion[i])])
        out.append(OutMessage(int(cams.log_time_ns[i]), cam_topic, "sensor_msgs/msg/CameraInfo", msg))
    obs = timeline.observations
    det_topic = chain.topics.detections or DEFAULT_TOPICS["detections"]
    for g in _groups([obs.stamp_ns, obs.log_time_ns, obs.camera_frame]):
        det_rows = [(int(obs.obs_id[i]), float(obs.u[i]), float(obs.v[i]), float(obs.depth_m[i]),
                     str(obs.label[i]), float(obs.score[i])) for i in g.tolist()]
        i0 = int(g[0])
        out.append(OutMessage(int(obs.log_time_ns[i0]), det_topic, "vision_msgs/msg/Detection2DArray",
                        b.detections(int(obs.stamp_ns[i0]), str(obs.camera_frame[i0]), det_rows)))
    depth = timeline.depth_frames
    depth_topic = chain.topics.depth or DEFAULT_TOPICS["depth"]
    for i in range(len(depth)):
        image = np.asarray(depth.load(i), dtype=np.float32)
        out.append(OutMessage(int(depth.log_time_ns[i]), depth_topic, "sensor_msgs/msg/Image",
                        b.image(str(depth.frame[i]), int(depth.stamp_ns[i]), image, depth_encoding)))
    images = timeline.image_frames
    image_topic = chain.topics.image or DEFAULT_TOPICS["image"]
    for i in np.flatnonzero(images.encoding != "video").tolist():
        kind = "sensor_msgs/msg/CompressedImage" if images.encoding[i] in ("jpeg", "png") else "sensor_msgs/msg/Image"
        out.append(OutMessage(int(images.log_time_ns[i]), image_topic, kind,
                        b.camera_image(str(images.frame[i]), int(images.stamp_ns[i]), int(images.width[i]),
                                       int(images.height[i]), str(images.encoding[i]), images.load(i))))
    if len(timeline.points):
        out.extend(_point_messages(timeline.points, chain, b))
    js = timeline.joint_states
    for g in _groups([js.stamp_ns, js.log_time_ns, js.source]):
        i0 = int(g[0])
        out.append(OutMessage(int(js.log_time_ns[i0]), "/joint_states", "sensor_msgs/msg/JointState",
                        b.joint_state(int(js.stamp_ns[i0]), [str(j) for j in js.joint[g]], js.position[g],
                                      js.velocity[g], js.effort[g])))
    descriptions = timeline.metadata.get("robot_description") or {}
    first = min((o.log_time_ns for o in out), default=0)
    for topic, text in sorted(dict(descriptions).items()):
        out.append(OutMessage(first, str(topic), "std_msgs/msg/String", b.string(str(text))))
    order = sorted(range(len(out)), key=lambda k: (out[k].log_time_ns, out[k].topic, k))
    return [out[k] for k in order]


def _point_messages(pts: PointTable, chain: ChainConfig, b: _Builder) -> list[OutMessage]:
    """The logged points on their evidence topics (by role): PoseStamped where a topic's points all have an
    orientation, PointStamped otherwise."""
    out: list[OutMessage] = []
    by_role = {role: topic for topic, role in chain.evidence_topics().items()}
    topics = np.array([by_role.get(str(r), "") for r in pts.role.tolist()], dtype=object)
    missing = sorted({str(r) for r, t in zip(pts.role.tolist(), topics.tolist(), strict=True) if not t})
    if missing:
        raise AdapterError("write_log", f"points with roles {missing} have no evidence topic in the chain")
    for topic in sorted(set(topics.tolist())):
        sel = np.flatnonzero(topics == topic)
        posed = bool(np.isfinite(pts.quat_xyzw[sel]).all())
        for i in sel.tolist():
            if posed:
                msg = b.pose_stamped(str(pts.frame[i]), int(pts.stamp_ns[i]), pts.xyz[i], pts.quat_xyzw[i])
                kind = "geometry_msgs/msg/PoseStamped"
            else:
                msg = b.point_stamped(str(pts.frame[i]), int(pts.stamp_ns[i]), pts.xyz[i])
                kind = "geometry_msgs/msg/PointStamped"
            out.append(OutMessage(int(pts.log_time_ns[i]), topic, kind, msg))
    return out


def write_log(
    timeline: Timeline,
    path: str | Path,
    *,
    container: str,
    chain: ChainConfig,
    depth_encoding: str = "16UC1",
    compression: str | None = None,
) -> Path:
    """Write ``timeline`` as a log in ``container``; returns the path written (file or bag directory).

    ``compression``: ``bz2``/``lz4`` chunks for ``rosbag1``; ``zstd-file``/``zstd-message`` for the
    rosbag2 containers; MCAP files are always written with zstd chunks.
    """
    if container not in CONTAINERS:
        raise AdapterError(str(path), f"unknown container {container!r}; expected one of {', '.join(CONTAINERS)}")
    if depth_encoding not in ("16UC1", "32FC1"):
        raise AdapterError(str(path), f"depth_encoding must be 16UC1 or 32FC1, not {depth_encoding!r}")
    target = Path(path)
    if target.exists():
        raise AdapterError(target, "exists already; write_log never overwrites")
    ros1 = container in ("mcap-ros1", "rosbag1")
    b = _Builder(ros1)
    messages = _messages(canonical_order(timeline), chain, b, depth_encoding)
    if container == "mcap-ros2":
        write_mcap_ros2(target, messages, b.ts)
    elif container == "mcap-ros1":
        write_mcap_ros1(target, messages, b.ts)
    elif container == "rosbag1":
        write_rosbag1(target, messages, b.ts, compression)
    else:
        write_rosbag2(target, messages, b.ts, compression, mcap=container == "rosbag2-mcap")
    return target
