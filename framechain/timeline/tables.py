"""Columnar tables of the timeline model, one per channel kind.

Every table is a frozen dataclass of NumPy arrays of equal length (one row per sample), never a
list of per-message objects. Times are integer nanoseconds (``*_ns``, int64). Strings are NumPy
unicode arrays so that they compare vectorised. Each table converts losslessly to and from an
Arrow table (the machinery they share is :mod:`framechain.timeline.columns`); :class:`Timeline` gathers
them and saves them as Parquet.

Conventions: ``T_parent_child`` maps points in the child frame into the parent frame, as a ROS
``TransformStamped`` with ``header.frame_id = parent`` and ``child_frame_id = child``;
quaternions are ``quat_xyzw`` (scalar last, as ROS and scipy).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from enum import StrEnum
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from framechain.arrays import BoolArray, FloatArray, IntArray, StrArray
from framechain.timeline.columns import Column, ColumnTable
from framechain.timeline.errors import InvalidCameraError, InvalidTransformError, TimelineError

#: Quaternions further than this from unit length are rejected rather than normalised.
QUATERNION_NORM_TOLERANCE = 1e-3
#: The largest distortion vector kept (OpenCV's 14-coefficient model).
MAX_DISTORTION_COEFFS = 14


class PointRole(StrEnum):
    """What a logged point is evidence of."""

    HOP_CAMERA = "hop_camera"  # the robot's own camera-frame point for an observation
    HOP_BODY = "hop_body"  # the robot's own body-frame point
    HOP_WORLD = "hop_world"  # the robot's own world-frame point
    TARGET = "target"  # the world-frame target the robot acted on
    REFERENCE = "reference"  # ground truth (motion capture, surveyed marker)


def format_stamp(stamp_ns: int) -> str:
    """Integer nanoseconds as seconds with all nine decimals exact (float seconds lose the last digits)."""
    sign = "-" if stamp_ns < 0 else ""
    whole, frac = divmod(abs(int(stamp_ns)), 1_000_000_000)
    return f"{sign}{whole}.{frac:09d}"


def normalize_frame(name: str) -> str:
    """Frame names as tf2 keys them: a leading ``/`` is dropped (ROS 1 ``/base_link``)."""
    return name.lstrip("/")


def normalize_frames(names: npt.ArrayLike) -> StrArray:
    """Vectorised :func:`normalize_frame`."""
    arr = np.asarray(names, dtype=str)
    if arr.size == 0:
        return arr.astype(str)
    # Most logs (ROS 2) have no leading "/": found from each name's first code point, the names are kept
    # as they are (lstrip over a table's 90,000 names takes 20-30 ms, and every table made checks its own).
    first = np.ascontiguousarray(arr).reshape(-1).view(np.uint32)[:: max(arr.dtype.itemsize // 4, 1)]
    if not (first == ord("/")).any():
        return arr
    return np.char.lstrip(arr, "/").astype(str)


@dataclass(frozen=True)
class TransformTable(ColumnTable):
    """Transform samples ``T_parent_child`` (one row per TransformStamped).

    ``is_static`` rows come from ``/tf_static`` (latched, timeless in lookups; every sample is
    kept here). On construction, frame names are normalised, non-finite values are rejected with
    the edge and stamp named, and quaternions within 1e-3 of unit length are normalised (others
    rejected).
    """

    COLUMNS: ClassVar[dict[str, Column]] = {
        "parent": Column("str"),
        "child": Column("str"),
        "stamp_ns": Column("i8"),
        "log_time_ns": Column("i8"),
        "translation": Column("f8", (3,)),
        "quat_xyzw": Column("f8", (4,)),
        "is_static": Column("bool"),
        "source": Column("str"),
    }
    parent: StrArray
    child: StrArray
    stamp_ns: IntArray
    log_time_ns: IntArray
    translation: FloatArray
    quat_xyzw: FloatArray
    is_static: BoolArray
    source: StrArray

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "parent", normalize_frames(self.parent))
        object.__setattr__(self, "child", normalize_frames(self.child))
        finite = np.isfinite(self.translation).all(axis=1) & np.isfinite(self.quat_xyzw).all(axis=1)
        if not finite.all():
            i = int(np.flatnonzero(~finite)[0])
            raise self._invalid(i, "translation or rotation is NaN or Inf")
        norm = np.linalg.norm(self.quat_xyzw, axis=1)
        bad = np.abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise self._invalid(i, f"quaternion norm {norm[i]:.6g} is not unit (|q| - 1 > 1e-3)")
        # Normalise only what is off unit by more than rounding, so a table built from a saved one
        # is bit-identical (dividing a unit quaternion by its computed norm moves it by an ulp).
        off = np.abs(norm - 1.0) > 4 * np.finfo(np.float64).eps
        if off.any():
            quat = self.quat_xyzw.copy()
            quat[off] /= norm[off, None]
            object.__setattr__(self, "quat_xyzw", quat)

    def _invalid(self, i: int, what: str) -> InvalidTransformError:
        return InvalidTransformError(
            str(self.parent[i]), str(self.child[i]), int(self.stamp_ns[i]), what, str(self.source[i])
        )

    @classmethod
    def from_rows(
        cls,
        parent: npt.ArrayLike,
        child: npt.ArrayLike,
        stamp_ns: npt.ArrayLike,
        translation: npt.ArrayLike,
        quat_xyzw: npt.ArrayLike,
        *,
        log_time_ns: npt.ArrayLike | None = None,
        is_static: bool | npt.ArrayLike = False,
        source: str | npt.ArrayLike = "",
    ) -> TransformTable:
        """Build from arrays, broadcasting scalar frame names, flags and sources."""
        stamps = np.atleast_1d(np.asarray(stamp_ns, dtype=np.int64))
        n = stamps.shape[0]
        return cls(
            parent=np.broadcast_to(np.asarray(parent, dtype=str), (n,)).copy(),
            child=np.broadcast_to(np.asarray(child, dtype=str), (n,)).copy(),
            stamp_ns=stamps,
            log_time_ns=stamps if log_time_ns is None else np.broadcast_to(log_time_ns, (n,)).copy(),
            translation=np.asarray(translation, dtype=float).reshape(n, 3),
            quat_xyzw=np.asarray(quat_xyzw, dtype=float).reshape(n, 4),
            is_static=np.broadcast_to(np.asarray(is_static, dtype=bool), (n,)).copy(),
            source=np.broadcast_to(np.asarray(source, dtype=str), (n,)).copy(),
        )


@dataclass(frozen=True)
class CameraTable(ColumnTable):
    """Camera models (one row per CameraInfo): intrinsics ``K`` (3x3) and distortion.

    ``distortion`` is zero-padded to 14 coefficients; ``n_distortion`` says how many the source
    gave (5 for plumb_bob, 8 for rational_polynomial, 4 for equidistant). ``distortion_model``
    uses ROS names: ``plumb_bob``, ``rational_polynomial``, ``equidistant`` (or ``none``).
    """

    COLUMNS: ClassVar[dict[str, Column]] = {
        "frame": Column("str"),
        "stamp_ns": Column("i8"),
        "log_time_ns": Column("i8"),
        "width": Column("i8"),
        "height": Column("i8"),
        "K": Column("f8", (3, 3)),
        "distortion_model": Column("str"),
        "distortion": Column("f8", (MAX_DISTORTION_COEFFS,)),
        "n_distortion": Column("i8"),
        "source": Column("str"),
    }
    frame: StrArray
    stamp_ns: IntArray
    log_time_ns: IntArray
    width: IntArray
    height: IntArray
    K: FloatArray
    distortion_model: StrArray
    distortion: FloatArray
    n_distortion: IntArray
    source: StrArray

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "frame", normalize_frames(self.frame))
        usable = np.isfinite(self.K).all(axis=(1, 2)) & self.K.any(axis=(1, 2))
        if not usable.all():
            i = int(np.flatnonzero(~usable)[0])
            raise InvalidCameraError(str(self.frame[i]), "K is all zero or not finite", str(self.source[i]))
        positive = (self.K[:, 0, 0] > 0) & (self.K[:, 1, 1] > 0)
        if not positive.all():
            i = int(np.flatnonzero(~positive)[0])
            raise InvalidCameraError(
                str(self.frame[i]),
                f"focal lengths fx={self.K[i, 0, 0]} fy={self.K[i, 1, 1]} must be positive",
                str(self.source[i]),
            )

    @classmethod
    def from_intrinsics(
        cls,
        frame: str,
        *,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        width: int,
        height: int,
        stamp_ns: int = 0,
        distortion_model: str = "plumb_bob",
        distortion: npt.ArrayLike = (),
        source: str = "",
    ) -> CameraTable:
        """One camera from its pinhole parameters."""
        d = np.zeros(MAX_DISTORTION_COEFFS)
        given = np.asarray(distortion, dtype=float).reshape(-1)
        d[: given.size] = given
        return cls(
            frame=np.array([frame]), stamp_ns=np.array([stamp_ns]), log_time_ns=np.array([stamp_ns]),
            width=np.array([width]), height=np.array([height]),
            K=np.array([[[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]]),
            distortion_model=np.array([distortion_model]), distortion=d[None, :],
            n_distortion=np.array([given.size]), source=np.array([source]),
        )


@dataclass(frozen=True)
class ObservationTable(ColumnTable):
    """Detections: a pixel ``(u, v)`` in a camera at a stamp, with depth in metres when known.

    ``depth_m`` is NaN when the depth must be sampled from depth frames at replay time.
    """

    COLUMNS: ClassVar[dict[str, Column]] = {
        "obs_id": Column("i8"),
        "stamp_ns": Column("i8"),
        "log_time_ns": Column("i8"),
        "camera_frame": Column("str"),
        "u": Column("f8"),
        "v": Column("f8"),
        "depth_m": Column("f8"),
        "label": Column("str"),
        "score": Column("f8"),
        "source": Column("str"),
    }
    obs_id: IntArray
    stamp_ns: IntArray
    log_time_ns: IntArray
    camera_frame: StrArray
    u: FloatArray
    v: FloatArray
    depth_m: FloatArray
    label: StrArray
    score: FloatArray
    source: StrArray

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "camera_frame", normalize_frames(self.camera_frame))
        if np.unique(self.obs_id).size != len(self):
            raise TimelineError("ObservationTable: obs_id values must be unique")


@dataclass(frozen=True)
class JointStateTable(ColumnTable):
    """Joint states in long form: one row per joint per message (messages may name any subset)."""

    COLUMNS: ClassVar[dict[str, Column]] = {
        "stamp_ns": Column("i8"),
        "log_time_ns": Column("i8"),
        "joint": Column("str"),
        "position": Column("f8"),
        "velocity": Column("f8"),
        "effort": Column("f8"),
        "source": Column("str"),
    }
    stamp_ns: IntArray
    log_time_ns: IntArray
    joint: StrArray
    position: FloatArray
    velocity: FloatArray
    effort: FloatArray
    source: StrArray

    def wide(self, joints: Iterable[str]) -> tuple[IntArray, FloatArray]:
        """Positions as ``(stamps, (T, J))`` for the named joints, rows where all are present."""
        names = list(joints)
        stamps = np.unique(self.stamp_ns)
        out = np.full((stamps.size, len(names)), np.nan)
        row = np.searchsorted(stamps, self.stamp_ns)
        for j, name in enumerate(names):
            sel = self.joint == name
            out[row[sel], j] = self.position[sel]
        keep = np.isfinite(out).all(axis=1)
        return stamps[keep], out[keep]


@dataclass(frozen=True)
class PointTable(ColumnTable):
    """Logged points: the robot's own hop points, the target it acted on, reference truth.

    ``quat_xyzw`` is NaN unless the point came from a pose. ``obs_id`` is -1 when the point is
    not tied to an observation (it is then matched by stamp).
    """

    COLUMNS: ClassVar[dict[str, Column]] = {
        "frame": Column("str"),
        "stamp_ns": Column("i8"),
        "log_time_ns": Column("i8"),
        "xyz": Column("f8", (3,)),
        "quat_xyzw": Column("f8", (4,)),
        "role": Column("str"),
        "obs_id": Column("i8"),
        "source": Column("str"),
    }
    frame: StrArray
    stamp_ns: IntArray
    log_time_ns: IntArray
    xyz: FloatArray
    quat_xyzw: FloatArray
    role: StrArray
    obs_id: IntArray
    source: StrArray

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "frame", normalize_frames(self.frame))
        valid = {r.value for r in PointRole}
        unknown = set(self.role.tolist()) - valid
        if unknown:
            raise TimelineError(f"PointTable: unknown roles {sorted(unknown)}; expected {sorted(valid)}")

    def with_role(self, role: PointRole) -> PointTable:
        """The rows of one role."""
        return self.take(self.role == role.value)


@dataclass(frozen=True)
class EgoMotionTable(ColumnTable):
    """A camera's motion between two of its frames, measured from the images alone.

    One row per frame pair: ``quat_xyzw`` is ``R_cam(t0)_cam(t1)``, the rotation that maps vectors
    in the optical frame at the later frame ``stamp1_ns`` into the optical frame at ``stamp0_ns``
    (frame stamps, the camera's clock). ``direction`` is the unit translation of the later camera
    centre in the earlier optical frame, NaN where the parallax is too small to show it.
    ``tracks`` features were matched between the two frames, ``inliers`` of them agree with the
    motion; ``residual_px`` is the inliers' RMS misfit and ``parallax_px`` their median image
    displacement due to translation (both in pixels at the camera's focal length).
    """

    COLUMNS: ClassVar[dict[str, Column]] = {
        "frame": Column("str"),
        "stamp0_ns": Column("i8"),
        "stamp1_ns": Column("i8"),
        "quat_xyzw": Column("f8", (4,)),
        "direction": Column("f8", (3,)),
        "tracks": Column("i8"),
        "inliers": Column("i8"),
        "residual_px": Column("f8"),
        "parallax_px": Column("f8"),
    }
    frame: StrArray
    stamp0_ns: IntArray
    stamp1_ns: IntArray
    quat_xyzw: FloatArray
    direction: FloatArray
    tracks: IntArray
    inliers: IntArray
    residual_px: FloatArray
    parallax_px: FloatArray

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "frame", normalize_frames(self.frame))
        if np.any(self.stamp1_ns <= self.stamp0_ns):
            raise TimelineError("EgoMotionTable: every pair needs stamp1_ns > stamp0_ns")


#: The translation direction a camera is expected to move in between two of its frames, in the
#: optical frame of the earlier one: ``prior(stamp0_ns (P,), stamp1_ns (P,)) -> (P, 3)``, rows of NaN
#: where it is not known. The analysis builds it from forward kinematics; the ego-motion measurement
#: uses it to tell the camera's translation from its rotation.
TranslationPrior = Callable[[IntArray, IntArray], FloatArray]
