"""`attribute DATASET --episodes all` without robot.yaml on a known arm: one fix per camera for the whole recording.

The generated SO-101 recording's camera sits 5.8 cm from gripper_link with a 180 px lens and video 30 ms late;
framechain guesses a 160 px lens at the link's origin. The fix it prints, applied to the robot.yaml it wrote as a
user would paste it, is checked against the generator's truth and then leaves nothing to find.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain.cli.main import main
from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset


def _applied(fix: str, robot_yaml: Path) -> dict[str, Any]:
    """The robot.yaml with every ``KEY: VALUE`` the fix names set, read as YAML: what a user pasting it gets."""
    config = yaml.safe_load(robot_yaml.read_text())
    said = fix.split(", set ", 1)[1].rsplit(" (the recording's fit", 1)[0]
    for key, value in re.findall(r"(cameras\.[\w.]+): (\{[^}]*\}|[-\d.]+)", said):
        *path, leaf = key.split(".")
        node = config
        for part in path:
            node = node.setdefault(part, {})
        node[leaf] = yaml.safe_load(value)
    return config


def test_the_recordings_fix_places_the_camera_and_leaves_nothing_to_find(so101_urdf: Path, tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(
        so101_urdf, seed=11, episodes=2, duration_s=5.0, video_delay_s=0.03))
    out = tmp_path / "out"
    assert main(["attribute", str(truth.root), "--episodes", "all", "--out", str(out), "-j", "1",
                 "--format", "md"]) == 0
    (fix,) = [line for line in capsys.readouterr().out.splitlines() if line.startswith("fix (camera wrist_optical")]
    assert fix.startswith(f"fix (camera wrist_optical_frame, recording): In {out / 'robot.yaml'}, set cameras.wrist.")
    config = _applied(fix, out / "robot.yaml")
    camera = config["cameras"]["wrist"]
    mount = camera["mount"]
    assert mount["parent"] == "gripper_link"
    assert np.linalg.norm(np.subtract(mount["xyz"], truth.xyz_link_cam)) < 0.01
    turned = Rotation.from_euler("xyz", mount["rpy"]).inv() * Rotation.from_quat(truth.q_link_cam)
    assert np.degrees(turned.magnitude()) < 1.5
    assert camera["intrinsics"]["fx"] == pytest.approx(truth.intrinsics[0], rel=0.03)
    assert camera["timing"]["offset_s"] == pytest.approx(truth.expected_offset_s, abs=0.006)
    fixed = tmp_path / "fixed.yaml"
    fixed.write_text(yaml.safe_dump(config))
    again_dir = tmp_path / "again"
    assert main(["attribute", str(truth.root), "--episode", "1", "--robot", str(fixed), "--out", str(again_dir),
                 "--format", "json", "-q"]) == 0
    again = json.loads((again_dir / "attribution.json").read_text())
    assert again["findings"] == []
    assert again["inconclusive"] is False
