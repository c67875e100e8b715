"""A mobile base (LeKiwi: an SO-101 on three omni wheels) recorded as body-frame velocities beside the arm's joints.

Truth: a circle worked by hand for the integration; the generator's closed-form base motion
(:mod:`framechain.sim.mobile_base`, its pose and the derivatives it records) for the path; the generator's injected
delay and mount for the camera; hand-written robot.yaml mistakes.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain.adapters.lerobot.adapter import open_dataset
from framechain.adapters.lerobot.odometry import base_poses
from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset
from framechain.cli.main import main
from framechain.config.robot import RobotConfig, RobotConfigError
from framechain.replay import TransformBuffer
from framechain.robot.known_arms import KNOWN_ARMS, LEROBOT_MOTORS
from framechain.sim.lerobot_video import VideoDatasetSpec, VideoDatasetTruth, generate_video_dataset, write_robot_yaml

VIDEO = {"video.fps": 30, "video.codec": "av1", "video.pix_fmt": "yuv420p", "video.is_depth_map": False}
LEKIWI_NAMES = [f"arm_{m}.pos" for m in LEROBOT_MOTORS] + ["x.vel", "y.vel", "theta.vel"]


def test_a_constant_turn_at_a_constant_speed_is_a_circle() -> None:
    """0.2 m/s forward while turning 0.5 rad/s counter-clockwise for 4 s: the arc of radius v / omega left of the
    start, (v / omega) (sin wt, 1 - cos wt), heading wt; the trapezoid's chords stay within (omega dt)^2 / 12 of it."""
    t = np.arange(121) / 30.0
    xyz, quat = base_poses((t * 1e9).astype(np.int64), np.full(t.size, 0.2), np.zeros(t.size), np.full(t.size, 0.5))
    arc = np.column_stack([0.4 * np.sin(0.5 * t), 0.4 * (1.0 - np.cos(0.5 * t)), np.zeros(t.size)])
    np.testing.assert_allclose(xyz, arc, atol=2e-5)
    np.testing.assert_allclose(Rotation.from_quat(quat).as_rotvec()[:, 2], 0.5 * t, atol=1e-12)


def test_sideways_speed_is_to_the_left_of_the_heading() -> None:
    """A quarter turn to the left in the first second (a turn rate of (pi/2)(1 - cos 2 pi t), smooth to rest), then
    0.1 m/s to the left of the base for 2 s: -x in the world, 0.2 m."""
    t = np.arange(0, 3.001, 0.01)
    rate = np.where(t <= 1.0, np.pi / 2 * (1.0 - np.cos(2 * np.pi * t)), 0.0)
    left = np.where(t > 1.0, 0.1, 0.0)
    xyz, quat = base_poses((t * 1e9).astype(np.int64), np.zeros(t.size), left, rate)
    heading = Rotation.from_quat(quat[-1]).as_euler("xyz")[2]
    assert heading == pytest.approx(np.pi / 2, abs=1e-4)
    np.testing.assert_allclose(xyz[-1], [-0.2, 0.0, 0.0], atol=1e-3)  # the speed starts within a row: 0.5 mm


@pytest.fixture(scope="module")
def lekiwi(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    """A LeKiwi episode: the base turning up to 25 deg either way and drifting a few cm, the wrist camera 50 ms
    late, the front camera on the base 80 ms."""
    folder = tmp_path_factory.mktemp("lekiwi")
    truth = generate_video_dataset(folder / "dataset", VideoDatasetSpec(
        so101_urdf, seed=4, episodes=2, duration_s=8.0, fps=30, video_delay_s=0.05, base_turn_deg=25.0,
        front_camera=True, camera_delays_s=(0.0, 0.03)))
    return truth, write_robot_yaml(truth, folder / "robot.yaml")


def test_the_base_moves_as_its_closed_form_from_the_first_row(lekiwi: tuple[VideoDatasetTruth, Path]) -> None:
    """world -> mobile_base at every row, against the generator's closed-form pose seen from the first row's (the
    integration starts there): within a millimetre and a twentieth of a degree over the episode."""
    truth, robot = lekiwi
    timeline = open_dataset(truth.root, episode=1, robot=RobotConfig.load(robot))
    stamps = np.unique(timeline.joint_states.stamp_ns)
    found = TransformBuffer(timeline.transforms).lookup("world", "mobile_base", stamps).matrix()
    t = truth.timestamps_s[1]
    closed = truth.base_motions[1].world_from_base(t)
    expected = np.linalg.inv(closed[0]) @ closed
    np.testing.assert_allclose(found[:, :3, 3], expected[:, :3, 3], atol=1e-3)
    turned = Rotation.from_matrix(found[:, :3, :3]).inv() * Rotation.from_matrix(expected[:, :3, :3])
    assert np.degrees(turned.magnitude()).max() < 0.05
    assert np.degrees(np.ptp(Rotation.from_matrix(expected[:, :3, :3]).as_rotvec()[:, 2])) > 30  # it did turn


def _camera(attribution: Path, name: str = "wrist") -> dict[str, object]:
    return dict(next(e for e in json.loads(attribution.read_text())["camera_motion"] if e["name"] == name))


def test_the_wrist_cameras_offset_is_found_with_the_bases_turns_and_not_claimed_without(
        lekiwi: tuple[VideoDatasetTruth, Path], tmp_path: Path) -> None:
    """With mobile_base the camera's motion is explained and its offset found (truth -50 ms). Without it the base's
    turns are misfit that no correction removes: framechain says the motion is not explained, and fixes nothing."""
    truth, robot = lekiwi
    assert main(["attribute", str(truth.root), "--episode", "1", "--robot", str(robot), "--out",
                 str(tmp_path / "with"), "--format", "json", "-q"]) == 0
    found = _camera(tmp_path / "with" / "attribution.json")
    assert (found["explained"], found["link"]) == (True, "gripper_link")
    assert found["offset_s"] == pytest.approx(truth.expected_offset_s, abs=0.006)
    mount = Rotation.from_quat(found["q_link_cam"]).inv() * Rotation.from_quat(truth.q_link_cam)
    assert np.degrees(mount.magnitude()) < 2.0
    config = yaml.safe_load(robot.read_text())
    del config["mobile_base"], config["cameras"]["front"]  # the front camera rides the base
    (tmp_path / "no_base.yaml").write_text(yaml.safe_dump(config))
    assert main(["attribute", str(truth.root), "--episode", "1", "--robot", str(tmp_path / "no_base.yaml"), "--out",
                 str(tmp_path / "without"), "--format", "json", "-q"]) == 0
    blind = json.loads((tmp_path / "without" / "attribution.json").read_text())
    assert _camera(tmp_path / "without" / "attribution.json")["explained"] is False
    assert not blind["findings"]


def test_the_front_camera_rides_the_base_and_its_offset_is_found_from_the_bases_turns(
        lekiwi: tuple[VideoDatasetTruth, Path], tmp_path: Path) -> None:
    """The front camera turns only as the base does, about one axis: its offset comes from those turns (truth
    -80 ms), and its focal length is said to be undetermined rather than fitted."""
    truth, robot = lekiwi
    assert main(["attribute", str(truth.root), "--episode", "1", "--robot", str(robot), "--out", str(tmp_path),
                 "--format", "json", "-q"]) == 0
    front = _camera(tmp_path / "attribution.json", "front")
    assert (front["explained"], front["link"]) == (True, "mobile_base")
    assert front["offset_s"] == pytest.approx(-truth.camera("front").delays_s[1], abs=0.006)
    assert "intrinsics" in front["undetermined"]  # type: ignore[operator]


def test_attribute_without_robot_reads_lekiwis_base_and_finds_the_wrist_camera(
        lekiwi: tuple[VideoDatasetTruth, Path], tmp_path: Path) -> None:
    """No robot.yaml: robot_type lekiwi gives the bundled SO-101 on a mobile base, the arm where LeKiwi's drawing
    puts it (this one built 1.4 cm off); the camera's link, offset and position come from its motion."""
    truth, _robot = lekiwi
    assert main(["attribute", str(truth.root), "--episode", "1", "--out", str(tmp_path), "--format", "json",
                 "-q"]) == 0
    assert "mobile_base:" in (tmp_path / "robot.yaml").read_text()
    found = _camera(tmp_path / "attribution.json")
    assert (found["explained"], found["link"]) == (True, "gripper_link")
    assert found["offset_s"] == pytest.approx(truth.expected_offset_s, abs=0.006)
    position = found["position"]
    assert isinstance(position, dict)
    assert np.linalg.norm(np.subtract(position["xyz_link_cam"], truth.xyz_link_cam)) < 0.015


def test_info_puts_lekiwis_base_under_its_arm_and_its_front_camera(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """LeKiwi as lerobot records it (robot_type lekiwi, arm_shoulder_pan.pos .. arm_gripper.pos, x.vel, y.vel,
    theta.vel; cameras front and wrist): the bundled SO-101 on a mobile base read from the three velocities, placed
    where LeKiwi's drawing has it, the wrist camera on gripper_link and the front one on the base; as printed it
    loads."""
    rng = np.random.default_rng(3)
    state = np.column_stack([rng.uniform(-40, 40, (6, 5)), rng.uniform(0, 100, 6), rng.uniform(-0.2, 0.2, (6, 2)),
                             rng.uniform(-60, 60, 6)]).astype(np.float32)
    image = FeatureSpec("video", (480, 640, 3), ["height", "width", "channels"], VIDEO)
    features = {"observation.state": FeatureSpec("float32", (9,), LEKIWI_NAMES),
                "observation.images.front": image, "observation.images.wrist": image}
    root = write_lerobot_dataset(tmp_path / "ds", [EpisodeData({"observation.state": state})], features=features,
                                 fps=30, robot_type="lekiwi")
    assert main(["info", str(root), "--episode", "0", "--chain"]) == 0
    skeleton = yaml.safe_load(capsys.readouterr().out)
    assert Path(skeleton["urdf"]) == KNOWN_ARMS["lekiwi"].urdf == KNOWN_ARMS["so101"].urdf
    assert skeleton["joints"]["arm_shoulder_pan.pos"] == "shoulder_pan"
    # LeKiwi's drawing: the arm's pan axis 7.4 cm ahead of the wheels' centre, base_link 3.9 cm behind the axis.
    assert skeleton["world_from_base"] == {"xyz": [0.035, 0.0, 0.09], "rpy": [0.0, 0.0, 0.0]}
    assert skeleton["mobile_base"] == {"frame": "mobile_base", "x_vel": "x.vel", "y_vel": "y.vel",
                                       "yaw_rate": "theta.vel", "speed_unit": "m/s", "yaw_rate_unit": "deg/s"}
    parents = {name: cam["mount"]["parent"] for name, cam in skeleton["cameras"].items()}
    assert parents == {"front": "mobile_base", "wrist": "gripper_link"}
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(skeleton))
    config = RobotConfig.load(tmp_path / "robot.yaml")
    assert config.mobile_base is not None
    assert config.mobile_base.states == ("x.vel", "y.vel", "theta.vel")
    timeline = open_dataset(root, episode=0, robot=config)
    stamps = np.unique(timeline.joint_states.stamp_ns)
    heading = TransformBuffer(timeline.transforms).lookup("world", "front_optical_frame", stamps).matrix()
    assert not np.allclose(heading[0], heading[-1])  # the front camera rides the turning base


@pytest.mark.parametrize(("section", "said"), [
    ({"yaw_rate": "omega.vel"}, "state names ['omega.vel'] are not in observation.state"),
    ({"yaw_rate": "theta.vel", "yaw_rate_unit": "rpm"}, "mobile_base.yaw_rate_unit is an unknown unit 'rpm'"),
    ({"frame": "world", "yaw_rate": "theta.vel"}, "mobile_base.frame is the world frame 'world'"),
    ({"frame": "base_link", "yaw_rate": "theta.vel"}, "mobile_base.frame 'base_link' is a link of the URDF already"),
    ({"frame": "mobile_base"}, "mobile_base: names none of x_vel, y_vel, yaw_rate"),
    ({"yaw_rate": "theta.vel", "odom": "x"}, "mobile_base: unknown keys ['odom']"),
])
def test_a_wrong_mobile_base_is_one_line_naming_the_file_and_key(
        lekiwi: tuple[VideoDatasetTruth, Path], tmp_path: Path, section: dict[str, str], said: str) -> None:
    truth, robot = lekiwi
    config = yaml.safe_load(robot.read_text())
    config["mobile_base"] = section
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(config))
    with pytest.raises(RobotConfigError) as err:
        open_dataset(truth.root, episode=0, robot=RobotConfig.load(path))
    assert str(path) in str(err.value)
    assert said in str(err.value)
    assert "\n" not in str(err.value)
