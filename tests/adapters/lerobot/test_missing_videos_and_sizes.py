"""A LeRobot episode whose camera video is not on disk, and a camera whose intrinsics are for another image size.

Generated SO-101 datasets (:mod:`framechain.sim.lerobot_video`, 2 s, 224x224): the missing file is the one
info.json's ``video_path`` template gives for the camera's ``video_key`` (filled here by hand, not by the
reader), and the video's size is the one the generator was asked for.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest
import yaml

from framechain.cli.main import main
from framechain.sim.lerobot_video import VideoDatasetSpec, VideoDatasetTruth
from tests.helpers.egomotion_scene import generated

pytest.importorskip("av")

DURATION_S = 2.0


@pytest.fixture(scope="module")
def single(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    """v3.0, one wrist camera."""
    return generated(tmp_path_factory, "one_camera", VideoDatasetSpec(so101_urdf, seed=31, duration_s=DURATION_S))


@pytest.fixture(scope="module")
def two_cameras(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    """v2.1, two arms with a wrist camera each, two episodes (one video per camera and episode)."""
    return generated(tmp_path_factory, "two_cameras", VideoDatasetSpec(
        so101_urdf, seed=32, duration_s=DURATION_S, version="v2.1", episodes=2, bimanual=True, camera_per_arm=True))


def copied(truth: VideoDatasetTruth, robot: Path, tmp_path: Path) -> tuple[Path, Path]:
    """A copy of the dataset (each test deletes its own files) and its robot.yaml."""
    root = tmp_path / "dataset"
    shutil.copytree(truth.root, root)
    return root, robot


def info_json(root: Path) -> dict[str, Any]:
    out: dict[str, Any] = json.loads((root / "meta" / "info.json").read_text())
    return out


def attribute(root: Path, robot: Path, out: Path, episode: int, *extra: str) -> int:
    return main(["attribute", str(root), "--episode", str(episode), "--robot", str(robot), "--out", str(out),
                 "--bootstrap", "0", "-q", *extra])


def error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    (line,) = [ln for ln in err.splitlines() if "error:" in ln]
    return line


def test_a_deleted_video_of_the_only_camera_is_one_line_naming_it(
        single: tuple[VideoDatasetTruth, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = single
    root, robot = copied(truth, robot, tmp_path)
    info = info_json(root)
    key = truth.cameras[0].video_key
    # v3.0: episode 0 is in chunk 0, file 0 of its camera's video (the generator writes one file).
    video = root / info["video_path"].format(video_key=key, chunk_index=0, file_index=0)
    assert video.is_file()
    video.unlink()
    assert attribute(root, robot, tmp_path / "out", 0) == 1
    line = error_line(capsys)
    assert str(video) in line
    assert f"video_key {key}" in line
    assert "restore it" in line
    assert "no camera video" not in line  # the old message, which hid the file
    assert not (tmp_path / "out" / "attribution.json").exists()


def test_a_deleted_video_of_one_of_two_cameras_is_a_note_and_the_other_is_measured(
        two_cameras: tuple[VideoDatasetTruth, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = two_cameras
    root, robot = copied(truth, robot, tmp_path)
    info = info_json(root)
    lost, kept = truth.cameras[0], truth.cameras[1]
    video = root / info["video_path"].format(video_key=lost.video_key, episode_chunk=0, episode_index=1)
    assert video.is_file()
    video.unlink()
    assert attribute(root, robot, tmp_path / "out", 1, "--format", "md") == 0
    printed = capsys.readouterr().out
    result = json.loads((tmp_path / "out" / "attribution.json").read_text())
    measured = {entry["name"] for entry in result["camera_motion"]}
    assert measured == {kept.name}
    (note,) = [n for n in result["notes"] if str(video) in n]
    assert f"video_key {lost.video_key}" in note
    assert f"camera {lost.name}'s frames are left out" in note
    assert f"note: {note}" in printed
    assert str(video) in (tmp_path / "out" / "report.md").read_text()
    # info lists the camera from robot.yaml and says its video is missing too, with or without robot.yaml.
    for extra in ((), ("--robot", str(robot))):
        assert main(["info", str(root), "--episode", "1", *extra]) == 0
        assert str(video) in capsys.readouterr().out.replace("\n", "")


def test_both_videos_of_two_cameras_deleted_is_one_line_naming_both(
        two_cameras: tuple[VideoDatasetTruth, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = two_cameras
    root, robot = copied(truth, robot, tmp_path)
    template = info_json(root)["video_path"]
    videos = [root / template.format(video_key=c.video_key, episode_chunk=0, episode_index=0) for c in truth.cameras]
    for video in videos:
        video.unlink()
    assert attribute(root, robot, tmp_path / "out", 0) == 1
    line = error_line(capsys)
    assert all(str(video) in line for video in videos)


def with_intrinsics(robot: Path, out: Path, intrinsics: dict[str, float]) -> Path:
    config = yaml.safe_load(robot.read_text())
    (name,) = config["cameras"]
    config["cameras"][name]["intrinsics"] = intrinsics
    out.write_text(yaml.safe_dump(config))
    return out


def test_intrinsics_of_another_image_size_are_an_error_naming_both_sizes(
        single: tuple[VideoDatasetTruth, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = single
    assert (truth.spec.width, truth.spec.height) == (224, 224)
    wrong = with_intrinsics(robot, tmp_path / "robot.yaml",
                            {"fx": 180, "fy": 180, "cx": 319.5, "cy": 239.5, "width": 640, "height": 480})
    assert attribute(truth.root, wrong, tmp_path / "out", 0) == 1
    line = error_line(capsys)
    assert f"{wrong}: cameras.{truth.cameras[0].name}.intrinsics are for a 640x480 image" in line
    assert f"{truth.cameras[0].video_key} is 224x224" in line
    assert "scaled by" not in line  # another aspect: no scale makes them fit


def test_intrinsics_of_the_same_aspect_at_another_size_name_the_scale(
        single: tuple[VideoDatasetTruth, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = single
    wrong = with_intrinsics(robot, tmp_path / "robot.yaml",
                            {"fx": 360, "fy": 360, "cx": 223.5, "cy": 223.5, "width": 448, "height": 448})
    assert attribute(truth.root, wrong, tmp_path / "out", 0) == 1
    line = error_line(capsys)
    assert "are for a 448x448 image" in line
    assert "is 224x224" in line
    assert "multiply fx, fy, cx, cy by 0.5 (224/448)" in line


def test_intrinsics_of_the_video_size_pass(single: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """The check compares sizes, not values: the generator's own intrinsics (224x224) run."""
    truth, robot = single
    assert main(["info", str(truth.root), "--episode", "0", "--robot", str(robot)]) == 0
    assert "error" not in capsys.readouterr().err
