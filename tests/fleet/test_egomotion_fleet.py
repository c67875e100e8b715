"""``framechain batch`` over generated recordings: the video/state offset of every episode, its spread, and
the episodes whose offset disagrees with the fleet (the generator's injected delays are the truth)."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq
import pytest

from framechain.fleet import run_batch
from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset, write_robot_yaml


def test_the_fleet_shows_each_episodes_offset_and_which_disagree(tmp_path: Path, so101_urdf: Path) -> None:
    # One recording of three episodes whose video is 40 ms late, and one episode of another rig 120 ms late.
    recording = generate_video_dataset(tmp_path / "recording", VideoDatasetSpec(
        so101_urdf, seed=51, duration_s=4.0, episodes=3, version="v3.0", video_delay_s=0.040))
    other = generate_video_dataset(tmp_path / "other_rig", VideoDatasetSpec(
        so101_urdf, seed=52, duration_s=4.0, version="v2.1", video_delay_s=0.120))
    robot = write_robot_yaml(recording, tmp_path / "robot.yaml")
    out = tmp_path / "out"
    result = run_batch([recording.root, other.root], out, robot=robot, jobs=1, bootstrap=0, report_formats=("md",))
    assert [r["status"] for r in result.records] == ["findings"] * 4
    table = pq.read_table(result.table_path).to_pylist()
    offsets = {(r["log"], r["episode"]): (r["video_offset_s"], r["video_offset_low_s"], r["video_offset_high_s"])
               for r in table}
    assert len(offsets) == 4
    for (log, _episode), (offset, low, high) in offsets.items():
        truth = -0.120 if log == str(other.root.resolve()) else -0.040
        assert offset == pytest.approx(truth, abs=0.010)
        assert low < offset < high
    same = [v for (log, _e), v in offsets.items() if log == str(recording.root.resolve())]
    assert max(v[0] for v in same) - min(v[0] for v in same) < 0.010  # one recording: one offset
    report = (out / "fleet_report.md").read_text()
    assert "## Video/state time offset per log" in report
    assert ("1 log(s) whose offset departs from the median by more than twice its bound disagree: "
            f"{other.root.resolve()} episode 0") in report
    rows = [line for line in report.splitlines()
            if line.startswith(f"| {recording.root.resolve()} episode") and "| wrist_optical_frame |" in line]
    assert len(rows) == 3
    assert all(line.rstrip(" |").endswith("yes") for line in rows)
