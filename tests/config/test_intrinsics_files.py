"""Camera calibration files read into intrinsics: ROS camera_info YAML, Kalibr camchain (a camera named by its
name, image topic or tag topic), OpenCV FileStorage in both YAML headers, the real TagSLAM cameras.yaml; and the chain
keys that name them, resolved against the chain file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from framechain.config.calibration import CalibrationError, read_intrinsics_file
from framechain.config.chain import ChainConfig
from tests.helpers.calibration_files import KALIBR, ROS_CAMERA_INFO, intrinsic_matrix
from tests.helpers.realdata import STAIRS


def test_ros_camera_info_yaml(tmp_path: Path) -> None:
    (tmp_path / "info.yaml").write_text(ROS_CAMERA_INFO)
    i = read_intrinsics_file(tmp_path / "info.yaml")
    np.testing.assert_array_equal(i.K, intrinsic_matrix(612.5, 611.75, 321.25, 243.5))
    assert (i.width, i.height, i.distortion_model) == (640, 480, "plumb_bob")
    assert i.distortion == (0.11, -0.22, 0.001, -0.002, 0.05)
    assert read_intrinsics_file(tmp_path / "info.yaml", camera="narrow_stereo").fx == 612.5
    with pytest.raises(CalibrationError, match="camera 'wide' is not in the file; it holds camera_name"):
        read_intrinsics_file(tmp_path / "info.yaml", camera="wide")


def test_opencv_filestorage_yaml(tmp_path: Path) -> None:
    import cv2

    path = tmp_path / "opencv.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)  # OpenCV's own writer: %YAML:1.0, !!opencv-matrix
    fs.write("image_width", 1280)
    fs.write("image_height", 720)
    fs.write("camera_matrix", intrinsic_matrix(910.0, 909.5, 640.5, 360.25))
    fs.write("distortion_coefficients", np.array([[0.1, -0.05, 0.0, 0.001, 0.002, 0.01, -0.02, 0.003]]))
    fs.release()
    text = path.read_text()
    assert text.startswith("%YAML 1.2")  # OpenCV 4; OpenCV 3 wrote "%YAML:1.0", not valid YAML: read both
    (tmp_path / "opencv3.yaml").write_text("%YAML:1.0\n" + text.split("\n", 1)[1])
    for name in ("opencv.yaml", "opencv3.yaml"):
        i = read_intrinsics_file(tmp_path / name)
        np.testing.assert_array_equal(i.K, intrinsic_matrix(910.0, 909.5, 640.5, 360.25))
        assert (i.width, i.height, i.distortion_model) == (1280, 720, "rational_polynomial")
        np.testing.assert_array_equal(i.distortion, [0.1, -0.05, 0.0, 0.001, 0.002, 0.01, -0.02, 0.003])


@pytest.mark.parametrize(("camera", "name"), [
    ("cam0", "cam0"), ("/cam0/image_raw", "cam0"), ("cam1", "cam1"), ("/t265/fisheye1/image_raw", "cam1"),
    ("/t265/fisheye1/tags", "cam1"),
])
def test_kalibr_camera_by_name_rostopic_or_tagtopic(camera: str, name: str, tmp_path: Path) -> None:
    (tmp_path / "camchain.yaml").write_text(KALIBR)
    i = read_intrinsics_file(tmp_path / "camchain.yaml", camera=camera)
    assert i.source.endswith(f"[{name}]")
    if name == "cam0":  # radtan = plumb_bob k1 k2 p1 p2
        np.testing.assert_array_equal(i.K, intrinsic_matrix(458.654, 457.296, 367.215, 248.375))
        assert (i.width, i.height, i.distortion_model) == (752, 480, "plumb_bob")
        assert i.distortion == (-0.28, 0.07, 0.0002, 0.00002)
    else:  # equidistant = OpenCV fisheye k1..k4
        np.testing.assert_array_equal(i.K, intrinsic_matrix(286.7, 286.8, 420.9, 396.9))
        assert (i.width, i.height, i.distortion_model) == (848, 800, "equidistant")
        assert i.distortion == (-0.0067, 0.0393, -0.0356, 0.0055)


def test_kalibr_camera_errors_list_the_names(tmp_path: Path) -> None:
    (tmp_path / "camchain.yaml").write_text(KALIBR)
    with pytest.raises(CalibrationError, match=r"2 cameras \(cam0, cam1\); pick one with camera:"):
        read_intrinsics_file(tmp_path / "camchain.yaml")
    with pytest.raises(CalibrationError, match=r"camera 'cam7' is not in the file; its cameras are "
                       r"cam0 \(/cam0/image_raw\), cam1 \(/t265/fisheye1/image_raw\)"):
        read_intrinsics_file(tmp_path / "camchain.yaml", camera="cam7")


def test_real_tagslam_cameras_yaml(realdata: Path) -> None:
    path = realdata / STAIRS / "cameras.yaml"
    fisheye = read_intrinsics_file(path, camera="/t265/fisheye2/tags")
    np.testing.assert_array_equal(fisheye.K, intrinsic_matrix(286.80, 286.692, 424.236, 401.151))
    assert (fisheye.width, fisheye.height, fisheye.distortion_model) == (848, 800, "equidistant")
    assert fisheye.distortion[3] == 0.008304417133331299
    tof = read_intrinsics_file(path, camera="cam2")
    np.testing.assert_array_equal(tof.K, intrinsic_matrix(210.689, 210.689, 106.708, 87.122))
    assert (tof.width, tof.height, tof.distortion_model, len(tof.distortion)) == (224, 171, "plumb_bob", 5)


def test_chain_keys_round_trip_and_resolve_against_the_chain_file(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    from framechain.config.errors import ChainConfigError

    raw = {"calibration": [{"file": "cams/c.yaml", "camera": "cam0"}, {"file": "/abs/d.yaml", "frame": "tof"}],
           "mounts": [{"parent": "a", "child": "b", "xyz": [1, 2, 3], "rpy": [0.1, 0.2, 0.3]}],
           "urdf": "robot.urdf", "topics": {"odometry": ["/odom", {"topic": "/pose", "child": "rig"}]}}
    (tmp_path / "chain.yaml").write_text(ChainConfig.from_dict(raw).to_yaml())
    config = ChainConfig.from_yaml(tmp_path / "chain.yaml")
    assert config == ChainConfig.from_dict(raw)
    assert config.resolve("cams/c.yaml") == tmp_path / "cams/c.yaml"
    assert config.resolve("/abs/d.yaml") == Path("/abs/d.yaml")
    monkeypatch.chdir(tmp_path / "..")
    assert ChainConfig.from_dict(raw).resolve("robot.urdf") == Path("robot.urdf")  # no base: the working directory
    with pytest.raises(ChainConfigError, match=r"calibration\[1\]: give frame:"):
        ChainConfig.from_dict({"calibration": [{"file": "a.yaml"}, {"file": "b.yaml"}]})
    with pytest.raises(ChainConfigError, match=r"calibration: needs file:"):
        ChainConfig.from_dict({"calibration": {"camera": "cam0"}})
    with pytest.raises(ChainConfigError, match=r"topics.odometry\[1\]: expected a topic name"):
        ChainConfig.from_dict({"topics": {"odometry": ["/odom", 3]}})
