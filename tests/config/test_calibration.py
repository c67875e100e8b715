"""Camera calibration files: inline, ROS camera_info, OpenCV FileStorage; mounts and the optical convention."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain.config.calibration import CalibrationError, load_calibration, read_intrinsics_file
from framechain.config.mount import Mount
from tests.helpers.lerobot_scene import LINK_FROM_OPTICAL, rx, ry, rz

INTRINSICS = {"fx": 600.0, "fy": 610.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}

ROS_CAMERA_INFO = """\
image_width: 1280
image_height: 720
camera_name: wrist
camera_matrix:
  rows: 3
  cols: 3
  data: [912.5, 0, 641.2, 0, 910.1, 362.7, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.11, -0.23, 0.001, -0.002, 0.05]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [912.5, 0, 641.2, 0, 0, 910.1, 362.7, 0, 0, 0, 1, 0]
"""


def _compose(edges: list[Mount]) -> np.ndarray:
    T = np.eye(4)
    for edge in edges:
        step = np.eye(4)
        step[:3, :3] = Rotation.from_quat(edge.quat_xyzw).as_matrix()
        step[:3, 3] = edge.xyz
        T = T @ step
    return T


def test_inline_optical_false_appends_rep103_rotation() -> None:
    cal = load_calibration({
        "intrinsics": INTRINSICS,
        "mount": {"parent": "flange_link", "xyz": [0.1, 0.2, 0.3], "rpy": [0.3, -0.2, 0.1], "optical": False},
    }, name="wrist")
    assert cal.optical_frame == "wrist_optical_frame"
    edges = cal.mount_edges()
    assert [(e.parent, e.child, e.optical) for e in edges] == [("flange_link", "wrist_link", False),
                                                              ("wrist_link", "wrist_optical_frame", True)]
    T = _compose(edges)
    # URDF rpy: R = Rz(yaw) Ry(pitch) Rx(roll), then camera_link -> optical (REP-103) by hand.
    expected = rz(0.1) @ ry(-0.2) @ rx(0.3) @ LINK_FROM_OPTICAL
    np.testing.assert_allclose(T[:3, :3], expected, atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [0.1, 0.2, 0.3])
    # Optical z (forward) is camera_link x (forward).
    np.testing.assert_allclose(Rotation.from_quat(edges[1].quat_xyzw).apply([0, 0, 1.0]), [1.0, 0, 0], atol=1e-15)
    table = cal.camera_table()
    assert table.frame.tolist() == ["wrist_optical_frame"]
    np.testing.assert_allclose(table.K[0], [[600, 0, 320], [0, 610, 240], [0, 0, 1]])


def test_optical_true_mount_is_the_optical_frame_and_quaternion_accepted() -> None:
    q = [0.5, -0.5, 0.5, -0.5]
    cal = load_calibration({
        "frame": "/cam_optical", "intrinsics": INTRINSICS,
        "mount": {"parent": "tool0", "xyz": [0, 0, 0.05], "quat_xyzw": q, "optical": True},
    }, name="scene")
    edges = cal.mount_edges()
    assert len(edges) == 1
    assert (edges[0].parent, edges[0].child, edges[0].optical) == ("tool0", "cam_optical", True)
    np.testing.assert_allclose(edges[0].quat_xyzw, q)


def test_ros_camera_info_file(tmp_path: Path) -> None:
    (tmp_path / "wrist_info.yaml").write_text(ROS_CAMERA_INFO)
    (tmp_path / "wrist.yaml").write_text(yaml.safe_dump({
        "intrinsics_file": "wrist_info.yaml",
        "mount": {"parent": "flange_link", "optical": True},
    }))
    cal = load_calibration(tmp_path / "wrist.yaml")
    assert cal.name == "wrist"
    i = cal.intrinsics
    assert (i.fx, i.fy, i.cx, i.cy, i.width, i.height) == (912.5, 910.1, 641.2, 362.7, 1280, 720)
    assert i.distortion_model == "plumb_bob"
    assert i.distortion == (0.11, -0.23, 0.001, -0.002, 0.05)


def test_opencv_filestorage_yaml(tmp_path: Path) -> None:
    cv2 = pytest.importorskip("cv2")
    K = np.array([[700.5, 0.0, 330.25], [0.0, 701.25, 245.5], [0.0, 0.0, 1.0]])
    D = np.array([[-0.3, 0.12, 0.001, 0.0005, -0.02, 0.01, 0.002, 0.003]])
    path = tmp_path / "calib_cv.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 800)
    fs.write("image_height", 600)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", D)
    fs.release()
    assert "!!opencv-matrix" in path.read_text()
    i = read_intrinsics_file(path)
    assert (i.fx, i.fy, i.cx, i.cy, i.width, i.height) == (700.5, 701.25, 330.25, 245.5, 800, 600)
    assert i.distortion_model == "rational_polynomial"
    np.testing.assert_allclose(i.distortion, D.ravel())


def test_legacy_opencv_header(tmp_path: Path) -> None:
    # OpenCV before 4.x wrote "%YAML:1.0", which is not valid YAML.
    path = tmp_path / "old.yml"
    path.write_text(
        "%YAML:1.0\n---\nimage_width: 320\nimage_height: 240\n"
        "K: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 300., 0., 160., 0., 301., 120., 0., 0., 1. ]\n"
        "D: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ 0.1, 0., 0., 0., 0. ]\n"
    )
    i = read_intrinsics_file(path)
    assert (i.fx, i.fy, i.cx, i.cy, i.width, i.height) == (300.0, 301.0, 160.0, 120.0, 320, 240)
    assert i.distortion_model == "plumb_bob"
    assert i.distortion == (0.1, 0.0, 0.0, 0.0, 0.0)


@pytest.mark.parametrize(
    ("mount", "message"),
    [
        ({"parent": "l", "xyz": [0, 0, 0]}, "mount.optical must be stated"),
        ({"parent": "l", "optical": "yes"}, "mount.optical must be stated"),
        ({"xyz": [0, 0, 0], "optical": True}, "missing parent"),
        ({"parent": "l", "optical": True, "rpy": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1]}, "either rpy or quat_xyzw"),
        ({"parent": "l", "optical": True, "quat_xyzw": [1, 0, 0, 1]}, "not 1 \\(order is x, y, z, w\\)"),
        ({"parent": "l", "optical": True, "xyz": [0, 0]}, "mount.xyz must be 3 finite numbers"),
        ({"parent": "l", "optical": True, "pose": [0, 0]}, "mount: unknown keys \\['pose'\\]"),
    ],
)
def test_mount_errors(mount: dict[str, object], message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        load_calibration({"intrinsics": INTRINSICS, "mount": mount}, name="c")


def test_intrinsics_errors(tmp_path: Path) -> None:
    mount = {"parent": "l", "optical": True}
    with pytest.raises(CalibrationError, match="no intrinsics"):
        load_calibration({"mount": mount}, name="c")
    with pytest.raises(CalibrationError, match=r"focal lengths fx=-1\.0"):
        load_calibration({"intrinsics": {**INTRINSICS, "fx": -1.0}, "mount": mount}, name="c")
    with pytest.raises(CalibrationError, match="intrinsics: missing cy"):
        load_calibration({"intrinsics": {k: v for k, v in INTRINSICS.items() if k != "cy"}, "mount": mount}, name="c")
    (tmp_path / "bad.yaml").write_text("camera_matrix: {rows: 3, cols: 3, data: [1, 2, 3]}\nimage_width: 4\n")
    with pytest.raises(CalibrationError, match=r"bad.yaml: camera_matrix must be 9 finite numbers"):
        read_intrinsics_file(tmp_path / "bad.yaml")
    with pytest.raises(CalibrationError, match="cannot read calibration"):
        load_calibration(tmp_path / "missing.yaml")
