"""A mobile base's motion for generated episodes (LeKiwi: an SO-101 on a three-wheeled base), in closed form.

The base sways about its heading and drifts in the plane as sums of sines; its pose and its body-frame velocities
(what LeKiwi records: ``x.vel``, ``y.vel`` in m/s, ``theta.vel`` in deg/s counter-clockwise) are the closed forms
and their derivatives, computed apart from framechain's integration of the velocities.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from framechain.arrays import FloatArray

__all__ = ["ARM_ON_BASE", "FRONT_ON_BASE", "BaseMotion", "base_motion"]

#: Where the arm's base_link stands on the mobile base, facing forward: LeKiwi's design puts it 3.5 cm ahead of the
#: wheels' centre and 9 cm up (SIGRobotics-UIUC/LeKiwi's URDF); this one is built 1 cm further forward and 1 cm to the
#: left, as a built robot departs from its drawing.
ARM_ON_BASE = np.array([[1.0, 0.0, 0.0, 0.045], [0.0, 1.0, 0.0, 0.01], [0.0, 0.0, 1.0, 0.09], [0.0, 0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class BaseMotion:
    """Heading ``turn_rad * sin(omega t + phase)``; position ``drift_m * sin(omega_xy t + phase_xy)`` per axis."""

    turn_rad: float
    omega: float
    phase: float
    drift_m: FloatArray  # (2,)
    omega_xy: FloatArray  # (2,)
    phase_xy: FloatArray  # (2,)

    def heading(self, t_s: FloatArray) -> FloatArray:
        out: FloatArray = self.turn_rad * np.sin(self.omega * t_s + self.phase)
        return out

    def world_from_base(self, t_s: FloatArray) -> FloatArray:
        """``T_world_base`` (T, 4, 4) at times ``t_s``."""
        psi = self.heading(t_s)
        out = np.tile(np.eye(4), (t_s.size, 1, 1))
        out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = np.cos(psi), -np.sin(psi), np.sin(psi), np.cos(psi)
        out[:, :2, 3] = (self.drift_m * np.sin(self.omega_xy * t_s[:, None] + self.phase_xy))
        return out

    def recorded(self, t_s: FloatArray) -> FloatArray:
        """(T, 3) what the base records: velocity forward and to the left in its own frame (m/s), turn rate (deg/s)."""
        psi = self.heading(t_s)
        world = self.drift_m * self.omega_xy * np.cos(self.omega_xy * t_s[:, None] + self.phase_xy)  # (T, 2)
        forward = np.cos(psi) * world[:, 0] + np.sin(psi) * world[:, 1]
        left = -np.sin(psi) * world[:, 0] + np.cos(psi) * world[:, 1]
        rate = np.rad2deg(self.turn_rad * self.omega * np.cos(self.omega * t_s + self.phase))
        out: FloatArray = np.column_stack([forward, left, rate])
        return out


def base_motion(rng: np.random.Generator, turn_deg: float) -> BaseMotion:
    """A base turning up to ``turn_deg`` either way and drifting a few centimetres."""
    return BaseMotion(turn_rad=float(np.deg2rad(turn_deg)), omega=float(rng.uniform(0.9, 1.4)),
                      phase=float(rng.uniform(0.0, 2 * np.pi)), drift_m=rng.uniform(0.03, 0.06, 2),
                      omega_xy=rng.uniform(0.6, 1.1, 2), phase_xy=rng.uniform(0.0, 2 * np.pi, 2))


def _front_camera() -> FloatArray:
    """LeKiwi's front camera on its base: 12 cm ahead, 10 cm up, looking ahead and 30 deg down (optical axes: x right,
    y down, z along the view)."""
    down = np.deg2rad(30.0)
    view = np.array([np.cos(down), 0.0, -np.sin(down)])
    right = np.array([0.0, -1.0, 0.0])
    out = np.eye(4)
    out[:3, :3] = np.column_stack([right, np.cross(view, right), view])
    out[:3, 3] = (0.12, 0.0, 0.10)
    return out


#: ``T_base_cam`` of LeKiwi's front camera (optical frame).
FRONT_ON_BASE = _front_camera()
