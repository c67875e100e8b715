"""A mobile base's pose per state row, integrated from its recorded body-frame velocities (robot.yaml's
``mobile_base``, :mod:`framechain.config.mobile_base`).

The base starts at the world's origin, facing +x, at the episode's first row. Between rows the turn rate and the
velocity (turned into the world by the heading at each row) are integrated by the trapezoid rule, all rows at
once: a constant turn rate gives the heading exactly, and a constant speed while turning a chord of the arc,
within ``(omega dt)^2 / 12`` of it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.arrays import FloatArray, IntArray
from framechain.config.mobile_base import MobileBase
from framechain.timeline import TransformTable

__all__ = ["base_poses", "mobile_base_edge"]


def base_poses(stamps_ns: IntArray, vx: FloatArray, vy: FloatArray, yaw_rate: FloatArray
               ) -> tuple[FloatArray, FloatArray]:
    """``world <- base`` at each stamp: translations (N, 3) and quaternions xyzw (N, 4), from the body-frame
    velocities ``vx``, ``vy`` (m/s) and the counter-clockwise turn rate ``yaw_rate`` (rad/s) at the stamps."""
    if not len(stamps_ns):
        return np.zeros((0, 3)), np.zeros((0, 4))
    t = (np.asarray(stamps_ns, dtype=np.int64) - int(stamps_ns[0])) * 1e-9
    dt = np.diff(t)
    heading = np.concatenate([[0.0], np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * dt)])
    cos, sin = np.cos(heading), np.sin(heading)
    world_velocity = np.stack([cos * vx - sin * vy, sin * vx + cos * vy], axis=1)
    planar = np.concatenate([np.zeros((1, 2)), np.cumsum(0.5 * (world_velocity[1:] + world_velocity[:-1])
                                                         * dt[:, None], axis=0)])
    xyz = np.column_stack([planar, np.zeros(len(t))])
    quat: FloatArray = Rotation.from_euler("z", heading[:, None]).as_quat()
    return xyz, quat


def mobile_base_edge(base: MobileBase, world: str, state: FloatArray, names: Sequence[str], stamps_ns: IntArray,
                     source: str) -> TransformTable:
    """``world -> base.frame`` at every state row, from the state's velocity columns (a speed not named is 0)."""

    def column(name: str | None, scale: float) -> FloatArray:
        if name is None:
            return np.zeros(state.shape[0])
        out: FloatArray = state[:, list(names).index(name)] * scale
        return out

    xyz, quat = base_poses(stamps_ns, column(base.x_vel, base.speed_scale), column(base.y_vel, base.speed_scale),
                           column(base.yaw_rate, base.yaw_rate_scale))
    return TransformTable.from_rows(world, base.frame, stamps_ns, xyz, quat, source=f"{source}->{base.frame}")
