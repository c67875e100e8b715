"""Cross-checks against independent readers: Rerun's LeRobotReader, and lerobot itself where installed."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from framechain.adapters.lerobot.reader import DatasetReader
from tests.helpers.lerobot_scene import ArmDataset


def _rerun_series(root: Path, episode: int, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(frame_index (T,), values (T, n)) of one feature as Rerun's LeRobotReader streams it."""
    from rerun.experimental import LeRobotReader

    reader = LeRobotReader(root)
    frames: list[np.ndarray] = []
    values: list[np.ndarray] = []
    for chunk in reader.stream(episode, video_mode="skip"):
        if chunk.entity_path != entity:
            continue
        batch = chunk.to_record_batch()
        if "Scalars:scalars" not in batch.schema.names:
            continue
        frames.append(np.asarray(batch.column("frame_index").to_numpy(zero_copy_only=False), dtype=np.int64))
        values.append(np.asarray(batch.column("Scalars:scalars").to_pylist(), dtype=np.float64))
    assert frames, f"Rerun streamed no {entity} scalars"
    index = np.concatenate(frames)
    order = np.argsort(index, kind="stable")
    return index[order], np.concatenate(values)[order]


def test_rerun_reads_the_same_state_and_frames(arm_dataset: ArmDataset) -> None:
    from rerun.experimental import LeRobotReader

    ours = DatasetReader(arm_dataset.root)
    theirs = LeRobotReader(arm_dataset.root)
    assert theirs.version == ours.layout.value
    assert theirs.episodes() == ours.episodes()
    for episode in ours.episodes():
        frames = ours.read(episode, ["observation.state", "observation.detection.wrist"])
        for feature in ("observation.state", "observation.detection.wrist"):
            index, values = _rerun_series(arm_dataset.root, episode, f"/{feature}")
            np.testing.assert_array_equal(index, frames.frame_index)
            np.testing.assert_array_equal(values, frames.columns[feature].astype(np.float64))


def test_rerun_reads_the_same_unitree_episode(unitree: Path) -> None:
    ours = DatasetReader(unitree).read(7, ["observation.state"])
    index, values = _rerun_series(unitree, 7, "/observation.state")
    np.testing.assert_array_equal(index, ours.frame_index)
    np.testing.assert_array_equal(values, ours.columns["observation.state"].astype(np.float64))


def test_lerobot_dataset_gives_the_same_frames(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    # Optional extra framechain[lerobot] (Python >= 3.12); CI does not install it. (Import the
    # submodule: this test folder is itself named lerobot, a namespace package a real install takes
    # precedence over. lerobot without its `dataset` extra raises ImportError, not ModuleNotFoundError.)
    module = pytest.importorskip("lerobot.datasets.lerobot_dataset", exc_type=ImportError)
    LeRobotDataset = module.LeRobotDataset

    ours = DatasetReader(arm_dataset.root)
    if ours.layout.value != "v3":
        pytest.skip("current lerobot reads v3.0 only (v2.1 raises BackwardCompatibilityError)")
    # lerobot reads a local copy only when every declared video file exists (else it goes to the Hub,
    # even with download_videos=False). The synthetic dataset declares a wrist video it never wrote:
    # give a copy empty files at those paths (the frames compared here never decode them).
    root = tmp_path / "dataset"
    shutil.copytree(arm_dataset.root, root)
    meta = module.LeRobotDatasetMetadata("local/framechain-test", root=root)
    assert meta.total_episodes == len(ours.episodes())
    assert meta.fps == ours.fps
    for episode in ours.episodes():
        for key in meta.video_keys:
            video = root / meta.get_video_file_path(episode, key)
            video.parent.mkdir(parents=True, exist_ok=True)
            video.touch()
    for episode in ours.episodes():
        dataset = LeRobotDataset("local/framechain-test", root=root, episodes=[episode], download_videos=False)
        frames = ours.read(episode, ["observation.state"])
        hf = dataset.hf_dataset.with_format("numpy")
        np.testing.assert_array_equal(np.asarray(hf["episode_index"]).reshape(-1), episode)
        np.testing.assert_array_equal(np.asarray(hf["frame_index"]).reshape(-1), frames.frame_index)
        np.testing.assert_array_equal(np.asarray(hf["observation.state"]), frames.columns["observation.state"])
        np.testing.assert_allclose(np.asarray(hf["timestamp"]).reshape(-1), frames.timestamp_s)
