"""Camera motion on recordings made as real recorders make them, against the generator's truth.

The generated recording (:mod:`framechain.sim.lerobot_video`) has every quirk of a real two-arm
SO-101 recording: rows stamped with their real capture times at a variable ~18.6 Hz while each
video holds one frame per row encoded at a nominal 20 fps (MPEG-4 Part 2, 224x224, a wide lens),
18% of frames resent, gripper pads in view, a cloth on the table, one camera's first episode black,
and each camera late by its own delay. Truth: the delays injected, which arm carries which camera.
"""

from __future__ import annotations

import copy
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from framechain.cli.main import main
from framechain.sim.lerobot_video import VideoDatasetSpec, VideoDatasetTruth, generate_video_dataset, write_robot_yaml

DELAYS_S = (0.06, 0.09)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    folder = tmp_path_factory.mktemp("as_recorded")
    spec = VideoDatasetSpec(so101_urdf, seed=5, episodes=2, duration_s=8.0, fps=20, codec="mpeg4", bimanual=True,
                            camera_per_arm=True, clock="realtime", focal_px=112.0, repeat_share=0.18,
                            black_first_episode="right_wrist", table="cloth", camera_delays_s=DELAYS_S)
    truth = generate_video_dataset(folder / "dataset", spec)
    return truth, write_robot_yaml(truth, folder / "robot.yaml")


_RUNS: dict[tuple[str, str, int], tuple[dict[str, Any], Path]] = {}


def attribute(root: Path, robot: Path, capsys: pytest.CaptureFixture[str], factory: pytest.TempPathFactory,
              episode: int = 1) -> dict[str, Any]:
    """attribution.json of a run (run once per process for the same inputs)."""
    return copy.deepcopy(attributed(root, robot, capsys, factory, episode)[0])


def attributed(root: Path, robot: Path, capsys: pytest.CaptureFixture[str], factory: pytest.TempPathFactory,
               episode: int = 1) -> tuple[dict[str, Any], Path]:
    """attribution.json of a run and the folder of its outputs (report.md beside it)."""
    key = (str(root), str(robot), episode)
    if key not in _RUNS:
        out = factory.mktemp("out")
        code = main(["attribute", str(root), "--episode", str(episode), "--robot", str(robot), "--out", str(out),
                     "--format", "json,md", "--json", "-q"])
        assert code == 0
        _RUNS[key] = json.loads(capsys.readouterr().out), out
    return _RUNS[key]


def entries(result: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {e["name"]: e for e in result["camera_motion"]}


def robot_with(robot: Path, folder: Path, change: Any) -> Path:
    config = yaml.safe_load(robot.read_text())
    change(config)
    out = folder / "robot.yaml"
    out.write_text(yaml.safe_dump(config))
    return out


def test_the_pairing_by_order_is_found_and_said(recording: tuple[VideoDatasetTruth, Path],
                                                capsys: pytest.CaptureFixture[str],
                                                tmp_path_factory: pytest.TempPathFactory) -> None:
    truth, robot = recording
    assert main(["info", str(truth.root)]) == 0
    said = " ".join(capsys.readouterr().out.split())
    for key in ("left_wrist", "right_wrist"):
        assert f"video observation.images.{key}: frames paired with rows by order: one frame per row" in said
    result = attribute(truth.root, robot, capsys, tmp_path_factory)
    notes = " ".join(result["notes"])
    assert "frames paired with rows by order" in notes
    assert "its motion confirms its frames' pairing by order" in notes
    assert all(e["pairing"] == "order" for e in result["camera_motion"])


def test_each_cameras_offset_is_found_within_10_ms(recording: tuple[VideoDatasetTruth, Path],
                                                   capsys: pytest.CaptureFixture[str],
                                                   tmp_path_factory: pytest.TempPathFactory) -> None:
    truth, robot = recording
    result = attribute(truth.root, robot, capsys, tmp_path_factory)
    found = {f["camera"]: f for f in result["findings"] if f["fault"] == "latency"}
    for camera in truth.cameras:
        entry = entries(result)[camera.name]
        assert entry["link"] == camera.camera_link
        assert entry["offset_s"] == pytest.approx(-camera.delays_s[1], abs=0.010)
        assert f"{camera.name}_optical_frame" in found
    assert_no_bound_below_its_estimate(result)


def test_the_reports_provenance_names_every_camera_and_its_lens(recording: tuple[VideoDatasetTruth, Path],
                                                                capsys: pytest.CaptureFixture[str],
                                                                tmp_path_factory: pytest.TempPathFactory) -> None:
    """Both wrist cameras, each with the link it is declared on and the focal length the generator declared; the
    episode logs no detection, which the stamps say instead of a span of nothing."""
    truth, robot = recording
    _result, out = attributed(truth.root, robot, capsys, tmp_path_factory)
    rows = {line.split(" | ")[0].strip("| "): line for line in (out / "report.md").read_text().splitlines()
            if line.startswith("| ")}
    frames = [f"{camera.name}_optical_frame" for camera in truth.cameras]
    assert f"cameras {', '.join(frames)}, body " in rows["frames"]
    assert rows["cameras"] == "| cameras | " + "; ".join(
        f"{frame}: declared on {camera.declared_link}, {truth.spec.width} px wide, focal {truth.declared_focal_px:g} px"
        for frame, camera in zip(frames, truth.cameras, strict=True)) + " |"
    assert rows["stamps"].startswith("| stamps | no observations logged, ")


def _state_later(dataset: Path, destination: Path, shift_s: float) -> Path:
    """A copy whose state is re-sampled ``shift_s`` later (linear interpolation per joint over the rows' stamps)."""
    shutil.copytree(dataset, destination)
    for path in sorted((destination / "data").rglob("*.parquet")):
        table = pq.read_table(path)
        episode = table["episode_index"].to_numpy()
        stamps = table["timestamp"].to_numpy().astype(float)
        state = np.stack(table["observation.state"].to_numpy(zero_copy_only=False)).astype(float)
        later = state.copy()
        for e in np.unique(episode):
            rows = episode == e
            for j in range(state.shape[1]):
                later[rows, j] = np.interp(stamps[rows] + shift_s, stamps[rows], state[rows, j])
        column = pa.FixedSizeListArray.from_arrays(pa.array(later.astype(np.float32).ravel()), state.shape[1])
        pq.write_table(table.set_column(table.column_names.index("observation.state"), "observation.state", column),
                       path)
    return destination


def test_state_resampled_100_ms_later_moves_each_offset_by_100_ms(recording: tuple[VideoDatasetTruth, Path],
                                                                  capsys: pytest.CaptureFixture[str],
                                                                  tmp_path_factory: pytest.TempPathFactory) -> None:
    truth, robot = recording
    before = entries(attribute(truth.root, robot, capsys, tmp_path_factory))
    later = _state_later(truth.root, tmp_path_factory.mktemp("later") / "dataset", 0.100)
    after = entries(attribute(later, robot, capsys, tmp_path_factory))
    for camera in truth.cameras:
        # The state at a row now shows the arm 100 ms later: frames match it 100 ms earlier.
        assert after[camera.name]["offset_s"] - before[camera.name]["offset_s"] == pytest.approx(-0.100, abs=0.010)


def test_declared_as_it_is_the_recording_is_clean(recording: tuple[VideoDatasetTruth, Path],
                                                  capsys: pytest.CaptureFixture[str],
                                                  tmp_path_factory: pytest.TempPathFactory) -> None:
    """robot.yaml that states each camera's true delay: no finding over a tenth of the misfit."""
    truth, robot = recording

    def timed(config: dict[str, Any]) -> None:
        for camera in truth.cameras:
            config["cameras"][camera.name]["timing"] = {"offset_s": -camera.delays_s[1]}

    result = attribute(truth.root, robot_with(robot, tmp_path_factory.mktemp("timed"), timed), capsys,
                       tmp_path_factory)
    assert all(f["share"] <= 0.10 for f in result["findings"]), result["findings"]
    assert all(abs(e["offset_s"]) < 0.010 for e in result["camera_motion"])
    assert_no_bound_below_its_estimate(result)


def test_a_wrong_pairing_forced_is_not_explained(recording: tuple[VideoDatasetTruth, Path],
                                                 capsys: pytest.CaptureFixture[str],
                                                 tmp_path_factory: pytest.TempPathFactory) -> None:
    """Pairing the rows with the frames shown at their stamps (LeRobot's convention, wrong here): the motion says
    so, and no fix is offered."""
    truth, robot = recording

    def forced(config: dict[str, Any]) -> None:
        for camera in truth.cameras:
            config["cameras"][camera.name]["timing"] = {"pairing": "presentation"}

    result = attribute(truth.root, robot_with(robot, tmp_path_factory.mktemp("forced"), forced), capsys,
                       tmp_path_factory)
    assert not result["findings"]
    assert result["verdict"].startswith("Inconclusive: the model does not explain the motion of camera")
    assert "no fix is offered" in result["verdict"]
    notes = " ".join(result["notes"])
    assert "as the configuration forces, but its motion contradicts it" in notes
    assert_no_bound_below_its_estimate(result)


def test_cameras_swapped_against_the_declared_arms_are_named(recording: tuple[VideoDatasetTruth, Path],
                                                             capsys: pytest.CaptureFixture[str],
                                                             tmp_path_factory: pytest.TempPathFactory) -> None:
    truth, robot = recording

    def swapped(config: dict[str, Any]) -> None:
        cameras = config["cameras"]
        cameras["left_wrist"]["video_key"], cameras["right_wrist"]["video_key"] = (
            cameras["right_wrist"]["video_key"], cameras["left_wrist"]["video_key"])

    result = attribute(truth.root, robot_with(robot, tmp_path_factory.mktemp("swapped"), swapped), capsys,
                       tmp_path_factory)
    named = {f["camera"]: f["estimate"] for f in result["findings"] if f["fault"] == "wrong_camera_frame"}
    assert named == {"left_wrist_optical_frame": {"used": "left_gripper_link", "meant": "right_gripper_link",
                                                  "hop": "camera_to_body"},
                     "right_wrist_optical_frame": {"used": "right_gripper_link", "meant": "left_gripper_link",
                                                   "hop": "camera_to_body"}}


def test_a_black_first_episode_says_so(recording: tuple[VideoDatasetTruth, Path], capsys: pytest.CaptureFixture[str],
                                       tmp_path_factory: pytest.TempPathFactory) -> None:
    truth, robot = recording
    result = attribute(truth.root, robot, capsys, tmp_path_factory, episode=0)
    right = entries(result)["right_wrist"]
    assert not right.get("link")
    assert any("frames black" in n for n in right["notes"])
    assert entries(result)["left_wrist"]["offset_s"] == pytest.approx(-DELAYS_S[0], abs=0.010)


def assert_no_bound_below_its_estimate(result: dict[str, Any]) -> None:
    """No verdict says "no fault above B" for a family whose own estimate is larger than B: each observable bound
    is at least the camera's estimate of that family, or that family is a finding on the camera."""
    found = {(f.get("camera"), f["fault"]) for f in result["findings"]}
    by_camera = {e["camera"]: e for e in result["camera_motion"]}
    for bound in result["bounds"]:
        entry = by_camera.get(bound.get("camera"))
        if not bound["observable"] or entry is None or "offset_s" not in entry:
            continue
        size = next(iter(bound["min_detectable"].values()))
        estimate = {"latency": abs(entry["offset_s"]), "rotation_error": entry.get("mount_error_deg") or 0.0,
                    "intrinsics": abs((entry.get("focal_scale") or 1.0) - 1.0)}[bound["fault"]]
        families = {"rotation_error", "missing_rotation", "axis_flip"} if bound["fault"] == "rotation_error" else {
            bound["fault"]}
        assert estimate <= size or any((bound["camera"], f) in found for f in families), (bound, estimate)
        if estimate > size:
            assert f"above {size}" not in result["verdict"]
