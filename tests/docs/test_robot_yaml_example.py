"""The robot file of docs/lerobot.md loads, and the wrist camera's frames it gives agree with independent maths
(yourdfpy's forward kinematics, the mount, REP-103's optical rotation)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain.cli.main import main
from tests.helpers.realdata import SO101_URDF

PAGE = Path(__file__).resolve().parents[2] / "docs" / "lerobot.md"
OPTICAL_Q = (-0.5, 0.5, -0.5, 0.5)  # camera_link (FLU) -> optical (RDF), REP-103


def _robot_file_example() -> str:
    """The block of the page that is robot.yaml (``file=robot.yaml`` in its check)."""
    block = re.search(r"<!-- check: robot [^>]*file=robot\.yaml[^>]*-->\n```yaml\n(.*?)```", PAGE.read_text(),
                      flags=re.DOTALL)
    assert block is not None, "docs/lerobot.md has no robot.yaml example"
    return block.group(1)


JOINTS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")


def _dataset(folder: Path, state: np.ndarray) -> Path:
    """A v3.0 SO-101 dataset of ``state`` (degrees, the gripper 0-100) with a wrist video key, and the two
    detections robot.yaml's ``detections.parquet`` names."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset

    features = {
        "observation.state": FeatureSpec("float32", (6,), [f"{j}.pos" for j in JOINTS]),
        "observation.images.wrist": FeatureSpec("video", (480, 640, 3), ["height", "width", "channels"],
                                                {"video.fps": 30, "video.codec": "av1", "video.is_depth_map": False}),
    }
    root = write_lerobot_dataset(folder / "so101", [EpisodeData({"observation.state": state})], features=features,
                                 fps=30, version="v3.0")
    pq.write_table(pa.table({"episode_index": [0, 0], "frame_index": [2, 5], "camera": ["wrist_cam", "wrist_cam"],
                             "u": [300.0, 340.0], "v": [200.0, 260.0], "depth_m": [0.3, 0.35]}),
                   folder / "detections.parquet")
    return root


@pytest.fixture
def example(realdata: Path, tmp_path: Path) -> tuple[str, Path, Path, np.ndarray]:
    """The example beside its URDF and a dataset it reads: (its text, the URDF, the dataset, the state)."""
    urdf = realdata / SO101_URDF
    if not urdf.is_file():
        pytest.skip(f"{urdf} not present")
    text = _robot_file_example()
    (tmp_path / yaml.safe_load(text)["urdf"]).symlink_to(urdf)
    (tmp_path / "robot.yaml").write_text(text)
    rng = np.random.default_rng(3)
    state = np.hstack([rng.uniform(-60, 60, (8, 5)), rng.uniform(0, 100, (8, 1))]).astype(np.float32)
    return text, urdf, _dataset(tmp_path, state), state


def test_the_robot_file_example_gives_the_wrist_chain_of_independent_maths(
        example: tuple[str, Path, Path, np.ndarray]) -> None:
    import yourdfpy

    from framechain.adapters.lerobot.adapter import open_dataset
    from framechain.replay import TransformBuffer

    text, urdf, root, state = example
    n = len(state)
    tl = open_dataset(root, episode=0, robot=root.parent / "robot.yaml")
    assert len(tl.observations) == 2
    # base_link <- wrist optical frame by independent maths: yourdfpy FK, the mount, REP-103.
    ref = yourdfpy.URDF.load(str(urdf), load_meshes=False, build_collision_scene_graph=False)
    lo, hi = ref.joint_map["gripper"].limit.lower, ref.joint_map["gripper"].limit.upper
    cam = yaml.safe_load(text)["cameras"]["wrist_cam"]["mount"]
    mount = np.eye(4)
    mount[:3, :3] = Rotation.from_euler("xyz", cam["rpy"]).as_matrix()
    mount[:3, 3] = cam["xyz"]
    optical = np.eye(4)
    optical[:3, :3] = Rotation.from_quat(OPTICAL_Q).as_matrix()
    stamps = np.round((np.arange(n) / 30).astype(np.float32).astype(np.float64) * 1e9).astype(np.int64)
    got = TransformBuffer.from_timeline(tl).lookup("base_link", "wrist_cam_optical_frame", stamps)
    for i in range(n):
        cfg = {j: float(state[i, k]) * np.pi / 180 for k, j in enumerate(JOINTS[:5])}
        cfg["gripper"] = lo + float(state[i, 5]) / 100 * (hi - lo)
        ref.update_cfg(cfg)
        expected = ref.get_transform(frame_to="gripper_link", frame_from="base_link") @ mount @ optical
        np.testing.assert_allclose(got.translation[i], expected[:3, 3], atol=1e-9)
        q = Rotation.from_matrix(expected[:3, :3]).as_quat()
        assert abs(float(np.dot(got.quat_xyzw[i], q))) == pytest.approx(1.0, abs=1e-9)


def test_the_robot_file_example_is_ready_and_its_camera_name_avoids_the_trap(
        example: tuple[str, Path, Path, np.ndarray], capsys: pytest.CaptureFixture[str]) -> None:
    text, _urdf, root, _state = example
    robot = root.parent / "robot.yaml"
    assert main(["info", str(root), "--episode", "0", "--robot", str(robot), "--json", "-q"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["suggested_chain"]["frames"] == {"camera": "wrist_cam_optical_frame", "body": "base_link",
                                                 "world": "world"}
    needs = {n["piece"]: n["status"] for n in info["needs"]}
    assert needs["mount"] == needs["pose"] == needs["intrinsics"] == needs["evidence"] == "found"
    # The trap the example avoids: lerobot names the camera "wrist", and SO-101 has a wrist_link.
    robot.write_text(text.replace("wrist_cam", "wrist"))
    assert main(["info", str(root), "--episode", "0", "--robot", str(robot)]) == 1
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "camera 'wrist': its frame 'wrist_link' is already a link of the URDF" in line
