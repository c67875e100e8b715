"""Vectorised unit-quaternion arithmetic for the lookup hot path.

Arrays are **components first**: a quaternion array has shape ``(4, N)`` ordered x, y, z, w
(``quat_xyzw``, scalar last, as ROS and scipy), a vector array ``(3, N)``. Public tables hold
``(N, 4)``; pass ``table.T`` (a view). Components first keeps each component contiguous, which
makes these products about 3x faster than on ``(N, 4)`` rows.

scipy's Rotation is the reference (tests check every function against it) and is used for
conversions, but in scipy 1.17 composing two Rotation arrays costs about 1.3 us per element and
``as_rotvec`` 0.7 us, too slow for 2e6 chain lookups a second.
"""

from __future__ import annotations

import numpy as np

from framechain.timeline.arrays import FloatArray

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def quat_multiply(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton product ``a * b`` (rotation b first, then a) of (4, ...) arrays; broadcasts."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    shape = np.broadcast_shapes(ax.shape, bx.shape)
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


def quat_rotate(q: FloatArray, v: FloatArray) -> FloatArray:
    """Rotate vectors v (3, ...) by unit quaternions q (4, ...): v + 2w(u x v) + 2u x (u x v)."""
    ux, uy, uz, w = q
    vx, vy, vz = v
    cx = uy * vz - uz * vy
    cy = uz * vx - ux * vz
    cz = ux * vy - uy * vx
    shape = np.broadcast_shapes(ux.shape, vx.shape)
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


# -- in-place kernels for the lookup hot path -------------------------------------------------------
# Components are passed one by one so that constants can be Python floats (broadcast for free) and
# outputs can be rows of preallocated buffers: no temporaries beyond the two scratch rows given.
Component = FloatArray | float
Vec3 = tuple[Component, Component, Component]
Quat4 = tuple[Component, Component, Component, Component]


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
