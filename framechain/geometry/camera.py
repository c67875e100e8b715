"""Camera models: pinhole with plumb_bob, rational_polynomial or equidistant (fisheye) distortion.

Pixels ``(u, v)`` map to normalised image coordinates ``(x, y)`` on the plane z = 1 of the optical
frame (x right, y down, z forward, REP-103); a camera-frame point is ``[x Z, y Z, Z]`` for a
z-depth Z. Distortion follows OpenCV (and ROS ``sensor_msgs/CameraInfo``):

- ``plumb_bob``: k1, k2, p1, p2, k3;
- ``rational_polynomial``: k1, k2, p1, p2, k3, k4, k5, k6;
- ``equidistant``: k1..k4 on the incidence angle (OpenCV's ``cv::fisheye``).

Undistortion is iterated to convergence (tests agree with OpenCV to 1e-6 rad). Where OpenCV does
the work (square-marker PnP, a camera's own motion), :mod:`framechain.vision.opencv` hands it this
model's ``K`` and :meth:`CameraModel.opencv_distortion`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray, IntArray, StrArray, names_and_codes
from framechain.errors import FramechainError

__all__ = ["ASSUMED_FOV_DEG", "FOV_RANGE_DEG", "CameraModel", "CameraModelError", "CameraRows", "distinct_models",
           "focal_of_fov", "fov_of_focal", "is_a_lens"]

#: The horizontal field of view (deg) taken for a camera without intrinsics: a typical wrist camera or webcam.
ASSUMED_FOV_DEG = 70.0


#: What a lens can be: its horizontal field of view across the image width (deg).
FOV_RANGE_DEG = (30.0, 175.0)


def is_a_lens(width_px: float, focal_px: float) -> bool:
    """A pinhole ``width_px`` wide with focal length ``focal_px`` has a field of view within :data:`FOV_RANGE_DEG`."""
    return bool(focal_px > 0 and FOV_RANGE_DEG[0] <= fov_of_focal(width_px, focal_px) <= FOV_RANGE_DEG[1])


def focal_of_fov(width_px: float, fov_deg: float) -> float:
    """The focal length (px) of a pinhole ``width_px`` wide whose horizontal field of view is ``fov_deg``."""
    return float(0.5 * width_px / np.tan(np.deg2rad(fov_deg) / 2.0))


def fov_of_focal(width_px: float, focal_px: float) -> float:
    """The horizontal field of view (deg) of a pinhole ``width_px`` wide with focal length ``focal_px``."""
    return float(np.rad2deg(2.0 * np.arctan(0.5 * width_px / focal_px)))


#: Coefficients of each distortion model (ROS names), in OpenCV's order.
_N_COEFFS = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4, "none": 0}
# librealsense's "Inverse Brown Conrady" is deprojected by current rsutil.h with the same iteration
# OpenCV uses to undistort plumb_bob (older copies applied the polynomial in closed form instead);
# the D435 samples carry zero coefficients, where every reading agrees.
_ALIASES = {"": "none", "brown_conrady": "plumb_bob", "brown conrady": "plumb_bob",
            "inverse brown conrady": "plumb_bob", "fisheye": "equidistant", "kannala_brandt": "equidistant"}


class CameraModelError(FramechainError):
    """A camera model cannot be used (unknown distortion model, bad coefficients)."""


class CameraRows(Protocol):
    """The columns of a table of camera models, one row per model (:class:`framechain.timeline.CameraTable`):
    ``distortion`` zero-padded, ``n_distortion`` the coefficients each row gave."""

    @property
    def frame(self) -> StrArray: ...
    @property
    def K(self) -> FloatArray: ...
    @property
    def width(self) -> IntArray: ...
    @property
    def height(self) -> IntArray: ...
    @property
    def distortion_model(self) -> StrArray: ...
    @property
    def distortion(self) -> FloatArray: ...
    @property
    def n_distortion(self) -> IntArray: ...


@dataclass(frozen=True)
class CameraModel:
    """One camera: intrinsics ``K`` (3x3), image size, distortion model and coefficients."""

    frame: str
    K: FloatArray
    width: int
    height: int
    distortion_model: str = "none"
    distortion: FloatArray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        model = _ALIASES.get(self.distortion_model.strip().lower(), self.distortion_model.strip().lower())
        if model not in _N_COEFFS:
            raise CameraModelError(
                f"camera {self.frame!r}: unknown distortion model {self.distortion_model!r}; "
                f"expected one of {sorted(_N_COEFFS)}"
            )
        coeffs = np.zeros(max(_N_COEFFS[model], 1))
        given = np.asarray(self.distortion, dtype=float).reshape(-1)[: _N_COEFFS[model]]
        coeffs[: given.size] = given
        object.__setattr__(self, "distortion_model", model)
        object.__setattr__(self, "distortion", coeffs)
        object.__setattr__(self, "K", np.asarray(self.K, dtype=float).reshape(3, 3))

    @classmethod
    def from_table(cls, table: CameraRows, row: int = 0) -> CameraModel:
        n = int(table.n_distortion[row])
        return cls(
            frame=str(table.frame[row]), K=table.K[row], width=int(table.width[row]),
            height=int(table.height[row]), distortion_model=str(table.distortion_model[row]),
            distortion=table.distortion[row, :n],
        )

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def is_distorted(self) -> bool:
        return self.distortion_model != "none" and bool(np.any(self.distortion))

    @property
    def is_fisheye(self) -> bool:
        """Equidistant distortion: OpenCV's ``cv2.fisheye`` functions, not its pinhole ones."""
        return self.distortion_model == "equidistant"

    def opencv_distortion(self) -> FloatArray:
        """The coefficients as OpenCV takes them: 4 for ``cv2.fisheye``, else 5 or 8 (zeros without distortion)."""
        if self.is_fisheye:
            return self.distortion.copy()
        out = np.zeros(max(self.distortion.size, 5))
        out[: self.distortion.size] = self.distortion
        return out

    def inside(self, u: FloatArray, v: FloatArray) -> npt.NDArray[np.bool_]:
        """Pixels within the image (pixel centres at integers, edges at -0.5 and size - 0.5). A model without
        an image (width or height 0: 3D points in the camera frame, in normalised coordinates) bounds nothing."""
        if self.width <= 0 or self.height <= 0:
            return np.ones(np.shape(u), dtype=bool)
        return (u >= -0.5) & (u < self.width - 0.5) & (v >= -0.5) & (v < self.height - 0.5)

    # -- pixel -> ray ---------------------------------------------------------------------
    def pixel_to_normalized(self, u: npt.ArrayLike, v: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Undistorted normalised coordinates ``(x, y)`` of pixels (the ray is ``[x, y, 1]``)."""
        k = self.K
        yd = (np.asarray(v, dtype=float) - k[1, 2]) / k[1, 1]
        xd = (np.asarray(u, dtype=float) - k[0, 2] - k[0, 1] * yd) / k[0, 0]
        if not self.is_distorted:
            return xd, yd
        if self.distortion_model == "equidistant":
            return self._undistort_fisheye(xd, yd)
        return self._undistort_radial(xd, yd)

    def pixel_to_camera(self, u: npt.ArrayLike, v: npt.ArrayLike, depth_m: npt.ArrayLike) -> FloatArray:
        """Camera-frame points (N, 3) of pixels at z-depth ``depth_m`` (hop 1, pixel_to_camera)."""
        x, y = self.pixel_to_normalized(u, v)
        z = np.asarray(depth_m, dtype=float)
        return np.stack([x * z, y * z, np.broadcast_to(z, x.shape)], axis=-1)

    def _radial_factors(self, x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        d = self.distortion
        k1, k2, p1, p2, k3 = d[0], d[1], d[2], d[3], d[4]
        k4, k5, k6 = (d[5], d[6], d[7]) if self.distortion_model == "rational_polynomial" else (0.0, 0.0, 0.0)
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return radial, dx, dy

    def _undistort_radial(self, xd: FloatArray, yd: FloatArray) -> tuple[FloatArray, FloatArray]:
        # OpenCV's fixed-point iteration, run to convergence instead of a fixed 5 rounds.
        x, y = xd.copy(), yd.copy()
        for _ in range(200):
            radial, dx, dy = self._radial_factors(x, y)
            x_new = (xd - dx) / radial
            y_new = (yd - dy) / radial
            change = max(_max_abs(x_new - x), _max_abs(y_new - y))
            x, y = x_new, y_new
            if change < 1e-15:
                break
        return x, y

    def _undistort_fisheye(self, xd: FloatArray, yd: FloatArray) -> tuple[FloatArray, FloatArray]:
        k1, k2, k3, k4 = self.distortion[:4]
        theta_d = np.sqrt(xd * xd + yd * yd)
        theta = theta_d.copy()
        for _ in range(50):  # Newton on theta_d = theta (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8)
            t2 = theta * theta
            f = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
            df = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            step = f / df
            theta = theta - step
            if _max_abs(step) < 1e-15:
                break
        scale = np.where(theta_d > 1e-12, np.tan(theta) / np.where(theta_d > 1e-12, theta_d, 1.0), 1.0)
        return xd * scale, yd * scale

    # -- point -> pixel ---------------------------------------------------------------------
    def project(self, points_cam: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Pixels ``(u, v)`` of camera-frame points (N, 3) with the distortion applied.

        Points not in front of the camera (z <= 0, or not finite) have no pixel: NaN.
        """
        p = np.asarray(points_cam, dtype=float).reshape(-1, 3)
        z = np.where(p[:, 2] > 0, p[:, 2], np.nan)
        x, y = p[:, 0] / z, p[:, 1] / z
        if self.is_distorted and self.distortion_model == "equidistant":
            r = np.sqrt(x * x + y * y)
            theta = np.arctan(r)
            k1, k2, k3, k4 = self.distortion[:4]
            t2 = theta * theta
            theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
            scale = np.where(r > 1e-12, theta_d / np.where(r > 1e-12, r, 1.0), 1.0)
            x, y = x * scale, y * scale
        elif self.is_distorted:
            radial, dx, dy = self._radial_factors(x, y)
            x, y = x * radial + dx, y * radial + dy
        k = self.K
        return k[0, 0] * x + k[0, 1] * y + k[0, 2], k[1, 1] * y + k[1, 2]


def distinct_models(table: CameraRows, rows: IntArray) -> tuple[list[CameraModel], IntArray]:
    """The distinct camera models among ``rows`` (all >= 0) of ``table`` and, per row, its model's index.

    A log republishes its CameraInfo at the camera's rate, so thousands of rows are usually one
    model: rows with the same frame, size, K, distortion model and coefficients share one.
    """
    used, row_of = np.unique(rows, return_inverse=True)
    if used.size == 0:
        return [], np.zeros(0, dtype=np.int64)
    n_coeffs = table.n_distortion[used]
    coeffs = np.where(np.arange(table.distortion.shape[1]) < n_coeffs[:, None], table.distortion[used], 0.0)
    codes = [names_and_codes(column[used].astype(str))[1] for column in (table.frame, table.distortion_model)]
    key = np.column_stack([table.K[used].reshape(used.size, 9), coeffs, n_coeffs, table.width[used],
                           table.height[used], *codes])
    # Runs of equal rows first (a camera's messages in a row are one model): np.unique over rows sorts
    # them all, 40 ms for the 18,000 CameraInfo messages of a 10-minute log, where the runs are few.
    new_run = np.r_[True, (key[1:] != key[:-1]).any(axis=1)]
    starts, run_of = np.flatnonzero(new_run), np.cumsum(new_run) - 1
    _, first, model_of_run = np.unique(key[starts], axis=0, return_index=True, return_inverse=True)
    models = [CameraModel.from_table(table, int(used[starts[i]])) for i in first.tolist()]
    which: IntArray = model_of_run.reshape(-1)[run_of[row_of.reshape(-1)]].astype(np.int64)
    return models, which


def _max_abs(values: FloatArray) -> float:
    """Largest absolute value, 0 for an empty array (NaN ignored)."""
    return float(np.nanmax(np.abs(values))) if values.size and np.isfinite(values).any() else 0.0
