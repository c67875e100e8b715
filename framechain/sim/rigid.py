"""The scene generator's own rigid-body and camera maths: 4x4 matrices, pinhole, tf-style interpolation.

Written out here, with numpy and scipy only, so that the scenes the benchmark and the tests check
framechain against are not built with framechain's own replay maths (a bug there would otherwise
cancel out). Conventions are DESIGN.md's: ``T_a_b`` (a ``(N, 4, 4)`` stack, or one ``(4, 4)``)
maps points in frame b into frame a; quaternions are ``xyzw``; times are integer nanoseconds.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from framechain.arrays import FloatArray, IntArray


def matrices(translation: FloatArray, quat_xyzw: FloatArray) -> FloatArray:
    """``(N, 4, 4)`` homogeneous matrices from ``(N, 3)`` translations and ``(N, 4)`` quaternions."""
    t = np.atleast_2d(np.asarray(translation, dtype=float))
    q = np.atleast_2d(np.asarray(quat_xyzw, dtype=float))
    out = np.zeros((max(t.shape[0], q.shape[0]), 4, 4))
    out[:, :3, :3] = Rotation.from_quat(q).as_matrix()
    out[:, :3, 3] = t
    out[:, 3, 3] = 1.0
    return out


def matrix(translation: FloatArray | Sequence[float], quat_xyzw: FloatArray | Sequence[float]) -> FloatArray:
    """One ``(4, 4)`` homogeneous matrix."""
    out: FloatArray = matrices(np.asarray(translation, dtype=float)[None], np.asarray(quat_xyzw, dtype=float)[None])[0]
    return out


def inverse(transform: FloatArray) -> FloatArray:
    """``T_b_a`` from ``T_a_b`` (one matrix or a stack): ``[R^T, -R^T t]``."""
    rot_t = np.swapaxes(transform[..., :3, :3], -1, -2)
    out = np.zeros_like(transform)
    out[..., :3, :3] = rot_t
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rot_t, transform[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def apply(transform: FloatArray, points: FloatArray) -> FloatArray:
    """Points ``(N, 3)`` in frame b to frame a with ``T_a_b`` (one matrix, or one per point)."""
    rotation = transform[..., :3, :3]
    translation = transform[..., :3, 3]
    out: FloatArray = np.einsum("...ij,...j->...i", rotation, points) + translation
    return out


def to_rows(transform: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(N, 3)`` translations and ``(N, 4)`` xyzw quaternions of a ``(N, 4, 4)`` stack."""
    stack = transform.reshape(-1, 4, 4)
    quat: FloatArray = Rotation.from_matrix(stack[:, :3, :3]).as_quat()
    translation: FloatArray = stack[:, :3, 3].copy()
    return translation, quat


def interpolate(stamp_ns: IntArray, translation: FloatArray, quat_xyzw: FloatArray, query_ns: IntArray) -> FloatArray:
    """``(M, 4, 4)`` transforms at ``query_ns`` from time-sorted samples, as tf2 does.

    Linear in translation between the two bracketing samples and slerp in rotation; a query
    outside the samples is an error (tf2's extrapolation), never clamped.
    """
    stamps = np.asarray(stamp_ns, dtype=np.int64)
    query = np.asarray(query_ns, dtype=np.int64)
    if query.size and (query.min() < stamps[0] or query.max() > stamps[-1]):
        raise ValueError("interpolation query outside the samples (extrapolation)")
    # Seconds from the first sample: float64 keeps sub-nanosecond resolution over hours.
    t = (stamps - stamps[0]).astype(float) * 1e-9
    tq = (query - stamps[0]).astype(float) * 1e-9
    trans = np.stack([np.interp(tq, t, translation[:, axis]) for axis in range(3)], axis=1)
    rotation = Slerp(t, Rotation.from_quat(quat_xyzw))(tq)
    out = np.zeros((query.size, 4, 4))
    out[:, :3, :3] = rotation.as_matrix()
    out[:, :3, 3] = trans
    out[:, 3, 3] = 1.0
    return out


def held(stamp_ns: IntArray, query_ns: IntArray) -> IntArray:
    """The stamp of the latest sample at or before each query (a zero-order hold)."""
    stamps = np.asarray(stamp_ns, dtype=np.int64)
    index = np.searchsorted(stamps, np.asarray(query_ns, dtype=np.int64), side="right") - 1
    if index.size and index.min() < 0:
        raise ValueError("zero-order hold before the first sample")
    out: IntArray = stamps[index]
    return out


def intrinsic_matrix(fx: float, fy: float, cx: float, cy: float) -> FloatArray:
    """The pinhole camera matrix ``K``."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def project(K: FloatArray, points: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Pixels ``(u, v)`` of optical-frame points ``(N, 3)`` (x right, y down, z forward)."""
    x = points[:, 0] / points[:, 2]
    y = points[:, 1] / points[:, 2]
    return K[0, 0] * x + K[0, 2], K[1, 1] * y + K[1, 2]


def back_project(K: FloatArray, u: FloatArray, v: FloatArray, depth: FloatArray) -> FloatArray:
    """Optical-frame points ``(N, 3)`` of pixels with depth along z: ``[(u-cx) Z/fx, (v-cy) Z/fy, Z]``."""
    x = (np.asarray(u, dtype=float) - K[0, 2]) / K[0, 0]
    y = (np.asarray(v, dtype=float) - K[1, 2]) / K[1, 1]
    z = np.asarray(depth, dtype=float)
    return np.stack([x * z, y * z, z], axis=1)
