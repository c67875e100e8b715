"""robot.yaml's ``mobile_base``: a base that drives around, its motion recorded as body-frame velocities.

A mobile manipulator (LeRobot's LeKiwi: an SO-101 on a three-wheeled base) records its base's velocities beside
the arm's joints: ``x.vel`` and ``y.vel`` (m/s, forward and to the left) and ``theta.vel`` (the turn rate,
counter-clockwise seen from above, deg/s), measured from its wheels. A camera on the arm or the base turns with
the base, so forward kinematics of the arm alone leaves every turn of the base unexplained. Named here, the
velocities are integrated into ``world -> frame`` per state row (:mod:`framechain.adapters.lerobot.odometry`),
and the arms hang from ``frame``: ``world_from_base`` (each arm's) then places an arm on the mobile base::

    mobile_base:
      frame: mobile_base        # default "mobile_base"
      x_vel: x.vel              # state names; a speed left out is taken as 0
      y_vel: y.vel
      yaw_rate: theta.vel
      speed_unit: m/s           # m/s or mm/s (default m/s)
      yaw_rate_unit: deg/s      # deg/s or rad/s (default deg/s, LeRobot's)

Integrated odometry drifts, but a camera's turn between two frames comes from the turn rate over that
interval alone: the drift moves where the base is, not how it turns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from framechain.config.schema import Section

__all__ = ["DEFAULT_FRAME", "MobileBase", "parse_mobile_base"]

#: The base's frame when robot.yaml names none.
DEFAULT_FRAME = "mobile_base"
_KEYS = {"frame", "x_vel", "y_vel", "yaw_rate", "speed_unit", "yaw_rate_unit"}
#: Per unit, the factor to SI (m/s, rad/s).
SPEED_UNITS = {"m/s": 1.0, "mm/s": 1e-3}
YAW_RATE_UNITS = {"deg/s": math.pi / 180.0, "rad/s": 1.0}


@dataclass(frozen=True)
class MobileBase:
    """Which state names hold the base's body-frame velocities, and their units (factors to m/s and rad/s)."""

    frame: str = DEFAULT_FRAME
    x_vel: str | None = None
    y_vel: str | None = None
    yaw_rate: str | None = None
    speed_scale: float = 1.0
    yaw_rate_scale: float = math.pi / 180.0

    @property
    def states(self) -> tuple[str, ...]:
        """The state names the base reads (the speeds left out are none of them)."""
        return tuple(s for s in (self.x_vel, self.y_vel, self.yaw_rate) if s is not None)


def parse_mobile_base(top: Section, world_frame: str) -> MobileBase | None:
    """The ``mobile_base`` section of robot.yaml (None: not given)."""
    if "mobile_base" not in top:
        return None
    section = top.section("mobile_base", _KEYS)
    names = {key: section.name(key, what="a state name") for key in ("x_vel", "y_vel", "yaw_rate")}
    if not any(names.values()):
        section.fail("names none of x_vel, y_vel, yaw_rate: the state names of the base's velocities")
    frame = section.frame("frame", DEFAULT_FRAME) or DEFAULT_FRAME
    if frame == world_frame:
        section.fail_at(section.path("frame"), f"is the world frame {world_frame!r}: name the base's own frame")
    return MobileBase(frame=frame, **names, speed_scale=_unit(section, "speed_unit", "m/s", SPEED_UNITS),
                      yaw_rate_scale=_unit(section, "yaw_rate_unit", "deg/s", YAW_RATE_UNITS))


def _unit(section: Section, key: str, default: str, units: dict[str, float]) -> float:
    value = section.name(key, default, what="a unit") or default
    if value not in units:
        section.fail_at(section.path(key), f"is an unknown unit {value!r}; units are {sorted(units)}")
    return units[value]
