"""Vectorised unit-quaternion arithmetic, shared by every room (the replay's lookups, the adapters' FK).

Arrays are **components first**: a quaternion array has shape ``(4, N)`` ordered x, y, z, w
(``quat_xyzw``, scalar last, as ROS and scipy), a vector array ``(3, N)``. Public tables hold
``(N, 4)``; pass ``table.T`` (a view). Components first keeps each component contiguous, which
makes these products about 3x faster than on ``(N, 4)`` rows.

scipy's Rotation is the reference (tests check every function against it) and is used for
conversions, but in scipy 1.17 composing two Rotation arrays costs about 1.3 us per element and
``as_rotvec`` 0.7 us, too slow for 2e6 chain lookups a second.

Components may also be given one by one as a tuple (``(x, y, z, w)``, each an array or a Python
float): constants then broadcast for free, as in a kinematic chain whose fixed joints are floats.
One rotation is a (4,) array, one vector a (3,) one; rows of a table ``(N, 4)`` go in as ``rows.T``.

The conversions every room uses, each once here: rotation vectors (:func:`quat_from_rotvec`,
:func:`quat_to_rotvec`), URDF roll-pitch-yaw (:func:`quat_from_rpy`, :func:`quat_to_rpy`),
matrices (:func:`quat_from_matrix`, :func:`quat_to_matrix`, :func:`homogeneous`), angles
(:func:`quat_angle`, :func:`quat_angle_between`) and rigid transforms ``T_a_b`` as a translation
and a quaternion (:func:`compose`, :func:`invert`); :mod:`framechain.geometry.transforms` applies
them to the rows tables hold.

Rotations as rows, for fits that hold a few rotations or rows of them (the camera's motion):
quaternion rows ``(..., 4)``, matrices ``(..., 3, 3)``, a :class:`RotationVector`, the
:class:`Inverse` of one, or a tuple of them (their product as written), read and converted by
scipy's Rotation (quaternions normalised as they are read; a product formed once, however many
of its forms are asked for): :func:`quat_of`, :func:`matrix_of`, :func:`rotvec_of`,
:func:`rpy_of`, :func:`angle_of`, :func:`rotate_by`.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, NamedTuple, TypeAlias

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])

Component = FloatArray | float
Vec3 = tuple[Component, Component, Component]
Quat4 = tuple[Component, Component, Component, Component]
#: A quaternion array (4, ...) or its four components.
QuatLike = FloatArray | Quat4
#: A vector array (3, ...) or its three components.
VecLike = FloatArray | Vec3


def quat_multiply(a: QuatLike, b: QuatLike) -> FloatArray:
    """Hamilton product ``a * b`` (rotation b first, then a) of (4, ...) arrays; broadcasts."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    shape = np.broadcast_shapes(*(np.shape(c) for c in (ax, ay, az, aw, bx, by, bz, bw)))
    out = np.empty((4, *shape))
    out[0] = aw * bx + ax * bw + ay * bz - az * by
    out[1] = aw * by - ax * bz + ay * bw + az * bx
    out[2] = aw * bz + ax * by - ay * bx + az * bw
    out[3] = aw * bw - ax * bx - ay * by - az * bz
    return out


def quat_conjugate(q: FloatArray) -> FloatArray:
    """Inverse of unit quaternions (4, ...)."""
    out = -np.asarray(q, dtype=float)
    out[3] = -out[3]
    return out


def quat_rotate(q: QuatLike, v: VecLike) -> FloatArray:
    """Rotate vectors v (3, ...) by unit quaternions q (4, ...): v + 2w(u x v) + 2u x (u x v)."""
    ux, uy, uz, w = q
    vx, vy, vz = v
    cx = uy * vz - uz * vy
    cy = uz * vx - ux * vz
    cz = ux * vy - uy * vx
    shape = np.broadcast_shapes(*(np.shape(c) for c in (ux, uy, uz, w, vx, vy, vz)))
    out = np.empty((3, *shape))
    out[0] = vx + 2.0 * (w * cx + uy * cz - uz * cy)
    out[1] = vy + 2.0 * (w * cy + uz * cx - ux * cz)
    out[2] = vz + 2.0 * (w * cz + ux * cy - uy * cx)
    return out


def quat_from_rotvec(rotvec: FloatArray) -> FloatArray:
    """Exponential map: rotation vectors (3, ...) (axis * angle, rad) to unit quaternions (4, ...)."""
    angle = np.sqrt(rotvec[0] ** 2 + rotvec[1] ** 2 + rotvec[2] ** 2)
    half = 0.5 * angle
    # sin(angle/2)/angle, by its Taylor series near 0 where the ratio loses precision.
    small = angle < 1e-6
    scale = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    out = np.empty((4, *angle.shape))
    out[:3] = rotvec * scale
    out[3] = np.cos(half)
    return out


def quat_from_rpy(rpy: FloatArray) -> FloatArray:
    """URDF/tf2 roll-pitch-yaw (3, ...) (fixed axes: roll about x, then pitch about y, then yaw about z,
    radians) to unit quaternions (4, ...): q = q_z(yaw) q_y(pitch) q_x(roll), scipy's ``from_euler("xyz")``."""
    half = 0.5 * np.asarray(rpy, dtype=float)
    zero = np.zeros_like(half[0])
    q_roll = (np.sin(half[0]), zero, zero, np.cos(half[0]))
    q_pitch = (zero, np.sin(half[1]), zero, np.cos(half[1]))
    q_yaw = (zero, zero, np.sin(half[2]), np.cos(half[2]))
    return quat_multiply(q_yaw, quat_multiply(q_pitch, q_roll))


def quat_to_rpy(q: FloatArray) -> FloatArray:
    """URDF/tf2 roll-pitch-yaw (3, ...) of unit quaternions (4, ...): the inverse of :func:`quat_from_rpy`
    (tf2's ``getRPY``, scipy's ``as_euler("xyz")``), pitch in [-pi/2, pi/2], roll and yaw in [-pi, pi]."""
    arr = np.asarray(q, dtype=float)
    out: FloatArray = rpy_of(arr.reshape(4, -1).T).T.reshape(3, *arr.shape[1:])
    return out


def quat_to_rotvec(q: FloatArray) -> FloatArray:
    """Logarithm map: unit quaternions (4, ...) to rotation vectors (3, ...), angle in [0, pi]."""
    sign = np.where(q[3] < 0, -1.0, 1.0)
    xyz = q[:3] * sign
    w = q[3] * sign
    s = np.sqrt(xyz[0] ** 2 + xyz[1] ** 2 + xyz[2] ** 2)
    angle = 2.0 * np.arctan2(s, w)
    small = s < 1e-9
    scale = np.where(small, 2.0 / np.maximum(w, 1e-300), angle / np.where(small, 1.0, s))
    out: FloatArray = xyz * scale
    return out


def quat_angle(q: FloatArray) -> FloatArray:
    """Rotation angle in radians, in [0, pi], of quaternions (4, ...)."""
    out: FloatArray = 2.0 * np.arctan2(np.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2), np.abs(q[3]))
    return out


def quat_angle_between(a: QuatLike, b: QuatLike) -> FloatArray:
    """Angle in radians, in [0, pi], of the rotation taking ``a`` to ``b`` (``a^-1 b``), quaternions (4, ...)."""
    ax, ay, az, aw = a
    return quat_angle(quat_multiply((-np.asarray(ax), -np.asarray(ay), -np.asarray(az), aw), b))


def quat_to_matrix(q: QuatLike) -> FloatArray:
    """Rotation matrices (..., 3, 3) of unit quaternions (4, ...)."""
    x, y, z, w = (np.asarray(c, dtype=float) for c in q)
    shape = np.broadcast_shapes(x.shape, y.shape, z.shape, w.shape)
    out = np.empty((*shape, 3, 3))
    out[..., 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[..., 0, 1] = 2.0 * (x * y - z * w)
    out[..., 0, 2] = 2.0 * (x * z + y * w)
    out[..., 1, 0] = 2.0 * (x * y + z * w)
    out[..., 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[..., 1, 2] = 2.0 * (y * z - x * w)
    out[..., 2, 0] = 2.0 * (x * z - y * w)
    out[..., 2, 1] = 2.0 * (y * z + x * w)
    out[..., 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return out


def quat_from_matrix(matrix: FloatArray) -> FloatArray:
    """Unit quaternions (4, ...) of rotation matrices (..., 3, 3) (scipy's conversion, w >= 0 not enforced)."""
    m = np.asarray(matrix, dtype=float)
    out: FloatArray = quat_of(m.reshape(-1, 3, 3)).T.reshape(4, *m.shape[:-2])
    return out


def compose(t_ab: VecLike, q_ab: QuatLike, t_bc: VecLike, q_bc: QuatLike) -> tuple[FloatArray, FloatArray]:
    """``T_a_c = T_a_b @ T_b_c``, components first: translations (3, ...), quaternions (4, ...)."""
    rotated = quat_rotate(q_ab, t_bc)
    if isinstance(t_ab, np.ndarray):  # the lookup hot path: one broadcast add
        return rotated + t_ab, quat_multiply(q_ab, q_bc)
    tx, ty, tz = t_ab
    shape = np.broadcast_shapes(rotated.shape[1:], *(np.shape(c) for c in (tx, ty, tz)))
    out = np.empty((3, *shape))
    for k, c in enumerate((tx, ty, tz)):
        np.add(rotated[k], c, out=out[k])
    return out, quat_multiply(q_ab, q_bc)


def invert(t_ab: FloatArray, q_ab: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``T_b_a`` from ``T_a_b``, components first."""
    q_ba = quat_conjugate(q_ab)
    return -quat_rotate(q_ba, t_ab), q_ba


def homogeneous(quat: QuatLike, translation: VecLike, *, n: int | None = None) -> FloatArray:
    """Homogeneous matrices (n, 4, 4) of components-first quaternions and translations.

    ``n`` defaults to the largest component size (constant components broadcast).
    """
    n = max(int(np.size(c)) for c in (*quat, *translation)) if n is None else n
    out = np.zeros((n, 4, 4))
    x, y, z, w = (np.broadcast_to(np.asarray(c, dtype=float), (n,)) for c in quat)
    out[:, :3, :3] = quat_to_matrix((x, y, z, w))
    for i in range(3):
        out[:, i, 3] = translation[i]
    out[:, 3, 3] = 1.0
    return out


# -- in-place kernels for the lookup hot path -------------------------------------------------------
# Components are passed one by one so that constants can be Python floats (broadcast for free) and
# outputs can be rows of preallocated buffers: no temporaries beyond the two scratch rows given.


def quat_multiply_into(
    a: Quat4,
    b: Quat4,
    out: FloatArray,
    scratch: FloatArray,
    *,
    conjugate_a: bool = False,
) -> None:
    """``out[:] = a * b`` (or ``conj(a) * b``) for (x, y, z, w) components; ``out`` (4, N), ``scratch`` (2, N).

    ``out`` must not share memory with ``a`` or ``b``.
    """
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    t1, t2 = scratch[0], scratch[1]
    # out_k = aw * b_k +/- (vector part of a times b), the sign flipping for the conjugate.
    for k, (p, q, r, s, u, v) in enumerate(
        ((ax, bw, ay, bz, az, by), (ay, bw, az, bx, ax, bz), (az, bw, ax, by, ay, bx))
    ):
        np.multiply(p, q, out=t1)  # a_k bw + a_(k+1) b_(k+2) - a_(k+2) b_(k+1)
        np.multiply(r, s, out=t2)
        t1 += t2
        np.multiply(u, v, out=t2)
        t1 -= t2
        row = out[k]
        np.multiply(aw, (bx, by, bz)[k], out=row)
        if conjugate_a:
            np.subtract(row, t1, out=row)
        else:
            row += t1
    w = out[3]
    np.multiply(ax, bx, out=t1)
    np.multiply(ay, by, out=t2)
    t1 += t2
    np.multiply(az, bz, out=t2)
    t1 += t2
    np.multiply(aw, bw, out=w)
    if conjugate_a:
        w += t1
    else:
        w -= t1


def quat_rotate_into(
    q: Quat4,
    v: Vec3,
    out: FloatArray,
    scratch: FloatArray,
    *,
    conjugate_q: bool = False,
) -> None:
    """``out[:] = q v q*`` (or by ``conj(q)``): ``v + 2w (u x v) + 2 u x (u x v)``; ``scratch`` (5, N).

    ``out`` (3, N) must not share memory with ``q`` or ``v``.
    """
    ux, uy, uz, w = q
    vx, vy, vz = v
    cx, cy, cz, t1, t2 = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    for row, (p, r, s, u) in zip((cx, cy, cz), ((uy, vz, uz, vy), (uz, vx, ux, vz), (ux, vy, uy, vx)), strict=True):
        np.multiply(p, r, out=row)  # (u x v), one component per row
        np.multiply(s, u, out=t1)
        np.subtract(row, t1, out=row)
    for k, (vk, p, r, s, u, ck) in enumerate(
        ((vx, uy, cz, uz, cy, cx), (vy, uz, cx, ux, cz, cy), (vz, ux, cy, uy, cx, cz))
    ):
        np.multiply(p, r, out=t1)  # (u x c)_k
        np.multiply(s, u, out=t2)
        t1 -= t2
        np.multiply(w, ck, out=t2)
        if conjugate_q:  # conj(q): the vector part u changes sign, so the w (u x v) term does
            t1 -= t2
        else:
            t1 += t2
        t1 *= 2.0
        np.add(t1, vk, out=out[k])


def kabsch(cross: FloatArray) -> FloatArray:
    """Rotations ``R`` maximising ``tr(R^T C)`` for a stack of cross-covariances ``C`` (..., 3, 3).

    With ``C = sum w a b^T`` this is the rotation taking the vectors ``b`` nearest to ``a`` in least
    squares (Kabsch/Wahba), a reflection never: ``R = U diag(1, 1, det(U V^T)) V^T`` from ``C = U S V^T``.
    """
    u, _s, vt = np.linalg.svd(cross)
    d = np.sign(np.linalg.det(u @ vt))
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    out: FloatArray = u @ vt
    return out


# -- rotations as rows, through scipy ----------------------------------------------------------------


class RotationVector(NamedTuple):
    """Rotations given by their rotation vectors (..., 3): axis times angle, radians."""

    rotvec: FloatArray


class Inverse(NamedTuple):
    """The inverse of a rotation: ``(Inverse(a), b)`` is ``a^-1 b``."""

    rotation: Rotations


#: One rotation or rows of them: quaternions (..., 4) xyzw or matrices (..., 3, 3) (arrays), a
#: :class:`RotationVector`, an :class:`Inverse`, or a tuple of these, their product as written
#: (``(a, b)`` is ``a b``: ``b`` first, then ``a``; nest tuples to group).
Rotations: TypeAlias = "FloatArray | RotationVector | Inverse | tuple[Rotations, ...]"


def _read(rotation: Rotations) -> Rotation:
    """scipy's Rotation of ``rotation`` (see :data:`Rotations`)."""
    from scipy.spatial.transform import Rotation

    if isinstance(rotation, Inverse):
        return _read(rotation.rotation).inv()
    if isinstance(rotation, RotationVector):
        return Rotation.from_rotvec(rotation.rotvec)
    if isinstance(rotation, tuple):
        product = _read(rotation[0])
        for factor in rotation[1:]:
            product = product * _read(factor)
        return product
    if not isinstance(rotation, np.ndarray):
        raise TypeError(f"a rotation is an array of quaternions or matrices, not {type(rotation).__name__}")
    if rotation.shape[-2:] == (3, 3):
        return Rotation.from_matrix(rotation)
    return Rotation.from_quat(rotation)


def quat_of(rotation: Rotations) -> FloatArray:
    """Quaternion rows (..., 4) xyzw of ``rotation`` (as scipy keeps them: w >= 0 not enforced)."""
    out: FloatArray = _read(rotation).as_quat()
    return out


def matrix_of(rotation: Rotations) -> FloatArray:
    """Rotation matrices (..., 3, 3) of ``rotation``."""
    out: FloatArray = _read(rotation).as_matrix()
    return out


def rotvec_of(rotation: Rotations) -> FloatArray:
    """Rotation vectors (..., 3) of ``rotation``, angles in [0, pi]."""
    out: FloatArray = _read(rotation).as_rotvec()
    return out


def rpy_of(rotation: Rotations) -> FloatArray:
    """URDF/tf2 roll-pitch-yaw (..., 3) of ``rotation`` (fixed axes x, y, z: scipy's ``as_euler("xyz")``)."""
    with warnings.catch_warnings():  # at pitch +-pi/2 any split of roll and yaw is right: scipy warns
        warnings.filterwarnings("ignore", message="Gimbal lock detected")
        out: FloatArray = _read(rotation).as_euler("xyz")
    return out


def angle_of(rotation: Rotations) -> FloatArray:
    """Rotation angles (...) of ``rotation``, radians in [0, pi]."""
    return np.asarray(_read(rotation).magnitude(), dtype=float)


def rotate_by(rotation: Rotations, vectors: npt.ArrayLike) -> FloatArray:
    """``vectors`` (..., 3) rotated by ``rotation`` (row by row; one rotation or one vector broadcasts)."""
    out: FloatArray = _read(rotation).apply(vectors)
    return out
