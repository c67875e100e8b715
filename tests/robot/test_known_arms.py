"""Arms framechain knows without a robot.yaml: the bundled URDFs, state names under any prefix, units guessed
from the values, and a run of a generated SO-101 episode with neither --robot nor --episode.

Truth: the official URDFs in ../shared/realdata (read by yourdfpy and by the generator's own URDF maths,
:class:`framechain.sim.urdf_chain.UrdfChain`), hand-written mappings, and the generator's injected faults.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain.adapters.lerobot.adapter import open_dataset
from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset
from framechain.cli.main import main
from framechain.config.robot import RobotConfig
from framechain.replay import TransformBuffer
from framechain.robot.known_arms import KNOWN_ARMS, LEROBOT_MOTORS, known_arm, match_state_names
from framechain.sim.lerobot_video import (
    ARM_JOINTS,
    VideoDatasetSpec,
    VideoDatasetTruth,
    generate_video_dataset,
    write_robot_yaml,
)
from framechain.sim.urdf_chain import UrdfChain
from framechain.suggest.lerobot import guess_arm_units
from tests.helpers.realdata import KOCH_URDF, SO101_URDF

VIDEO = {"video.fps": 30, "video.codec": "av1", "video.pix_fmt": "yuv420p", "video.is_depth_map": False}


@pytest.mark.parametrize(("arm", "official"), [("so101", SO101_URDF), ("koch", KOCH_URDF)])
def test_bundled_urdfs_keep_the_published_kinematics(realdata: Path, arm: str, official: str) -> None:
    import yourdfpy

    bundled = KNOWN_ARMS[arm].urdf
    assert (bundled.parent / "LICENSE").is_file()
    assert "<mesh" not in bundled.read_text()
    ours = yourdfpy.URDF.load(str(bundled), load_meshes=False, build_scene_graph=True)
    theirs = yourdfpy.URDF.load(str(realdata / official), load_meshes=False, build_scene_graph=True)
    assert ours.actuated_joint_names == theirs.actuated_joint_names
    q = np.random.default_rng(4).uniform(-1.0, 1.0, len(ours.actuated_joint_names))
    ours.update_cfg(q)
    theirs.update_cfg(q)
    for link in theirs.link_map:
        np.testing.assert_allclose(ours.get_transform(link), theirs.get_transform(link), atol=1e-12)


def test_the_so100_urdf_loads_without_meshes_and_names_lerobot_motors() -> None:
    import yourdfpy

    urdf = yourdfpy.URDF.load(str(KNOWN_ARMS["so100"].urdf), load_meshes=False, build_scene_graph=True)
    assert set(urdf.actuated_joint_names) == set(LEROBOT_MOTORS)
    assert KNOWN_ARMS["so100"].camera_link in urdf.link_map


#: The ViperX 300 6DOF's joints from base_link to gripper_link, read off Interbotix's vx300s.urdf.xacro by hand: each
#: joint's origin (its rpy all zero) and axis.
VX300S_CHAIN = (("waist", (0.0, 0.0, 0.079), (0, 0, 1)), ("shoulder", (0.0, 0.0, 0.04805), (0, 1, 0)),
                ("elbow", (0.05955, 0.0, 0.3), (0, 1, 0)), ("forearm_roll", (0.2, 0.0, 0.0), (1, 0, 0)),
                ("wrist_angle", (0.1, 0.0, 0.0), (0, 1, 0)), ("wrist_rotate", (0.069744, 0.0, 0.0), (1, 0, 0)))
ALOHA_NAMES = [f"{side}_{m}" for side in ("left", "right") for m in
               ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate", "gripper")]


def _vx300s_gripper(q: np.ndarray) -> np.ndarray:
    """base_link -> gripper_link (T, 4, 4) at joint angles q (T, 6), by scipy's rotations along VX300S_CHAIN."""
    out = np.tile(np.eye(4), (len(q), 1, 1))
    for k, (_name, xyz, axis) in enumerate(VX300S_CHAIN):
        step = np.tile(np.eye(4), (len(q), 1, 1))
        step[:, :3, :3] = Rotation.from_rotvec(np.outer(q[:, k], axis)).as_matrix()
        step[:, :3, 3] = xyz
        out = out @ step
    return out


def test_the_bundled_viperx_keeps_the_published_kinematics() -> None:
    """ALOHA's arm, expanded from Interbotix's xacro: its joints, limits and the chain to the wrist camera's link as
    published (and as yourdfpy reads the bundled file), the published 0.75 m reach, its BSD-3 licence beside it."""
    import yourdfpy

    arm = KNOWN_ARMS["aloha"]
    text = arm.urdf.read_text()
    assert "<mesh" not in text
    assert (arm.urdf.parent / "LICENSE").read_text().startswith("BSD 3-Clause License")
    urdf = yourdfpy.URDF.load(str(arm.urdf), load_meshes=False, build_scene_graph=True)
    assert urdf.actuated_joint_names == [name for name, _xyz, _axis in VX300S_CHAIN] + ["gripper", "left_finger"]
    assert urdf.joint_map["shoulder"].limit.lower == pytest.approx(np.radians(-106))
    assert urdf.joint_map["wrist_angle"].limit.upper == pytest.approx(np.radians(128))
    assert urdf.joint_map["right_finger"].mimic.joint == "left_finger"
    q = np.random.default_rng(6).uniform(-1.2, 1.2, (5, 6))
    expected = _vx300s_gripper(q)
    for i in range(len(q)):
        urdf.update_cfg(np.concatenate([q[i], [0.0, 0.03]]))
        np.testing.assert_allclose(urdf.get_transform("gripper_link", "base_link"), expected[i], atol=1e-12)
    # Stretched out level (the upper arm turned forward onto the forearm's line): the fingers' tips 0.78 m ahead of
    # the shoulder joint, worked by hand from the link lengths (Trossen publishes a 750 mm reach).
    urdf.update_cfg(np.array([0.0, np.arctan2(0.3, 0.05955), -np.arctan2(0.3, 0.05955), 0, 0, 0, 0, 0.03]))
    tip = urdf.get_transform("ee_gripper_link", "shoulder_link")[:3, 3]
    reach = np.hypot(0.3, 0.05955) + 0.2 + 0.1 + 0.069744 + 0.042825 + 0.025875 + 0.0385
    np.testing.assert_allclose(tip, [reach, 0.0, 0.04805], atol=1e-9)
    assert reach == pytest.approx(0.783, abs=0.001)
    assert arm.camera_link in urdf.link_map
    assert KNOWN_ARMS["viperx"].urdf == KNOWN_ARMS["mobilealoha"].urdf == arm.urdf
    assert (KNOWN_ARMS["mobilealoha"].bases, KNOWN_ARMS["aloha"].bases["right"][1]) == ({}, (0.0, 0.0, np.pi))


@pytest.mark.parametrize(("robot_type", "arm", "arms"), [
    ("so101_follower", "so101", 1), ("bi_so100_follower", "so100", 2), ("koch_follower", "koch", 1),
    ("SO-101", "so101", 1), ("aloha", "aloha", 2), ("mobile_aloha", "mobilealoha", 2), ("viperx", "viperx", 1),
    ("lekiwi", "lekiwi", 1), ("lekiwi_client", "lekiwi", 1),
    ("ur5e", None, 0), (None, None, 0)])
def test_robot_type_selects_the_urdf(robot_type: str | None, arm: str | None, arms: int) -> None:
    found = known_arm(robot_type)
    assert (found.name if found else None) == arm
    assert (found.arms_in(robot_type or "") if found else 0) == arms


@pytest.mark.parametrize(("names", "expected"), [
    (["left_shoulder_pan.pos", "left_gripper.pos", "right_shoulder_pan.pos", "right_gripper.pos"],
     {"left_": [("left_shoulder_pan.pos", "shoulder_pan"), ("left_gripper.pos", "gripper")],
      "right_": [("right_shoulder_pan.pos", "shoulder_pan"), ("right_gripper.pos", "gripper")]}),
    (["l_wrist_roll.pos", "r_wrist_roll.pos", "l_wrist_flex.vel"],
     {"l_": [("l_wrist_roll.pos", "wrist_roll")], "r_": [("r_wrist_roll.pos", "wrist_roll")]}),
    (["follower_elbow_flex.pos", "follower_shoulder_lift.pos"],
     {"follower_": [("follower_elbow_flex.pos", "elbow_flex"), ("follower_shoulder_lift.pos", "shoulder_lift")]}),
    ([f"arm{a}_j{k}" for a in (1, 2) for k in (1, 2, 6)],
     {"arm1_": [("arm1_j1", "shoulder_pan"), ("arm1_j2", "shoulder_lift"), ("arm1_j6", "gripper")],
      "arm2_": [("arm2_j1", "shoulder_pan"), ("arm2_j2", "shoulder_lift"), ("arm2_j6", "gripper")]}),
    (["joint_0", "joint_4"], {"": [("joint_0", "shoulder_pan"), ("joint_4", "wrist_roll")]}),
])
def test_state_names_are_matched_under_any_prefix(names: list[str], expected: dict[str, list[tuple[str, str]]]
                                                  ) -> None:
    arms, unmatched = match_state_names(names, LEROBOT_MOTORS)
    assert {a.prefix: list(a.motors) for a in arms} == expected
    matched = {n for items in expected.values() for n, _m in items}
    assert unmatched == [n for n in names if n not in matched]


@pytest.mark.parametrize(("arms", "count", "expected"), [
    # Both arms' worth of numbered names on a two-arm robot (as conversions that kept no names write them): the left
    # arm first, as LeRobot orders its two-arm robots.
    (2, 12, {"left_": [(f"motor_{k}", m) for k, m in enumerate(LEROBOT_MOTORS)],
             "right_": [(f"motor_{k + 6}", m) for k, m in enumerate(LEROBOT_MOTORS)]}),
    # One arm's positions then velocities, numbered alike: one arm, the rest matched to nothing.
    (1, 12, {"": [(f"motor_{k}", m) for k, m in enumerate(LEROBOT_MOTORS)]}),
    # Not both arms' worth: the first arm's.
    (2, 8, {"": [(f"motor_{k}", m) for k, m in enumerate(LEROBOT_MOTORS)]}),
])
def test_numbered_names_are_split_into_the_robots_arms(arms: int, count: int,
                                                       expected: dict[str, list[tuple[str, str]]]) -> None:
    names = [f"motor_{k}" for k in range(count)]
    found, unmatched = match_state_names(names, LEROBOT_MOTORS, arms=arms)
    assert {a.prefix: list(a.motors) for a in found} == expected
    matched = {n for items in expected.values() for n, _m in items}
    assert unmatched == [n for n in names if n not in matched]


@pytest.mark.parametrize(("body", "unit", "said"), [
    ([[12.0, -150.0], [40.0, 88.0]], "deg", "values reach 150"),
    ([[0.2, -1.5], [2.9, 0.1]], "rad", "values within +-2.90"),
    ([[812.0, 2048.0], [3301.0, 1990.0]], "ticks", "whole numbers 812..3301"),
    ([[100.0, -20.0], [-63.5, 4.0]], "range_m100_100", "where LeRobot clamps"),
    ([[45.0, -20.0], [-63.5, 4.0]], "deg", "range_m100_100 would fit too"),
])
def test_units_are_guessed_per_arm_and_said(body: list[list[float]], unit: str, said: str) -> None:
    values = np.hstack([np.asarray(body), [[3.0], [97.0]]])
    units, why = guess_arm_units(["shoulder_pan.pos", "elbow_flex.pos", "gripper.pos"], values)
    assert units[:2] == [unit, unit]
    assert units[2] == ("range_0_100" if unit in ("deg", "range_m100_100") else unit)
    assert said in why


def _ticks_dataset(root: Path) -> tuple[Path, np.ndarray, list[str]]:
    """Two SO-101 arms named arm1_j1 .. arm2_j6, raw ticks; a camera on the second arm's wrist and one above."""
    rng = np.random.default_rng(11)
    names = [f"arm{a}_j{k}" for a in (1, 2) for k in range(1, 7)]
    ticks = np.round(2048 + rng.uniform(-600, 600, (12, 12))).astype(np.float32)
    features = {"observation.state": FeatureSpec("float32", (12,), names),
                "observation.images.arm2_wrist": FeatureSpec("video", (224, 224, 3), ["height", "width", "channels"],
                                                             VIDEO),
                "observation.images.top": FeatureSpec("video", (480, 640, 3), ["height", "width", "channels"], VIDEO)}
    path = write_lerobot_dataset(root, [EpisodeData({"observation.state": ticks})], features=features, fps=20,
                                 robot_type="bi_so101_follower")
    return path, ticks.astype(np.float64), names


def test_info_prints_a_complete_robot_yaml_for_numbered_joints_in_ticks(
        so101_urdf: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root, ticks, names = _ticks_dataset(tmp_path / "ds")
    assert main(["info", str(root), "--episode", "0", "--chain"]) == 0
    text = capsys.readouterr().out
    skeleton = yaml.safe_load(text)
    assert set(skeleton["arms"]) == {"arm1", "arm2"}
    arm2 = skeleton["arms"]["arm2"]
    assert (arm2["prefix"], arm2["default_unit"]) == ("arm2_", "ticks")
    assert Path(arm2["urdf"]) == KNOWN_ARMS["so101"].urdf
    assert arm2["joints"] == {f"arm2_j{k + 1}": m for k, m in enumerate(LEROBOT_MOTORS)}
    assert skeleton["cameras"]["arm2_wrist"]["mount"]["parent"] == "arm2_gripper_link"
    assert skeleton["cameras"]["top"]["mount"]["parent"] == "world"
    assert skeleton["cameras"]["top"]["intrinsics"]["fx"] == pytest.approx(320 / np.tan(np.radians(35)), abs=0.1)
    assert "FILL IN" not in text
    assert "whole numbers" in text
    # As printed, it loads and gives the arms' frame tree: the generator's URDF maths on the official file,
    # ticks as (value - 2048) * 2 pi / 4096, the second arm's base 0.2 m to the right.
    del skeleton["cameras"]
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(skeleton))
    timeline = open_dataset(root, episode=0, robot=RobotConfig.load(tmp_path / "robot.yaml"))
    found = TransformBuffer(timeline.transforms).lookup("world", "arm2_gripper_link",
                                                        np.unique(timeline.joint_states.stamp_ns)).matrix()
    q = {m: (ticks[:, names.index(f"arm2_j{k + 1}")] - 2048) * 2 * np.pi / 4096 for k, m in enumerate(LEROBOT_MOTORS)}
    base = np.eye(4)
    base[1, 3] = -0.2
    expected = base @ UrdfChain(so101_urdf).root_from_link(q, "gripper_link")
    np.testing.assert_allclose(found, expected, atol=1e-9)


def test_a_koch_state_without_a_urdf_joint_is_left_out_and_said(realdata: Path, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    import yourdfpy

    deg = np.random.default_rng(5).uniform(-120, 120, (8, 6)).astype(np.float32)
    deg[:, 5] = np.linspace(5, 95, 8)
    features = {"observation.state": FeatureSpec("float32", (6,), [f"{m}.pos" for m in LEROBOT_MOTORS])}
    root = write_lerobot_dataset(tmp_path / "koch", [EpisodeData({"observation.state": deg})], features=features,
                                 fps=30, robot_type="koch_follower")
    assert main(["info", str(root), "--episode", "0", "--chain"]) == 0
    text = capsys.readouterr().out
    assert "# wrist_flex.pos: not mapped (the bundled URDF has no such joint)" in text
    assert "# gripper.pos: not mapped (its URDF joint 'Revolute 7' has no limits for range_0_100)" in text
    path = tmp_path / "robot.yaml"
    path.write_text(text)
    timeline = open_dataset(root, episode=0, robot=path)
    link = KNOWN_ARMS["koch"].camera_link
    found = TransformBuffer(timeline.transforms).lookup("base_link", link, np.unique(
        timeline.joint_states.stamp_ns)).matrix()
    official = yourdfpy.URDF.load(str(realdata / KOCH_URDF), load_meshes=False)
    for i in range(len(deg)):
        official.update_cfg({"Revolute 2": np.radians(deg[i, 0]), "Revolute 3": np.radians(deg[i, 1]),
                             "Revolute 5": np.radians(deg[i, 2]), "Revolute 6": np.radians(deg[i, 4])})
        np.testing.assert_allclose(found[i], official.get_transform(link, "base_link"), atol=1e-6)


def test_info_prints_a_complete_robot_yaml_for_an_aloha_recording(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """ALOHA as its datasets are written (robot_type aloha, left_waist .. right_gripper in radians, the grippers'
    opening 0..1, a camera above, one below and one on each wrist): both arms on the bundled ViperX, facing each
    other as in ALOHA 2's model (mujoco_menagerie's aloha.xml: bases at x = -+0.469 m, the right one turned
    about z), the grippers driving nothing (and saying why), each wrist camera on its arm's gripper_link; as printed
    it loads, and each arm's gripper_link is where the xacro's own chain puts it from its base."""
    rng = np.random.default_rng(12)
    state = rng.uniform(-0.8, 0.8, (6, 14)).astype(np.float32)
    state[:, [6, 13]] = rng.uniform(0.0, 1.0, (6, 2))
    image = FeatureSpec("video", (480, 640, 3), ["height", "width", "channels"], VIDEO)
    features = {"observation.state": FeatureSpec("float32", (14,), {"motors": ALOHA_NAMES}),  # as ALOHA writes them
                **{f"observation.images.{cam}": image
                   for cam in ("cam_high", "cam_low", "cam_left_wrist", "cam_right_wrist")}}
    root = write_lerobot_dataset(tmp_path / "ds", [EpisodeData({"observation.state": state})], features=features,
                                 fps=50, robot_type="aloha")
    assert main(["info", str(root), "--episode", "0", "--chain"]) == 0
    text = capsys.readouterr().out
    assert "FILL IN" not in text
    for side in ("left", "right"):
        assert f"# {side}_gripper: not mapped (ALOHA records the fingers' opening normalised to 0..1" in text
    skeleton = yaml.safe_load(text)
    bases = {"left": ([-0.469, -0.019, 0.02], 0.0), "right": ([0.469, -0.019, 0.02], np.pi)}
    for side in ("left", "right"):
        arm = skeleton["arms"][side]
        assert (arm["prefix"], arm["default_unit"], Path(arm["urdf"])) == (f"{side}_", "rad", KNOWN_ARMS["aloha"].urdf)
        assert arm["joints"] == {f"{side}_{name}": name for name, _xyz, _axis in VX300S_CHAIN}
        assert arm["world_from_base"]["xyz"] == bases[side][0]
        assert arm["world_from_base"]["rpy"] == pytest.approx([0.0, 0.0, bases[side][1]], abs=1e-6)
    parents = {name: cam["mount"]["parent"] for name, cam in skeleton["cameras"].items()}
    assert parents == {"cam_high": "world", "cam_low": "world", "cam_left_wrist": "left_gripper_link",
                       "cam_right_wrist": "right_gripper_link"}
    del skeleton["cameras"]
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(skeleton))
    timeline = open_dataset(root, episode=0, robot=RobotConfig.load(tmp_path / "robot.yaml"))
    stamps = np.unique(timeline.joint_states.stamp_ns)
    for side, first in (("left", 0), ("right", 7)):
        found = TransformBuffer(timeline.transforms).lookup("world", f"{side}_gripper_link", stamps).matrix()
        base = np.eye(4)
        base[:3, :3] = Rotation.from_euler("z", bases[side][1]).as_matrix()
        base[:3, 3] = bases[side][0]
        np.testing.assert_allclose(found, base @ _vx300s_gripper(state[:, first:first + 6].astype(np.float64)),
                                   atol=1e-6)


def test_an_aloha_recording_with_numbered_motors_is_two_arms_left_first(tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """``motor_0 .. motor_13`` (a conversion that kept no names) of an ALOHA: the left arm's seven, then the right's,
    each arm's seventh its gripper, mapped to nothing; the wrist cameras on their arms."""
    names = [f"motor_{k}" for k in range(14)]
    image = FeatureSpec("video", (480, 640, 3), ["height", "width", "channels"], VIDEO)
    features = {"observation.state": FeatureSpec("float32", (14,), names),
                "observation.images.cam_left_wrist": image, "observation.images.cam_right_wrist": image}
    state = np.random.default_rng(13).uniform(-0.8, 0.8, (4, 14)).astype(np.float32)
    root = write_lerobot_dataset(tmp_path / "ds", [EpisodeData({"observation.state": state})], features=features,
                                 fps=50, robot_type="aloha")
    skeleton = _info_yaml(root, capsys)
    joints = [name for name, _xyz, _axis in VX300S_CHAIN]
    assert {side: arm["joints"] for side, arm in skeleton["arms"].items()} == {
        "left": {f"motor_{k}": j for k, j in enumerate(joints)},
        "right": {f"motor_{k + 7}": j for k, j in enumerate(joints)}}
    assert {name: cam["mount"]["parent"] for name, cam in skeleton["cameras"].items()} == {
        "cam_left_wrist": "left_gripper_link", "cam_right_wrist": "right_gripper_link"}


def test_attribute_without_robot_finds_both_aloha_wrist_cameras(tmp_path: Path) -> None:
    """A generated two-arm ALOHA episode, its wrist cameras 40 and 70 ms late and 5 cm above their gripper_link:
    without --robot each camera is found on its own arm's gripper_link, with its offset, mount and position."""
    spec = VideoDatasetSpec(KNOWN_ARMS["aloha"].urdf, arm="aloha", seed=5, duration_s=6.0, bimanual=True,
                            camera_per_arm=True, camera_delays_s=(0.04, 0.07), mount_xyz=(0.0, 0.0, 0.05))
    truth = generate_video_dataset(tmp_path / "dataset", spec)
    out = tmp_path / "out"
    assert main(["attribute", str(truth.root), "--episode", "0", "--out", str(out), "--format", "json", "-q"]) == 0
    result = json.loads((out / "attribution.json").read_text())
    motions = {m["camera"]: m for m in result["camera_motion"]}
    assert len(motions) == 2
    for cam in truth.cameras:
        motion = motions[f"{cam.name}_optical_frame"]
        assert motion["link"] == cam.camera_link
        assert motion["explained"] is True
        assert motion["offset_s"] == pytest.approx(-cam.delays_s[0], abs=0.006)
        turned = Rotation.from_quat(motion["q_link_cam"]).inv() * Rotation.from_quat(cam.q_link_cam)
        assert turned.magnitude() < np.radians(3.0)
        assert np.linalg.norm(np.subtract(motion["position"]["xyz_link_cam"], spec.mount_xyz)) < 0.01


@pytest.fixture(scope="module")
def wrist_episode(so101_urdf: Path, tmp_path_factory: pytest.TempPathFactory) -> VideoDatasetTruth:
    """A generated SO-101 episode: video 50 ms late, the camera on gripper_link, a 180 px focal length."""
    return generate_video_dataset(tmp_path_factory.mktemp("known") / "dataset",
                                  VideoDatasetSpec(so101_urdf, seed=23, duration_s=4.0, video_delay_s=0.05))


def test_attribute_without_robot_or_episode_runs_on_the_bundled_urdf(
        wrist_episode: VideoDatasetTruth, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth = wrist_episode
    out = tmp_path / "out"
    assert main(["attribute", str(truth.root), "--out", str(out), "--format", "json", "-q"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    said = [line for line in err if "no --robot given" in line]
    assert len(said) == 1
    for piece in ("episode 0 (no --episode given)", "bundled SO-101 URDF", f"wrote {out / 'robot.yaml'}"):
        assert piece in said[0]
    assert RobotConfig.load(out / "robot.yaml").cameras["wrist"].mount.parent == "gripper_link"
    motion = json.loads((out / "attribution.json").read_text())["camera_motion"][0]
    assert motion["link"] == "gripper_link"
    assert motion["explained"] is True
    # Nothing declared but the arm: the camera's position on its link (5.8 cm from the guessed origin), its mount, its
    # focal length and its offset are all fitted from its images (1.2 ms, 10.6 mm here; over eight such episodes the
    # offsets 0.7 ms off at the median and 1.5 at most, the positions 5.3 mm and 18.8 mm).
    assert motion["offset_s"] == pytest.approx(truth.expected_offset_s, abs=0.006)
    fitted = Rotation.from_quat(motion["q_link_cam"])
    assert (fitted.inv() * Rotation.from_quat(truth.q_link_cam)).magnitude() < np.radians(3.0)
    assert np.linalg.norm(np.subtract(motion["position"]["xyz_link_cam"], truth.xyz_link_cam)) < 0.015
    # The guessed focal length (70 deg field of view) times the scale the motion implies: the true one.
    guessed = 112.0 / np.tan(np.radians(35.0))
    assert guessed * motion["focal_scale"] == pytest.approx(truth.intrinsics[0], rel=0.04)


def test_tf_without_robot_gives_the_bundled_arm_frames(wrist_episode: VideoDatasetTruth, so101_urdf: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """tf on the bundled URDF: the row's joint values (degrees, as the generator recorded them) through the
    generator's own URDF maths on the official file."""
    import pyarrow.parquet as pq

    truth = wrist_episode
    assert main(["tf", str(truth.root), "base_link", "gripper_link", "--episode", "0", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    rows = pq.read_table(next((truth.root / "data").rglob("*.parquet")))
    k = int(np.argmin(np.abs(rows.column("timestamp").to_numpy() - got["t_rel_s"])))
    state = np.asarray(rows.column("observation.state")[k].as_py())
    q = {j: np.radians(state[[truth.state_names.index(f"{j}.pos")]]) for j in ARM_JOINTS}
    expected = UrdfChain(so101_urdf).root_from_link(q, "gripper_link")[0]
    np.testing.assert_allclose(got["translation"], expected[:3, 3], atol=1e-6)
    turned = Rotation.from_quat(got["quat_xyzw"]).inv() * Rotation.from_matrix(expected[:3, :3])
    assert turned.magnitude() < 1e-6
    assert got["path"] == ["gripper_link", "wrist_link", "lower_arm_link", "upper_arm_link", "shoulder_link",
                           "base_link"]


def test_a_dataset_of_an_unknown_arm_asks_for_all_it_lacks_at_once(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    features = {"observation.state": FeatureSpec("float32", (2,), ["a.pos", "b.pos"])}
    root = write_lerobot_dataset(tmp_path / "ds", [EpisodeData({"observation.state": np.zeros((3, 2), np.float32)})
                                                   for _ in range(3)], features=features, fps=10,
                                 robot_type="my_arm")
    out = str(tmp_path / "out")
    cases = [([], ["--episode N (episodes 0..2) and --robot robot.yaml", f"framechain info {root} --episode 0`"]),
             (["--episode", "2"], ["needs --robot robot.yaml", "'my_arm' is no arm", f"info {root} --episode 2`"]),
             (["--robot", str(tmp_path / "robot.yaml")], ["needs --episode N (episodes 0..2)"])]
    (tmp_path / "robot.yaml").write_text("urdf: arm.urdf\njoints: {a.pos: a}\ndefault_unit: deg\n")
    for extra, expected in cases:
        assert main(["attribute", str(root), *extra, "--out", out]) == 1
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1
        for piece in expected:
            assert piece in err
        assert ("--robot" in err) == ("--robot" not in extra)


def _info_yaml(root: Path, capsys: pytest.CaptureFixture[str]) -> Any:
    assert main(["info", str(root), "--episode", "0", "--chain"]) == 0
    return yaml.safe_load(capsys.readouterr().out)


def test_cameras_ride_the_arm_their_name_mentions(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    names = [f"{side}_{m}.pos" for side in ("l", "r") for m in LEROBOT_MOTORS]
    image = FeatureSpec("video", (96, 128, 3), ["height", "width", "channels"], VIDEO)
    features = {"observation.state": FeatureSpec("float32", (12,), names), "observation.images.cam_right_wrist": image,
                "observation.images.left_wrist": image, "observation.images.front": image}
    state = np.random.default_rng(2).uniform(-80, 80, (5, 12)).astype(np.float32)
    root = write_lerobot_dataset(tmp_path / "ds", [EpisodeData({"observation.state": state})], features=features,
                                 fps=30, robot_type="bi_so100_follower")
    skeleton = _info_yaml(root, capsys)
    assert {name: arm["prefix"] for name, arm in skeleton["arms"].items()} == {"l": "l_", "r": "r_"}
    parents = {name: cam["mount"]["parent"] for name, cam in skeleton["cameras"].items()}
    assert parents == {"cam_right_wrist": "r_gripper", "left_wrist": "l_gripper", "front": "world"}


def test_an_unknown_arm_gets_one_arm_per_shared_prefix(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    names = [f"arm{a}_j{k}" for a in (1, 2) for k in range(1, 4)]
    features = {"observation.state": FeatureSpec("float32", (6,), names)}
    root = write_lerobot_dataset(tmp_path / "ds", [EpisodeData({"observation.state": np.zeros((4, 6), np.float32)})],
                                 features=features, fps=30, robot_type="my_arm")
    skeleton = _info_yaml(root, capsys)
    arms = skeleton["arms"]
    assert {name: (arm["prefix"], arm["urdf"], arm["joints"]) for name, arm in arms.items()} == {
        f"arm{a}": (f"arm{a}_", "URDF", {f"arm{a}_j{k}": f"j{k}" for k in range(1, 4)}) for a in (1, 2)}


@pytest.mark.parametrize(("seed", "delay_s"), [(3, 0.0), (7, 0.03)])
def test_a_camera_away_from_its_links_origin_is_placed_from_its_images(
        so101_urdf: Path, tmp_path: Path, seed: int, delay_s: float) -> None:
    """Without robot.yaml the camera is put at its link's origin; here it is 5.8 cm away. Measured with a translation
    from there its motion was not explained (17 deg/s of misfit left on seed 3); its position is now fitted from its
    matched features, and the link, mount, focal length and offset with it (the generator's truth). The fix writes
    the fitted position; the generated robot.yaml keeps its placeholder."""
    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(so101_urdf, seed=seed, duration_s=6.0,
                                                                          video_delay_s=delay_s))
    out = tmp_path / "out"
    assert main(["attribute", str(truth.root), "--out", str(out), "--format", "json", "-q"]) == 0
    result = json.loads((out / "attribution.json").read_text())
    assert result["inconclusive"] is False
    assert not [n for n in result["notes"] if "is a placeholder at the origin of" in n]
    (motion,) = result["camera_motion"]
    assert motion["link"] == "gripper_link"
    position = motion["position"]
    assert np.linalg.norm(np.subtract(position["xyz_link_cam"], truth.xyz_link_cam)) < 0.01
    assert position["residual_px"]["fitted"] < position["residual_px"]["at_link_origin"] / 3
    fitted = Rotation.from_quat(motion["q_link_cam"])
    assert (fitted.inv() * Rotation.from_quat(truth.q_link_cam)).magnitude() < np.radians(3.0)
    # Seed 3's motion reads offsets up to 10 ms long (docs/lerobot.md); the guessed focal length is 160 px.
    assert motion["offset_s"] == pytest.approx(truth.expected_offset_s, abs=0.012)
    assert 160.0 * motion["focal_scale"] == pytest.approx(truth.intrinsics[0], rel=0.04)
    (mount_fix,) = [f["fix"] for f in result["findings"] if "cameras.wrist.mount" in f["fix"]]
    assert mount_fix.startswith(f"In {out / 'robot.yaml'}, set cameras.wrist.mount: ")  # the file written to edit
    written = yaml.safe_load(mount_fix.split("cameras.wrist.mount: ", 1)[1].split(" (the mount", 1)[0])
    assert written["xyz"] == pytest.approx(position["xyz_link_cam"], abs=1e-4)
    assert yaml.safe_load((out / "robot.yaml").read_text())["cameras"]["wrist"]["mount"]["xyz"] == [0.0, 0.0, 0.0]


def test_degrees_read_as_radians_are_named_by_the_joint_limits(wrist_episode: VideoDatasetTruth, so101_urdf: Path,
                                                               tmp_path: Path) -> None:
    """The generator records degrees; robot.yaml saying radians puts the joints tens of radians out, far past the
    URDF's limits (about +-1.9 rad): a note names each such joint and asks for the unit. Read as degrees, none."""
    right = write_robot_yaml(wrist_episode, tmp_path / "robot.yaml")
    config = yaml.safe_load(right.read_text())
    assert config["default_unit"] == "deg"
    assert not [n for n in open_dataset(wrist_episode.root, episode=0, robot=right).metadata["notes"]
                if "outside their URDF limits" in n]
    config["default_unit"] = "rad"
    (tmp_path / "rad.yaml").write_text(yaml.safe_dump(config))
    notes = open_dataset(wrist_episode.root, episode=0, robot=tmp_path / "rad.yaml").metadata["notes"]
    (said,) = [n for n in notes if "outside their URDF limits" in n]
    assert "shoulder_pan.pos (rad) puts shoulder_pan at" in said
    assert "gripper" not in said  # its range_0_100 is its own unit, within its limits
    assert "is the unit right" in said


def test_degrees_declared_as_ticks_are_named_by_their_values(wrist_episode: VideoDatasetTruth, tmp_path: Path
                                                             ) -> None:
    """Degrees read as servo ticks put every joint near -180 deg, barely moving, within no limit's reach of a note:
    the values themselves say it (negative, and fractional, where servo counts are whole from 0 to 4096)."""
    right = write_robot_yaml(wrist_episode, tmp_path / "robot.yaml")
    assert not [n for n in open_dataset(wrist_episode.root, episode=0, robot=right).metadata["notes"]
                if "declared unit cannot" in n]
    config = yaml.safe_load(right.read_text())
    config["default_unit"] = "ticks"
    (tmp_path / "ticks.yaml").write_text(yaml.safe_dump(config))
    notes = open_dataset(wrist_episode.root, episode=0, robot=tmp_path / "ticks.yaml").metadata["notes"]
    (said,) = [n for n in notes if "declared unit cannot" in n]
    assert said.startswith(f"{tmp_path / 'ticks.yaml'}: the state holds values its declared unit cannot: ")
    # The recorded shoulder_pan column, read here with pyarrow: the first of the state vector.
    (table_path,) = sorted((wrist_episode.root / "data").rglob("*.parquet"))
    pan = np.array([row[0] for row in pq.read_table(table_path, columns=["observation.state"]).column(0).to_pylist()])
    assert f"shoulder_pan.pos (ticks) holds {pan.min():.4g}..{pan.max():.4g}, outside a servo's 0..4096" in said
    assert "gripper" not in said  # range_0_100 as declared: its values fit it
    assert "is the unit right (joints.NAME.unit, default_unit)?" in said


def test_a_guessed_lens_is_corrected_by_a_departure_a_calibration_would_keep(so101_urdf: Path, tmp_path: Path) -> None:
    """The generated robot.yaml guesses a 70 deg field of view: 457 px on a 640 px image whose lens has 500. A
    declared calibration 9% off would be within the 10% a focal finding needs; a guess is not a calibration, and its
    fix is offered (3% suffices), with the lens said to be guessed."""
    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(
        so101_urdf, seed=3, duration_s=6.0, width=640, height=480, focal_px=500.0))
    out = tmp_path / "out"
    assert main(["attribute", str(truth.root), "--out", str(out), "--format", "json", "-q"]) == 0
    result = json.loads((out / "attribution.json").read_text())
    (motion,) = result["camera_motion"]
    assert motion["intrinsics_known"] is False
    (focal,) = [f for f in result["findings"] if f["fault"] == "intrinsics"]
    fx = float(focal["fix"].split("cameras.wrist.intrinsics.fx: ", 1)[1].split(" ", 1)[0])
    assert fx == pytest.approx(truth.intrinsics[0], rel=0.02)
