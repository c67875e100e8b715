"""Arms framechain knows without a robot.yaml: a bundled URDF per LeRobot robot type, and dataset state
names matched to its joints under any per-arm prefix.

The URDFs under ``urdfs/`` are the published models with their visual and collision geometry removed
(the meshes are not bundled), each with its licence beside it: SO-100 and SO-101 from
TheRobotStudio/SO-ARM100 (Apache-2.0), Koch v1.0 from AlexanderKoch-Koch/low_cost_robot (MIT), and the
ViperX 300 6DOF of ALOHA (``aloha``, ``mobile_aloha``, ``viperx``) from Interbotix/interbotix_ros_manipulators
(BSD-3-Clause). LeKiwi (``lekiwi``) is an SO-101 on a mobile base: its base's recorded velocities
(:data:`BASE_VELOCITIES`) move the arm in the world (robot.yaml's ``mobile_base``).

State names are matched to an arm's motors (LeRobot's names, ``shoulder_pan`` ... ``gripper``) by
suffix, so ``shoulder_pan.pos``, ``left_shoulder_pan.pos``, ``arm1_shoulder_pan.pos`` and
``follower_shoulder_pan.pos`` all drive ``shoulder_pan``, and what comes before the motor is the
arm's prefix. Numbered names (``arm1_j1 .. arm2_j6``, ``joint_3``) take the motors in order, per arm; on a
two-arm robot (``bi_...``, ALOHA) a run as long as both arms' motors (``motor_0 .. motor_13``) is both arms, the left
first.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["BASE_VELOCITIES", "KNOWN_ARMS", "ArmJoints", "KnownArm", "arm_prefixes", "known_arm", "match_state_names"]

_URDFS = Path(__file__).resolve().parent / "urdfs"
#: LeRobot's motor names of its SO-100/SO-101 and Koch arms, from the base out (their ids 1..6).
LEROBOT_MOTORS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
#: ALOHA's (and Interbotix's) names of a ViperX 300 6DOF's joints, from the base out, as its datasets record them
#: (``left_waist`` ... ``right_gripper``, radians; the gripper its fingers' opening, normalised).
VIPERX_MOTORS = ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate", "gripper")
#: A numbered joint at the end of a state name: ``j1``, ``joint_3``, ``motor2``.
_NUMBERED = re.compile(r"^(?P<prefix>.*?)(?:joint|motor|j)_?(?P<index>\d+)$", re.IGNORECASE)


@dataclass(frozen=True)
class KnownArm:
    """One arm model: its bundled URDF, its motors in order, the URDF joint each drives, and its wrist link."""

    name: str
    title: str
    urdf: Path
    source: str
    #: The link a wrist camera rides (the fixed jaw's link).
    camera_link: str
    motors: tuple[str, ...] = LEROBOT_MOTORS
    #: motor -> URDF joint; a motor absent here has no joint in the URDF.
    joints: Mapping[str, str] = field(default_factory=lambda: {m: m for m in LEROBOT_MOTORS})
    #: motor -> why it drives no joint of the URDF (absent: the URDF has no such joint).
    unmapped: Mapping[str, str] = field(default_factory=dict)
    #: Where a two-arm rig of this arm has each arm's base, by the arm's side ("left", "right"): world xyz (m) and
    #: rpy (rad), a better guess than side by side (absent: side by side, 0.4 m apart).
    bases: Mapping[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = field(default_factory=dict)
    #: The robot always has two of these arms (ALOHA), whatever its ``robot_type`` says.
    pair: bool = False
    #: Where the arm stands on its mobile base in the robot's drawing (LeKiwi): xyz (m) and rpy (rad) in the base's
    #: frame, x forward (None: not known, guessed at the base's centre).
    on_base: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None

    def arms_in(self, robot_type: str) -> int:
        """How many of these arms a robot of ``robot_type`` has: two for LeRobot's ``bi_...`` robots and a pair's."""
        return 2 if self.pair or re.match(r"bi[_-]", robot_type.lower()) else 1


KNOWN_ARMS = {
    "so101": KnownArm("so101", "SO-101", _URDFS / "so101" / "so101_new_calib.urdf",
                      "TheRobotStudio/SO-ARM100, Apache-2.0", "gripper_link"),
    "so100": KnownArm("so100", "SO-100", _URDFS / "so100" / "so100.urdf", "TheRobotStudio/SO-ARM100, Apache-2.0",
                      "gripper"),
    # Koch v1.0 has no wrist flex: its fourth joint turns about the forearm.
    "koch": KnownArm("koch", "Koch", _URDFS / "koch" / "low-cost-arm.urdf", "AlexanderKoch-Koch/low_cost_robot, MIT",
                     "gripper-static-motor_v2_1",
                     joints={"shoulder_pan": "Revolute 2", "shoulder_lift": "Revolute 3", "elbow_flex": "Revolute 5",
                             "wrist_roll": "Revolute 6", "gripper": "Revolute 7"}),
    # LeKiwi: an SO-101 (``arm_shoulder_pan.pos`` ...) on a three-wheeled base whose velocities it records too. In
    # LeKiwi's design (SIGRobotics-UIUC/LeKiwi, URDF/LeKiwi.urdf, Apache-2.0) the arm faces forward with its pan axis
    # 7.4 cm ahead of the wheels' centre: the SO-101's base_link (3.9 cm behind its pan axis) 3.5 cm ahead, 9 cm up.
    "lekiwi": KnownArm("lekiwi", "LeKiwi SO-101", _URDFS / "so101" / "so101_new_calib.urdf",
                       "TheRobotStudio/SO-ARM100, Apache-2.0", "gripper_link", on_base=((0.035, 0.0, 0.09),
                                                                                      (0.0, 0.0, 0.0))),
}
#: LeRobot's names of a mobile base's body-frame velocities (LeKiwi: m/s forward and to the left, deg/s
#: counter-clockwise), as robot.yaml's ``mobile_base`` keys take them.
BASE_VELOCITIES = {"x_vel": "x.vel", "y_vel": "y.vel", "yaw_rate": "theta.vel"}


#: ALOHA 2's arms face each other across the table (google-deepmind/mujoco_menagerie, aloha/aloha.xml).
ALOHA_BASES = {"left": ((-0.469, -0.019, 0.02), (0.0, 0.0, 0.0)), "right": ((0.469, -0.019, 0.02), (0.0, 0.0, math.pi))}


def _viperx(name: str, title: str, bases: Mapping[str, tuple[tuple[float, float, float], tuple[float, float, float]]],
            *, pair: bool) -> KnownArm:
    """ALOHA's arm: its wrist cameras ride the gripper, past wrist_rotate. Its gripper state is the fingers' opening
    normalised to 0..1 (closed..open), not the gripper servo's turn: it drives nothing (the fingers carry no
    camera). ``pair``: the robot always has two."""
    return KnownArm(name, title, _URDFS / "vx300s" / "vx300s.urdf", "Interbotix/interbotix_ros_manipulators, "
                    "BSD-3-Clause", "gripper_link", VIPERX_MOTORS, {m: m for m in VIPERX_MOTORS[:-1]},
                    {"gripper": "ALOHA records the fingers' opening normalised to 0..1, not a joint angle"}, bases,
                    pair)


# Matched in this order: a mobile ALOHA's arms sit side by side on its base, facing forward.
KNOWN_ARMS |= {"mobilealoha": _viperx("mobilealoha", "Mobile ALOHA ViperX 300 6DOF", {}, pair=True),
               "aloha": _viperx("aloha", "ALOHA ViperX 300 6DOF", ALOHA_BASES, pair=True),
               "viperx": _viperx("viperx", "ViperX 300 6DOF", {}, pair=False)}


def known_arm(robot_type: str | None) -> KnownArm | None:
    """The arm a LeRobot ``robot_type`` names (``so101_follower``, ``bi_so100_follower``, ``koch``, ``aloha``), or
    None."""
    key = re.sub(r"[^a-z0-9]", "", (robot_type or "").lower())
    return next((arm for name, arm in KNOWN_ARMS.items() if name in key), None)


@dataclass(frozen=True)
class ArmJoints:
    """The state names of one arm: its prefix, each name with the motor it drives, in the dataset's order."""

    prefix: str
    motors: tuple[tuple[str, str], ...]  # (state name, motor)

    @property
    def name(self) -> str:
        """The arm's name in robot.yaml: its prefix without the separator (``arm`` for none)."""
        return self.prefix.strip("_.- ") or "arm"


def arm_prefixes(count: int) -> tuple[str, ...]:
    """Prefixes for ``count`` arms whose names do not say which is which, in LeRobot's order (the left arm first)."""
    if count == 1:
        return ("",)
    return ("left_", "right_") if count == 2 else tuple(f"arm{i + 1}_" for i in range(count))


def match_state_names(names: Sequence[str], motors: Sequence[str], *, arms: int = 1
                      ) -> tuple[list[ArmJoints], list[str]]:
    """The arms ``names`` hold (grouped by prefix, in order of appearance) and the names matched to no motor.

    A name matches the longest motor it ends with (``.pos`` aside; velocities and efforts match none);
    numbered names (``arm1_j1``) take the motors in order per prefix, from 0 or 1 as the names start; on a robot of
    ``arms`` arms a run of numbered names as long as all their motors (``motor_0 .. motor_13`` of ALOHA's two) is
    those arms in order (:func:`arm_prefixes`). One arm's positions and velocities, numbered alike, stay one arm."""
    by_prefix: dict[str, list[tuple[str, str]]] = {}
    numbered: dict[str, list[tuple[str, int]]] = {}
    unmatched: list[str] = []
    for name in names:
        stem = name.removesuffix(".pos")
        motor = max((m for m in motors if stem.endswith(m)), key=len, default=None)
        found = _NUMBERED.match(stem)
        if "." in stem:
            unmatched.append(name)
        elif motor is not None:
            by_prefix.setdefault(stem[: len(stem) - len(motor)], []).append((name, motor))
        elif found is not None:
            numbered.setdefault(found["prefix"], []).append((name, int(found["index"])))
        else:
            unmatched.append(name)
    for prefix, items in numbered.items():
        first = min(i for _n, i in items)
        several = (arms >= 2 and len(items) == arms * len(motors)
                   and sorted(i for _n, i in items) == list(range(first, first + len(items))))
        for name, index in items:
            k = index - first
            if several:
                arm = prefix + arm_prefixes(arms)[k // len(motors)]
                by_prefix.setdefault(arm, []).append((name, motors[k % len(motors)]))
            elif 0 <= k < len(motors):
                by_prefix.setdefault(prefix, []).append((name, motors[k]))
            else:
                unmatched.append(name)
    return [ArmJoints(prefix, tuple(items)) for prefix, items in by_prefix.items()], unmatched
