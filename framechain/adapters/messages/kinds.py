"""Message kinds framechain understands, and which topics of a log feed which table."""

from __future__ import annotations

from collections.abc import Mapping
from enum import StrEnum

from framechain.config.chain import ChainConfig


class Kind(StrEnum):
    """What a topic's messages become in the Timeline."""

    TF = "tf"  # tf2_msgs/TFMessage, tf/tfMessage, foxglove.FrameTransforms
    TRANSFORM = "transform"  # geometry_msgs/TransformStamped, foxglove.FrameTransform
    CAMERA_INFO = "camera_info"  # sensor_msgs/CameraInfo, foxglove.CameraCalibration
    DEPTH = "depth"  # sensor_msgs/Image (16UC1, 32FC1), CompressedImage (compressedDepth)
    DETECTIONS = "detections"  # vision_msgs/Detection2DArray
    DETECTION = "detection"  # vision_msgs/Detection2D
    PIXEL_POINT = "pixel_point"  # geometry_msgs/PointStamped holding (u, v, depth)
    POINT = "point"  # PointStamped, PoseStamped, TransformStamped as logged evidence
    ODOMETRY = "odometry"  # nav_msgs/Odometry
    POSE = "pose"  # PoseStamped, PoseWithCovarianceStamped, TransformStamped on a pose topic the chain names
    JOINT_STATE = "joint_state"  # sensor_msgs/JointState
    URDF = "urdf"  # std_msgs/String robot description
    RS_EXTRINSIC = "rs_extrinsic"  # librealsense geometry_msgs/Transform on .../tf/<ref>
    RS_DEPTH_UNITS = "rs_depth_units"  # librealsense option Depth_Units (std_msgs/Float32)
    # Fiducials (framechain.adapters.messages.fiducials): one observation per tag.
    APRILTAGS = "apriltags"  # apriltag_msgs ApriltagArrayStamped (ROS 1) / AprilTagDetectionArray (ROS 2): corners
    APRILTAG_POSES = "apriltag_poses"  # apriltag_ros/AprilTagDetectionArray: tag poses in the camera frame
    FIDUCIAL_VERTICES = "fiducial_vertices"  # fiducial_msgs/FiducialArray: corners
    FIDUCIAL_TRANSFORMS = "fiducial_transforms"  # fiducial_msgs/FiducialTransformArray: poses in the camera frame
    DETECTIONS_3D = "detections_3d"  # vision_msgs/Detection3DArray: box centres in the camera frame
    CAMERA_POINT = "camera_point"  # geometry_msgs/PointStamped named as the detections: a camera-frame point
    MARKER_IMAGE = "marker_image"  # sensor_msgs/Image or CompressedImage searched for markers
    IMAGE = "image"  # sensor_msgs/Image or CompressedImage on topics.image, shown by the sinks


def normalize_msgtype(name: str) -> str:
    """``tf2_msgs/msg/TFMessage`` and ``tf2_msgs/TFMessage`` both become ``tf2_msgs/TFMessage``."""
    return name.replace("/msg/", "/")


_BY_TYPE: dict[str, Kind] = {
    "tf2_msgs/TFMessage": Kind.TF,
    "tf/tfMessage": Kind.TF,
    "foxglove.FrameTransforms": Kind.TF,
    "foxglove.FrameTransform": Kind.TRANSFORM,
    "geometry_msgs/TransformStamped": Kind.TRANSFORM,
    "sensor_msgs/CameraInfo": Kind.CAMERA_INFO,
    "foxglove.CameraCalibration": Kind.CAMERA_INFO,
    "vision_msgs/Detection2DArray": Kind.DETECTIONS,
    "vision_msgs/Detection2D": Kind.DETECTION,
    "nav_msgs/Odometry": Kind.ODOMETRY,
    "sensor_msgs/JointState": Kind.JOINT_STATE,
}

#: Detector messages whose detections are fiducials (corners or camera-frame points).
_FIDUCIAL_TYPES: dict[str, Kind] = {
    "apriltag_msgs/ApriltagArrayStamped": Kind.APRILTAGS,
    "apriltag_msgs/AprilTagDetectionArray": Kind.APRILTAGS,
    "apriltag_ros/AprilTagDetectionArray": Kind.APRILTAG_POSES,
    "fiducial_msgs/FiducialArray": Kind.FIDUCIAL_VERTICES,
    "fiducial_msgs/FiducialTransformArray": Kind.FIDUCIAL_TRANSFORMS,
    "vision_msgs/Detection3DArray": Kind.DETECTIONS_3D,
}
_BY_TYPE.update(_FIDUCIAL_TYPES)

_IMAGE_TYPES = frozenset({"sensor_msgs/Image", "sensor_msgs/CompressedImage"})
#: Message types a pose topic (``topics.odometry``) may carry, read as a dynamic edge.
POSE_TYPES = frozenset({"nav_msgs/Odometry", "geometry_msgs/PoseStamped", "geometry_msgs/PoseWithCovarianceStamped",
                        "geometry_msgs/TransformStamped"})


def is_realsense_layout(topics: dict[str, str]) -> bool:
    """A librealsense recording (``/file_version`` and ``/device_0/...`` topics)."""
    return "/file_version" in topics and any(t.startswith("/device_") for t in topics)


def _looks_depth(topic: str, msgtype: str) -> bool:
    low = topic.lower()
    if msgtype == "sensor_msgs/CompressedImage":
        return "compresseddepth" in low
    return "depth" in low and "color" not in low.rsplit("/", 3)[-1]


def select_topics(topics: dict[str, str], chain: ChainConfig | None) -> dict[str, Kind]:
    """Topic -> kind for the topics to decode; every other topic is skipped without decoding.

    ``topics`` maps topic name to message type. With a chain, only the topics it names plus the
    frame tree (/tf, /tf_static), joint states and robot descriptions are read; without one,
    every topic of a kind framechain understands (evidence points need a chain to give them a
    role, so they are read only when the chain names them).
    """
    norm = {name: normalize_msgtype(t) for name, t in topics.items()}
    realsense = is_realsense_layout(norm)
    named = _named_kinds(chain, norm) if chain is not None else {}
    out: dict[str, Kind] = {}
    for name, msgtype in norm.items():
        kind = _as_named(named[name], msgtype) if name in named else _unnamed_kind(name, msgtype, chain, realsense)
        if kind is not None:
            out[name] = kind
    return out


def _named_kinds(chain: ChainConfig, norm: Mapping[str, str]) -> dict[str, Kind]:
    """Topic -> kind for every topic ``chain`` names (``norm``: topic -> normalised message type)."""
    named: dict[str, Kind] = {}
    t = chain.topics
    for topic, kind in (
        (t.camera_info, Kind.CAMERA_INFO), (t.depth, Kind.DEPTH), (t.pixel_points, Kind.PIXEL_POINT),
    ):
        if topic:
            named[topic] = kind
    for pose in chain.pose_topics():
        msgtype = norm.get(pose.topic, "")
        if msgtype in POSE_TYPES:  # other types: api notes that the topic is not a pose
            named[pose.topic] = Kind.ODOMETRY if msgtype == "nav_msgs/Odometry" else Kind.POSE
    if t.detections:
        named[t.detections] = Kind.DETECTIONS
    if t.image:  # markers are searched in it and it is shown; or only shown
        named[t.image] = Kind.MARKER_IMAGE if chain.evidence.markers is not None else Kind.IMAGE
    for cam in chain.cameras:  # a rig: every camera's own topics
        named[cam.detections] = Kind.DETECTIONS
        for topic, kind in ((cam.camera_info, Kind.CAMERA_INFO), (cam.depth, Kind.DEPTH)):
            if topic:
                named[topic] = kind
        if cam.image:
            markers = cam.markers or chain.evidence.markers
            named[cam.image] = Kind.MARKER_IMAGE if markers is not None else Kind.IMAGE
    for topic in chain.evidence_topics():
        named[topic] = Kind.POINT
    return named


def _as_named(kind: Kind, msgtype: str) -> Kind:
    """A named topic's kind, detections told apart by their message type."""
    if kind == Kind.DETECTIONS and msgtype == "vision_msgs/Detection2D":
        return Kind.DETECTION
    if kind == Kind.DETECTIONS and msgtype in _FIDUCIAL_TYPES:
        return _FIDUCIAL_TYPES[msgtype]
    if kind == Kind.DETECTIONS and msgtype == "geometry_msgs/PointStamped":
        return Kind.CAMERA_POINT
    return kind


def _unnamed_kind(name: str, msgtype: str, chain: ChainConfig | None, realsense: bool) -> Kind | None:
    """The kind of a topic the chain does not name (None: skipped)."""
    kind_or_none = _BY_TYPE.get(msgtype)
    if realsense:
        if msgtype == "geometry_msgs/Transform" and "/tf/" in name:
            return Kind.RS_EXTRINSIC
        if name.endswith("/option/Depth_Units/value"):
            return Kind.RS_DEPTH_UNITS
    if msgtype == "std_msgs/String" and name.rstrip("/").endswith("robot_description"):
        return Kind.URDF
    if chain is not None:
        # With a chain: the frame tree and joints always; other kinds only where named (or
        # where the chain leaves the slot empty, so the tree stays complete).
        if kind_or_none in (Kind.TF, Kind.TRANSFORM, Kind.JOINT_STATE) or (
            (kind_or_none == Kind.ODOMETRY and not chain.topics.odometry)
            or (kind_or_none == Kind.CAMERA_INFO and (realsense or not _names_camera_info(chain)))
        ):
            return kind_or_none
        return None
    if kind_or_none is not None:
        return kind_or_none
    if msgtype in _IMAGE_TYPES and _looks_depth(name, msgtype):
        return Kind.DEPTH
    return None


def _names_camera_info(chain: ChainConfig) -> bool:
    """Whether the chain names its CameraInfo topics (then only those are read)."""
    return bool(chain.topics.camera_info) or any(c.camera_info for c in chain.cameras)
