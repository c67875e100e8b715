"""``--episodes`` of attribute and batch on a generated LeRobot dataset: every episode is analysed or said why not,
episodes the dataset lacks are named (an error when it has none of them), and conflicting options are usage errors.

The dataset: four 2 s episodes of one wrist camera (v2.1, one mp4 per episode), episode 1's video cut to half its
bytes, as a copy that stopped mid-write leaves it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from framechain.cli.main import main
from framechain.fleet.units import episode_ranges
from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset, write_robot_yaml

EPISODES = 4
CUT_EPISODE = 1


def _cut_in_half(video: Path) -> None:
    whole = video.read_bytes()
    video.write_bytes(whole[: len(whole) // 2])


def _video(dataset: Path, episode: int) -> Path:
    (video,) = dataset.glob(f"videos/chunk-000/*/episode_{episode:06d}.mp4")
    return video


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[Path, Path]:
    """The dataset (episode 1's video cut) and its robot.yaml."""
    folder = tmp_path_factory.mktemp("episodes")
    spec = VideoDatasetSpec(so101_urdf, seed=3, episodes=EPISODES, duration_s=2.0, fps=15, codec="mpeg4",
                            version="v2.1", width=96, height=96, focal_px=60.0)
    truth = generate_video_dataset(folder / "dataset", spec)
    robot = write_robot_yaml(truth, folder / "robot.yaml")
    _cut_in_half(_video(truth.root, CUT_EPISODE))
    return truth.root, robot


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    said = capsys.readouterr()
    return code, said.out, said.err


def _episodes_in_table(out: Path) -> list[int]:
    return sorted({row["episode"] for row in pq.read_table(out / "fleet.parquet").to_pylist()})


def test_attribute_episodes_says_why_an_episode_failed_and_the_counts_reconcile(
        dataset: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root, robot = dataset
    code, out, err = _run(["attribute", str(root), "--robot", str(robot), "--episodes", "all", "--out",
                           str(tmp_path / "out"), "--format", "json", "--bootstrap", "0", "-j", "1", "-q"], capsys)
    assert code == 0, err  # three episodes were analysed
    lines = out.splitlines()
    assert lines[0].startswith(f"{EPISODES} episodes: ")
    counts = {status: int(n) for n, status in (part.split() for part in lines[0].split(": ", 1)[1].rstrip(".")
                                                .split(", "))}
    assert sum(counts.values()) == EPISODES
    assert counts["error"] == 1
    # The batch's own line for it: the episode, and its video that cannot be opened.
    (failure,) = [line for line in lines if line.startswith("1 error (")]
    assert failure.startswith(f"1 error ({root} episode {CUT_EPISODE}): {_video(root, CUT_EPISODE)}: cannot open video")
    assert _episodes_in_table(tmp_path / "out") == list(range(EPISODES))


def test_attribute_episodes_exits_1_when_no_episode_was_analysed(
        dataset: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root, robot = dataset
    code, out, err = _run(["attribute", str(root), "--robot", str(robot), "--episodes", str(CUT_EPISODE), "--out",
                           str(tmp_path / "out"), "--format", "json", "--bootstrap", "0", "-j", "1", "-q"], capsys)
    assert code == 1
    assert out == ""
    (line,) = err.splitlines()  # the one reason is the error, as attribute of one episode says it
    assert line.startswith(f"framechain attribute: error: {root} episode {CUT_EPISODE}: {_video(root, CUT_EPISODE)}: "
                           "cannot open video (")


def test_every_reason_is_said_before_the_error_when_episodes_fail_for_different_reasons(
        dataset: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root, robot = dataset
    copy = tmp_path / "dataset"
    shutil.copytree(root, copy)
    _cut_in_half(_video(copy, 3))
    code, out, err = _run(["attribute", str(copy), "--robot", str(robot), "--episodes", f"{CUT_EPISODE},3",
                           "--out", str(tmp_path / "out"), "--format", "json", "--bootstrap", "0", "-j", "1", "-q"],
                          capsys)
    assert code == 1
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 3
    for episode in (CUT_EPISODE, 3):
        assert f"1 error ({copy} episode {episode}): {_video(copy, episode)}: cannot open video" in err
    assert lines[-1] == f"framechain attribute: error: {copy}: no episode could be analysed (2 run; each one's " \
        "reason above)"


def test_a_dataset_without_robot_type_fails_once_before_any_episode(
        dataset: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root, _robot = dataset
    copy = tmp_path / "dataset"
    shutil.copytree(root, copy)
    info_path = copy / "meta" / "info.json"
    info = json.loads(info_path.read_text())
    del info["robot_type"]
    info_path.write_text(json.dumps(info))
    out = tmp_path / "out"
    code, stdout, err = _run(["attribute", str(copy), "--episodes", "all", "--out", str(out), "-q"], capsys)
    assert code == 1
    assert stdout == ""
    (line,) = err.splitlines()
    assert line.startswith(f"framechain attribute: error: {copy}: a LeRobot dataset needs --robot robot.yaml")
    assert "no robot_type" in line
    assert not (out / "fleet.parquet").exists()  # nothing ran


@pytest.mark.parametrize("command", ["attribute", "batch"])
def test_episodes_the_dataset_lacks_are_an_error_naming_the_dataset_and_what_it_has(
        command: str, dataset: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root, robot = dataset
    code, out, err = _run([command, str(root), "--robot", str(robot), "--episodes", "7,9-12", "--out",
                           str(tmp_path / "out"), "-q"], capsys)
    assert code == 1
    assert out == ""
    assert err.splitlines() == [f"framechain {command}: error: {root}: --episodes 7,9-12: the dataset has no such "
                                f"episode (it has {EPISODES} episodes: 0-{EPISODES - 1})"]


@pytest.mark.parametrize("command", ["attribute", "batch"])
def test_episodes_partly_outside_the_dataset_are_named_in_a_note(
        command: str, dataset: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root, robot = dataset
    out = tmp_path / "out"
    code, stdout, err = _run([command, str(root), "--robot", str(robot), "--episodes", "0,2-9,12", "--out", str(out),
                              "--format", "md", "--bootstrap", "0", "-j", "1", "-q"], capsys)
    assert code == 0, err
    note = f"note: {root}: --episodes 0,2-9,12: episodes 4-9,12 are not in the dataset (it has 4 episodes: 0-3)"
    assert note in stdout.splitlines()
    assert _episodes_in_table(out) == [0, 2, 3]
    report = (out / "fleet_report.md").read_text()
    assert "episodes 4-9,12 are not in the dataset" in report


@pytest.mark.parametrize(("argv", "complaint"), [
    (["--episodes", "0,,1"], "argument --episodes: expected episode numbers like 0-9,20, got '0,,1' "
                             "(an empty part between commas)"),
    (["--episodes", "0,x"], "got '0,x' ('x' is no episode number or range)"),
    (["--episodes", "all", "--episode", "1"], "argument --episode: not allowed with argument --episodes"),
    (["--episodes", "all", "-j", "0"], "argument --jobs/-j: must be 1 or more, got 0"),
])
def test_attribute_usage_errors(argv: list[str], complaint: str, tmp_path: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["attribute", str(tmp_path), "--out", str(tmp_path / "out"), *argv])
    assert exc.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1].endswith(complaint)


def test_batch_usage_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for argv, complaint in ((["--episodes", "0,,1"], "got '0,,1' (an empty part between commas)"),
                            (["-j", "0"], "argument --jobs/-j: must be 1 or more, got 0")):
        with pytest.raises(SystemExit) as exc:
            main(["batch", str(tmp_path), "--out", str(tmp_path / "out"), *argv])
        assert exc.value.code == 2
        assert capsys.readouterr().err.splitlines()[-1].endswith(complaint)


@pytest.mark.parametrize(("episodes", "text"), [
    ([7], "7"), ([3, 1, 2, 0], "0-3"), ([0, 2, 3, 4, 9, 12, 11, 10], "0,2-4,9-12"), ([5, 5, 6], "5-6"), ([], ""),
])
def test_episode_ranges(episodes: list[int], text: str) -> None:
    assert episode_ranges(episodes) == text


def test_attribute_episodes_without_robot_writes_the_robot_yaml_it_made(
        dataset: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A known arm without --robot: as attribute of one episode, the robot.yaml made (from the first episode) is
    written beside the outputs and said in one line, to edit and pass back."""
    from framechain.config.robot import RobotConfig

    root, _robot = dataset
    out = tmp_path / "out"
    code, _said, err = _run(["attribute", str(root), "--episodes", "0,2", "--out", str(out), "--format", "json",
                             "--bootstrap", "0", "-j", "1", "-q"], capsys)
    assert code == 0
    (line,) = [ln for ln in err.splitlines() if "no --robot given" in ln]
    assert "made from episode 0: " in line
    assert f"wrote {out / 'robot.yaml'}: edit it and pass --robot {out / 'robot.yaml'}" in line
    assert RobotConfig.load(out / "robot.yaml").cameras["wrist"].mount.parent == "gripper_link"
