"""LeRobot's calibration JSON read as LeRobot reads its Feetech servos.

The expected angles are worked by hand from LeRobot's normalisation (``MotorsBus._normalize`` in
huggingface/lerobot ``src/lerobot/motors/motors_bus.py``): the servo applies ``homing_offset``
itself, so recorded ticks are already homed; DEGREES is ``(ticks - (range_min + range_max) / 2) *
360 / 4095``; RANGE_M100_100 is ``(ticks - min) / (max - min) * 200 - 100``, negated where
``drive_mode`` is 1; RANGE_0_100 is ``(ticks - min) / (max - min) * 100``, ``100 - x`` where
``drive_mode`` is 1.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from framechain.config.robot import JointMapping, RobotConfig, RobotConfigError
from framechain.robot.binding import convert_joint

#: As LeRobot writes it (``calibration/robots/so101_follower/<id>.json``): one entry per motor.
CALIBRATION = {
    "shoulder_pan": {"id": 1, "drive_mode": 0, "homing_offset": -1937, "range_min": 737, "range_max": 3483},
    "shoulder_lift": {"id": 2, "drive_mode": 0, "homing_offset": 1302, "range_min": 1000, "range_max": 3000},
    "elbow_flex": {"id": 3, "drive_mode": 1, "homing_offset": 40, "range_min": 1000, "range_max": 3000},
    "gripper": {"id": 6, "drive_mode": 1, "homing_offset": 1150, "range_min": 2000, "range_max": 3400},
}


def mapping(tmp_path: Path, joints: dict[str, object], *, arms: bool = False) -> dict[str, JointMapping]:
    path = tmp_path / "follower.json"
    path.write_text(json.dumps(CALIBRATION))
    body = {"urdf": "arm.urdf", "calibration": str(path), "joints": joints}
    raw = {"arms": {"left": body}} if arms else body
    return {m.state: m for m in RobotConfig.from_mapping(raw, base_dir=tmp_path).joints}


def degrees(m: JointMapping, value: float) -> float:
    return float(np.rad2deg(convert_joint(m, np.array([value]), None, None)[0]))


def test_ticks_are_homed_and_zero_at_the_middle_of_the_range(tmp_path: Path) -> None:
    joints = mapping(tmp_path, {"shoulder_pan.pos": {"joint": "shoulder_pan", "unit": "ticks"},
                                "elbow_flex.pos": {"joint": "elbow_flex", "unit": "ticks"}})
    # (2070 - (737 + 3483) / 2) * 360 / 4095 = -40 * 360 / 4095
    assert degrees(joints["shoulder_pan.pos"], 2070) == pytest.approx(-3.5165, abs=1e-4)
    assert degrees(joints["shoulder_pan.pos"], 3483) == pytest.approx(1373 * 360 / 4095, abs=1e-9)
    # LeRobot applies no drive_mode in DEGREES: (2500 - 2000) * 360 / 4095
    assert degrees(joints["elbow_flex.pos"], 2500) == pytest.approx(43.956, abs=1e-3)


def test_range_units_are_read_back_to_ticks_with_the_drive_mode(tmp_path: Path) -> None:
    joints = mapping(tmp_path, {"left_shoulder_lift.pos": {"joint": "shoulder_lift", "unit": "range_m100_100"},
                                "left_elbow_flex.pos": {"joint": "elbow_flex", "unit": "range_m100_100"},
                                "left_gripper.pos": {"joint": "gripper", "unit": "range_0_100"}}, arms=True)
    # 50 -> ticks 1000 + 150/200 * 2000 = 2500 -> (2500 - 2000) * 360 / 4095
    assert degrees(joints["left_shoulder_lift.pos"], 50.0) == pytest.approx(43.956, abs=1e-3)
    # drive_mode 1: 50 was -50 -> ticks 1500 -> -43.956
    assert degrees(joints["left_elbow_flex.pos"], 50.0) == pytest.approx(-43.956, abs=1e-3)
    # drive_mode 1: 30 was 70 -> ticks 2000 + 0.7 * 1400 = 2980 -> (2980 - 2700) * 360 / 4095
    assert degrees(joints["left_gripper.pos"], 30.0) == pytest.approx(24.615, abs=1e-3)
    assert joints["left_gripper.pos"].joint == "left_gripper"


def test_without_a_calibration_ticks_keep_the_plain_default(tmp_path: Path) -> None:
    joints = {m.state: m for m in RobotConfig.from_mapping(
        {"urdf": "arm.urdf", "joints": {"shoulder_pan.pos": {"joint": "shoulder_pan", "unit": "ticks"}}},
        base_dir=tmp_path).joints}
    # (3072 - 2048) * 360 / 4096
    assert degrees(joints["shoulder_pan.pos"], 3072) == pytest.approx(90.0)


def test_a_joint_own_zero_wins_over_the_calibration(tmp_path: Path) -> None:
    joints = mapping(tmp_path, {"shoulder_pan.pos": {"joint": "shoulder_pan", "unit": "ticks", "zero_ticks": 2070}})
    assert degrees(joints["shoulder_pan.pos"], 2070) == 0.0


@pytest.mark.parametrize(("motor", "expected"), [
    ({"range_min": 3000, "range_max": 1000}, "range_max 1000 must be above range_min 3000"),
    ({"range_min": 10, "range_max": "x"}, "shoulder_pan.range_max must be a number of ticks"),
    ({"range_min": 10, "range_max": 20, "drive_mode": 2}, "drive_mode must be 0 or 1"),
])
def test_a_bad_calibration_is_one_line(tmp_path: Path, motor: dict[str, object], expected: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"shoulder_pan": {"id": 1, "homing_offset": 0, **motor}}))
    with pytest.raises(RobotConfigError, match=expected) as err:
        RobotConfig.from_mapping({"urdf": "arm.urdf", "calibration": str(path), "joints": {"a": "shoulder_pan"},
                                  "default_unit": "ticks"}, base_dir=tmp_path)
    assert "\n" not in str(err.value)

