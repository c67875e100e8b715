"""What a LeRobot dataset says of itself: its layout family, ``meta/info.json``'s keys, its features, one
episode's metadata and frames as values, and the error a dataset that disagrees with its metadata raises.

The reader (:mod:`framechain.adapters.lerobot.reader`) fills them from the files on disk.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, TypedDict

import numpy as np
import numpy.typing as npt

from framechain.adapters.errors import AdapterError
from framechain.arrays import FloatArray, IntArray

#: lerobot's default tolerance between a frame's timestamp and frame_index / fps.
TIMESTAMP_TOLERANCE_S = 1e-4
#: The per-frame columns lerobot adds to every dataset.
INDEX_COLUMNS = ("timestamp", "frame_index", "episode_index", "index", "task_index")

__all__ = [
    "INDEX_COLUMNS",
    "TIMESTAMP_TOLERANCE_S",
    "DatasetError",
    "EpisodeFrames",
    "EpisodeInfo",
    "FeatureInfo",
    "InfoJson",
    "Layout",
    "flatten_names",
    "is_lerobot_dataset",
]


class DatasetError(AdapterError):
    """A LeRobot dataset cannot be read as its metadata says: names the file and the inconsistency (one line:
    pyarrow's and FFmpeg's messages may span several)."""

    def __init__(self, path: str | Path, what: str) -> None:
        super().__init__(path, " ".join(what.split()))


class Layout(StrEnum):
    """On-disk layout family: v2 (one episode per file) or v3 (many episodes per file)."""

    V2 = "v2"
    V3 = "v3"


class InfoJson(TypedDict, total=False):
    """The keys of ``meta/info.json`` framechain reads."""

    codebase_version: str
    robot_type: str | None
    fps: float
    total_episodes: int
    total_frames: int
    total_chunks: int
    chunks_size: int
    data_path: str
    video_path: str | None
    features: dict[str, dict[str, Any]]
    splits: dict[str, str]


@dataclass(frozen=True)
class FeatureInfo:
    """One entry of ``info.json`` ``features``; ``names`` flattened (nested lists and dicts)."""

    key: str
    dtype: str
    shape: tuple[int, ...]
    names: tuple[str, ...] | None
    info: Mapping[str, Any] = field(default_factory=dict)

    @property
    def is_video(self) -> bool:
        return self.dtype == "video"

    @property
    def is_depth_map(self) -> bool:
        return bool(self.info.get("video.is_depth_map", False))

    @property
    def size(self) -> int:
        return int(np.prod(self.shape)) if self.shape else 1

    @property
    def image_size(self) -> tuple[int, int] | None:
        """(width, height) of an image or video feature: from its shape by its names, else ``video.width`` and
        ``video.height`` in its info, else a (height, width, channels) or (channels, height, width) shape; None when
        none of them says."""
        names = list(self.names or ())
        if "height" in names and "width" in names and len(self.shape) == len(names):
            return self.shape[names.index("width")], self.shape[names.index("height")]
        width, height = self.info.get("video.width"), self.info.get("video.height")
        if isinstance(width, int) and isinstance(height, int):
            return width, height
        if len(self.shape) == 3 and self.shape[-1] in (1, 3, 4):
            return self.shape[1], self.shape[0]
        if len(self.shape) == 3 and self.shape[0] in (1, 3, 4):
            return self.shape[2], self.shape[1]
        return None


@dataclass(frozen=True)
class EpisodeInfo:
    """One episode's metadata: where its frames and videos live."""

    index: int
    length: int
    tasks: tuple[str, ...]
    data_file: Path
    from_index: int | None = None  # v3: global index range [from, to)
    to_index: int | None = None
    video_files: Mapping[str, Path] = field(default_factory=dict)
    #: v3: where the episode starts inside the shared mp4, per video key (s); v2: 0.
    video_from_s: Mapping[str, float] = field(default_factory=dict)
    #: v3: where it ends (s, exclusive), per video key; v2: absent (the file's end).
    video_to_s: Mapping[str, float] = field(default_factory=dict)
    #: The videos info.json's ``video_path`` points to (filled with the video key and the episode's chunk and file)
    #: that are not on disk, per video key: a glob pattern where the template has a variable LeRobot does not define.
    missing_videos: Mapping[str, Path] = field(default_factory=dict)


@dataclass(frozen=True)
class EpisodeFrames:
    """The frames of one episode, sorted by ``index``: timestamps, indices and requested columns."""

    episode: EpisodeInfo
    timestamp_s: FloatArray
    frame_index: IntArray
    index: IntArray
    columns: Mapping[str, npt.NDArray[Any]]

    def __len__(self) -> int:
        return int(self.timestamp_s.shape[0])

    @property
    def stamp_ns(self) -> IntArray:
        """Timestamps as integer nanoseconds (rounded)."""
        out: IntArray = np.round(self.timestamp_s * 1e9).astype(np.int64)
        return out


def flatten_names(raw: Any) -> tuple[str, ...] | None:
    """``names`` of a feature as one flat tuple: lists, nested lists (Unitree) and dicts of lists."""
    if raw is None:
        return None
    out: list[str] = []

    def walk(node: Any) -> None:
        if isinstance(node, str):
            out.append(node)
        elif isinstance(node, Mapping):
            for value in node.values():
                walk(value)
        elif isinstance(node, list | tuple):
            for value in node:
                walk(value)
        else:
            out.append(str(node))

    walk(raw)
    return tuple(out)


def is_lerobot_dataset(path: str | Path) -> bool:
    """True when ``path`` is a directory with ``meta/info.json``: a LeRobot dataset, perhaps a damaged one
    (an info.json that cannot be read, or of another codebase version, is for :class:`DatasetReader` to
    say in one line, not a reason to read the folder as something else)."""
    return (Path(path) / "meta" / "info.json").is_file()
