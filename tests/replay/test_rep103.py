"""REP-103: the camera_link (x forward, y left, z up) to camera_optical (x right, y down, z forward) rotation."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.geometry.camera import CameraModel
from framechain.replay import LookupStatus, TransformBuffer
from framechain.timeline import TransformTable
from tests.helpers.reference_maths import assert_same_rotation

Q_LINK_OPTICAL = [-0.5, 0.5, -0.5, 0.5]


def optical_buffer() -> TransformBuffer:
    return TransformBuffer(TransformTable.concat([
        TransformTable.from_rows("base_link", "camera_link", [0], [[0.3, 0.0, 0.8]], [[0, 0, 0, 1.0]],
                                 is_static=True),
        TransformTable.from_rows("camera_link", "camera_optical", [0], [[0.0, 0.0, 0.0]], [Q_LINK_OPTICAL],
                                 is_static=True),
    ]))


def test_the_optical_quaternion_is_roll_minus_90_yaw_minus_90() -> None:
    expected = Rotation.from_euler("xyz", [-np.pi / 2, 0, -np.pi / 2]).as_quat()
    assert_same_rotation([Q_LINK_OPTICAL], [expected], atol=1e-15)
    result = optical_buffer().lookup("camera_link", "camera_optical", [0])
    np.testing.assert_allclose(
        result.matrix()[0, :3, :3], [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-15
    )


def test_straight_ahead_of_the_lens_is_body_forward() -> None:
    buf = optical_buffer()
    ahead = buf.lookup("camera_link", "camera_optical", [0]).apply([[0.0, 0.0, 2.5]])
    np.testing.assert_allclose(ahead[0], [2.5, 0.0, 0.0], atol=1e-15)
    in_body = buf.lookup("base_link", "camera_optical", [0]).apply([[0.0, 0.0, 2.5]])
    np.testing.assert_allclose(in_body[0], [2.8, 0.0, 0.8], atol=1e-15)


def test_right_of_the_image_is_body_minus_y_and_below_is_body_minus_z() -> None:
    buf = optical_buffer()
    right = buf.lookup("camera_link", "camera_optical", [0]).apply([[1.0, 0.0, 0.0]])
    np.testing.assert_allclose(right[0], [0.0, -1.0, 0.0], atol=1e-15)
    # A pixel below the image centre: optical +y, so it lands below the lens in the body frame.
    camera = CameraModel("camera_optical", np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]]), 640, 480)
    p_cam = camera.pixel_to_camera([320.0], [300.0], [2.0])
    np.testing.assert_allclose(p_cam[0], [0.0, 0.2, 2.0], atol=1e-15)
    result = buf.lookup("base_link", "camera_optical", [0])
    assert result.status.tolist() == [LookupStatus.OK]
    p_body = result.apply(p_cam)
    np.testing.assert_allclose(p_body[0], [0.3 + 2.0, 0.0, 0.8 - 0.2], atol=1e-15)
    assert p_body[0, 2] < 0.8  # below the camera
