"""The one schema style of CHAIN.yaml, robot.yaml and calibration files: every mistake one line naming
the file, the key and the value, whatever YAML holds (mixed key types, huge integers, bad text)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.config.calibration import load_calibration, read_intrinsics_file
from framechain.config.chain import ChainConfig
from framechain.config.errors import CalibrationError, ChainConfigError, ConfigError, RobotConfigError
from framechain.config.robot import RobotConfig
from framechain.config.schema import Section

MOUNT = {"parent": "link", "optical": True}
INTRINSICS = {"fx": 600.0, "fy": 600.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}


def _one_line(error: pytest.ExceptionInfo[ConfigError]) -> str:
    text = str(error.value)
    assert "\n" not in text
    return text


def test_unknown_keys_of_mixed_types_are_listed_not_sorted_into_a_type_error() -> None:
    with pytest.raises(ChainConfigError) as err:
        ChainConfig.from_dict({"topics": {1: "x", "b": 2}}, where="chain.yaml")
    assert _one_line(err).startswith("chain.yaml: topics: unknown keys ['1', 'b']; known keys are ['camera_info', ")


@pytest.mark.parametrize(("raw", "expected"), [
    ({"latency_budget_s": 10**400}, "latency_budget_s must be a number >= 0 (s), got 1000000"),
    ({"evidence": {"reference_point": [10**400, 0, 0]}}, "evidence.reference_point must be [x, y, z], three finite"),
    ({"evidence": {"tag_size_m": {"default": 10**400}}}, "evidence.tag_size_m.default must be a positive number (m)"),
    ({"mounts": [{"parent": "a", "child": "b", "xyz": [1e308, 1e308, 0], "rpy": [0, 0, 0]}]},
     "mounts[0].xyz puts the frame 1.41421e+308 m from its parent, farther than any mount on a robot (10 m): give "
     "metres"),
    ({"mounts": [{"parent": "a", "child": "b", "quat_xyzw": [1e308, 1e308, 0, 0]}]}, "has norm inf, not 1"),
    ({"frames": {"camera": ["c"]}}, "frames.camera must be a frame name, got ['c']"),
    ({"frames": {"camera": "/"}}, "frames.camera must be a frame name, got '/'"),
    ({"topics": {"detections": {"a": 1}}}, "topics.detections must be a topic name, got {'a': 1}"),
    ({"evidence": {"static_target": "yes"}}, "evidence.static_target must be true or false, got 'yes'"),
    ({"evidence": {"hops": [1]}}, "evidence.hops must be a mapping, got [1]"),
    ({"robot": 3}, "robot must be a mapping, got 3"),
    ({"calibration": [{"file": "a.yaml", "frame": 7.5}]}, "calibration[0].frame must be a frame name, got 7.5"),
    ({"mounts": [{"parent": "a", "child": "b"}]}, "mounts[0]: no rotation: give either rpy or quat_xyzw or rotvec"),
    ({"mounts": [{"child": "b", "rpy": [0, 0, 0]}]}, "mounts[0]: missing parent (a frame name)"),
])
def test_values_of_any_shape_are_one_line(raw: dict[str, Any], expected: str) -> None:
    with pytest.raises(ChainConfigError) as err:
        ChainConfig.from_dict(raw, where="chain.yaml")
    assert expected in _one_line(err)


def test_files_that_are_not_yaml_are_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "chain.yaml"
    bad.write_text("frames: {camera: c\nbody: b\n")
    with pytest.raises(ChainConfigError) as err:
        ChainConfig.from_yaml(bad)
    assert _one_line(err).startswith(f"{bad}: not valid YAML (line 2, column 5: ")
    bad.write_bytes(b"frames: {camera: \xff}\n")
    with pytest.raises(ChainConfigError, match=r"cannot read chain configuration: not UTF-8 text \(byte 17\)"):
        ChainConfig.from_yaml(bad)
    bad.write_text("")
    with pytest.raises(ChainConfigError, match="the chain configuration is empty"):
        ChainConfig.from_yaml(bad)
    bad.write_text("[1, 2]\n")
    with pytest.raises(ChainConfigError, match="expected a mapping at the top level, got list"):
        ChainConfig.from_yaml(bad)
    robot = tmp_path / "robot.yaml"
    robot.write_text("urdf: [\n")
    with pytest.raises(RobotConfigError) as robot_err:
        RobotConfig.load(robot)
    assert _one_line(robot_err).startswith(f"{robot}: not valid YAML (")


def test_a_broken_opencv_matrix_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "cv.yaml"
    path.write_text("%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
                    "   data: [ 300., 0., 160. ]\nimage_width: 320\nimage_height: 240\n")
    with pytest.raises(CalibrationError) as err:
        read_intrinsics_file(path)
    assert "an opencv-matrix needs rows, cols and rows x cols numbers as data" in _one_line(err)


@pytest.mark.parametrize(("calibration", "expected"), [
    ({"intrinsics": {**INTRINSICS, "width": "x"}, "mount": MOUNT}, "intrinsics.width must be a number, got 'x'"),
    ({"intrinsics": {**INTRINSICS, "distortion": [0.1, "a"]}, "mount": MOUNT},
     "intrinsics.distortion must be at most 14 finite numbers, got [0.1, 'a']"),
    ({"intrinsics": INTRINSICS, "mount": {**MOUNT, "rotvec": [0, 0, 1], "rpy": [0, 0, 0]}},
     "mount: two rotations (rpy and rotvec): give either rpy or quat_xyzw or rotvec, one only"),
    ({"intrinsics": INTRINSICS, "mount": MOUNT, "timing": [1]}, "timing must be a mapping, got [1]"),
    ({"intrinsics": INTRINSICS, "mount": MOUNT, "depth": {"scale_m": 0.001}},
     "depth: missing feature (the dataset's depth image feature)"),
])
def test_calibration_mistakes_name_the_key(calibration: dict[str, Any], expected: str) -> None:
    with pytest.raises(CalibrationError) as err:
        load_calibration(calibration, name="c")
    assert _one_line(err) == f"calibration c: {expected}" or expected in str(err.value)


def test_calibration_mounts_take_a_rotation_vector_like_chain_mounts() -> None:
    rotvec = [0.1, -0.2, 0.3]
    cal = load_calibration({"intrinsics": INTRINSICS, "mount": {**MOUNT, "rotvec": rotvec}}, name="c")
    np.testing.assert_allclose(cal.mount.quat_xyzw, Rotation.from_rotvec(rotvec).as_quat(), atol=1e-15)
    chain = ChainConfig.from_dict({"mounts": [{"parent": "link", "child": "c", "rotvec": rotvec}]})
    assert chain.mounts[0].quat_xyzw == cal.mount.quat_xyzw


def test_inline_cameras_of_robot_yaml_are_named_by_their_path_in_it() -> None:
    raw = {"urdf": "r.urdf", "default_unit": "rad", "joints": {"a.pos": "a"},
           "cameras": {"wrist": {"intrinsics": {**INTRINSICS, "cx": 900.0}, "mount": MOUNT}}}
    with pytest.raises(CalibrationError) as err:
        RobotConfig.from_mapping(raw, source="robot.yaml")
    assert _one_line(err).startswith("robot.yaml: cameras.wrist.intrinsics: cx 900 is outside the image")


@pytest.mark.parametrize(("change", "expected"), [
    ({"joints": {"a.pos": {"joint": "a", "sign": True}}}, "joints.a.pos.sign must be 1 or -1, got True"),
    ({"joints": {"a.pos": {"joint": "a", "unit": ["deg"]}}}, "joints.a.pos.unit is an unknown unit ['deg']"),
    ({"joints": {1: "a", "b": {"joint": "a"}}}, "joints: joint 'a' is driven by both '1' and 'b'"),
    ({"hold": {"b": "x"}}, "hold.b must be a number (rad or m), got 'x'"),
    ({"chain": {"camera": "nope"}}, "chain.camera 'nope' is not one of the cameras []"),
    ({"chain": {"zoom": 2}}, "chain: unknown keys ['zoom']; known keys are"),
    ({"detections": [{"table": "t.csv", "feature": "f"}]}, "detections[0]: give exactly one of table or feature"),
])
def test_robot_yaml_mistakes_name_the_key(change: dict[str, Any], expected: str) -> None:
    raw = {"urdf": "r.urdf", "default_unit": "rad", "joints": {"a.pos": "a"}, **change}
    with pytest.raises(RobotConfigError) as err:
        RobotConfig.from_mapping(raw, source="robot.yaml")
    assert expected in _one_line(err)


def test_section_paths_and_messages() -> None:
    top = Section({"evidence": {"tag_size_m": 0.1}}, source="f.yaml", known={"evidence"})
    evidence = top.section("evidence", {"tag_size_m"})
    assert evidence.path("tag_size_m") == "evidence.tag_size_m"
    assert evidence.number("tag_size_m", positive=True) == 0.1
    assert evidence.number("missing", 2.0) == 2.0
    with pytest.raises(ConfigError, match=r"^f\.yaml: evidence: missing other \(why\)$"):
        evidence.require("other", "why")
    with pytest.raises(ConfigError, match=r"^f\.yaml: unknown keys \['x'\]; known keys are \['evidence'\]$"):
        Section({"evidence": {}, "x": 1}, source="f.yaml", known={"evidence"})
    with pytest.raises(ConfigError, match=r"^f\.yaml: evidence must be a mapping, got 3$"):
        top.child(3, "evidence")
