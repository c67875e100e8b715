"""OpenCV, imported on first use, and the camera model through it: undistortion and projection.

Pixels ``(u, v)`` have their origin at the centre of the top-left pixel; camera points are in the
optical frame (x right, y down, z forward, REP-103). The camera model is
:class:`framechain.geometry.camera.CameraModel`: ``plumb_bob`` and ``rational_polynomial`` go through
OpenCV's ``undistortPoints``/``projectPoints``, ``equidistant`` through ``cv2.fisheye``. Every
undistortion and projection is one OpenCV call per camera model.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from types import ModuleType

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray
from framechain.errors import FramechainError
from framechain.geometry.camera import CameraModel

__all__ = ["MissingOpenCVError", "bright_shares", "mean_abs_differences", "opencv_threads", "project", "require_cv2",
           "undistort_normalised"]


class MissingOpenCVError(FramechainError):
    """OpenCV is needed (tag corners, markers in images) but cannot be imported."""


def require_cv2() -> ModuleType:
    """``cv2``, imported on first use (an install without it still reads logs without fiducials)."""
    try:
        import cv2
    except ImportError as err:
        raise MissingOpenCVError(
            "fiducial corners and markers in images need OpenCV: pip install 'opencv-python-headless>=4.10' "
            f"({err})"
        ) from err
    return cv2


@contextlib.contextmanager
def opencv_threads(count: int) -> Iterator[None]:
    """OpenCV's own worker threads set to ``count`` within the block, as they were after it (nothing without OpenCV).

    Cameras measured at once (each in a process or on a thread of its own) each call Lucas-Kanade, whose loop over the
    points runs on every core: two cameras would put four threads on two cores (a generated two-camera episode
    tracked in 0.55 s with one OpenCV thread each, 0.65 s with OpenCV's own)."""
    try:
        cv2 = require_cv2()
    except MissingOpenCVError:
        yield
        return
    before = cv2.getNumThreads()
    cv2.setNumThreads(count)
    try:
        yield
    finally:
        cv2.setNumThreads(before)


def undistort_normalised(model: CameraModel, pixels: npt.ArrayLike) -> FloatArray:
    """Undistorted normalised image coordinates ``(x, y)`` (N, 2) of pixels (N, 2): one OpenCV call."""
    cv2 = require_cv2()
    pts = np.ascontiguousarray(np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2))
    if pts.shape[0] == 0:
        return np.zeros((0, 2))
    k = np.asarray(model.K, dtype=np.float64)
    if model.is_fisheye:
        # Newton iterations to convergence; OpenCV's default criteria stop after 10.
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
        out = cv2.fisheye.undistortPoints(pts, k, model.opencv_distortion(), criteria=criteria)
    else:
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4: the iterated form is a separate function
            out = cv2.undistortPointsIter(pts, k, model.opencv_distortion(), None, None, criteria)
        else:  # OpenCV 5 folded it into undistortPoints
            out = cv2.undistortPoints(pts, k, model.opencv_distortion(), criteria=criteria)
    result: FloatArray = np.asarray(out, dtype=np.float64).reshape(-1, 2)
    return result


def project(model: CameraModel, points_cam: npt.ArrayLike) -> FloatArray:
    """Pixels (N, 2) of camera-frame points (N, 3), distortion applied: one OpenCV call."""
    cv2 = require_cv2()
    pts = np.ascontiguousarray(np.asarray(points_cam, dtype=np.float64).reshape(-1, 1, 3))
    if pts.shape[0] == 0:
        return np.zeros((0, 2))
    zero = np.zeros(3)
    k = np.asarray(model.K, dtype=np.float64)
    if model.is_fisheye:
        out, _ = cv2.fisheye.projectPoints(pts, zero, zero, k, model.opencv_distortion())
    else:
        out, _ = cv2.projectPoints(pts, zero, zero, k, model.opencv_distortion())
    result: FloatArray = np.asarray(out, dtype=np.float64).reshape(-1, 2)
    return result


def mean_abs_differences(images: npt.NDArray[np.uint8], first: npt.ArrayLike, second: npt.ArrayLike) -> FloatArray:
    """The mean absolute difference (grey levels) between ``images[first[k]]`` and ``images[second[k]]``: one OpenCV
    L1 norm per pair, no copy of the images (an episode of 640x480 frames is hundreds of megabytes)."""
    cv2 = require_cv2()
    a = np.asarray(first, dtype=np.int64)
    b = np.asarray(second, dtype=np.int64)
    size = max(int(images[0].size), 1) if len(images) else 1
    out: FloatArray = np.array([cv2.norm(images[i], images[j], cv2.NORM_L1) for i, j in zip(a.tolist(), b.tolist(),
                                                                                             strict=True)],
                               dtype=np.float64).reshape(-1) / size
    return out


def bright_shares(images: npt.NDArray[np.uint8], level: int) -> FloatArray:
    """Per image of ``images`` (N, H, W[, C]), the share of its values above ``level``: one OpenCV threshold and
    count per image (a mean over a boolean copy of a 640x480 episode costs forty times as much)."""
    if len(images) == 0:
        return np.zeros(0)
    cv2 = require_cv2()
    counts = [cv2.countNonZero(cv2.threshold(np.ascontiguousarray(image).reshape(image.shape[0], -1), level, 255,
                                             cv2.THRESH_BINARY)[1]) for image in images]
    out: FloatArray = np.asarray(counts, dtype=np.float64) / max(int(images[0].size), 1)
    return out
