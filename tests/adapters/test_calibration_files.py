"""Camera calibration files named by the chain (``calibration: {file, camera}``) join the log's CameraTable: the
file's camera replaces the log's CameraInfo with a note saying how they differ (or that they agree), one file serves
several frames, a bad entry is one line, and the real TagSLAM bag gets its cameras and mount from the files beside
it. Reading the files themselves: tests/config/test_intrinsics_files.py."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from framechain.adapters import open_log
from framechain.cli.main import main
from framechain.config.chain import ChainConfig
from tests.helpers.calibration_files import KALIBR, ROS_CAMERA_INFO, intrinsic_matrix
from tests.helpers.realdata import STAIRS

T0 = 1_700_000_000 * 10**9


def _camera_info_bag(path: Path, frame: str, k: list[float], d: list[float], size: tuple[int, int]) -> Path:
    """A ROS 1 bag with /tf and CameraInfo, written with rosbags' writer."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = ts.types

    def header(t: int, frame_id: str) -> Any:
        return T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=0),
                                        frame_id=frame_id)

    with Writer(path) as w:
        info = w.add_connection("/camera/camera_info", "sensor_msgs/msg/CameraInfo", typestore=ts)
        tf = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        for n in range(3):
            t = T0 + n * 10**9
            msg = T["sensor_msgs/msg/CameraInfo"](
                header=header(t, frame), height=size[1], width=size[0], distortion_model="plumb_bob",
                D=np.array(d), K=np.array(k), R=np.eye(3).reshape(-1), P=np.zeros(12), binning_x=0, binning_y=0,
                roi=roi)
            w.write(info, t, bytes(ts.serialize_ros1(msg, "sensor_msgs/msg/CameraInfo")))
            edge = T["geometry_msgs/msg/TransformStamped"](
                header=header(t, "base_link"), child_frame_id=frame,
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=0.3, y=0.0, z=0.8),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
            w.write(tf, t, bytes(ts.serialize_ros1(T["tf2_msgs/msg/TFMessage"](transforms=[edge]),
                                                   "tf2_msgs/msg/TFMessage")))
    return path


def test_file_calibration_replaces_the_logs_camera_info_with_a_note(tmp_path: Path) -> None:
    # The log's CameraInfo: fx 600 at 640x480; the file (relative to the chain file in another folder): 612.5.
    log = _camera_info_bag(tmp_path / "log.bag", "camera_optical", [600.0, 0, 320.0, 0, 600.0, 240.0, 0, 0, 1],
                           [0.0] * 5, (640, 480))
    (tmp_path / "config").mkdir()
    (tmp_path / "config/info.yaml").write_text(ROS_CAMERA_INFO)
    chain = tmp_path / "config/chain.yaml"
    chain.write_text("frames: {camera: camera_optical, body: base_link, world: odom}\n"
                     "topics: {camera_info: /camera/camera_info}\ncalibration: {file: info.yaml}\n")
    loaded = open_log(log, ChainConfig.from_yaml(chain))
    cams = loaded.timeline.cameras
    assert len(cams) == 1  # the file's row only, for every stamp
    assert cams.source.tolist() == ["info.yaml"]
    np.testing.assert_array_equal(cams.K[0], intrinsic_matrix(612.5, 611.75, 321.25, 243.5))
    assert int(cams.stamp_ns[0]) == 0  # timeless: in force before the first observation
    note = next(n for n in loaded.info.notes if n.startswith("camera camera_optical:"))
    assert "the calibration from info.yaml is used (the chain names it)" in note
    assert "/camera/camera_info" in note
    assert "fx 612.5 (file) vs 600 (log)" in note
    assert "cy 243.5 (file) vs 240 (log)" in note
    assert "distortion plumb_bob [0.11, -0.22, 0.001, -0.002, 0.05] (file) vs plumb_bob [0, 0, 0, 0, 0] (log)" in note


def test_file_calibration_that_agrees_says_so(tmp_path: Path) -> None:
    log = _camera_info_bag(tmp_path / "log.bag", "camera_optical",
                           [612.5, 0, 321.25, 0, 611.75, 243.5, 0, 0, 1], [0.11, -0.22, 0.001, -0.002, 0.05],
                           (640, 480))
    (tmp_path / "info.yaml").write_text(ROS_CAMERA_INFO)
    config = ChainConfig.from_dict({"frames": {"camera": "camera_optical", "body": "base_link", "world": "odom"},
                                    "calibration": {"file": "info.yaml"}}, base_dir=tmp_path)
    loaded = open_log(log, config)
    assert any("agrees with the log's CameraInfo on /camera/camera_info; the file's is used" in n
               for n in loaded.info.notes)


def test_kalibr_cameras_for_several_frames(tmp_path: Path) -> None:
    log = _camera_info_bag(tmp_path / "log.bag", "camera_optical", [600.0, 0, 320.0, 0, 600.0, 240.0, 0, 0, 1],
                           [0.0] * 5, (640, 480))
    (tmp_path / "camchain.yaml").write_text(KALIBR)
    config = ChainConfig.from_dict({
        "frames": {"camera": "fisheye_optical", "body": "base_link", "world": "odom"},
        "calibration": [{"file": "camchain.yaml", "camera": "/t265/fisheye1/tags"},
                        {"file": "camchain.yaml", "camera": "cam0", "frame": "cam0_optical"}],
    }, base_dir=tmp_path)
    cams = open_log(log, config).timeline.cameras
    by = {str(f): i for i, f in enumerate(cams.frame.tolist())}
    assert set(by) == {"fisheye_optical", "cam0_optical", "camera_optical"}  # the log's own camera stays
    assert str(cams.source[by["fisheye_optical"]]) == "camchain.yaml [cam1]"
    assert str(cams.distortion_model[by["fisheye_optical"]]) == "equidistant"
    assert float(cams.K[by["cam0_optical"], 0, 0]) == 458.654


@pytest.mark.parametrize(("entry", "message"), [
    ("{file: missing.yaml}", "missing.yaml: calibration file not found"),
    ("{file: camchain.yaml, camera: cam9}", "camera 'cam9' is not in the file; its cameras are cam0"),
])
def test_calibration_errors_are_one_line(entry: str, message: str, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    log = _camera_info_bag(tmp_path / "log.bag", "camera_optical", [600.0, 0, 320.0, 0, 600.0, 240.0, 0, 0, 1],
                           [0.0] * 5, (640, 480))
    (tmp_path / "camchain.yaml").write_text(KALIBR)
    chain = tmp_path / "chain.yaml"
    chain.write_text(f"frames: {{camera: camera_optical, body: base_link, world: odom}}\ncalibration: {entry}\n")
    assert main(["tf", str(log), "base_link", "camera_optical", "--chain", str(chain)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert message in err
    if "missing" in entry:  # the resolved path says where it was looked for
        assert f"{(tmp_path / 'missing.yaml').resolve()}: calibration file not found" in err


def test_real_tagslam_bag_with_calibration_and_mount(realdata: Path, tmp_path: Path) -> None:
    """No /tf, no CameraInfo: four cameras from cameras.yaml, the rig mount from tagslam.yaml's
    T_body_odom (position + rotation vector), the pose from nav_msgs/Odometry."""
    from scipy.spatial.transform import Rotation

    from framechain.replay import TransformBuffer

    folder = realdata / STAIRS
    entries = "\n".join(
        f"  - {{file: {folder / 'cameras.yaml'}, camera: /{topic}/tags, frame: {frame}}}"
        for topic, frame in (("t265/fisheye1", "t265_fisheye1_optical_frame"),
                             ("t265/fisheye2", "t265_fisheye2_optical_frame"),
                             ("left_tof", "left_tof_optical_frame"), ("right_tof", "right_tof_optical_frame")))
    rotvec = [0.0135696, -0.0062165, 3.1391944]
    chain = tmp_path / "chain.yaml"
    chain.write_text(
        "frames: {camera: t265_fisheye1_optical_frame, body: basalt_pose_frame, world: world}\n"
        f"topics: {{odometry: /vio_node/odom}}\ncalibration:\n{entries}\n"
        f"mounts:\n  - {{parent: basalt_pose_frame, child: t265_fisheye1_optical_frame, "
        f"xyz: [0.010699568316340447, 0, 0], rotvec: {rotvec}}}\n")
    loaded = open_log(folder / "tag_detections.bag", ChainConfig.from_yaml(chain))
    cams = loaded.timeline.cameras
    assert sorted(cams.source.tolist()) == [f"cameras.yaml [cam{i}]" for i in range(4)]
    assert cams.distortion_model.tolist().count("equidistant") == 2
    tf = loaded.timeline.transforms
    assert int((tf.source == "/vio_node/odom").sum()) == 2596
    buffer = TransformBuffer(tf)
    stamp = np.array([int(np.median(tf.stamp_ns[tf.source == "/vio_node/odom"]))])
    got = buffer.lookup("basalt_pose_frame", "t265_fisheye1_optical_frame", stamp)
    expected = Rotation.from_rotvec(rotvec)
    assert abs(float(got.quat_xyzw[0] @ expected.as_quat())) == pytest.approx(1.0, abs=1e-12)
    assert buffer.lookup("world", "t265_fisheye1_optical_frame", stamp).ok.all()
