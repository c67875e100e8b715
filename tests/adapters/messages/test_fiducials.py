"""Fiducial detections as observations: square-marker PnP against known poses (OpenCV's own
projections), every reader layout written with the real writers, rejections that reconcile, and
the TagSLAM stairs log."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml

from framechain.adapters import open_log
from framechain.adapters.messages.fiducials import FiducialRows, counts_reconcile, resolve_fiducials
from framechain.config.chain import ChainConfig
from framechain.config.errors import ChainConfigError
from framechain.geometry.camera import CameraModel
from framechain.timeline import CameraTable
from framechain.vision.tag_pose import solve_square_tags, square_object_points
from tests.helpers.realdata import STAIRS

T0 = 1_700_000_000 * 10**9
K = np.array([[600.0, 0.0, 320.0], [0.0, 610.0, 240.0], [0.0, 0.0, 1.0]])
PLUMB_BOB = np.array([0.12, -0.25, 0.001, -0.002, 0.08])
RATIONAL = np.array([0.12, -0.25, 0.001, -0.002, 0.08, 0.02, -0.01, 0.005])
# Kalibr's equidistant coefficients of the TagSLAM left fisheye (cameras.yaml, cam0).
FISHEYE = np.array([-0.006671324837952852, 0.03932977095246315, -0.03556782007217407, 0.005536118987947702])
MODELS = {"plumb_bob": PLUMB_BOB, "rational_polynomial": RATIONAL, "equidistant": FISHEYE}


def _render(model: str, rvec: np.ndarray, tvec: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of tag-frame points through OpenCV's own projection of ``model``."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 1, 3)
    if model == "equidistant":
        out, _ = cv2.fisheye.projectPoints(pts, rvec.reshape(1, 1, 3), tvec.reshape(1, 1, 3), K, FISHEYE)
    else:
        out, _ = cv2.projectPoints(pts, rvec, tvec, K, MODELS[model])
    return np.asarray(out).reshape(-1, 2)


def _poses(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Tags facing the camera (180 deg about x, then up to ~35 deg of tilt), 0.4-2.5 m ahead."""
    from scipy.spatial.transform import Rotation

    tilt = Rotation.from_rotvec(rng.normal(scale=0.3, size=(n, 3)))
    rot = tilt * Rotation.from_rotvec([np.pi, 0.0, 0.0])
    z = rng.uniform(0.4, 2.5, n)
    xy = rng.uniform(-0.25, 0.25, (n, 2)) * z[:, None]
    return rot.as_rotvec(), np.column_stack([xy, z])


@pytest.mark.parametrize("model", sorted(MODELS))
def test_pnp_recovers_known_centres(model: str) -> None:
    rng = np.random.default_rng(7)
    rvecs, tvecs = _poses(rng, 40)
    sizes = rng.uniform(0.05, 0.3, 40)
    corners = np.stack([_render(model, r, t, square_object_points(s)) for r, t, s in zip(rvecs, tvecs, sizes,
                                                                                          strict=True)])
    cam = CameraModel("cam", K, 0, 0, model, MODELS[model])
    poses = solve_square_tags(cam, corners, sizes)
    assert poses.ok.all()
    assert np.abs(poses.centre_cam - tvecs).max() < 1e-6
    assert poses.reprojection_px.max() < 1e-6
    assert not poses.reversed_order.any()  # OpenCV's order is IPPE_SQUARE's
    # Any starting corner, and the mirrored (counter-clockwise) order, name the same centre.
    for order, mirrored in (([1, 2, 3, 0], False), ([0, 3, 2, 1], True), ([2, 1, 0, 3], True)):
        other = solve_square_tags(cam, corners[:, order], sizes)
        assert np.abs(other.centre_cam - tvecs).max() < 1e-6
        assert (other.reversed_order == mirrored).all()


@pytest.mark.parametrize("model", ["plumb_bob", "equidistant"])
def test_pnp_with_pixel_noise(model: str) -> None:
    rng = np.random.default_rng(11)
    n, size = 200, 0.16
    rvecs, tvecs = _poses(rng, n)
    tvecs[:, 2] = rng.uniform(0.5, 1.5, n)
    corners = np.stack([_render(model, r, t, square_object_points(size)) for r, t in zip(rvecs, tvecs, strict=True)])
    noisy = corners + rng.normal(scale=0.3, size=corners.shape)
    poses = solve_square_tags(CameraModel("cam", K, 0, 0, model, MODELS[model]), noisy, size)
    assert poses.ok.all()
    depth_err = np.abs(poses.centre_cam[:, 2] - tvecs[:, 2]) / tvecs[:, 2]
    lateral = np.linalg.norm(poses.centre_cam[:, :2] - tvecs[:, :2], axis=1)
    # 0.3 px on a 60-190 px tag: the depth is good to about a percent, the bearing far better.
    assert np.median(depth_err) < 0.005
    assert np.percentile(depth_err, 95) < 0.02
    assert np.median(lateral) < 0.001
    # Four corners, 8 residuals, 6 pose parameters: the RMS sits below the noise.
    assert 0.05 < np.median(poses.reprojection_px) < 0.3


def _rows(model: str, rng: np.random.Generator, n: int, size: float, *, frame: str = "cam") -> tuple[
        FiducialRows, np.ndarray]:
    rows = FiducialRows(size_for_tag=lambda label: size)
    rvecs, tvecs = _poses(rng, n)
    for i, (r, t) in enumerate(zip(rvecs, tvecs, strict=True)):
        corners = _render(model, r, t, square_object_points(size))
        rows.add_corners("/tags", T0 + i, T0 + i, frame, str(i), corners.reshape(-1).tolist())
    return rows, tvecs


def _camera(model: str, frame: str = "cam") -> CameraTable:
    return CameraTable.from_intrinsics(frame, fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], width=640,
                                       height=480, distortion_model=model, distortion=MODELS[model])


def test_resolve_gives_projected_centre_and_depth() -> None:
    rows, tvecs = _rows("plumb_bob", np.random.default_rng(3), 25, 0.12)
    res = resolve_fiducials(rows, _camera("plumb_bob"))
    assert res.u.size == 25
    expected = np.stack([_render("plumb_bob", np.zeros(3), np.zeros(3), t) for t in tvecs]).reshape(-1, 2)
    assert np.abs(np.column_stack([res.u, res.v]) - expected).max() < 1e-5
    assert np.abs(res.depth_m - tvecs[:, 2]).max() < 1e-6
    assert res.counts["/tags"] == {"detections": 25, "observations": 25, "bearing_only": 0, "rejected": {}}


def test_rejections_are_counted_with_reasons() -> None:
    rng = np.random.default_rng(5)
    rows, _ = _rows("plumb_bob", rng, 6, 0.12)
    # A 2:1 rectangle is no square of any size: the corners cannot be reprojected.
    rect = np.array([[100.0, 100.0], [300.0, 100.0], [300.0, 200.0], [100.0, 200.0]])
    rows.add_corners("/tags", T0, T0, "cam", "77", rect.reshape(-1).tolist())
    rows.add_corners("/tags", T0, T0, "cam", "78", [np.nan] * 8)
    rows.add_corners("/tags", T0, T0, "other_cam", "79", rect.reshape(-1).tolist())
    point = type("P", (), {"x": 0.1, "y": 0.0, "z": -1.0})()
    rows.add_point("/points", T0, T0, "cam", "behind", point)
    res = resolve_fiducials(rows, _camera("plumb_bob"))
    assert res.counts["/tags"]["rejected"] == {"corners_invalid": 1, "no_intrinsics": 1,
                                               "reprojection_too_large": 1}
    assert res.counts["/tags"]["observations"] == 6
    assert res.counts["/points"]["rejected"] == {"behind_camera": 1}
    assert counts_reconcile(res.counts)
    assert any("no intrinsics for camera other_cam (add calibration" in n for n in res.notes)
    assert sorted(res.label.tolist()) == sorted(str(i) for i in range(6))


def test_bearing_only_without_size_is_the_image_of_the_centre() -> None:
    rng = np.random.default_rng(9)
    sized, tvecs = _rows("equidistant", rng, 10, 0.2)
    rows = FiducialRows()  # no tag size
    for i in range(len(sized)):
        rows.add_corners("/tags", T0, T0, "cam", str(i), sized.corners_px[8 * i: 8 * i + 8])
    res = resolve_fiducials(rows, _camera("equidistant"))
    assert np.isnan(res.depth_m).all()
    assert res.counts["/tags"]["bearing_only"] == 10
    expected = np.stack([_render("equidistant", np.zeros(3), np.zeros(3), t) for t in tvecs]).reshape(-1, 2)
    assert np.abs(np.column_stack([res.u, res.v]) - expected).max() < 1e-6
    # With no camera model, the detector's centre pixel is kept as given.
    rows2 = FiducialRows()
    rows2.add_corners("/tags", T0, T0, "nocam", "1", [0, 0, 10, 0, 10, 10, 0, 10], (4.0, 6.0))
    res2 = resolve_fiducials(rows2, CameraTable.empty())
    assert (res2.u[0], res2.v[0]) == (4.0, 6.0)


def test_chain_tag_size_keys() -> None:
    chain = ChainConfig.from_dict({"topics": {"image": "/cam/image"},
                                   "evidence": {"tag_size_m": {"default": 0.16, 100: 0.1},
                                                "markers": {"dictionary": "DICT_5X5_1000", "size_m": 0.14}}})
    assert chain.evidence.tag_size_m == {"default": 0.16, "100": 0.1}
    assert ChainConfig.from_dict(chain.to_dict()) == chain
    with pytest.raises(ChainConfigError, match=r"evidence.tag_size_m: expected a positive size"):
        ChainConfig.from_dict({"evidence": {"tag_size_m": 0}})
    with pytest.raises(ChainConfigError, match=r"evidence.markers: needs dictionary"):
        ChainConfig.from_dict({"topics": {"image": "/cam/image"}, "evidence": {"markers": {"size_m": 0.1}}})
    with pytest.raises(ChainConfigError, match=r"evidence.markers needs topics.image"):
        ChainConfig.from_dict({"evidence": {"markers": {"dictionary": "DICT_4X4_50"}}})


# -- readers, with fixtures from the real writers ------------------------------------------------------
MSG_ROS1 = {  # christianrauch/apriltag_msgs (ROS 1, as in the TagSLAM bag), AprilRobotics/apriltag_ros,
    # UbiquityRobotics/fiducials, ros-perception/vision_msgs noetic-devel
    "apriltag_msgs/msg/Apriltag": "int32 id\nstring family\nint32 hamming\nint32 border\nint32 bits\n"
                                  "geometry_msgs/Point center\ngeometry_msgs/Point[4] corners\n",
    "apriltag_msgs/msg/ApriltagArrayStamped": "std_msgs/Header header\napriltag_msgs/Apriltag[] apriltags\n",
    "apriltag_ros/msg/AprilTagDetection": "int32[] id\nfloat64[] size\ngeometry_msgs/PoseWithCovarianceStamped pose\n",
    "apriltag_ros/msg/AprilTagDetectionArray": "std_msgs/Header header\napriltag_ros/AprilTagDetection[] detections\n",
    "fiducial_msgs/msg/Fiducial": "int32 fiducial_id\nint32 direction\nfloat64 x0\nfloat64 y0\nfloat64 x1\n"
                                  "float64 y1\nfloat64 x2\nfloat64 y2\nfloat64 x3\nfloat64 y3\n",
    "fiducial_msgs/msg/FiducialArray": "std_msgs/Header header\nint32 image_seq\nfiducial_msgs/Fiducial[] fiducials\n",
    "fiducial_msgs/msg/FiducialTransform": "int32 fiducial_id\ngeometry_msgs/Transform transform\n"
                                           "float64 image_error\nfloat64 object_error\nfloat64 fiducial_area\n",
    "fiducial_msgs/msg/FiducialTransformArray": "std_msgs/Header header\nint32 image_seq\n"
                                                "fiducial_msgs/FiducialTransform[] transforms\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": "int64 id\nfloat64 score\ngeometry_msgs/PoseWithCovariance pose\n",
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
                                   "vision_msgs/BoundingBox3D bbox\nsensor_msgs/PointCloud2 source_cloud\n",
    "vision_msgs/msg/Detection3DArray": "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n",
}
MSG_ROS2 = {  # apriltag_msgs 2.x (ROS 2), vision_msgs 4.x
    "apriltag_msgs/msg/Point": "float64 x\nfloat64 y\n",
    "apriltag_msgs/msg/AprilTagDetection": "string family\nint32 id\nint32 hamming\nfloat32 goodness\n"
                                           "float32 decision_margin\napriltag_msgs/Point centre\n"
                                           "apriltag_msgs/Point[4] corners\nfloat64[9] homography\n",
    "apriltag_msgs/msg/AprilTagDetectionArray": "std_msgs/Header header\n"
                                                "apriltag_msgs/AprilTagDetection[] detections\n",
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": "vision_msgs/ObjectHypothesis hypothesis\n"
                                                "geometry_msgs/PoseWithCovariance pose\n",
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
                                   "vision_msgs/BoundingBox3D bbox\nstring id\n",
    "vision_msgs/msg/Detection3DArray": "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n",
}


def _store(ros1: bool) -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in (MSG_ROS1 if ros1 else MSG_ROS2).items():
        types.update(get_types_from_msg(text, name))
    ts.register(types)
    return ts


class _Ros1:
    """Message builders of a ROS 1 typestore."""

    def __init__(self) -> None:
        self.ts = _store(ros1=True)
        self.T = self.ts.types

    def header(self, stamp: int, frame: str) -> Any:
        t = self.T["builtin_interfaces/msg/Time"](sec=stamp // 10**9, nanosec=stamp % 10**9)
        return self.T["std_msgs/msg/Header"](seq=0, stamp=t, frame_id=frame)

    def point(self, x: float, y: float, z: float) -> Any:
        return self.T["geometry_msgs/msg/Point"](x=x, y=y, z=z)

    def pose(self, p: np.ndarray) -> Any:
        q = self.T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
        return self.T["geometry_msgs/msg/Pose"](position=self.point(*p), orientation=q)

    def camera_info(self, stamp: int, frame: str, model: str) -> Any:
        T = self.T
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return T["sensor_msgs/msg/CameraInfo"](
            header=self.header(stamp, frame), height=480, width=640, distortion_model=model,
            D=np.asarray(MODELS[model], dtype=np.float64), K=K.reshape(-1).copy(), R=np.eye(3).reshape(-1),
            P=np.column_stack([K, np.zeros(3)]).reshape(-1), binning_x=0, binning_y=0, roi=roi)


def _write_ros1(path: Path, messages: list[tuple[str, str, int, Any]], ts: Any) -> Path:
    from rosbags.rosbag1 import Writer

    with Writer(path) as w:
        conns: dict[str, Any] = {}
        for topic, msgtype, t, msg in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
            w.write(conns[topic], t, ts.serialize_ros1(msg, msgtype))
    return path


def _expected_pixels(model: str, points: np.ndarray) -> np.ndarray:
    return _render(model, np.zeros(3), np.zeros(3), points)


def test_apriltag_ros1_corners_in_a_bag(tmp_path: Path) -> None:
    """TagSLAM's layout: corners in the MIT detector's (counter-clockwise) order, camera info beside."""
    b = _Ros1()
    rng = np.random.default_rng(21)
    sizes = {"3": 0.16, "100": 0.10}
    msgs: list[tuple[str, str, int, Any]] = [
        ("/cam/camera_info", "sensor_msgs/msg/CameraInfo", T0, b.camera_info(T0, "cam_optical", "plumb_bob"))]
    truth: list[tuple[str, np.ndarray]] = []
    for k in range(5):
        stamp = T0 + k * 200_000_000
        rvecs, tvecs = _poses(rng, 2)
        tags = []
        for tag_id, r, t in zip(("3", "100"), rvecs, tvecs, strict=True):
            px = _render("plumb_bob", r, t, square_object_points(sizes[tag_id]))[[0, 3, 2, 1]]
            centre = _expected_pixels("plumb_bob", t[None])[0]
            tags.append(b.T["apriltag_msgs/msg/Apriltag"](
                id=int(tag_id), family="mit", hamming=0, border=1, bits=6, center=b.point(*centre, 0.0),
                corners=[b.point(x, y, 0.0) for x, y in px]))
            truth.append((tag_id, t))
        msg = b.T["apriltag_msgs/msg/ApriltagArrayStamped"](header=b.header(stamp, "cam_optical"), apriltags=tags)
        msgs.append(("/cam/tags", "apriltag_msgs/msg/ApriltagArrayStamped", stamp + 5_000_000, msg))
    path = _write_ros1(tmp_path / "tags.bag", msgs, b.ts)
    chain = ChainConfig.from_dict({"frames": {"camera": "cam_optical"}, "topics": {"detections": "/cam/tags"},
                                   "evidence": {"tag_size_m": {"default": 0.16, 100: 0.10}}})
    loaded = open_log(path, chain)
    assert loaded.decoded_topics["/cam/tags"] == "apriltags"
    obs = loaded.timeline.observations
    assert len(obs) == 10
    assert obs.label.tolist() == [tag for tag, _ in truth]
    centres = np.stack([t for _, t in truth])
    assert np.abs(obs.depth_m - centres[:, 2]).max() < 1e-6
    assert np.abs(np.column_stack([obs.u, obs.v]) - _expected_pixels("plumb_bob", centres)).max() < 1e-5
    assert set(obs.camera_frame.tolist()) == {"cam_optical"}
    assert obs.stamp_ns[0] == T0
    assert obs.log_time_ns[0] == T0 + 5_000_000
    meta = loaded.timeline.metadata["fiducials"]
    assert meta["counts"]["/cam/tags"] == {"detections": 10, "observations": 10, "bearing_only": 0, "rejected": {}}
    side = meta["corners"]
    assert sorted(side["obs_id"]) == sorted(obs.obs_id.tolist())
    assert side["size_m"][:2] == [0.16, 0.10]
    assert any("matched in reverse order" in n for n in loaded.info.notes)
    # Without a chain every tag topic is read, bearing only.
    bare = open_log(path)
    assert np.isnan(bare.timeline.observations.depth_m).all()
    assert len(bare.timeline.observations) == 10


def test_apriltag_ros2_mcap_fisheye(tmp_path: Path) -> None:
    from mcap_ros2.writer import Writer

    ts = _store(ros1=False)
    rng = np.random.default_rng(33)
    rvecs, tvecs = _poses(rng, 6)
    path = tmp_path / "tags.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        s_tags = w.register_msgdef("apriltag_msgs/msg/AprilTagDetectionArray",
                                   ts.generate_msgdef("apriltag_msgs/msg/AprilTagDetectionArray", ros_version=2)[0])
        s_info = w.register_msgdef("sensor_msgs/msg/CameraInfo",
                                   ts.generate_msgdef("sensor_msgs/msg/CameraInfo", ros_version=2)[0])
        header = {"stamp": {"sec": T0 // 10**9, "nanosec": 0}, "frame_id": "fisheye_optical"}
        w.write_message("/fisheye/camera_info", s_info, {
            "header": header, "height": 800, "width": 848, "distortion_model": "equidistant",
            "d": FISHEYE.tolist(), "k": K.reshape(-1).tolist(), "r": np.eye(3).reshape(-1).tolist(),
            "p": np.column_stack([K, np.zeros(3)]).reshape(-1).tolist(), "binning_x": 0, "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False}},
            log_time=T0, publish_time=T0)
        dets = []
        for i, (r, t) in enumerate(zip(rvecs, tvecs, strict=True)):
            px = _render("equidistant", r, t, square_object_points(0.2))
            c = _render("equidistant", r, t, np.zeros((1, 3)))[0]
            dets.append({"family": "36h11", "id": i, "hamming": 0, "goodness": 0.0, "decision_margin": 50.0,
                         "centre": {"x": c[0], "y": c[1]}, "corners": [{"x": x, "y": y} for x, y in px],
                         "homography": [0.0] * 9})
        w.write_message("/tags", s_tags, {"header": header, "detections": dets}, log_time=T0 + 1, publish_time=T0)
        w.finish()
    chain = ChainConfig.from_dict({"frames": {"camera": "fisheye_optical"}, "topics": {"detections": "/tags"},
                                   "evidence": {"tag_size_m": 0.2}})
    timeline = open_log(path, chain).timeline
    obs = timeline.observations
    assert obs.label.tolist() == [str(i) for i in range(6)]
    assert np.abs(obs.depth_m - tvecs[:, 2]).max() < 1e-6
    assert np.abs(np.column_stack([obs.u, obs.v]) - _expected_pixels("equidistant", tvecs)).max() < 1e-5
    # Hop 1 of the replay (its own fisheye undistortion) takes the pixel and depth back to the tag centre.
    p_cam = CameraModel.from_table(timeline.cameras).pixel_to_camera(obs.u, obs.v, obs.depth_m)
    assert np.abs(p_cam - tvecs).max() < 1e-6


def test_pose_and_vertex_layouts_ros1(tmp_path: Path) -> None:
    """apriltag_ros poses, fiducial_msgs vertices and transforms, vision_msgs Detection3D (ROS 1)."""
    b = _Ros1()
    T = b.T
    rng = np.random.default_rng(44)
    rvecs, tvecs = _poses(rng, 4)
    stamp = T0 + 10**9
    cov = np.zeros(36)
    pws = T["geometry_msgs/msg/PoseWithCovarianceStamped"](
        header=b.header(stamp, "cam_optical"),
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=b.pose(tvecs[0]), covariance=cov))
    april = T["apriltag_ros/msg/AprilTagDetectionArray"](header=b.header(stamp, "cam_optical"), detections=[
        T["apriltag_ros/msg/AprilTagDetection"](id=np.array([5], dtype=np.int32), size=np.array([0.1]), pose=pws)])
    corners = _render("plumb_bob", rvecs[1], tvecs[1], square_object_points(0.14)).reshape(-1)
    vertices = T["fiducial_msgs/msg/FiducialArray"](header=b.header(stamp, "cam_optical"), image_seq=1, fiducials=[
        T["fiducial_msgs/msg/Fiducial"](fiducial_id=12, direction=0, **{
            f"{axis}{i}": float(corners[2 * i + (axis == "y")]) for i in range(4) for axis in "xy"})])
    tr = T["geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](*tvecs[2]),
                                          rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    transforms = T["fiducial_msgs/msg/FiducialTransformArray"](
        header=b.header(stamp, "cam_optical"), image_seq=1, transforms=[T["fiducial_msgs/msg/FiducialTransform"](
            fiducial_id=13, transform=tr, image_error=0.1, object_error=0.01, fiducial_area=100.0)])
    cloud = T["sensor_msgs/msg/PointCloud2"](header=b.header(0, ""), height=0, width=0, fields=[], is_bigendian=False,
                                             point_step=0, row_step=0, data=np.zeros(0, dtype=np.uint8),
                                             is_dense=True)
    det3d = T["vision_msgs/msg/Detection3DArray"](header=b.header(stamp, "cam_optical"), detections=[
        T["vision_msgs/msg/Detection3D"](
            header=b.header(0, ""), results=[T["vision_msgs/msg/ObjectHypothesisWithPose"](
                id=42, score=0.9,
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=b.pose(tvecs[3]), covariance=cov))],
            bbox=T["vision_msgs/msg/BoundingBox3D"](center=b.pose(tvecs[3]),
                                                    size=T["geometry_msgs/msg/Vector3"](0.1, 0.1, 0.1)),
            source_cloud=cloud)])
    msgs = [("/camera_info", "sensor_msgs/msg/CameraInfo", T0, b.camera_info(T0, "cam_optical", "plumb_bob")),
            ("/tag_detections", "apriltag_ros/msg/AprilTagDetectionArray", stamp, april),
            ("/fiducial_vertices", "fiducial_msgs/msg/FiducialArray", stamp, vertices),
            ("/fiducial_transforms", "fiducial_msgs/msg/FiducialTransformArray", stamp, transforms),
            ("/objects", "vision_msgs/msg/Detection3DArray", stamp, det3d)]
    path = _write_ros1(tmp_path / "layouts.bag", msgs, b.ts)
    loaded = open_log(path)  # no chain: every topic of a kind framechain understands
    assert {t: loaded.decoded_topics[t] for t in ("/tag_detections", "/fiducial_vertices", "/fiducial_transforms",
                                                  "/objects")} == {
        "/tag_detections": "apriltag_poses", "/fiducial_vertices": "fiducial_vertices",
        "/fiducial_transforms": "fiducial_transforms", "/objects": "detections_3d"}
    obs = loaded.timeline.observations
    by_source = {s: i for i, s in enumerate(obs.source.tolist())}
    order = [by_source[t] for t in ("/tag_detections", "/fiducial_vertices", "/fiducial_transforms", "/objects")]
    assert obs.label[order].tolist() == ["5", "12", "13", "42"]
    # Points carry their own z; the vertices got no size (no chain): a bearing only.
    assert np.abs(obs.depth_m[order][[0, 2, 3]] - tvecs[[0, 2, 3], 2]).max() < 1e-12
    assert np.isnan(obs.depth_m[order][1])
    uv = np.column_stack([obs.u, obs.v])[order]
    assert np.abs(uv - _expected_pixels("plumb_bob", tvecs)).max() < 1e-5
    assert obs.score[order][3] == 0.9


def test_camera_points_need_no_intrinsics(tmp_path: Path) -> None:
    """A PointStamped named as the detections is a camera-frame point: with no camera model it is kept as it
    is (in normalised image coordinates, with a camera-less model: intrinsics would only draw it); with a
    CameraInfo it is projected to its pixel."""
    b = _Ros1()
    pts = np.array([[0.1, -0.05, 1.2], [-0.2, 0.1, 2.0], [0.0, 0.0, -1.0]])
    msgs = [("/target_cam", "geometry_msgs/msg/PointStamped", T0 + i,
             b.T["geometry_msgs/msg/PointStamped"](header=b.header(T0 + i, "cam_optical"), point=b.point(*p)))
            for i, p in enumerate(pts)]
    chain = ChainConfig.from_dict({"frames": {"camera": "cam_optical"}, "topics": {"detections": "/target_cam"}})
    path = _write_ros1(tmp_path / "points.bag", msgs, b.ts)
    loaded = open_log(path, chain)
    assert loaded.decoded_topics["/target_cam"] == "camera_point"
    bare = loaded.timeline.observations
    assert np.abs(np.column_stack([bare.u, bare.v]) - pts[:2, :2] / pts[:2, 2:]).max() < 1e-15
    assert bare.depth_m.tolist() == pts[:2, 2].tolist()
    assert loaded.timeline.metadata["fiducials"]["counts"]["/target_cam"]["rejected"] == {"behind_camera": 1}
    cams = loaded.timeline.cameras
    assert (cams.frame.tolist(), cams.width.tolist(), cams.height.tolist()) == (["cam_optical"], [0], [0])
    assert any("no intrinsics; its detections are 3D points in the camera frame" in n for n in loaded.info.notes)
    model = CameraModel.from_table(cams)  # hop 1 of the replay gives the logged points back, unbounded by an image
    assert model.inside(bare.u, bare.v).all()
    assert np.abs(model.pixel_to_camera(bare.u, bare.v, bare.depth_m) - pts[:2]).max() < 1e-15
    with_info = _write_ros1(tmp_path / "points_info.bag", [
        ("/camera_info", "sensor_msgs/msg/CameraInfo", T0, b.camera_info(T0, "cam_optical", "plumb_bob")), *msgs],
        b.ts)
    loaded = open_log(with_info, chain)
    obs = loaded.timeline.observations
    assert np.abs(obs.depth_m - pts[:2, 2]).max() == 0
    assert np.abs(np.column_stack([obs.u, obs.v]) - _expected_pixels("plumb_bob", pts[:2])).max() < 1e-6
    counts = loaded.timeline.metadata["fiducials"]["counts"]["/target_cam"]
    assert counts == {"detections": 3, "observations": 2, "bearing_only": 0, "rejected": {"behind_camera": 1}}
    # The replay's totals count the detection the reader rejected: every detection is accounted for.
    from framechain.replay import replay

    replayed = replay(loaded.timeline, chain.frames).counts()
    assert replayed["total"] == 3
    assert replayed["rejected"]["behind_camera"] == 1
    assert replayed["replayed"] + sum(replayed["rejected"].values()) == 3


def test_detection3d_ros2_mcap(tmp_path: Path) -> None:
    from mcap_ros2.writer import Writer

    ts = _store(ros1=False)
    path = tmp_path / "det3d.mcap"
    centre = [0.3, -0.1, 1.7]
    with path.open("wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("vision_msgs/msg/Detection3DArray",
                                   ts.generate_msgdef("vision_msgs/msg/Detection3DArray", ros_version=2)[0])
        header = {"stamp": {"sec": T0 // 10**9, "nanosec": 500}, "frame_id": "cam_optical"}
        pose = {"position": dict(zip("xyz", centre, strict=True)), "orientation": {"x": 0, "y": 0, "z": 0, "w": 1.0}}
        det = {"header": header, "id": "track-9", "bbox": {"center": pose, "size": {"x": 0.2, "y": 0.2, "z": 0.2}},
               "results": [{"hypothesis": {"class_id": "cup", "score": 0.75},
                            "pose": {"pose": pose, "covariance": [0.0] * 36}}]}
        w.write_message("/objects", schema, {"header": header, "detections": [det]}, log_time=T0 + 9,
                        publish_time=T0)
        w.finish()
    info = {"file": str(tmp_path / "cam.yaml")}
    (tmp_path / "cam.yaml").write_text(yaml.safe_dump({
        "image_width": 640, "image_height": 480, "camera_name": "cam",
        "camera_matrix": {"rows": 3, "cols": 3, "data": K.reshape(-1).tolist()},
        "distortion_model": "plumb_bob", "distortion_coefficients": {"rows": 1, "cols": 5, "data": PLUMB_BOB.tolist()},
    }))
    chain = ChainConfig.from_dict({"frames": {"camera": "cam_optical"}, "topics": {"detections": "/objects"},
                                   "calibration": info})
    obs = open_log(path, chain).timeline.observations
    assert obs.label.tolist() == ["cup"]
    assert obs.stamp_ns.tolist() == [T0 + 500]
    assert obs.depth_m.tolist() == [1.7]
    assert np.abs(np.column_stack([obs.u, obs.v]) - _expected_pixels("plumb_bob", np.array([centre]))).max() < 1e-6


# -- the real TagSLAM stairs log ---------------------------------------------------------------------
def _tagslam_cameras(folder: Path) -> tuple[CameraTable, dict[str, str]]:
    """The four cameras from cameras.yaml by hand (Kalibr: radtan is plumb_bob, equidistant is fisheye)."""
    cams = yaml.safe_load((folder / "cameras.yaml").read_text())
    frames = {"cam0": "t265_fisheye1_optical_frame", "cam1": "t265_fisheye2_optical_frame",
              "cam2": "left_tof_optical_frame", "cam3": "right_tof_optical_frame"}
    tables = []
    for name, c in cams.items():
        fx, fy, cx, cy = c["intrinsics"]
        model = {"radtan": "plumb_bob"}.get(c["distortion_model"], c["distortion_model"])
        tables.append(CameraTable.from_intrinsics(frames[name], fx=fx, fy=fy, cx=cx, cy=cy, width=c["resolution"][0],
                                                  height=c["resolution"][1], distortion_model=model,
                                                  distortion=c["distortion_coeffs"]))
    return CameraTable.concat(tables), {c["tagtopic"]: frames[n] for n, c in cams.items()}


def _tagslam_rows(folder: Path, size: Any) -> FiducialRows:
    from rosbags.highlevel import AnyReader

    rows = FiducialRows(size_for_tag=size)
    with AnyReader([folder / "tag_detections.bag"]) as reader:
        conns = [c for c in reader.connections if c.topic.endswith("/tags")]
        for conn, t, raw in reader.messages(connections=conns):
            rows.apriltags(conn.topic, t, reader.deserialize(raw, conn.msgtype))
    return rows


def test_tagslam_stairs_depths(realdata: Path) -> None:
    folder = realdata / STAIRS
    cameras, frames = _tagslam_cameras(folder)
    small = {str(i) for i in range(100, 109)}  # tagslam.yaml: ids 100-108 are 0.10 m, the rest 0.16 m
    res = resolve_fiducials(_tagslam_rows(folder, lambda label: 0.10 if label in small else 0.16), cameras)
    assert sum(c["detections"] for c in res.counts.values()) == 3079
    assert all(not c["rejected"] for c in res.counts.values())
    assert set(res.camera_frame.tolist()) == set(frames.values())
    reproj = np.array(list(res.side["reprojection_px"]), dtype=float)
    assert np.median(reproj) < 0.1
    assert np.percentile(reproj, 99) < 1.0
    assert 0.70 < np.median(res.depth_m) < 0.80  # 0.749 m
    # Every tag taken as 0.16 m gives REFERENCE.md's 0.85 m: depth scales with the size.
    res16 = resolve_fiducials(_tagslam_rows(folder, lambda label: 0.16), cameras)
    assert abs(np.median(res16.depth_m) - 0.85) < 0.01
    sized_small = np.isin(res.label, sorted(small))
    assert np.allclose(res16.depth_m[sized_small] * 0.10 / 0.16, res.depth_m[sized_small], rtol=1e-9)
    # The detector's centre pixel (in distorted pixels) lies near the projected PnP centre.
    det_centre = np.array(res.side["detector_centre_px"], dtype=float)
    gap = np.linalg.norm(det_centre - np.column_stack([res.u, res.v]), axis=1)
    assert np.median(gap) < 1.0


def test_tagslam_stairs_through_open_log(realdata: Path) -> None:
    folder = realdata / STAIRS
    chain = ChainConfig.from_dict({
        "frames": {"camera": "t265_fisheye1_optical_frame", "body": "rig", "world": "world"},
        "topics": {"detections": "/t265/fisheye1/tags"},
        "evidence": {"tag_size_m": {"default": 0.16, **dict.fromkeys(range(100, 109), 0.1)}}})
    bare = open_log(folder / "tag_detections.bag", chain)
    counts = bare.timeline.metadata["fiducials"]["counts"]["/t265/fisheye1/tags"]
    assert counts == {"detections": 1274, "observations": 0, "bearing_only": 0, "rejected": {"no_intrinsics": 1274}}
    assert any("no intrinsics for camera t265_fisheye1_optical_frame" in n for n in bare.info.notes)
    calibrated = ChainConfig.from_dict({**chain.to_dict(), "calibration": {"file": "cameras.yaml", "camera": "cam0"}},
                                       base_dir=folder)
    obs = open_log(folder / "tag_detections.bag", calibrated).timeline.observations
    assert len(obs) == 1274
    assert 0.70 < float(np.median(obs.depth_m)) < 0.78


def test_opencv_is_imported_only_when_needed(monkeypatch: pytest.MonkeyPatch) -> None:
    import subprocess
    import sys

    from framechain.vision.opencv import MissingOpenCVError

    code = "import sys, framechain.adapters, framechain.adapters.messages.fiducials; print('cv2' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() \
        == "False"
    monkeypatch.setitem(sys.modules, "cv2", None)  # as if not installed
    with pytest.raises(MissingOpenCVError, match=r"need OpenCV: pip install 'opencv-python-headless>=4.10'"):
        solve_square_tags(CameraModel("cam", K, 0, 0), np.zeros((1, 4, 2)), 0.1)


def test_apriltag_ros2_old_array_layout() -> None:
    """apriltag_msgs before 2.0: ``float64[2] centre`` and ``float64[8] corners`` (CDR round trip)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    types = get_types_from_msg("string family\nint32 id\nint32 hamming\nfloat32 goodness\nfloat32 decision_margin\n"
                               "float64[2] centre\nfloat64[8] corners\nfloat64[9] homography\n",
                               "apriltag_msgs/msg/AprilTagDetection")
    types.update(get_types_from_msg("std_msgs/Header header\napriltag_msgs/AprilTagDetection[] detections\n",
                                    "apriltag_msgs/msg/AprilTagDetectionArray"))
    ts.register(types)
    T = ts.types
    corners = np.array([10.0, 20.0, 30.0, 20.0, 30.0, 40.0, 10.0, 40.0])
    det = T["apriltag_msgs/msg/AprilTagDetection"](family="36h11", id=4, hamming=0, goodness=0.0,
                                                   decision_margin=1.0, centre=np.array([20.0, 30.0]),
                                                   corners=corners, homography=np.zeros(9))
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=5, nanosec=6), frame_id="cam")
    name = "apriltag_msgs/msg/AprilTagDetectionArray"
    msg = ts.deserialize_cdr(ts.serialize_cdr(T[name](header=header, detections=[det]), name), name)
    rows = FiducialRows()
    rows.apriltags("/tags", 7, msg)
    assert rows.corners_px == corners.tolist()
    assert rows.centre_px == [20.0, 30.0]
    assert (rows.label, rows.stamp_ns, rows.frame) == (["4"], [5_000_000_006], ["cam"])
