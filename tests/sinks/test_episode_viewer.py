"""An episode's Rerun recording, read back with Rerun's own reader: its time axis is the episode's own (a duration
from its first row, and the wall-clock where the dataset stores one), its layout holds only views that have data
(the cameras, the FK tree in 3D, one rotation-rate plot per camera, the text), and its 3D labels name only the
chain's frames."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from framechain.cli.main import main
from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset
from framechain.sim.lerobot_video import write_robot_yaml as write_video_robot_yaml
from tests.helpers.lerobot_scene import write_arm_dataset, write_robot_yaml
from tests.helpers.rrd_views import blueprint_views, labels_in_3d, views_without_data

START_S = 0.25  # the first row's timestamp: the time axis still starts at 0
WALL_S = 1_760_000_000.125  # the first row's Unix time, stored per frame in observation.unix_time


@pytest.fixture(scope="module")
def episode_rrd(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> Path:
    """A 3 s SO-101 episode as recorded (joint states and a wrist video, no detections), replayed to an .rrd."""
    folder = tmp_path_factory.mktemp("episode_viewer")
    truth = generate_video_dataset(folder / "dataset", VideoDatasetSpec(so101_urdf, seed=3, duration_s=3.0,
                                                                         video_delay_s=0.06))
    robot = write_video_robot_yaml(truth, folder / "robot.yaml")
    rrd = folder / "episode.rrd"
    assert main(["replay", str(truth.root), "--episode", "0", "--robot", str(robot), "--save", str(rrd), "-q"]) == 0
    return rrd


def test_an_episode_shows_its_cameras_its_tree_its_rates_and_no_empty_view(episode_rrd: Path) -> None:
    assert views_without_data(episode_rrd) == []
    views = blueprint_views(episode_rrd)
    assert Counter(v.kind for v in views) == {"3D": 1, "2D": 1, "TimeSeries": 1, "TextDocument": 2, "TextLog": 1}
    (camera,) = [v for v in views if v.kind == "2D"]
    assert camera.origin == "/camera"  # the wrist video under its pinhole
    (rates,) = [v for v in views if v.kind == "TimeSeries"]  # one plot for the one camera
    assert rates.origin == "/series/rotation_rate_deg_s/wrist"
    assert {e.rsplit("/", 1)[-1] for e in ("/x/measured", "/measured", "/declared", "/corrected")
            if rates.shows(rates.origin + e)} == {"measured", "declared", "corrected"}


def test_an_episodes_3d_labels_name_only_the_chains_frames_once(episode_rrd: Path) -> None:
    # robot.yaml's chain: the wrist camera's optical frame, base_link, and the world, where the base stands
    # (world_from_base is the identity): those two share one label.
    assert sorted(labels_in_3d(episode_rrd)) == ["world = base_link", "wrist_optical_frame"]


def _times(rrd: Path, entity: str, timeline: str) -> np.ndarray:
    from rerun.chunk import RrdReader

    out = [np.asarray(c.to_record_batch().column(timeline).cast(pa.int64())) for c in RrdReader(rrd).stream()
           if c.entity_path == entity and not c.is_static]
    return np.sort(np.concatenate(out))


def test_an_episodes_time_axis_starts_at_zero_with_the_wall_clock_beside(tmp_path: Path) -> None:
    dataset = write_arm_dataset(tmp_path / "ds", version="v2.1", lengths=(20,), detection_feature=True,
                                start_s=START_S, wall_clock_s=WALL_S)
    robot = write_robot_yaml(tmp_path, detections=[{"feature": "observation.detection.wrist", "camera": "wrist"}])
    rrd = tmp_path / "episode.rrd"
    assert main(["replay", str(dataset.root), "--episode", "0", "--robot", str(robot), "--save", str(rrd),
                 "--no-attribute", "-q"]) == 0
    from rerun.chunk import RrdReader

    timelines = {f.name: str(f.type) for c in RrdReader(rrd).stream() if not c.is_static
                 for f in c.to_record_batch().schema if f.name in ("episode_time", "sensor_time", "wall_time")}
    assert timelines == {"episode_time": "duration[ns]", "wall_time": "timestamp[ns]"}
    # The rows as stored (float32 seconds, from 0.25 s): the tree moves at each row, from 0 s on the episode's axis.
    stored = pq.read_table(dataset.root / "data" / "chunk-000" / "episode_000000.parquet")
    row_ns = np.round(stored.column("timestamp").to_numpy().astype(np.float64) * 1e9).astype(np.int64)
    assert row_ns[0] == round(START_S * 1e9)
    moving = "/tf/shoulder_link"
    np.testing.assert_array_equal(_times(rrd, moving, "episode_time"), row_ns - row_ns[0])
    wall = stored.column("observation.unix_time").to_numpy()
    np.testing.assert_allclose(_times(rrd, moving, "wall_time") / 1e9, wall, rtol=0, atol=1e-6)
    assert views_without_data(rrd) == []
    assert "wrist_optical_frame" in labels_in_3d(rrd)


@pytest.mark.parametrize(("first", "expected_ns"), [
    (np.int64(1_760_000_000_123_456_789), 1_760_000_000_123_456_789),  # ns, kept exact
    (np.int64(1_760_000_000_123), 1_760_000_000_123_000_000),  # ms
    (np.int64(1_760_000_000_123_456), 1_760_000_000_123_456_000),  # us
    (np.float64(1_760_000_000.5), 1_760_000_000_500_000_000),  # s
    (np.float64(12.5), None),  # seconds from the start: no date
    (np.float64(np.nan), None),
])
def test_a_unix_time_column_in_any_unit_is_the_wall_clock(first: np.generic, expected_ns: int | None) -> None:
    from framechain.adapters.lerobot.reader import EpisodeFrames, EpisodeInfo
    from framechain.adapters.lerobot.wall_clock import wall_clock_start_ns

    frames = EpisodeFrames(EpisodeInfo(0, 2, (), Path("x.parquet")), np.array([0.0, 0.1]), np.arange(2),
                           np.arange(2), {"unix_time_ns": np.array([first, first], dtype=np.asarray(first).dtype)})
    found = wall_clock_start_ns(frames, ["unix_time_ns"])
    assert found == (None if expected_ns is None else ("unix_time_ns", expected_ns))


def test_an_episodes_summary_says_what_its_cameras_measured(episode_rrd: Path) -> None:
    """No detection to count: the summary names the frames the camera's motion was measured on (the episode's
    3 s of rows at the generator's 30 fps), not a table of zeros."""
    from tests.helpers.rrd_views import column_values, read_chunks

    (summary,) = column_values(read_chunks(episode_rrd), "/summary", "TextDocument:text", static=True)
    text = str(summary[0] if isinstance(summary, list) else summary)
    assert "Observations: none logged (no detections); the cameras' own motion measured instead: " in text
    assert "camera wrist_optical_frame: 90 frames, " in text
    assert "| total |" not in text
