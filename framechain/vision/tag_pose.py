"""Square-marker pose from four pixel corners (PnP), with OpenCV.

Conventions: pixels ``(u, v)`` with the origin at the centre of the top-left pixel; camera points
in the optical frame (x right, y down, z forward, REP-103). A tag's corners are given in the
order ArUco and most AprilTag detectors use for IPPE_SQUARE: the object points
``(-s/2, s/2, 0), (s/2, s/2, 0), (s/2, -s/2, 0), (-s/2, -s/2, 0)`` (top-left, top-right,
bottom-right, bottom-left seen from the front, marker y up), so the image quad winds clockwise
on screen (y down). A quad that winds the other way is the same square read in mirror order;
its correspondences are reversed (corner 0 kept), which leaves the centre where it is.

The camera model is :class:`framechain.geometry.camera.CameraModel`, undistorted and projected
through OpenCV (:mod:`framechain.vision.opencv`, one call per model); only ``solvePnP`` runs
once per detection (OpenCV has no batched form).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from framechain.arrays import BoolArray, FloatArray
from framechain.geometry.camera import CameraModel
from framechain.vision.opencv import project, require_cv2, undistort_normalised

#: Tags whose corners reproject further than this (RMS over the four corners, pixels) are rejected.
MAX_REPROJECTION_PX = 2.0


def square_object_points(size_m: float) -> FloatArray:
    """The four corners of a square marker of side ``size_m`` in its own frame (IPPE_SQUARE order)."""
    h = size_m / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def clockwise_on_screen(quads: npt.ArrayLike) -> BoolArray:
    """Whether each quad (N, 4, 2) winds clockwise in image coordinates (y down): shoelace > 0."""
    q = np.asarray(quads, dtype=np.float64)
    x, y = q[..., 0], q[..., 1]
    area = np.sum(x * np.roll(y, -1, axis=-1) - np.roll(x, -1, axis=-1) * y, axis=-1)
    out: BoolArray = area > 0
    return out


@dataclass(frozen=True)
class TagPoses:
    """Square-marker poses of N detections in the camera frame.

    ``centre_cam`` (N, 3) is the tag centre; ``rvec`` (N, 3) its rotation (Rodrigues, camera from
    tag); ``reprojection_px`` (N,) the RMS distance of the four corners reprojected through the
    camera model from the detected ones; ``ok`` (N,) where PnP gave a solution in front of the
    camera; ``reversed_order`` (N,) where the corners wound counter-clockwise and were read in
    mirror order. Rows with ``ok`` False hold NaN.
    """

    centre_cam: FloatArray
    rvec: FloatArray
    reprojection_px: FloatArray
    ok: BoolArray
    reversed_order: BoolArray


def solve_square_tags(model: CameraModel, corners_px: npt.ArrayLike, sizes_m: npt.ArrayLike) -> TagPoses:
    """Pose of each square tag (N, 4, 2 pixel corners; N sizes in metres) seen by ``model``.

    One undistortion call for all corners, ``solvePnP(SOLVEPNP_IPPE_SQUARE)`` per tag on the
    undistorted normalised corners (identity K, no distortion), one projection call for the
    reprojection error.
    """
    cv2 = require_cv2()
    corners = np.asarray(corners_px, dtype=np.float64).reshape(-1, 4, 2)
    sizes = np.broadcast_to(np.asarray(sizes_m, dtype=np.float64), (corners.shape[0],))
    n = corners.shape[0]
    centre = np.full((n, 3), np.nan)
    rvecs = np.full((n, 3), np.nan)
    reproj = np.full(n, np.nan)
    ok = np.zeros(n, dtype=bool)
    if n == 0:
        return TagPoses(centre, rvecs, reproj, ok, np.zeros(0, dtype=bool))
    finite = np.isfinite(corners).all(axis=(1, 2)) & np.isfinite(sizes) & (sizes > 0)
    norm = np.full((n, 4, 2), np.nan)
    norm[finite] = undistort_normalised(model, corners[finite].reshape(-1, 2)).reshape(-1, 4, 2)
    flip = ~clockwise_on_screen(norm) & finite
    order = np.where(flip[:, None], np.array([0, 3, 2, 1]), np.array([0, 1, 2, 3]))
    norm_ordered = np.take_along_axis(norm, order[:, :, None], axis=1)
    eye, no_dist = np.eye(3), np.zeros(5)
    rot = np.full((n, 3, 3), np.nan)
    tvecs = np.full((n, 3), np.nan)
    for i in np.flatnonzero(finite).tolist():
        found, rvec, tvec = cv2.solvePnP(square_object_points(float(sizes[i])), norm_ordered[i], eye, no_dist,
                                         flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not found:
            continue
        rvecs[i] = np.asarray(rvec, dtype=np.float64).reshape(3)
        tvecs[i] = np.asarray(tvec, dtype=np.float64).reshape(3)
        rot[i] = cv2.Rodrigues(rvecs[i])[0]
        ok[i] = True
    ok &= tvecs[:, 2] > 0
    if ok.any():
        idx = np.flatnonzero(ok)
        objects = np.stack([square_object_points(float(s)) for s in sizes[idx]])  # (M, 4, 3)
        corners_cam = np.einsum("mij,mkj->mki", rot[idx], objects) + tvecs[idx][:, None, :]
        reprojected = project(model, corners_cam.reshape(-1, 3)).reshape(-1, 4, 2)
        detected = np.take_along_axis(corners[idx], order[idx][:, :, None], axis=1)
        reproj[idx] = np.sqrt(np.mean(np.sum((reprojected - detected) ** 2, axis=2), axis=1))
    # The tag centre is the tag frame's origin: the translation of camera-from-tag.
    centre[ok] = tvecs[ok]
    rvecs[~ok] = np.nan
    return TagPoses(centre, rvecs, reproj, ok, flip)
