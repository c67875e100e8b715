"""LeRobot datasets on disk (v2.0, v2.1, v3.0) read with pyarrow alone: no lerobot, no torch.

Layouts (``meta/info.json`` in both; see REFERENCE.md section 4):

- v2.x: ``meta/episodes.jsonl`` (``episode_index``, ``tasks``, ``length``), one episode per data
  file ``data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet`` with
  ``episode_chunk = episode_index // chunks_size``; videos one mp4 per episode and key.
- v3.0: ``meta/episodes/chunk-*/file-*.parquet`` (one row per episode: ``length``,
  ``data/chunk_index``, ``data/file_index``, ``dataset_from_index``, ``dataset_to_index``,
  ``videos/<key>/...``), many episodes per data file ``data/chunk-{c:03d}/file-{f:03d}.parquet``;
  an episode's rows are those with its ``episode_index``.

Per-frame columns: ``timestamp`` (seconds from the episode start), ``frame_index`` (0..length-1),
``index`` (global), ``episode_index``, ``task_index``, and one column per non-video feature
(vectors as ``fixed_size_list`` or ``list``). Only the columns asked for are read.

Metadata that disagrees with the files is handled in two ways. What would make the frames read
wrong (an episode whose row count differs from its declared length, a data file missing or
holding another episode, timestamps that go backwards, names that do not fit a feature's shape)
raises :class:`DatasetError` naming the file and the inconsistency. What does not (a
``total_chunks`` that does not count the chunk folders, a declared video key with no files,
timestamps offset from ``frame_index / fps``) becomes a note on :attr:`DatasetReader.notes`, or
a :class:`DatasetError` with ``strict=True``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, TypedDict

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.parquet as pq

from framechain.adapters.errors import AdapterError
from framechain.arrays import FloatArray, IntArray

#: lerobot's default tolerance between a frame's timestamp and frame_index / fps.
TIMESTAMP_TOLERANCE_S = 1e-4
#: The per-frame columns lerobot adds to every dataset.
INDEX_COLUMNS = ("timestamp", "frame_index", "episode_index", "index", "task_index")

__all__ = [
    "INDEX_COLUMNS",
    "DatasetError",
    "DatasetReader",
    "EpisodeFrames",
    "EpisodeInfo",
    "FeatureInfo",
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


class DatasetReader:
    """A LeRobot dataset directory: its metadata, its episodes, one episode's columns at a time.

    Constructing it reads ``meta/info.json`` and the episode index (episodes.jsonl or the
    episodes parquet's ``episode_index`` column) and checks them against the files present.
    """

    def __init__(self, root: str | Path, *, strict: bool = False) -> None:
        self.root = Path(root)
        self.strict = strict
        self.notes: list[str] = []
        info_path = self.root / "meta" / "info.json"
        if not self.root.is_dir():
            raise DatasetError(self.root, "not a directory")
        if not info_path.is_file():
            raise DatasetError(info_path, "missing: not a LeRobot dataset (no meta/info.json)")
        try:
            raw = json.loads(info_path.read_text())
        except (OSError, ValueError) as err:
            raise DatasetError(info_path, f"cannot read as JSON ({err})") from err
        if not isinstance(raw, dict):
            raise DatasetError(info_path, "expected a JSON object")
        self._info_path = info_path
        self.info: InfoJson = raw  # type: ignore[assignment]
        self.version = str(raw.get("codebase_version", ""))
        if self.version.startswith("v2"):
            self.layout = Layout.V2
        elif self.version.startswith("v3"):
            self.layout = Layout.V3
        else:
            raise DatasetError(info_path, f"codebase_version {self.version!r} is not v2.x or v3.x")
        fps = raw.get("fps")
        if isinstance(fps, bool) or not isinstance(fps, int | float) or not fps > 0 or not math.isfinite(fps):
            raise DatasetError(info_path, f"fps must be a positive number, got {fps!r}")
        self.fps = float(fps)
        self.robot_type = raw.get("robot_type")
        feats = raw.get("features")
        if not isinstance(feats, dict) or not feats:
            raise DatasetError(info_path, "features is missing or empty")
        self.features: dict[str, FeatureInfo] = {k: self._feature(k, v) for k, v in feats.items()}
        self.chunks_size = int(raw.get("chunks_size") or 1000)
        data_path = raw.get("data_path")
        if not isinstance(data_path, str):
            raise DatasetError(info_path, "data_path template is missing")
        self.data_path = data_path
        video_path = raw.get("video_path")
        self.video_path = video_path if isinstance(video_path, str) else None
        self._episodes_v3: pa.Table | None = None
        if self.layout is Layout.V2:
            self._episodes_v2 = self._read_episodes_v2()
            self._episode_ids = sorted(self._episodes_v2)
        else:
            self._episode_ids = self._read_episode_ids_v3()
        self._check_totals()
        self._check_videos()

    # ------------------------------------------------------------------------------- metadata

    def note(self, path: str | Path, what: str) -> None:
        """Record a harmless inconsistency (raise it with ``strict=True``)."""
        if self.strict:
            raise DatasetError(path, what)
        text = f"{path}: {what}"
        if text not in self.notes:
            self.notes.append(text)

    def _feature(self, key: str, raw: Any) -> FeatureInfo:
        if not isinstance(raw, Mapping) or "dtype" not in raw:
            raise DatasetError(self._info_path, f"feature {key!r} has no dtype")
        shape_raw = raw.get("shape") or [1]
        try:
            shape = tuple(int(s) for s in shape_raw)
        except (TypeError, ValueError):
            raise DatasetError(
                self._info_path, f"feature {key!r} has shape {shape_raw!r}, not a list of ints"
            ) from None
        info = raw.get("info") or raw.get("video_info") or {}
        return FeatureInfo(key, str(raw["dtype"]), shape, flatten_names(raw.get("names")),
                           dict(info) if isinstance(info, Mapping) else {})

    def feature(self, key: str) -> FeatureInfo:
        try:
            return self.features[key]
        except KeyError:
            raise DatasetError(
                self._info_path, f"no feature {key!r}; features are {sorted(self.features)}"
            ) from None

    def names(self, key: str) -> tuple[str, ...]:
        """Element names of a vector feature (``key_0``... when info.json gives none)."""
        feat = self.feature(key)
        n = feat.size
        if feat.names is None:
            return tuple(f"{key}_{i}" for i in range(n))
        if len(feat.names) != n:
            raise DatasetError(
                self._info_path,
                f"feature {key!r} has shape {list(feat.shape)} ({n} values) but {len(feat.names)} names",
            )
        return feat.names

    @property
    def video_keys(self) -> list[str]:
        return [k for k, f in self.features.items() if f.is_video]

    def episodes(self) -> list[int]:
        """Episode indices, ascending."""
        return list(self._episode_ids)

    def lengths(self) -> dict[int, int]:
        """Declared frame count of every episode (episodes.jsonl or the episodes parquet)."""
        if self.layout is Layout.V2:
            return {e: int(row["length"]) for e, row in sorted(self._episodes_v2.items())}
        table = self._episodes_table_v3()
        pairs = zip(table.column("episode_index").to_pylist(), table.column("length").to_pylist(), strict=True)
        return {int(e): int(n) for e, n in sorted(pairs)}

    def _read_episodes_v2(self) -> dict[int, dict[str, Any]]:
        path = self.root / "meta" / "episodes.jsonl"
        if not path.is_file():
            raise DatasetError(path, "missing: a v2 dataset lists its episodes here")
        out: dict[int, dict[str, Any]] = {}
        for lineno, row in _jsonl(path, self.note):
            ep, length = _whole(row.get("episode_index")), _whole(row.get("length"))
            if ep is None or length is None or length < 0:
                self.note(path, f"line {lineno} lacks a whole episode_index or length; left out")
                continue
            if ep in out:
                self.note(path, f"line {lineno}: episode {ep} is listed twice; the first is kept")
                continue
            out[ep] = row
        if not out:
            raise DatasetError(path, "lists no episode that can be read")
        return out

    def _episodes_files_v3(self) -> list[Path]:
        folder = self.root / "meta" / "episodes"
        files = sorted(folder.glob("chunk-*/file-*.parquet"))
        if not files:
            raise DatasetError(folder, "no episodes parquet files (chunk-*/file-*.parquet): not a v3 dataset?")
        return files

    def _episodes_table_v3(self) -> pa.Table:
        """Every readable episodes parquet file as one table (read once); a file that cannot be read is a note
        and its episodes are left out, the others kept."""
        if self._episodes_v3 is not None:
            return self._episodes_v3
        folder = self.root / "meta" / "episodes"
        tables = []
        for path in self._episodes_files_v3():
            try:
                table = pq.read_table(path)
            except (OSError, pa.ArrowException) as err:
                self.note(path, f"cannot read ({_one_line(err)}); its episodes are left out")
                continue
            missing = [c for c in ("episode_index", "length", "data/chunk_index", "data/file_index")
                       if c not in table.column_names]
            if missing:
                self.note(path, f"lacks columns {missing}; its episodes are left out")
                continue
            tables.append(table)
        if not tables:
            raise DatasetError(folder, "no episodes parquet file can be read (see above): no episode is known")
        try:
            self._episodes_v3 = pa.concat_tables(tables, promote_options="permissive")
        except pa.ArrowException as err:
            raise DatasetError(folder, f"the episodes parquet files disagree on their columns ({_one_line(err)})") \
                from err
        return self._episodes_v3

    def _read_episode_ids_v3(self) -> list[int]:
        table = self._episodes_table_v3()
        ids = table.column("episode_index").to_numpy(zero_copy_only=False)
        if not np.isfinite(ids.astype(np.float64)).all():
            raise DatasetError(self.root / "meta" / "episodes", "an episode row has no episode_index")
        if np.unique(ids).size != ids.size:
            raise DatasetError(self.root / "meta" / "episodes", "an episode_index appears in two episode rows")
        return sorted(int(i) for i in ids)

    def _check_totals(self) -> None:
        info = self.info
        total = info.get("total_episodes")
        if isinstance(total, int) and total != len(self._episode_ids):
            self.note(self._info_path, f"total_episodes is {total} but {len(self._episode_ids)} episodes are listed")
        if self.layout is Layout.V2:
            frames = sum(int(r["length"]) for r in self._episodes_v2.values())
            if isinstance(info.get("total_frames"), int) and info["total_frames"] != frames:
                self.note(self._info_path, f"total_frames is {info['total_frames']} but the episodes' lengths "
                          f"add up to {frames}")
            chunks = sorted(p.name for p in (self.root / "data").glob("chunk-*") if p.is_dir())
            declared = info.get("total_chunks")
            if isinstance(declared, int) and declared != len(chunks):
                self.note(self._info_path, f"total_chunks is {declared} but data/ holds {len(chunks)} chunk folders "
                          f"({', '.join(chunks) or 'none'})")
        splits = info.get("splits") or {}
        for split, span in splits.items() if isinstance(splits, Mapping) else ():
            try:
                lo, hi = (int(x) for x in str(span).split(":"))
            except ValueError:
                self.note(self._info_path, f"split {split!r} is {span!r}, not 'start:stop'")
                continue
            if hi > len(self._episode_ids) or lo < 0:
                self.note(self._info_path, f"split {split!r} is {span!r} but the dataset has "
                          f"{len(self._episode_ids)} episodes")

    def _check_videos(self) -> None:
        for key in self.video_keys:
            present = any((self.root / "videos").glob(f"**/{key}/*.mp4")) or any(
                (self.root / "videos" / key).glob("chunk-*/*.mp4")
            )
            if not present:
                self.note(self._info_path, f"video feature {key!r} is declared but no video files exist for it "
                          f"under {self.root / 'videos'}")

    # ------------------------------------------------------------------------------- episodes

    def episode(self, index: int) -> EpisodeInfo:
        """Metadata of one episode (its data file, length, tasks, videos)."""
        self._check_known(index)
        if self.layout is Layout.V2:
            return self._episode_v2(index)
        return self._episode_v3(index)

    def _check_known(self, index: int) -> None:
        if index not in self._episode_ids:
            ids = self._episode_ids
            shown = f"{ids[0]}..{ids[-1]}" if ids == list(range(ids[0], ids[-1] + 1)) else str(ids)
            raise DatasetError(self.root, f"no episode {index}; episodes are {shown}")

    def episode_patterns(self, index: int) -> list[str]:
        """Where episode ``index``'s data file and videos are, relative to the root, as glob patterns (a
        variable LeRobot does not define matches anything), whether or not the files are on disk yet: what
        to fetch of a dataset whose metadata alone is here."""
        self._check_known(index)
        if self.layout is Layout.V2:
            chunk = index // self.chunks_size
            data = {"episode_chunk": chunk, "chunk_index": chunk, "episode_index": index}
            videos = {key: {**data, "video_key": key} for key in self.video_keys}
        else:
            row = self._episode_row_v3(index)
            data = {"chunk_index": int(row["data/chunk_index"]), "file_index": int(row["data/file_index"]),
                    "episode_index": index}
            videos = {key: {"video_key": key, "chunk_index": int(c), "file_index": int(f), "episode_index": index}
                      for key in self.video_keys
                      if (c := row.get(f"videos/{key}/chunk_index")) is not None
                      and (f := row.get(f"videos/{key}/file_index")) is not None}
        patterns = [self._pattern("data_path", self.data_path, data)[0]]
        if self.video_path is not None:
            patterns += [self._pattern("video_path", self.video_path, fields)[0] for fields in videos.values()]
        return patterns

    def _episode_v2(self, index: int) -> EpisodeInfo:
        row = self._episodes_v2[index]
        chunk = index // self.chunks_size
        fields = {"episode_chunk": chunk, "chunk_index": chunk, "episode_index": index}
        data_file = self._fill("data_path", self.data_path, fields)
        videos: dict[str, Path] = {}
        if self.video_path is not None:
            for key in self.video_keys:
                vf = self._fill_if_found("video_path", self.video_path, {**fields, "video_key": key})
                if vf is not None and vf.is_file():
                    videos[key] = vf
        tasks = row.get("tasks") or []
        return EpisodeInfo(index=index, length=int(row["length"]), tasks=tuple(str(t) for t in tasks),
                           data_file=data_file, video_files=videos, video_from_s=dict.fromkeys(videos, 0.0))

    def _episode_v3(self, index: int) -> EpisodeInfo:
        row = self._episode_row_v3(index)
        fields = {"chunk_index": int(row["data/chunk_index"]), "file_index": int(row["data/file_index"]),
                  "episode_index": index}
        data_file = self._fill("data_path", self.data_path, fields)
        videos: dict[str, Path] = {}
        video_from: dict[str, float] = {}
        video_to: dict[str, float] = {}
        for key in self.video_keys:
            c, f = row.get(f"videos/{key}/chunk_index"), row.get(f"videos/{key}/file_index")
            if c is None or f is None or self.video_path is None:
                continue
            vf = self._fill_if_found("video_path", self.video_path, {"video_key": key, "chunk_index": int(c),
                                                                      "file_index": int(f), "episode_index": index})
            if vf is not None and vf.is_file():
                videos[key] = vf
                video_from[key] = float(row.get(f"videos/{key}/from_timestamp") or 0.0)
                if row.get(f"videos/{key}/to_timestamp") is not None:
                    video_to[key] = float(row[f"videos/{key}/to_timestamp"])
        tasks = row.get("tasks") or []
        return EpisodeInfo(
            index=index, length=int(row["length"]), tasks=tuple(str(t) for t in tasks), data_file=data_file,
            from_index=None if row.get("dataset_from_index") is None else int(row["dataset_from_index"]),
            to_index=None if row.get("dataset_to_index") is None else int(row["dataset_to_index"]),
            video_files=videos, video_from_s=video_from, video_to_s=video_to,
        )

    def _episode_row_v3(self, index: int) -> dict[str, Any]:
        """Episode ``index``'s row of the episodes parquet files: its length, tasks, data file and videos."""
        episodes = self._episodes_table_v3()
        names = set(episodes.column_names)
        wanted = ["episode_index", "length", "tasks", "data/chunk_index", "data/file_index",
                  "dataset_from_index", "dataset_to_index"]
        for key in self.video_keys:
            wanted += [f"videos/{key}/chunk_index", f"videos/{key}/file_index", f"videos/{key}/from_timestamp",
                       f"videos/{key}/to_timestamp"]
        where = self.root / "meta" / "episodes"
        import pyarrow.compute as pc  # here: its import costs a command reading a log 40 ms

        table = episodes.select([c for c in wanted if c in names]).filter(pc.equal(episodes["episode_index"], index))
        if table.num_rows == 0:
            raise DatasetError(where, f"episode {index} has no row in the episodes parquet files that could be read")
        row = {k: v[0] for k, v in table.to_pydict().items()}
        if any(row.get(c) is None for c in ("length", "data/chunk_index", "data/file_index")):
            raise DatasetError(where, f"episode {index}'s row lacks its length or data file")
        return row

    def _fill(self, key: str, template: str, fields: Mapping[str, Any]) -> Path:
        """``template`` (info.json's ``key``) filled with ``fields``; a variable LeRobot does not define (a
        recorder's own, ``{robot_id}``) is matched against the files on disk (with a note), which must be one."""
        path = self._fill_if_found(key, template, fields, required=True)
        assert path is not None  # required: raised otherwise
        return path

    def _fill_if_found(self, key: str, template: str, fields: Mapping[str, Any], *,
                       required: bool = False) -> Path | None:
        """:meth:`_fill`, None when a template with a variable LeRobot does not define matches no single file."""
        pattern, unknown = self._pattern(key, template, fields)
        if not unknown:
            return self.root / template.format(**fields)
        matches = sorted(self.root.glob(pattern))
        if len(matches) == 1:
            self.note(self._info_path, f"{key} uses {', '.join('{' + u + '}' for u in unknown)}, which LeRobot does "
                      "not define; matched by the other fields")
            return matches[0]
        if not required:
            return None
        found = "no file" if not matches else f"{len(matches)} files ({matches[0].name}, ...)"
        raise DatasetError(self._info_path, f"{key} {template!r} uses {', '.join(unknown)}, which LeRobot does not "
                           f"define, and {found} on disk match{'es' if len(matches) == 1 else ''} the rest")

    def _pattern(self, key: str, template: str, fields: Mapping[str, Any]) -> tuple[str, list[str]]:
        """``template`` filled with ``fields`` as a glob pattern relative to the root (a variable LeRobot does not
        define, a recorder's own ``{robot_id}``, matches anything), and those variables."""
        import glob
        import string

        try:
            parsed = list(string.Formatter().parse(template))
        except ValueError as err:
            raise DatasetError(self._info_path, f"{key} {template!r} is not a path template ({err})") from err
        unknown = sorted({name for _text, name, _spec, _conv in parsed if name and name not in fields})
        try:
            return "".join(glob.escape(text) + ("" if name is None else "*" if name in unknown
                                                else glob.escape(format(fields[name], spec or "")))
                           for text, name, spec, _conv in parsed), unknown
        except (KeyError, IndexError, ValueError) as err:
            raise DatasetError(self._info_path, f"{key} {template!r} cannot be filled ({err})") from err

    def read(self, index: int, columns: Sequence[str] = ()) -> EpisodeFrames:
        """One episode's frames: timestamps, frame and global indices, and ``columns`` as arrays.

        Vector features come back as ``(T, *shape)``, scalars as ``(T,)``. Only the columns asked
        for (plus the index columns) are read from the Parquet file.
        """
        ep = self.episode(index)
        path = ep.data_file
        if not path.is_file():
            raise DatasetError(path, f"data file of episode {index} is missing")
        try:
            schema = pq.read_schema(path)
        except (OSError, pa.ArrowException) as err:
            raise DatasetError(path, f"cannot read Parquet ({_one_line(err)})") from err
        present = set(schema.names)
        for col in columns:
            if col in self.features and self.features[col].is_video:
                raise DatasetError(self._info_path, f"feature {col!r} is a video: it has no Parquet column")
            if col not in present:
                declared = "declared in info.json but " if col in self.features else ""
                raise DatasetError(path, f"column {col!r} is {declared}not in this file; it has {sorted(present)}")
        index_cols = [c for c in ("timestamp", "frame_index", "episode_index", "index") if c in present]
        read_cols = list(dict.fromkeys([*index_cols, *columns]))
        filters = [("episode_index", "=", index)] if self.layout is Layout.V3 and "episode_index" in present else None
        try:
            table = pq.read_table(path, columns=read_cols, filters=filters)
        except (OSError, pa.ArrowException) as err:
            raise DatasetError(path, f"cannot read Parquet ({_one_line(err)})") from err
        if "index" in present:
            table = table.sort_by("index")
        n = table.num_rows
        if n == 0:
            raise DatasetError(path, f"holds no rows of episode {index}")
        if "episode_index" in present:
            eps = np.unique(table.column("episode_index").to_numpy())
            if eps.tolist() != [index]:
                raise DatasetError(path, f"expected rows of episode {index}, found episode_index {eps.tolist()}")
        if n != ep.length:
            raise DatasetError(path, f"episode {index} has {n} rows but its metadata declares length {ep.length}")
        global_index = (table.column("index").to_numpy().astype(np.int64) if "index" in present
                        else np.arange(n, dtype=np.int64))
        if ep.from_index is not None and ep.to_index is not None and (
            ep.to_index - ep.from_index != n or int(global_index[0]) != ep.from_index
        ):
            raise DatasetError(path, f"episode {index} rows have index {global_index[0]}..{global_index[-1]} but "
                               f"the episodes parquet declares [{ep.from_index}, {ep.to_index})")
        if "frame_index" in present:
            frame_index = table.column("frame_index").to_numpy().astype(np.int64)
            if not np.array_equal(frame_index, np.arange(n)):
                self.note(path, f"frame_index of episode {index} is not 0..{n - 1}")
        else:
            frame_index = global_index - global_index[0]
            self.note(path, "no frame_index column: frame indices derived from index")
        ts = self._timestamps(table, path, index, frame_index)
        out: dict[str, npt.NDArray[Any]] = {}
        for col in columns:
            arr = _column(table.column(col), path, col)
            feat = self.features.get(col)
            if feat is not None and feat.shape and feat.size > 1 and arr.ndim >= 2 and arr[0].size == feat.size:
                arr = arr.reshape((n, *feat.shape))
            out[col] = arr
        return EpisodeFrames(episode=ep, timestamp_s=ts, frame_index=frame_index, index=global_index,
                             columns=out)

    def _timestamps(self, table: pa.Table, path: Path, index: int, frame_index: IntArray) -> FloatArray:
        """The episode's timestamps (s), checked: finite, increasing, near ``frame_index / fps`` (else a note);
        derived from ``frame_index / fps`` when the file has none."""
        n = table.num_rows
        if "timestamp" not in table.column_names:
            self.note(path, "no timestamp column: timestamps derived from frame_index / fps")
            derived: FloatArray = frame_index / self.fps
            return derived
        ts: FloatArray = _column(table.column("timestamp"), path, "timestamp").astype(np.float64).reshape(n)
        if not np.isfinite(ts).all():
            raise DatasetError(path, f"episode {index} has non-finite timestamps")
        if n > 1 and not (np.diff(ts) > 0).all():
            k = int(np.flatnonzero(np.diff(ts) <= 0)[0])
            raise DatasetError(path, f"timestamps of episode {index} do not increase at frame {k + 1} "
                               f"({ts[k]:.6f} s then {ts[k + 1]:.6f} s)")
        dev = ts - frame_index / self.fps
        if np.abs(dev).max() > TIMESTAMP_TOLERANCE_S:
            if np.ptp(dev) <= TIMESTAMP_TOLERANCE_S:
                self.note(path, f"timestamps start at {ts[0]:.6g} s, not 0: offset {dev[0]:+.6g} s "
                          f"from frame_index / fps ({self.fps:g} fps)")
            else:
                self.note(path, f"timestamps depart from frame_index / fps by up to "
                          f"{np.abs(dev).max():.6g} s (variable rate)")
        return ts


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


def _whole(value: Any) -> int | None:
    """``value`` as an int when it is a finite whole number (JSON may write 12 as 12.0), else None."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return int(value) if float(value).is_integer() else None


def _jsonl(path: Path, note: Callable[[Path, str], None]) -> list[tuple[int, dict[str, Any]]]:
    """(line number, object) of each line that is a JSON object; every other line is a note (a cut file
    loses its last line, not its episodes)."""
    rows: list[tuple[int, dict[str, Any]]] = []
    try:
        lines = path.read_bytes().decode("utf-8", errors="replace").splitlines()
    except OSError as err:
        raise DatasetError(path, f"cannot read ({err.strerror})") from err
    for lineno, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except ValueError as err:
            note(path, f"line {lineno} is not JSON ({err}); left out")
            continue
        if not isinstance(row, dict):
            note(path, f"line {lineno} is not a JSON object; left out")
            continue
        rows.append((lineno, row))
    return rows


def _column(col: pa.ChunkedArray, path: Path, name: str) -> npt.NDArray[Any]:
    """An Arrow column as NumPy: scalars (T,); lists and fixed-size lists (T, n) or (T, n, m)."""
    arr = col.combine_chunks()
    n = len(arr)
    shape: list[int] = [n]
    while pa.types.is_list(arr.type) or pa.types.is_fixed_size_list(arr.type) or pa.types.is_large_list(arr.type):
        if arr.null_count:
            raise DatasetError(path, f"column {name!r} has null rows")
        import pyarrow.compute as pc

        lengths = pc.list_value_length(arr).to_numpy(zero_copy_only=False)
        width = int(lengths[0]) if lengths.size else 0
        if lengths.size and not (lengths == width).all():
            raise DatasetError(path, f"column {name!r} holds lists of different lengths "
                               f"({int(lengths.min())}..{int(lengths.max())})")
        shape.append(width)
        arr = arr.flatten()
    if pa.types.is_struct(arr.type) or pa.types.is_binary(arr.type) or pa.types.is_string(arr.type):
        return np.asarray(arr.to_pylist(), dtype=object).reshape(shape)
    if arr.null_count and (pa.types.is_floating(arr.type) or pa.types.is_integer(arr.type)):
        arr = arr.cast(pa.float64()).fill_null(math.nan)
    values = arr.to_numpy(zero_copy_only=False)
    return np.asarray(values).reshape(shape)
