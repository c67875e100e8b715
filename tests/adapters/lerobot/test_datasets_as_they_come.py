"""Datasets as real recordings write them: two arms, raw servo ticks with a LeRobot calibration JSON, a data_path
with a template variable LeRobot does not use, frames stored in the Parquet, and no robot.yaml yet.

Truth: the generator's own URDF maths (:class:`framechain.sim.urdf_chain.UrdfChain`) on the stored
state, the generator's injected delay, and the values written.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from framechain.adapters.lerobot.adapter import open_dataset
from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset
from framechain.cli.main import main
from framechain.config.robot import RobotConfig
from framechain.replay import TransformBuffer
from framechain.sim.lerobot_video import (
    ARM_JOINTS,
    VideoDatasetSpec,
    VideoDatasetTruth,
    generate_video_dataset,
    write_robot_yaml,
)
from framechain.sim.urdf_chain import UrdfChain
from framechain.suggest.lerobot import guess_unit


@pytest.fixture(scope="module")
def bimanual(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    folder = tmp_path_factory.mktemp("bimanual_data")
    truth = generate_video_dataset(folder / "dataset", VideoDatasetSpec(so101_urdf, seed=81, duration_s=1.0,
                                                                        bimanual=True, camera_arm="left_"))
    return truth, write_robot_yaml(truth, folder / "robot.yaml")


def stored_state(root: Path) -> tuple[np.ndarray, list[str]]:
    """Episode 0's observation.state (T, n) and its names, read with pyarrow alone."""
    info = json.loads((root / "meta" / "info.json").read_text())
    table = pq.read_table(sorted((root / "data").rglob("*.parquet"))[0], filters=[("episode_index", "=", 0)])
    table = table.sort_by("index")
    state = np.asarray(table.column("observation.state").combine_chunks().flatten()).reshape(table.num_rows, -1)
    return state.astype(np.float64), list(info["features"]["observation.state"]["names"])


def truth_poses(urdf: Path, state_deg: np.ndarray, names: list[str], arm: str, link: str) -> np.ndarray:
    """``T_world_link`` by the generator's own URDF maths (bases 0.4 m apart along y, as it places them)."""
    q = {j: np.deg2rad(state_deg[:, names.index(f"{arm}{j}.pos")]) for j in ARM_JOINTS}
    base = np.eye(4)
    base[1, 3] = 0.2 if arm == "left_" else -0.2
    out: np.ndarray = base @ UrdfChain(urdf).root_from_link(q, link)
    return out


def test_two_arms_in_ticks_with_a_calibration_json(bimanual: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                                   so101_urdf: Path) -> None:
    truth, robot = bimanual
    state_deg, names = stored_state(truth.root)
    # The same motion recorded as LeRobot records raw Feetech ticks: the servo applies the homing offset
    # itself, so the ticks are homed and LeRobot's degrees are (ticks - mid-range) * 360 / 4095. The right
    # arm's elbow has drive_mode 1, which LeRobot's degrees ignore.
    rng = np.random.default_rng(0)
    homing = {f"{arm}{j}": int(rng.integers(-1500, 1500)) for arm in ("left_", "right_") for j in ARM_JOINTS}
    ranges = {j: (700 + 40 * k, 3400 - 25 * k) for k, j in enumerate(ARM_JOINTS)}
    ticks = state_deg.copy()
    for i, name in enumerate(names):
        joint = name.removesuffix(".pos")
        if joint in homing:
            lo, hi = ranges[joint.split("_", 1)[1]]
            ticks[:, i] = np.round((lo + hi) / 2 + state_deg[:, i] * 4095 / 360)
    dataset = write_lerobot_dataset(tmp_path / "ticks", [EpisodeData({"observation.state": ticks})],
                                    features={"observation.state": FeatureSpec("float32", (len(names),), names)},
                                    fps=30, version="v3.0", robot_type="bi_so101_follower")
    config = yaml.safe_load(robot.read_text())
    for arm, spec in config["arms"].items():
        calibration = {j: {"id": k + 1, "drive_mode": int(f"{arm}_{j}" == "right_elbow_flex"),
                           "homing_offset": homing[f"{arm}_{j}"], "range_min": ranges[j][0],
                           "range_max": ranges[j][1]}
                       for k, j in enumerate(ARM_JOINTS)}
        (tmp_path / f"{arm}.json").write_text(json.dumps(calibration))
        spec["calibration"] = str(tmp_path / f"{arm}.json")
        spec["default_unit"] = "ticks"
        spec["joints"] = {k: v for k, v in spec["joints"].items() if "gripper" not in k}
    config.pop("cameras")
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(config))
    timeline = open_dataset(dataset, episode=0, robot=tmp_path / "robot.yaml")
    buffer = TransformBuffer(timeline.transforms)
    stamps = np.unique(timeline.joint_states.stamp_ns)
    for arm in ("left_", "right_"):
        found = buffer.lookup("world", f"{arm}gripper_link", stamps).matrix()
        expected = truth_poses(so101_urdf, state_deg, names, arm, "gripper_link")
        # Ticks are whole counts: 2 pi / 4095 rad each, a few tenths of a millimetre at the gripper.
        assert np.abs(found[:, :3, 3] - expected[:, :3, 3]).max() < 1.5e-3


def test_a_path_template_variable_lerobot_does_not_use(bimanual: tuple[VideoDatasetTruth, Path],
                                                       tmp_path: Path) -> None:
    truth, robot = bimanual
    root = shutil.copytree(truth.root, tmp_path / "dataset")
    info = json.loads((root / "meta" / "info.json").read_text())
    data = sorted((root / "data").rglob("*.parquet"))[0]
    moved = root / "data" / "rig-A" / data.relative_to(root / "data")
    moved.parent.mkdir(parents=True)
    data.rename(moved)
    info["data_path"] = "data/{rig}/" + info["data_path"].removeprefix("data/")
    (root / "meta" / "info.json").write_text(json.dumps(info))
    timeline = open_dataset(root, episode=0, robot=robot)
    assert len(timeline.joint_states)
    assert any("data_path uses {rig}, which LeRobot does not define" in n for n in timeline.metadata["notes"])


def test_frames_stored_in_the_parquet_are_evidence(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                   so101_urdf: Path) -> None:
    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(
        so101_urdf, seed=71, duration_s=4.0, version="v3.0", storage="image", video_delay_s=0.060))
    assert not (truth.root / "videos").exists()
    robot = write_robot_yaml(truth, tmp_path / "robot.yaml")
    assert main(["attribute", str(truth.root), "--episode", "0", "--robot", str(robot), "--out",
                 str(tmp_path / "out"), "--format", "json", "--json", "-q"]) == 0
    result = json.loads(capsys.readouterr().out)
    top = result["findings"][0]
    assert (top["fault"], top["camera"]) == ("latency", "wrist_optical_frame")
    assert top["estimate"]["offset_s"] == pytest.approx(-0.060, abs=0.010)


def test_info_suggests_a_robot_yaml_that_loads(bimanual: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str], so101_urdf: Path) -> None:
    truth, _robot = bimanual
    assert main(["info", str(truth.root), "--episode", "0", "--chain"]) == 0
    text = capsys.readouterr().out
    assert "topics." not in text  # every key is robot.yaml's
    skeleton = yaml.safe_load(text)
    assert set(skeleton["arms"]) == {"left", "right"}
    left = skeleton["arms"]["left"]
    assert left["prefix"] == "left_"
    assert left["default_unit"] == "deg"
    assert left["joints"]["left_gripper.pos"] == {"joint": "gripper", "unit": "range_0_100"}
    assert skeleton["cameras"]["wrist"]["video_key"] == "observation.images.wrist"
    assert skeleton["cameras"]["wrist"]["intrinsics"]["width"] == 224
    for arm in skeleton["arms"].values():
        arm["urdf"] = str(so101_urdf)  # what the user fills in
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(skeleton))
    config = RobotConfig.load(path)
    assert {a.prefix for a in config.arms} == {"left_", "right_"}
    timeline = open_dataset(truth.root, episode=0, robot=config)
    assert {"left_gripper_link", "right_gripper_link"} <= set(timeline.transforms.child.tolist())


def test_units_are_guessed_from_the_values() -> None:
    assert guess_unit("shoulder_pan.pos", np.array([-1.2, 0.4, 2.9])) == "rad"
    assert guess_unit("shoulder_pan.pos", np.array([-80.0, 45.0, 120.0])) == "deg"
    assert guess_unit("shoulder_pan.pos", np.array([812.0, 2048.0, 3301.0])) == "ticks"
    assert guess_unit("gripper.pos", np.array([3.0, 45.5, 97.0])) == "range_0_100"


def test_no_detections_hint_names_robot_yaml_keys(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                  so101_urdf: Path) -> None:
    """An episode with neither detections nor a video: one line, and the keys robot.yaml can use."""
    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(so101_urdf, seed=82, duration_s=0.5))
    robot = write_robot_yaml(truth, tmp_path / "robot.yaml")
    config = yaml.safe_load(robot.read_text())
    del config["cameras"]["wrist"]["video_key"]
    robot.write_text(yaml.safe_dump(config))
    assert main(["attribute", str(truth.root), "--episode", "0", "--robot", str(robot), "--out",
                 str(tmp_path / "out"), "-q"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "topics.detections" not in err
    assert "detections: [{table: DETECTIONS.parquet}]" in err


def test_a_cut_episodes_file_keeps_the_episodes_of_the_others(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                              so101_urdf: Path) -> None:
    """v3.0 with its episodes index in two files, one cut: the other file's episodes are still read."""
    import pyarrow as pa

    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(so101_urdf, seed=83, duration_s=0.5,
                                                                          episodes=3, version="v3.0"))
    robot = write_robot_yaml(truth, tmp_path / "robot.yaml")
    index = sorted((truth.root / "meta" / "episodes").rglob("*.parquet"))
    assert len(index) == 1
    rows = pq.read_table(index[0]).to_pylist()
    pq.write_table(pa.Table.from_pylist(rows[:2]), index[0])
    second = index[0].with_name("file-001.parquet")
    pq.write_table(pa.Table.from_pylist(rows[2:]), second)
    data = index[0].read_bytes()
    index[0].write_bytes(data[: len(data) // 2])  # cut: episodes 0 and 1 are lost, episode 2 is not
    assert main(["info", str(truth.root), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert any("file-000.parquet: cannot read" in n and "its episodes are left out" in n for n in info["notes"])
    assert main(["tf", str(truth.root), "world", "gripper_link", "--episode", "2", "--robot", str(robot),
                 "--json"]) == 0
    capsys.readouterr()
    assert main(["info", str(truth.root), "--episode", "0", "--robot", str(robot)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "no episode 0; episodes are 2..2" in err
