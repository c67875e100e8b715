"""Every frame pair a camera's usable frames give is measured or left out with why, and the counts reconcile in
attribution.json, the printed observations line and the report.

The possible pairs are counted here from the frames (the frames used, less those the run says repeat the previous
one) and the spans, not from the measurement.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from framechain.cli.main import main
from framechain.sim.lerobot_video import VideoDatasetSpec, VideoDatasetTruth, generate_video_dataset, write_robot_yaml
from framechain.vision.egomotion import EgoMotionOptions, FeatureTracks, frame_pair_counts


def test_pairs_are_counted_within_windows_by_why_they_are_left_out() -> None:
    """Six usable frames in two windows (4 + 2), spans (1, 3), three moving matches needed, track 3 fixed.

    Possible: (0,1) (1,2) (2,3) (4,5) and (0,3); (3,4), (1,4) and (2,5) cross the windows' edge. Moving tracks
    shared: (0,1) 0,1,2; (1,2) 0,1; (2,3) 0,1; (4,5) 20,21,22; (0,3) 0,1,2: two with too few. Frames 4 and 5 share a
    stamp: (4,5) is out of order.
    """
    ids = [np.array(i, dtype=np.int64) for i in
           ([0, 1, 2, 3], [0, 1, 2, 3], [0, 1, 9], [0, 1, 2, 3], [20, 21, 22], [20, 21, 22])]
    tracks = FeatureTracks(rows=np.arange(6, dtype=np.int64), ids=tuple(ids),
                           pixels=tuple(np.zeros((i.size, 2)) for i in ids), fixed=np.array([3], dtype=np.int64),
                           segment=np.array([0, 0, 0, 0, 1, 1], dtype=np.int64))
    counts = frame_pair_counts(tracks, np.array([0, 10, 20, 30, 40, 40]), EgoMotionOptions(spans=(1, 3), min_inliers=3))
    assert (counts.possible, counts.few_matches, counts.unordered, counts.gathered) == (5, 2, 1, 2)
    # One window: the three pairs across the edge are possible too (and have no shared track).
    one = FeatureTracks(rows=tracks.rows, ids=tracks.ids, pixels=tracks.pixels, fixed=tracks.fixed)
    counts = frame_pair_counts(one, np.arange(6) * 10, EgoMotionOptions(spans=(1, 3), min_inliers=3))
    assert (counts.possible, counts.few_matches, counts.unordered) == (8, 5, 0)


@pytest.fixture(scope="module")
def low_texture(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    """3 s over cloth, MPEG-4, a wide lens, real-time stamps, 15% of the frames resent: pairs go unmatched."""
    folder = tmp_path_factory.mktemp("pair_counts")
    truth = generate_video_dataset(folder / "dataset", VideoDatasetSpec(
        so101_urdf, seed=5, duration_s=3.0, fps=20, table="cloth", codec="mpeg4", focal_px=112.0, clock="realtime",
        repeat_share=0.15))
    return truth, write_robot_yaml(truth, folder / "robot.yaml")


def test_pairs_left_out_reconcile_in_every_output(low_texture: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = low_texture
    assert main(["attribute", str(truth.root), "--episode", "0", "--robot", str(robot), "--out", str(tmp_path),
                 "--format", "md", "--bootstrap", "0", "-q"]) == 0
    (line,) = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("observations:")]
    (entry,) = json.loads((tmp_path / "attribution.json").read_text())["camera_motion"]
    assert entry["frames"] == truth.timestamps_s[0].size
    repeated = next(int(m.group(1)) for n in entry["notes"]
                    if (m := re.search(r"(\d+) of \d+ frames duplicated", n)))
    usable = entry["frames"] - repeated
    assert entry["pairs_possible"] == sum(usable - span for span in EgoMotionOptions().spans)
    left = entry["pairs_left_out"]
    assert set(left) == {"too_few_matched_features", "stamps_out_of_order", "too_few_inliers"}
    assert entry["pairs"] + sum(left.values()) == entry["pairs_possible"]
    # This episode loses pairs both ways.
    assert left["too_few_matched_features"] > 0
    assert left["too_few_inliers"] > 0
    shown = (f"camera wrist_optical_frame: {entry['frames']} frames, {entry['pairs']} frame pairs of "
             f"{entry['pairs_possible']} possible ({sum(left.values())} left out: "
             f"{left['too_few_matched_features']} too few matched features, {left['too_few_inliers']} too few inliers)")
    assert shown in line
    assert shown in (tmp_path / "report.md").read_text()
