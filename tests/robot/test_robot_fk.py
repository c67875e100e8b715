"""Batched forward kinematics against yourdfpy's get_transform and hand-worked numbers."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yourdfpy

from framechain.config.robot import JointMapping, JointUnit, RobotConfig, RobotConfigError
from framechain.robot.binding import convert_joint, joint_positions, robot_model
from framechain.robot.kinematics import RobotModel
from framechain.robot.urdf import JointType, RobotModelError
from tests.helpers.lerobot_scene import ARM6

SO101_JOINTS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")

PLANAR = """<?xml version="1.0"?>
<robot name="planar">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="1 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3"/></joint>
  <joint name="tip" type="fixed"><parent link="l2"/><child link="tool"/>
    <origin xyz="1.1 0 0" rpy="0 0 0"/></joint>
</robot>
"""


def _yourdfpy(path: Path) -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(path), load_meshes=False, build_collision_scene_graph=False)


def test_planar_arm_hand_worked(tmp_path: Path) -> None:
    path = tmp_path / "planar.urdf"
    path.write_text(PLANAR)
    model = RobotModel.from_urdf(path)
    q = np.deg2rad([[90.0, 0.0], [0.0, 0.0], [90.0, -90.0]])
    T = model.fk(q, "tool")
    # j1 = 90 deg: both links along +y; tool at (0, 2.1, 0.5).
    np.testing.assert_allclose(T[0, :3, 3], [0.0, 2.1, 0.5], atol=1e-12)
    np.testing.assert_allclose(T[1, :3, 3], [2.1, 0.0, 0.5], atol=1e-12)
    # j1 = 90, j2 = -90: first link along +y to (0, 1), second along +x: (1.1, 1, 0.5).
    np.testing.assert_allclose(T[2, :3, 3], [1.1, 1.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(T[2, :3, :3], np.eye(3), atol=1e-12)


def test_arm6_every_link_matches_yourdfpy(rng: np.random.Generator) -> None:
    model = RobotModel.from_urdf(ARM6)
    ref = _yourdfpy(ARM6)
    assert list(model.actuated) == list(ref.actuated_joint_names)
    n = 40
    lower = np.array([model.joints[j].lower for j in model.actuated])
    upper = np.array([model.joints[j].upper for j in model.actuated])
    q = rng.uniform(lower, upper, size=(n, len(model.actuated)))
    poses = model.link_poses(q)
    local = model.joint_transforms(q)
    for i in range(n):
        ref.update_cfg(q[i])
        for link in model.links:
            # get_transform(frame_to, frame_from) is the pose of frame_to in frame_from: T_from_to.
            np.testing.assert_allclose(poses[link][i], ref.get_transform(link, "base_link"), atol=1e-12)
        for joint in model.joints.values():
            M = local[joint.name][i if local[joint.name].shape[0] > 1 else 0]
            np.testing.assert_allclose(M, ref.get_transform(joint.child, joint.parent), atol=1e-12)
    # The argument order matters: swapped arguments give the inverse.
    ref.update_cfg(q[0])
    np.testing.assert_allclose(np.linalg.inv(poses["wrist_camera_link"][0]),
                               ref.get_transform("base_link", "wrist_camera_link"), atol=1e-12)


def test_mimic_prismatic_joint_follows_its_source() -> None:
    model = RobotModel.from_urdf(ARM6)
    assert model.joints["finger_right"].type is JointType.PRISMATIC
    assert "finger_right" not in model.actuated
    pos = model.positions({"finger_left": [0.01, 0.03]}, default=0.0)
    np.testing.assert_allclose(pos["finger_right"], [-0.01, -0.03])
    T = model.joint_transforms({"finger_left": [0.01, 0.03]}, joints=["finger_right"], default=0.0)
    # origin (0, -0.01, 0.08), axis +y, q = -finger_left.
    np.testing.assert_allclose(T["finger_right"][:, :3, 3], [[0.0, -0.02, 0.08], [0.0, -0.04, 0.08]], atol=1e-15)


def test_joint_poses_are_the_rows_of_joint_transforms(rng: np.random.Generator) -> None:
    from scipy.spatial.transform import Rotation

    model = RobotModel.from_urdf(ARM6)
    q = rng.uniform(-1, 1, size=(10, len(model.actuated)))
    mats = model.joint_transforms(q)
    for name, (t, quat) in model.joint_poses(q).items():
        np.testing.assert_allclose(t, mats[name][:, :3, 3], atol=1e-14)
        np.testing.assert_allclose(Rotation.from_quat(quat).as_matrix(), mats[name][:, :3, :3], atol=1e-14)


def test_fk_path_blocks_agree_with_link_poses(rng: np.random.Generator) -> None:
    model = RobotModel.from_urdf(ARM6)
    path = model.path_joints("wrist_camera_link")
    moving = [i for i, j in enumerate(path) if j.moves]
    n = 9000  # more than one block
    q = np.zeros((n, len(path)))
    q[:, moving] = rng.uniform(-1, 1, size=(n, len(moving)))
    t, quat = model.fk_path(q, path)
    T = model.fk({path[i].name: q[:, i] for i in moving}, "wrist_camera_link", default=0.0)
    np.testing.assert_allclose(t, T[:, :3, 3], atol=1e-12)
    from scipy.spatial.transform import Rotation

    np.testing.assert_allclose(Rotation.from_quat(quat).as_matrix(), T[:, :3, :3], atol=1e-12)


def _limits_from_xml(path: Path) -> dict[str, tuple[float, float]]:
    out = {}
    for joint in ET.parse(path).getroot().iter("joint"):
        limit = joint.find("limit")
        if limit is not None and joint.get("type") == "revolute":
            out[str(joint.get("name"))] = (float(limit.get("lower", "nan")), float(limit.get("upper", "nan")))
    return out


def test_so101_degrees_and_gripper_range_match_yourdfpy(so101_urdf: Path, rng: np.random.Generator) -> None:
    cfg = RobotConfig.from_mapping(
        {"urdf": str(so101_urdf), "default_unit": "deg",
         "joints": {**{f"{j}.pos": j for j in SO101_JOINTS[:5]},
                    "gripper.pos": {"joint": "gripper", "unit": "range_0_100"}}},
        source="so101",
    )
    model = robot_model(cfg)
    names = [f"{j}.pos" for j in SO101_JOINTS]
    n = 25
    state = np.hstack([rng.uniform(-80, 80, size=(n, 5)), rng.uniform(0, 100, size=(n, 1))])
    q = joint_positions(cfg, model, state, names)
    lo, hi = _limits_from_xml(so101_urdf)["gripper"]
    # Independent conversion: degrees by hand, the gripper 0..100 onto the URDF's limits.
    expected = {j: state[:, i] * np.pi / 180.0 for i, j in enumerate(SO101_JOINTS[:5])}
    expected["gripper"] = lo + state[:, 5] / 100.0 * (hi - lo)
    for j in SO101_JOINTS:
        np.testing.assert_allclose(q[j], expected[j], atol=1e-12)
    poses = model.link_poses(q, links=["gripper_frame_link", "moving_jaw_so101_v1_link"])
    ref = _yourdfpy(so101_urdf)
    for i in range(n):
        ref.update_cfg({j: expected[j][i] for j in SO101_JOINTS})
        for link in poses:
            np.testing.assert_allclose(poses[link][i], ref.get_transform(frame_to=link, frame_from="base_link"),
                                       atol=1e-12)


@pytest.mark.parametrize(
    ("unit", "value", "limits", "expected"),
    [
        (JointUnit.DEG, 90.0, (None, None), np.pi / 2),
        (JointUnit.RAD, 0.25, (None, None), 0.25),
        (JointUnit.MM, 12.5, (None, None), 0.0125),
        (JointUnit.M, 0.5, (None, None), 0.5),
        (JointUnit.RANGE_0_100, 25.0, (-0.2, 1.8), 0.3),
        (JointUnit.RANGE_M100_100, 50.0, (-1.0, 1.0), 0.5),
        (JointUnit.RANGE_M100_100, -100.0, (-2.0, 1.0), -2.0),
    ],
)
def test_unit_conversions(unit: JointUnit, value: float, limits: tuple[float | None, float | None],
                          expected: float) -> None:
    m = JointMapping("x.pos", "x", unit)
    assert convert_joint(m, [value], *limits)[0] == pytest.approx(expected, abs=1e-15)


def test_sign_and_offset_apply_after_conversion() -> None:
    m = JointMapping("x.pos", "x", JointUnit.DEG, sign=-1.0, offset=0.1)
    assert convert_joint(m, [180.0], None, None)[0] == pytest.approx(-np.pi + 0.1)


def test_model_errors(tmp_path: Path) -> None:
    with pytest.raises(RobotModelError, match="URDF file not found"):
        RobotModel.from_urdf(tmp_path / "missing.urdf")
    floating = PLANAR.replace('name="j2" type="revolute"', 'name="j2" type="floating"')
    (tmp_path / "f.urdf").write_text(floating)
    with pytest.raises(RobotModelError, match=r"joint 'j2' has type 'floating'"):
        RobotModel.from_urdf(tmp_path / "f.urdf")
    model = RobotModel.from_urdf(ARM6)
    with pytest.raises(RobotModelError, match="no link 'camera'"):
        model.fk(np.zeros((1, 7)), "camera")
    with pytest.raises(RobotModelError, match=r"expected \(T, 7\)"):
        model.fk(np.zeros((3, 6)), "tool_link")
    with pytest.raises(RobotModelError, match=r"no positions for joints \['wrist_roll', 'finger_left'\]"):
        model.fk({j: [0.0] for j in model.actuated[:5]}, "tool_link")


def test_config_errors_name_the_problem(tmp_path: Path) -> None:
    base = {"urdf": str(ARM6), "joints": {"shoulder_pan.pos": "shoulder_pan"}}
    with pytest.raises(RobotConfigError, match=r"joints.shoulder_pan.pos: no unit stated"):
        RobotConfig.from_mapping(base)
    with pytest.raises(RobotConfigError, match="unknown unit 'degrees'"):
        RobotConfig.from_mapping({**base, "default_unit": "degrees"})
    cfg = RobotConfig.from_mapping({**base, "joints": {"a.pos": {"joint": "nope", "unit": "rad"}}})
    with pytest.raises(RobotConfigError, match="the URDF has no joint 'nope'"):
        robot_model(cfg)
    cfg = RobotConfig.from_mapping({**base, "joints": {"a.pos": {"joint": "shoulder_pan", "unit": "rad"}}})
    with pytest.raises(RobotConfigError, match=r"state names \['a.pos'\] are not in observation.state"):
        joint_positions(cfg, robot_model(cfg), np.zeros((1, 2)), ["b.pos", "c.pos"])
    with pytest.raises(RobotConfigError, match="unknown keys"):
        RobotConfig.from_mapping({**base, "default_unit": "rad", "urdf_path": "x"})
