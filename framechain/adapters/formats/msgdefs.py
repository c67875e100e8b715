"""Message definitions the writer needs beyond rosbags' stores: vision_msgs in three layouts and,
for ROS 1, tf2_msgs (missing from ROS1_NOETIC)."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, Literal

DetectionLayout = Literal["ros2", "ros2-old", "ros1"]

#: vision_msgs >= 4 (ROS 2 Humble and later): bbox.center.position.x, results[].hypothesis.class_id.
VISION_ROS2 = {
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/msg/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/msg/BoundingBox2D": "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose":
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n",
    "vision_msgs/msg/Detection2D":
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\nvision_msgs/BoundingBox2D bbox\n"
        "string id\n",
    "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n",
}

#: vision_msgs 2.x (ROS 2 Foxy/Galactic): bbox.center is geometry_msgs/Pose2D, results[].id/score.
VISION_ROS2_OLD = {
    "vision_msgs/msg/BoundingBox2D": "geometry_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/ObjectHypothesisWithPose":
        "string id\nfloat64 score\ngeometry_msgs/PoseWithCovariance pose\n",
    "vision_msgs/msg/Detection2D":
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\nvision_msgs/BoundingBox2D bbox\n"
        "sensor_msgs/Image source_img\nbool is_tracking\nstring tracking_id\n",
    "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n",
}

#: vision_msgs for ROS 1 (noetic): results[].id is an int64, no Detection2D.id but tracking_id.
VISION_ROS1 = {
    "vision_msgs/msg/BoundingBox2D": "geometry_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": "int64 id\nfloat64 score\ngeometry_msgs/PoseWithCovariance pose\n",
    "vision_msgs/msg/Detection2D":
        "Header header\nvision_msgs/ObjectHypothesisWithPose[] results\nvision_msgs/BoundingBox2D bbox\n"
        "sensor_msgs/Image source_img\nbool is_tracking\nstring tracking_id\n",
    "vision_msgs/msg/Detection2DArray": "Header header\nvision_msgs/Detection2D[] detections\n",
}

_ROS1_VISION_ROS2 = {k: v.replace("std_msgs/Header header", "Header header") for k, v in VISION_ROS2.items()}


@functools.cache
def typestore(*, ros1: bool, layout: DetectionLayout = "ros2") -> Any:
    """A rosbags typestore (Humble or Noetic) with tf2_msgs and vision_msgs in ``layout``."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    if ros1:
        types.update(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    layouts = {"ros2": _ROS1_VISION_ROS2 if ros1 else VISION_ROS2, "ros2-old": VISION_ROS2_OLD, "ros1": VISION_ROS1}
    defs = layouts[layout]
    for name, text in defs.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


@dataclass
class OutMessage:
    """A message to write: a rosbags message object of ``msgtype`` on ``topic`` at ``log_time_ns``."""

    log_time_ns: int
    topic: str
    msgtype: str
    msg: Any
