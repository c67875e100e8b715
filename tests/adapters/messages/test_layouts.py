"""Message layouts beyond the writer's own: Foxglove schemas (protobuf and JSON), vision_msgs in
the older ROS 2 and the ROS 1 layouts, pixel points, side tables, odometry, URDF, compressedDepth."""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from framechain.adapters import open_log
from framechain.adapters.formats.msgdefs import typestore
from framechain.config.chain import ChainConfig
from tests.helpers.adapter_scene import T0


def _fds(descriptor: Any) -> bytes:
    from google.protobuf import descriptor_pb2

    out = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(fd: Any) -> None:
        if fd.name in seen:
            return
        for dep in fd.dependencies:
            add(dep)
        seen.add(fd.name)
        proto = descriptor_pb2.FileDescriptorProto()
        fd.CopyToProto(proto)
        out.file.append(proto)

    add(descriptor.file)
    return out.SerializeToString()


def test_foxglove_protobuf_and_json(tmp_path: Path) -> None:
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from mcap.writer import Writer

    path = tmp_path / "fox.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        s_tf = w.register_schema("foxglove.FrameTransform", "protobuf", _fds(FrameTransform.DESCRIPTOR))
        s_tfs = w.register_schema("foxglove.FrameTransforms", "protobuf", _fds(FrameTransforms.DESCRIPTOR))
        s_cam = w.register_schema("foxglove.CameraCalibration", "protobuf", _fds(CameraCalibration.DESCRIPTOR))
        s_json = w.register_schema("foxglove.FrameTransform", "jsonschema", b'{"type": "object"}')
        c_tf = w.register_channel("/tf_single", "protobuf", s_tf)
        c_tfs = w.register_channel("/tf", "protobuf", s_tfs)
        c_cam = w.register_channel("/cam/calibration", "protobuf", s_cam)
        c_json = w.register_channel("/tf_json", "json", s_json)
        for i in range(3):
            t = T0 + i * 100_000_000
            m = FrameTransform(parent_frame_id="map", child_frame_id="odom")
            m.timestamp.FromNanoseconds(t)
            m.translation.x, m.rotation.w = 0.5 * i, 1.0
            w.add_message(c_tf, log_time=t + 1, publish_time=t, data=m.SerializeToString())
            ms = FrameTransforms()
            e = ms.transforms.add(parent_frame_id="odom", child_frame_id="base_link")
            e.timestamp.FromNanoseconds(t)
            e.translation.y, e.rotation.z, e.rotation.w = 1.0 + i, np.sin(0.1), np.cos(0.1)
            w.add_message(c_tfs, log_time=t + 2, publish_time=t, data=ms.SerializeToString())
            js = {"timestamp": {"sec": t // 10**9, "nsec": t % 10**9}, "parent_frame_id": "base_link",
                  "child_frame_id": "camera", "translation": {"x": 0.3, "y": 0.0, "z": 0.8},
                  "rotation": {"x": -0.5, "y": 0.5, "z": -0.5, "w": 0.5}}
            w.add_message(c_json, log_time=t + 3, publish_time=t, data=json.dumps(js).encode())
        cal = CameraCalibration(frame_id="camera", width=640, height=480, distortion_model="plumb_bob",
                                D=[0.1, 0.01, 0, 0, 0], K=[600, 0, 320, 0, 610, 240, 0, 0, 1])
        cal.timestamp.FromNanoseconds(T0)
        w.add_message(c_cam, log_time=T0, publish_time=T0, data=cal.SerializeToString())
        w.finish()
    tl = open_log(path).timeline
    tf = tl.transforms
    assert len(tf) == 9
    single = tf.take(tf.child == "odom")
    assert single.parent.tolist() == ["map"] * 3
    assert np.array_equal(single.translation[:, 0], [0.0, 0.5, 1.0])
    assert np.array_equal(single.stamp_ns, T0 + np.arange(3) * 100_000_000)
    base = tf.take(tf.child == "base_link")
    np.testing.assert_allclose(base.quat_xyzw[0], [0, 0, np.sin(0.1), np.cos(0.1)])
    cam = tf.take(tf.child == "camera")
    np.testing.assert_allclose(cam.quat_xyzw, np.tile([-0.5, 0.5, -0.5, 0.5], (3, 1)))
    assert cam.source.tolist() == ["/tf_json"] * 3
    assert len(tl.cameras) == 1
    assert tl.cameras.K[0, 1, 1] == 610.0
    assert tl.cameras.n_distortion[0] == 5


def _write_bag(path: Path, ros1: bool, layout: str, topic: str, msgtype: str, msgs: list[tuple[int, Any]]) -> Path:
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2

    ts = typestore(ros1=ros1, layout=layout)  # type: ignore[arg-type]
    if ros1:
        with Writer1(path) as w:
            c = w.add_connection(topic, msgtype, typestore=ts)
            for t, m in msgs:
                w.write(c, t, bytes(ts.serialize_ros1(m, msgtype)))
    else:
        with Writer2(path, version=9) as w:
            c = w.add_connection(topic, msgtype, typestore=ts)
            for t, m in msgs:
                w.write(c, t, bytes(ts.serialize_cdr(m, msgtype)))
    return path


def _pose_cov(T: Any, z: float) -> Any:
    return T["geometry_msgs/msg/PoseWithCovariance"](
        pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=z),
                                         orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
        covariance=np.zeros(36))


@pytest.mark.parametrize("layout", ["ros2-old", "ros1"])
def test_older_detection_layouts(layout: str, tmp_path: Path) -> None:
    ros1 = layout == "ros1"
    ts = typestore(ros1=ros1, layout=layout)  # type: ignore[arg-type]
    T = ts.types
    stamp = T["builtin_interfaces/msg/Time"](sec=T0 // 10**9, nanosec=5)
    hdr = (T["std_msgs/msg/Header"](seq=1, stamp=stamp, frame_id="cam_optical") if ros1
           else T["std_msgs/msg/Header"](stamp=stamp, frame_id="cam_optical"))
    image = T["sensor_msgs/msg/Image"](header=hdr, height=0, width=0, encoding="", is_bigendian=0, step=0,
                                       data=np.zeros(0, dtype=np.uint8))
    hyp = (T["vision_msgs/msg/ObjectHypothesisWithPose"](id=7, score=0.9, pose=_pose_cov(T, 1.5)) if ros1 else
           T["vision_msgs/msg/ObjectHypothesisWithPose"](id="cup", score=0.9, pose=_pose_cov(T, 1.5)))
    det = T["vision_msgs/msg/Detection2D"](
        header=hdr, results=[hyp], bbox=T["vision_msgs/msg/BoundingBox2D"](
            center=T["geometry_msgs/msg/Pose2D"](x=312.0, y=204.0, theta=0.0), size_x=10.0, size_y=10.0),
        source_img=image, is_tracking=False, tracking_id="42")
    arr = T["vision_msgs/msg/Detection2DArray"](header=hdr, detections=[det])
    path = _write_bag(tmp_path / ("d.bag" if ros1 else "d"), ros1, layout, "/dets",
                      "vision_msgs/msg/Detection2DArray", [(T0 + 10, arr)])
    chain = ChainConfig.from_dict({"topics": {"detections": "/dets"}})
    obs = open_log(path, chain).timeline.observations
    assert (obs.u[0], obs.v[0], obs.depth_m[0]) == (312.0, 204.0, 1.5)
    assert obs.stamp_ns[0] == T0 + 5
    assert obs.log_time_ns[0] == T0 + 10
    assert obs.label[0] == ("7" if ros1 else "cup")
    assert obs.score[0] == 0.9
    assert obs.obs_id[0] == 42
    assert obs.camera_frame[0] == "cam_optical"


def test_pixel_points_side_table_points_odometry_urdf(tmp_path: Path) -> None:
    from rosbags.rosbag2 import Writer

    ts = typestore(ros1=False)
    T = ts.types

    def hdr(t: int, frame: str) -> Any:
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9),
                                        frame_id=frame)

    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(0.2), w=np.cos(0.2))
    path = tmp_path / "bag"
    with Writer(path, version=9) as w:
        c_px = w.add_connection("/pixels", "geometry_msgs/msg/PointStamped", typestore=ts)
        c_pose = w.add_connection("/mocap", "geometry_msgs/msg/PoseStamped", typestore=ts)
        c_odom = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        c_urdf = w.add_connection("/robot_description", "std_msgs/msg/String", typestore=ts)
        px = T["geometry_msgs/msg/PointStamped"](header=hdr(T0, "cam"),
                                                  point=T["geometry_msgs/msg/Point"](x=380.0, y=210.0, z=2.0))
        w.write(c_px, T0 + 1, bytes(ts.serialize_cdr(px, "geometry_msgs/msg/PointStamped")))
        pose = T["geometry_msgs/msg/PoseStamped"](header=hdr(T0, "map"), pose=T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=1.5, y=0.4, z=2.8), orientation=q))
        w.write(c_pose, T0 + 2, bytes(ts.serialize_cdr(pose, "geometry_msgs/msg/PoseStamped")))
        for i in range(3):
            t = T0 + i * 10**8
            odom = T["nav_msgs/msg/Odometry"](
                header=hdr(t, "odom"), child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=float(i), y=0.0, z=0.0), orientation=q),
                    covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=T["geometry_msgs/msg/Twist"](
                    linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                    angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)), covariance=np.zeros(36)))
            w.write(c_odom, t + 3, bytes(ts.serialize_cdr(odom, "nav_msgs/msg/Odometry")))
        w.write(c_urdf, T0, bytes(ts.serialize_cdr(T["std_msgs/msg/String"](data="<robot name='r'/>"),
                                                   "std_msgs/msg/String")))
    (tmp_path / "dets.csv").write_text("stamp,frame,u,v,depth,label\n1700000000.5,cam,100.5,50.25,,box\n")
    chain = ChainConfig.from_dict({"topics": {"pixel_points": "/pixels", "detections_table": "dets.csv"},
                                   "evidence": {"reference": "/mocap"}})
    tl = open_log(path, chain).timeline
    obs = tl.observations
    assert len(obs) == 2
    px_row = int(np.flatnonzero(obs.source == "/pixels")[0])
    assert (obs.u[px_row], obs.v[px_row], obs.depth_m[px_row]) == (380.0, 210.0, 2.0)
    side = int(np.flatnonzero(obs.source == "dets.csv")[0])
    assert obs.stamp_ns[side] == 1_700_000_000_500_000_000
    assert np.isnan(obs.depth_m[side])
    assert (obs.u[side], obs.v[side], obs.label[side]) == (100.5, 50.25, "box")
    pts = tl.points
    assert pts.role.tolist() == ["reference"]
    assert pts.frame.tolist() == ["map"]
    np.testing.assert_allclose(pts.quat_xyzw[0], [0, 0, np.sin(0.2), np.cos(0.2)])
    odom = tl.transforms
    assert odom.parent.tolist() == ["odom"] * 3
    assert odom.child.tolist() == ["base_link"] * 3
    assert np.array_equal(odom.translation[:, 0], [0.0, 1.0, 2.0])
    assert odom.source[0] == "/odom"
    assert tl.metadata["robot_description"] == {"/robot_description": "<robot name='r'/>"}


@pytest.mark.parametrize("base", ["16UC1", "32FC1"])
def test_compressed_depth(base: str, tmp_path: Path) -> None:
    import cv2
    from rosbags.rosbag1 import Writer

    depth_m = np.array([[0.0, 1.0, 2.5], [0.75, 4.0, 0.5]], dtype=np.float32)
    if base == "16UC1":
        png = cv2.imencode(".png", np.rint(depth_m * 1000).astype(np.uint16))[1].tobytes()
        header = struct.pack("<iff", 0, 0.0, 0.0)
        expected = depth_m
    else:  # image_transport's inverse-depth quantisation for 32FC1
        a, b = 100.0, 10.0  # depth = a / (value - b)
        value = np.where(depth_m > 0, a / np.where(depth_m > 0, depth_m, 1) + b, 0)
        png = cv2.imencode(".png", np.rint(value).astype(np.uint16))[1].tobytes()
        header = struct.pack("<iff", 0, a, b)
        expected = np.where(depth_m > 0, a / (np.rint(value) - b), np.nan).astype(np.float32)
    ts = typestore(ros1=True)
    T = ts.types
    msg = T["sensor_msgs/msg/CompressedImage"](
        header=T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=T0 // 10**9, nanosec=0),
                                        frame_id="cam"),
        format=f"{base}; compressedDepth png", data=np.frombuffer(header + png, dtype=np.uint8))
    path = tmp_path / "cd.bag"
    with Writer(path) as w:
        c = w.add_connection("/cam/depth/image_raw/compressedDepth", "sensor_msgs/msg/CompressedImage", typestore=ts)
        w.write(c, T0, bytes(ts.serialize_ros1(msg, "sensor_msgs/msg/CompressedImage")))
    d = open_log(path).timeline.depth_frames
    assert (int(d.width[0]), int(d.height[0]), str(d.encoding[0])) == (3, 2, f"compressedDepth {base}")
    np.testing.assert_allclose(d.load(0), expected, rtol=1e-6, equal_nan=True)
