"""LeRobot v2.x / v3.0 on disk with pyarrow: episodes, boundaries, columns, names, bad metadata."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from framechain.adapters.errors import AdapterError
from framechain.adapters.lerobot.reader import (
    DatasetError,
    DatasetReader,
    Layout,
    flatten_names,
    is_lerobot_dataset,
)
from framechain.errors import FramechainError
from tests.helpers.lerobot_scene import FPS, STATE_NAMES, ArmDataset, episode_times, state_vectors, write_arm_dataset


def test_episodes_and_boundaries(arm_dataset: ArmDataset) -> None:
    reader = DatasetReader(arm_dataset.root)
    assert reader.layout is (Layout.V2 if reader.version == "v2.1" else Layout.V3)
    assert reader.episodes() == [0, 1, 2]
    assert reader.fps == FPS
    assert reader.names("observation.state") == tuple(STATE_NAMES)
    starts = np.cumsum([0, *arm_dataset.lengths])
    for e, n in enumerate(arm_dataset.lengths):
        frames = reader.read(e, ["observation.state"])
        assert len(frames) == n
        np.testing.assert_array_equal(frames.frame_index, np.arange(n))
        np.testing.assert_array_equal(frames.index, np.arange(starts[e], starts[e] + n))
        np.testing.assert_array_equal(frames.timestamp_s, episode_times(e, n))
        expected = state_vectors(episode_times(e, n)).astype(np.float32)
        np.testing.assert_array_equal(frames.columns["observation.state"], expected)
        assert set(frames.columns) == {"observation.state"}
        assert frames.episode.tasks == (f"reach {e % 2}",)
    # The writer declares a video key without writing an mp4: a note, not an error.
    assert any("'observation.images.wrist' is declared but no video files" in n for n in reader.notes)


def test_v3_episodes_share_files(arm_dataset: ArmDataset) -> None:
    reader = DatasetReader(arm_dataset.root)
    if reader.layout is not Layout.V3:
        pytest.skip("v3 only")
    files = [reader.episode(e).data_file.name for e in reader.episodes()]
    assert files == ["file-000.parquet", "file-000.parquet", "file-001.parquet"]
    ep1 = reader.episode(1)
    assert (ep1.from_index, ep1.to_index) == (24, 64)
    # Only the episode's rows come back from the shared file.
    assert pq.read_metadata(ep1.data_file).num_rows == 64
    assert len(reader.read(1, [])) == 40


def test_stamps_are_integer_nanoseconds(arm_dataset: ArmDataset) -> None:
    frames = DatasetReader(arm_dataset.root).read(2, [])
    assert frames.stamp_ns.dtype == np.int64
    np.testing.assert_array_equal(frames.stamp_ns, np.round(episode_times(2, 30) * 1e9).astype(np.int64))


def test_flatten_names() -> None:
    assert flatten_names(None) is None
    assert flatten_names(["a", "b"]) == ("a", "b")
    assert flatten_names([["kLeftShoulderPitch", "kLeftElbow"]]) == ("kLeftShoulderPitch", "kLeftElbow")
    assert flatten_names({"motors": ["m1", "m2"]}) == ("m1", "m2")


def test_is_lerobot_dataset(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    assert is_lerobot_dataset(arm_dataset.root)
    assert not is_lerobot_dataset(tmp_path)


def _copy(ds: ArmDataset, tmp_path: Path) -> Path:
    dst = tmp_path / "copy"
    shutil.copytree(ds.root, dst)
    return dst


def _edit_info(root: Path, **changes: object) -> None:
    path = root / "meta" / "info.json"
    info = json.loads(path.read_text())
    info.update(changes)
    path.write_text(json.dumps(info))


def test_errors_name_file_and_inconsistency(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    root = _copy(arm_dataset, tmp_path)
    reader = DatasetReader(root)
    with pytest.raises(DatasetError, match=r"no episode 7; episodes are 0..2"):
        reader.read(7, [])
    with pytest.raises(DatasetError, match=r"no feature 'observation.joints'"):
        reader.names("observation.joints")
    with pytest.raises(DatasetError, match=r"'observation.images.wrist' is a video: it has no Parquet column"):
        reader.read(0, ["observation.images.wrist"])
    with pytest.raises(DatasetError, match=r"column 'effort' is not in this file"):
        reader.read(0, ["effort"])
    data_file = reader.episode(2).data_file
    # A declared length that disagrees with the rows.
    if reader.layout is Layout.V2:
        lines = (root / "meta" / "episodes.jsonl").read_text().splitlines()
        row = json.loads(lines[2])
        row["length"] = 31
        lines[2] = json.dumps(row)
        (root / "meta" / "episodes.jsonl").write_text("\n".join(lines) + "\n")
        with pytest.raises(DatasetError, match=r"episode_000002.parquet: episode 2 has 30 rows but its metadata "
                                               r"declares length 31"):
            DatasetReader(root).read(2, [])
    data_file.unlink()
    with pytest.raises(DatasetError, match=r"data file of episode 2 is missing") as err:
        DatasetReader(root).read(2, [])
    assert isinstance(err.value, AdapterError)
    assert isinstance(err.value, FramechainError)
    assert str(data_file) in str(err.value)


def test_bad_info_json(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    root = _copy(arm_dataset, tmp_path)
    _edit_info(root, codebase_version="v1.6")
    with pytest.raises(DatasetError, match=r"info.json: codebase_version 'v1.6' is not v2.x or v3.x"):
        DatasetReader(root)
    _edit_info(root, codebase_version="v2.1", fps=0)
    with pytest.raises(DatasetError, match=r"fps must be a positive number, got 0"):
        DatasetReader(root)
    (root / "meta" / "info.json").write_text("{not json")
    with pytest.raises(DatasetError, match=r"info.json: cannot read as JSON"):
        DatasetReader(root)
    with pytest.raises(DatasetError, match=r"missing: not a LeRobot dataset"):
        DatasetReader(tmp_path)


def test_names_that_do_not_fit_the_shape(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    root = _copy(arm_dataset, tmp_path)
    info = json.loads((root / "meta" / "info.json").read_text())
    info["features"]["observation.state"]["names"] = STATE_NAMES[:-1]
    (root / "meta" / "info.json").write_text(json.dumps(info))
    with pytest.raises(DatasetError, match=r"feature 'observation.state' has shape \[7\] \(7 values\) but 6 names"):
        DatasetReader(root).names("observation.state")


def test_timestamps_going_backwards_and_notes(tmp_path: Path) -> None:
    t = episode_times(0, 10)
    t_bad = t.copy()
    t_bad[5] = t_bad[3]
    from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset

    spec = {"observation.state": FeatureSpec("float32", (7,), STATE_NAMES)}
    root = write_lerobot_dataset(tmp_path / "bad", [EpisodeData({"observation.state": state_vectors(t)},
                                                                timestamp_s=t_bad)],
                                 features=spec, fps=FPS, version="v2.1")
    with pytest.raises(DatasetError, match=r"timestamps of episode 0 do not increase at frame 5 "
                                           r"\(0.133333 s then 0.100000 s\)"):
        DatasetReader(root).read(0, [])
    # Timestamps offset by one frame: loads, with a note; strict refuses.
    root2 = write_lerobot_dataset(tmp_path / "offset", [EpisodeData({"observation.state": state_vectors(t)},
                                                                    timestamp_s=t + 1 / FPS)],
                                  features=spec, fps=FPS, version="v3.0")
    reader = DatasetReader(root2)
    reader.read(0, [])
    assert any("timestamps start at 0.0333333 s, not 0" in n for n in reader.notes)
    with pytest.raises(DatasetError, match=r"timestamps start at 0.0333333 s"):
        DatasetReader(root2, strict=True).read(0, [])


def test_variable_rate_timestamps_are_kept(tmp_path: Path) -> None:
    from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset

    t = np.cumsum(np.r_[0.0, np.full(11, 0.04) + np.linspace(-0.01, 0.01, 11)])
    spec = {"observation.state": FeatureSpec("float32", (7,), STATE_NAMES)}
    root = write_lerobot_dataset(tmp_path / "vr", [EpisodeData({"observation.state": state_vectors(t)},
                                                               timestamp_s=t)], features=spec, fps=25,
                                 version="v3.0")
    reader = DatasetReader(root)
    frames = reader.read(0, [])
    np.testing.assert_array_equal(frames.timestamp_s, t.astype(np.float32).astype(np.float64))
    assert any("variable rate" in n for n in reader.notes)


def test_list_columns_of_equal_length_are_accepted(tmp_path: Path) -> None:
    # lerobot may write plain list<float> instead of fixed_size_list.
    root = write_arm_dataset(tmp_path / "ds", version="v2.1", lengths=(6,)).root
    path = root / "data" / "chunk-000" / "episode_000000.parquet"
    table = pq.read_table(path)
    state = table.column("observation.state").cast(pa.list_(pa.float32()))
    pq.write_table(table.set_column(table.column_names.index("observation.state"), "observation.state", state), path)
    frames = DatasetReader(root).read(0, ["observation.state"])
    assert frames.columns["observation.state"].shape == (6, 7)


# ------------------------------------------------------------------------------------ real data


def test_unitree_v21_nested_names(unitree: Path) -> None:
    reader = DatasetReader(unitree)
    assert reader.version == "v2.1"
    assert len(reader.episodes()) == 100
    names = reader.names("observation.state")
    assert len(names) == 26
    assert names[0] == "kLeftShoulderPitch"
    assert names[-1] == "kRightHandThumbRotation"
    lengths = {json.loads(line)["episode_index"]: json.loads(line)["length"]
               for line in (unitree / "meta" / "episodes.jsonl").read_text().splitlines() if line}
    frames = reader.read(3, ["observation.state", "action"])
    assert len(frames) == lengths[3]
    assert frames.columns["observation.state"].shape == (lengths[3], 26)
    raw = pq.read_table(unitree / "data" / "chunk-000" / "episode_000003.parquet", columns=["observation.state"])
    np.testing.assert_array_equal(frames.columns["observation.state"],
                                  np.asarray(raw.column(0).to_pylist(), dtype=np.float32))
    assert frames.timestamp_s[0] == 0.0
    assert not any("episode_000003" in n for n in reader.notes)


def test_gr00t_v20_loads_with_notes_naming_each_inconsistency(gr00t: Path) -> None:
    reader = DatasetReader(gr00t)
    assert reader.version == "v2.0"
    frames = reader.read(0, ["observation.state"])
    assert len(frames) == 416
    assert frames.columns["observation.state"].shape == (416, 44)
    np.testing.assert_array_equal(frames.frame_index, np.arange(416))
    notes = "\n".join(reader.notes)
    assert "total_chunks is 0 but data/ holds 1 chunk folders (chunk-000)" in notes
    assert "video feature 'observation.images.egoview' is declared but no video files exist" in notes
    assert "'observation.images.ego_view' is declared" not in notes
    assert "split 'train' is '0:100' but the dataset has 5 episodes" in notes
    assert "no frame_index column: frame indices derived from index" in notes
    assert "timestamps start at 0.05 s, not 0: offset +0.05 s from frame_index / fps (20 fps)" in notes
    assert str(reader.episode(0).video_files["observation.images.ego_view"]).endswith(
        "videos/chunk-000/observation.images.ego_view/episode_000000.mp4")


def test_gr00t_v20_strict_fails_naming_the_inconsistency(gr00t: Path) -> None:
    with pytest.raises(DatasetError, match=r"meta/info.json: total_chunks is 0 but data/ holds 1 chunk folders"):
        DatasetReader(gr00t, strict=True)
