"""Camera calibration files as their tools write them, for the tests that read them and the tests that join them to a
log: a ROS camera_info YAML (camera_calibration's format) and a Kalibr camchain with a pinhole and a fisheye camera.
"""

from __future__ import annotations

import numpy as np

ROS_CAMERA_INFO = """\
image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [612.5, 0, 321.25, 0, 611.75, 243.5, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.11, -0.22, 0.001, -0.002, 0.05]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [612.5, 0, 321.25, 0, 0, 611.75, 243.5, 0, 0, 0, 1, 0]
"""

# A Kalibr camchain as kalibr_calibrate_cameras writes it (extrinsics included, not read).
KALIBR = """\
cam0:
  T_cam_imu:
  - [0.01, -0.99, 0.0, 0.05]
  - [0.99, 0.01, 0.0, -0.01]
  - [0.0, 0.0, 1.0, 0.002]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.28, 0.07, 0.0002, 0.00002]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
  timeshift_cam_imu: 0.003
cam1:
  T_cn_cnm1:
  - [1.0, 0.002, 0.0, -0.11]
  - [-0.002, 1.0, 0.0, 0.0004]
  - [0.0, 0.0, 1.0, 0.0]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  distortion_coeffs: [-0.0067, 0.0393, -0.0356, 0.0055]
  distortion_model: equidistant
  intrinsics: [286.7, 286.8, 420.9, 396.9]
  resolution: [848, 800]
  rostopic: /t265/fisheye1/image_raw
  tagtopic: /t265/fisheye1/tags
"""


def intrinsic_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """K, 3x3, of a pinhole without skew."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
