"""Markers in a LeRobot episode's video: ``evidence.markers`` in robot.yaml, static-target findings as for ROS images.

The generator paints an ArUco marker on its table (its own renderer and URDF maths) and delays the
wrist video by 80 ms; the marker's position and the delay are the truth.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from framechain import pipeline
from framechain.cli.main import main
from framechain.sim.lerobot_video import VideoDatasetSpec, VideoDatasetTruth, generate_video_dataset, write_robot_yaml

MARKER_M = 0.12


@pytest.fixture(scope="module")
def marked(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    folder = tmp_path_factory.mktemp("markers")
    truth = generate_video_dataset(folder / "dataset", VideoDatasetSpec(
        so101_urdf, seed=63, duration_s=4.0, version="v2.1", marker_size_m=MARKER_M, video_delay_s=0.080))
    chain = {"camera": "wrist", "evidence": {"markers": {"dictionary": "DICT_4X4_50", "size_m": MARKER_M},
                                             "static_target": True}}
    return truth, write_robot_yaml(truth, folder / "robot.yaml", extra={"chain": chain})


def test_markers_in_the_video_give_a_static_target_latency(marked: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = marked
    assert main(["attribute", str(truth.root), "--episode", "0", "--robot", str(robot), "--out", str(tmp_path),
                 "--format", "json", "--json", "-q"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["error_m"]["metric"] == "static_spread"
    assert result["observations"]["replayed"] >= 20
    top = result["findings"][0]
    assert (top["fault"], top["hop"]) == ("latency", "camera_to_body")
    assert top["estimate"]["offset_s"] == pytest.approx(truth.expected_offset_s, abs=0.010)
    assert any("images searched for DICT_4X4_50 markers" in n for n in result["notes"])
    # The camera's own motion says the same, as corroboration (another metric: no share).
    (entry,) = result["camera_motion"]
    assert entry["offset_s"] == pytest.approx(truth.expected_offset_s, abs=0.010)


def test_the_marker_lands_where_it_lies(marked: tuple[VideoDatasetTruth, Path]) -> None:
    truth, robot = marked
    made = pipeline.run(truth.root, episode=0, robot=robot, bootstrap=0)
    result = made.attributed()
    labels = set(made.replay.observations.label.tolist())
    assert labels == {"7"}
    corners = made.timeline.metadata["fiducials"]["corners"]
    assert len(corners["obs_id"]) == len(made.replay.observations)
    # With the finding applied, the marker's world points gather on the generator's marker.
    corrected = np.median(result.corrected_world, axis=0)
    assert np.linalg.norm(corrected - np.asarray(truth.marker_xyz)) < 0.015
