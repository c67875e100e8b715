"""Write LeRobot datasets (v2.1 or v3.0) with pyarrow, following the on-disk format.

For tests, the scene generator and notebooks: a dataset written here is read by framechain's
reader, by Rerun's ``LeRobotReader`` and (where installed) by lerobot itself. Videos are not
encoded: a video feature is declared in ``info.json`` (with its episode columns in v3.0) but no
mp4 is written unless the caller puts one there.

Per episode, the caller gives a mapping ``feature -> (T, *shape)`` array; the writer adds
``timestamp`` (``frame_index / fps`` unless the episode gives ``timestamp``), ``frame_index``,
``episode_index``, the global ``index`` and ``task_index``. Vectors are stored as
``fixed_size_list`` columns (Hugging Face ``Sequence(length=n)``), as lerobot writes them.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.parquet as pq

from framechain.adapters.lerobot.reader import DatasetError
from framechain.timeline import numpy_of

__all__ = ["EpisodeData", "FeatureSpec", "write_lerobot_dataset"]

V21_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
V21_VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
V30_DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
V30_VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
V30_EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"

_ARROW = {"float32": pa.float32(), "float64": pa.float64(), "int64": pa.int64(), "int32": pa.int32(),
          "uint16": pa.uint16(), "uint8": pa.uint8(), "bool": pa.bool_()}


@dataclass(frozen=True)
class FeatureSpec:
    """A feature of ``info.json``: dtype, shape and names (list, nested list, dict or None)."""

    dtype: str
    shape: tuple[int, ...]
    names: Any = None
    info: Mapping[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"dtype": self.dtype, "shape": list(self.shape), "names": self.names}
        if self.info is not None:
            out["info"] = dict(self.info)
        return out


@dataclass(frozen=True)
class EpisodeData:
    """One episode: per-frame feature arrays, its task, optional per-frame timestamps (s)."""

    frames: Mapping[str, npt.ArrayLike]
    task: str = "task"
    timestamp_s: npt.ArrayLike | None = None


def write_lerobot_dataset(
    root: str | Path,
    episodes: Sequence[EpisodeData],
    *,
    features: Mapping[str, FeatureSpec],
    fps: int,
    version: str = "v3.0",
    robot_type: str = "so101_follower",
    chunks_size: int = 1000,
    episodes_per_file: int | None = None,
) -> Path:
    """Write a dataset under ``root`` (created; must not hold a dataset already) and return it.

    ``version`` is ``"v2.1"`` (one Parquet file per episode, ``episodes.jsonl``) or ``"v3.0"``
    (``episodes_per_file`` episodes per data file, default all; ``meta/episodes`` parquet).
    """
    out = Path(root)
    if (out / "meta" / "info.json").exists():
        raise DatasetError(out, "already holds a dataset")
    if version not in ("v2.1", "v3.0"):
        raise DatasetError(out, f"cannot write codebase_version {version!r}; choose v2.1 or v3.0")
    (out / "meta").mkdir(parents=True, exist_ok=True)
    tasks: dict[str, int] = {}
    for ep in episodes:
        tasks.setdefault(ep.task, len(tasks))
    all_features = {k: v for k, v in features.items() if k not in ("timestamp", "frame_index", "episode_index",
                                                                    "index", "task_index")}
    tables: list[pa.Table] = []
    start = 0
    for e, ep in enumerate(episodes):
        tables.append(_episode_table(ep, e, start, tasks[ep.task], all_features, fps))
        start += tables[-1].num_rows
    info_features = {k: f.to_json() for k, f in all_features.items()}
    info_features.update({
        "timestamp": {"dtype": "float32", "shape": [1], "names": None},
        "frame_index": {"dtype": "int64", "shape": [1], "names": None},
        "episode_index": {"dtype": "int64", "shape": [1], "names": None},
        "index": {"dtype": "int64", "shape": [1], "names": None},
        "task_index": {"dtype": "int64", "shape": [1], "names": None},
    })
    info: dict[str, Any] = {
        "codebase_version": version, "robot_type": robot_type, "total_episodes": len(episodes),
        "total_frames": start, "total_tasks": len(tasks), "chunks_size": chunks_size, "fps": fps,
        "splits": {"train": f"0:{len(episodes)}"}, "features": info_features,
    }
    if version == "v2.1":
        _write_v21(out, episodes, tables, tasks, all_features, info, chunks_size=chunks_size)
    else:
        _write_v30(out, episodes, tables, tasks, all_features, info, fps=fps, episodes_per_file=episodes_per_file)
    (out / "meta" / "info.json").write_text(json.dumps(info, indent=4))
    return out


def _write_v21(out: Path, episodes: Sequence[EpisodeData], tables: list[pa.Table], tasks: Mapping[str, int],
               features: Mapping[str, FeatureSpec], info: dict[str, Any], *, chunks_size: int) -> None:
    """v2.1: one Parquet file per episode; episodes, tasks and per-episode stats as JSON lines."""
    video_keys = [k for k, f in features.items() if f.dtype == "video"]
    lengths = [t.num_rows for t in tables]
    info.update({"total_videos": len(video_keys) * len(episodes),
                 "total_chunks": max(1, (len(episodes) + chunks_size - 1) // chunks_size),
                 "data_path": V21_DATA_PATH, "video_path": V21_VIDEO_PATH if video_keys else None})
    for e, table in enumerate(tables):
        path = out / V21_DATA_PATH.format(episode_chunk=e // chunks_size, episode_index=e)
        _write_parquet(table, path)
    with (out / "meta" / "episodes.jsonl").open("w") as fh:
        for e, ep in enumerate(episodes):
            fh.write(json.dumps({"episode_index": e, "tasks": [ep.task], "length": lengths[e]}) + "\n")
    with (out / "meta" / "tasks.jsonl").open("w") as fh:
        for task, i in tasks.items():
            fh.write(json.dumps({"task_index": i, "task": task}) + "\n")
    with (out / "meta" / "episodes_stats.jsonl").open("w") as fh:
        for e, table in enumerate(tables):
            fh.write(json.dumps({"episode_index": e, "stats": _stats(table, features)}) + "\n")


def _write_v30(out: Path, episodes: Sequence[EpisodeData], tables: list[pa.Table], tasks: Mapping[str, int],
               features: Mapping[str, FeatureSpec], info: dict[str, Any], *, fps: int,
               episodes_per_file: int | None) -> None:
    """v3.0: ``episodes_per_file`` episodes per data file (default all), the episodes parquet, tasks, stats."""
    video_keys = [k for k, f in features.items() if f.dtype == "video"]
    lengths = [t.num_rows for t in tables]
    info.update({"data_files_size_in_mb": 100, "video_files_size_in_mb": 200,
                 "data_path": V30_DATA_PATH, "video_path": V30_VIDEO_PATH if video_keys else None})
    per_file = episodes_per_file or max(1, len(episodes))
    rows: list[dict[str, Any]] = []
    offsets = np.cumsum([0, *lengths])
    for e, ep in enumerate(episodes):
        file_index = e // per_file
        row: dict[str, Any] = {
            "episode_index": e, "tasks": [ep.task], "length": lengths[e],
            "data/chunk_index": 0, "data/file_index": file_index,
            "dataset_from_index": int(offsets[e]), "dataset_to_index": int(offsets[e + 1]),
        }
        for key in video_keys:
            # Episodes concatenated in one mp4 per key: the episode starts where the last ended.
            first = e - e % per_file
            from_s = float(sum(lengths[first:e]) / fps)
            row.update({f"videos/{key}/chunk_index": 0, f"videos/{key}/file_index": file_index,
                        f"videos/{key}/from_timestamp": from_s,
                        f"videos/{key}/to_timestamp": from_s + lengths[e] / fps})
        row.update({"meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0})
        rows.append(row)
    for file_index in range((len(episodes) + per_file - 1) // per_file):
        part = tables[file_index * per_file:(file_index + 1) * per_file]
        _write_parquet(pa.concat_tables(part), out / V30_DATA_PATH.format(chunk_index=0, file_index=file_index))
    episodes_table = pa.Table.from_pylist(rows)
    _write_parquet(episodes_table, out / V30_EPISODES_PATH.format(chunk_index=0, file_index=0), hf=False)
    task_table = pa.table({"task_index": pa.array(list(tasks.values()), pa.int64()),
                           "task": pa.array(list(tasks), pa.string())})
    pq.write_table(task_table, out / "meta" / "tasks.parquet")
    stats = _stats(pa.concat_tables(tables), features)
    (out / "meta" / "stats.json").write_text(json.dumps(stats, indent=2))


def _episode_table(
    ep: EpisodeData, e: int, start: int, task_index: int, features: Mapping[str, FeatureSpec], fps: int
) -> pa.Table:
    columns: dict[str, pa.Array] = {}
    n: int | None = None
    for key, spec in features.items():
        if spec.dtype == "video":
            continue
        if key not in ep.frames:
            raise DatasetError(key, f"episode {e} gives no values for feature {key!r}")
        arr = np.asarray(ep.frames[key])
        if n is None:
            n = arr.shape[0]
        elif arr.shape[0] != n:
            raise DatasetError(key, f"episode {e}: feature {key!r} has {arr.shape[0]} frames, expected {n}")
        columns[key] = _arrow_column(arr, spec, key)
    if n is None:
        raise DatasetError("features", "at least one non-video feature is needed")
    frame_index = np.arange(n, dtype=np.int64)
    ts = (frame_index / fps) if ep.timestamp_s is None else np.asarray(ep.timestamp_s, dtype=float)
    out = dict(columns)
    out["timestamp"] = pa.array(ts.astype(np.float32), pa.float32())
    out["frame_index"] = pa.array(frame_index)
    out["episode_index"] = pa.array(np.full(n, e, dtype=np.int64))
    out["index"] = pa.array(np.arange(start, start + n, dtype=np.int64))
    out["task_index"] = pa.array(np.full(n, task_index, dtype=np.int64))
    return pa.table(out)


def _arrow_column(arr: npt.NDArray[Any], spec: FeatureSpec, key: str) -> pa.Array:
    if spec.dtype == "image":  # HF datasets.Image: the encoded file's bytes (PNG/JPEG), no path
        return pa.array([{"bytes": bytes(b), "path": None} for b in arr],
                        pa.struct([("bytes", pa.binary()), ("path", pa.string())]))
    if spec.dtype not in _ARROW:
        raise DatasetError(key, f"cannot write dtype {spec.dtype!r}; supported: {sorted(_ARROW)}")
    typ = _ARROW[spec.dtype]
    values = arr.astype(np.dtype(spec.dtype))
    size = int(np.prod(spec.shape))
    if spec.shape in ((), (1,)):
        return pa.array(values.reshape(-1), typ)
    if values[0].size != size:
        raise DatasetError(key, f"feature {key!r} has {values[0].size} values per frame, shape {list(spec.shape)}")
    # Nested fixed-size lists, innermost dimension last (HF Array2D/Sequence layout).
    flat: pa.Array = pa.array(values.reshape(-1), typ)
    for dim in reversed(spec.shape):
        flat = pa.FixedSizeListArray.from_arrays(flat, dim)
    return flat


def _hf_features(schema: pa.Schema) -> dict[str, Any]:
    def convert(t: pa.DataType) -> dict[str, Any]:
        if pa.types.is_struct(t) and {f.name for f in t} == {"bytes", "path"}:
            return {"_type": "Image"}
        if pa.types.is_fixed_size_list(t):
            return {"feature": convert(t.value_type), "length": t.list_size, "_type": "Sequence"}
        return {"dtype": {"float": "float32", "double": "float64"}.get(str(t), str(t)), "_type": "Value"}

    return {f.name: convert(f.type) for f in schema}


def _write_parquet(table: pa.Table, path: Path, *, hf: bool = True) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if hf:
        meta = {b"huggingface": json.dumps({"info": {"features": _hf_features(table.schema)}}).encode()}
        table = table.replace_schema_metadata(meta)
    pq.write_table(table, path)


def _stats(table: pa.Table, features: Mapping[str, FeatureSpec]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key in [*features, "timestamp", "frame_index", "episode_index", "index", "task_index"]:
        if key not in table.column_names or features.get(key, FeatureSpec("float32", (1,))).dtype == "image":
            continue
        col = table.column(key).combine_chunks()
        n = len(col)
        while pa.types.is_fixed_size_list(col.type):
            col = col.flatten()
        values = np.asarray(numpy_of(col), dtype=float).reshape(n, -1)
        out[key] = {"min": values.min(0).tolist(), "max": values.max(0).tolist(),
                    "mean": values.mean(0).tolist(), "std": values.std(0).tolist(), "count": [n]}
    return out
