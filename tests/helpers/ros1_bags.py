"""ROS 1 bags written with rosbags' writer for the CLI tests: /tf, odometry and fiducial_msgs detections
(types from their upstream .msg definitions: UbiquityRobotics/fiducials)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from framechain.adapters.formats.msgdefs import typestore

FIDUCIAL_MSGS = {
    "fiducial_msgs/msg/FiducialTransform": "int32 fiducial_id\ngeometry_msgs/Transform transform\n"
                                           "float64 image_error\nfloat64 object_error\nfloat64 fiducial_area\n",
    "fiducial_msgs/msg/FiducialTransformArray": "std_msgs/Header header\nint32 image_seq\n"
                                                "fiducial_msgs/FiducialTransform[] transforms\n",
}
NS = 1_000_000_000


class Ros1Bag:
    """Message builders of a ROS 1 typestore with tf2_msgs and fiducial_msgs, and the bag writer."""

    def __init__(self) -> None:
        from rosbags.typesys import get_types_from_msg

        self.ts = typestore(ros1=True)
        types: dict[str, Any] = {}
        for name, text in FIDUCIAL_MSGS.items():
            types.update(get_types_from_msg(text, name))
        self.ts.register(types)
        self.T = self.ts.types
        self.messages: list[tuple[str, str, int, Any]] = []

    def header(self, stamp_ns: int, frame: str) -> Any:
        t = self.T["builtin_interfaces/msg/Time"](sec=stamp_ns // NS, nanosec=stamp_ns % NS)
        return self.T["std_msgs/msg/Header"](seq=0, stamp=t, frame_id=frame)

    def _vector(self, xyz: Sequence[float]) -> Any:
        return self.T["geometry_msgs/msg/Vector3"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))

    def _quaternion(self, q: Sequence[float]) -> Any:
        return self.T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def transform(self, xyz: Sequence[float], quat_xyzw: Sequence[float] = (0.0, 0.0, 0.0, 1.0)) -> Any:
        return self.T["geometry_msgs/msg/Transform"](translation=self._vector(xyz),
                                                     rotation=self._quaternion(quat_xyzw))

    def tf(self, topic: str, stamp_ns: int, parent: str, child: str, xyz: Sequence[float],
           quat_xyzw: Sequence[float] = (0.0, 0.0, 0.0, 1.0), *, log_ns: int | None = None) -> None:
        ts = self.T["geometry_msgs/msg/TransformStamped"](header=self.header(stamp_ns, parent), child_frame_id=child,
                                                          transform=self.transform(xyz, quat_xyzw))
        self.messages.append((topic, "tf2_msgs/msg/TFMessage", log_ns or stamp_ns,
                              self.T["tf2_msgs/msg/TFMessage"](transforms=[ts])))

    def odometry(self, topic: str, stamp_ns: int, parent: str, child: str, xyz: Sequence[float]) -> None:
        T = self.T
        point = T["geometry_msgs/msg/Point"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
        pose = T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](position=point, orientation=self._quaternion((0, 0, 0, 1))),
            covariance=np.zeros(36))
        zero = self._vector((0, 0, 0))
        still = T["geometry_msgs/msg/Twist"](linear=zero, angular=zero)
        twist = T["geometry_msgs/msg/TwistWithCovariance"](twist=still, covariance=np.zeros(36))
        msg = T["nav_msgs/msg/Odometry"](header=self.header(stamp_ns, parent), child_frame_id=child, pose=pose,
                                         twist=twist)
        self.messages.append((topic, "nav_msgs/msg/Odometry", stamp_ns, msg))

    def fiducial_transforms(self, topic: str, stamp_ns: int, frame: str, points: dict[int, Sequence[float]]) -> None:
        T = self.T
        transforms = [T["fiducial_msgs/msg/FiducialTransform"](fiducial_id=i, transform=self.transform(p),
                                                               image_error=0.1, object_error=0.01, fiducial_area=100.0)
                      for i, p in points.items()]
        msg = T["fiducial_msgs/msg/FiducialTransformArray"](header=self.header(stamp_ns, frame), image_seq=0,
                                                            transforms=transforms)
        self.messages.append((topic, "fiducial_msgs/msg/FiducialTransformArray", stamp_ns, msg))

    def write(self, path: Path) -> Path:
        from rosbags.rosbag1 import Writer

        with Writer(path) as w:
            conns: dict[str, Any] = {}
            for topic, msgtype, t, msg in sorted(self.messages, key=lambda m: m[2]):
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, msgtype, typestore=self.ts)
                w.write(conns[topic], t, self.ts.serialize_ros1(msg, msgtype))
        return path


def tf_typestore(*, ros1: bool) -> Any:
    """rosbags' own Humble or Noetic typestore, with tf2_msgs/TFMessage registered for Noetic (which lacks it):
    the fixtures' writer side, built without framechain's message definitions."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if not ros1:
        return get_typestore(Stores.ROS2_HUMBLE)
    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return store
