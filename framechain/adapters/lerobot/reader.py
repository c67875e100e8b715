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
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from framechain.adapters.lerobot.dataset_info import (
    INDEX_COLUMNS,
    DatasetError,
    EpisodeFrames,
    EpisodeInfo,
    FeatureInfo,
    InfoJson,
    Layout,
    flatten_names,
    is_lerobot_dataset,
)
from framechain.adapters.lerobot.frames import read_episode_frames
from framechain.errors import one_line
from framechain.timeline import numpy_of, read_parquet

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
        self._episode_positions_v3: dict[int, int] | None = None
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
                table = read_parquet(path)
            except (OSError, pa.ArrowException) as err:
                self.note(path, f"cannot read ({one_line(err)}); its episodes are left out")
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
            raise DatasetError(folder, f"the episodes parquet files disagree on their columns ({one_line(err)})") \
                from err
        return self._episodes_v3

    def _read_episode_ids_v3(self) -> list[int]:
        table = self._episodes_table_v3()
        ids = numpy_of(table.column("episode_index"))
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
        missing: dict[str, Path] = {}
        if self.video_path is not None:
            for key in self.video_keys:
                vf = self._video_file({**fields, "video_key": key})
                if vf.is_file():
                    videos[key] = vf
                else:
                    missing[key] = vf
        tasks = row.get("tasks") or []
        return EpisodeInfo(index=index, length=int(row["length"]), tasks=tuple(str(t) for t in tasks),
                           data_file=data_file, video_files=videos, video_from_s=dict.fromkeys(videos, 0.0),
                           missing_videos=missing)

    def _episode_v3(self, index: int) -> EpisodeInfo:
        row = self._episode_row_v3(index)
        fields = {"chunk_index": int(row["data/chunk_index"]), "file_index": int(row["data/file_index"]),
                  "episode_index": index}
        data_file = self._fill("data_path", self.data_path, fields)
        videos: dict[str, Path] = {}
        video_from: dict[str, float] = {}
        video_to: dict[str, float] = {}
        missing: dict[str, Path] = {}
        for key in self.video_keys:
            c, f = row.get(f"videos/{key}/chunk_index"), row.get(f"videos/{key}/file_index")
            if c is None or f is None or self.video_path is None:
                continue
            vf = self._video_file({"video_key": key, "chunk_index": int(c), "file_index": int(f),
                                   "episode_index": index})
            if not vf.is_file():
                missing[key] = vf
            else:
                videos[key] = vf
                video_from[key] = float(row.get(f"videos/{key}/from_timestamp") or 0.0)
                if row.get(f"videos/{key}/to_timestamp") is not None:
                    video_to[key] = float(row[f"videos/{key}/to_timestamp"])
        tasks = row.get("tasks") or []
        return EpisodeInfo(
            index=index, length=int(row["length"]), tasks=tuple(str(t) for t in tasks), data_file=data_file,
            from_index=None if row.get("dataset_from_index") is None else int(row["dataset_from_index"]),
            to_index=None if row.get("dataset_to_index") is None else int(row["dataset_to_index"]),
            video_files=videos, video_from_s=video_from, video_to_s=video_to, missing_videos=missing,
        )

    def _video_file(self, fields: Mapping[str, Any]) -> Path:
        """Where ``video_path`` filled with ``fields`` points: the file, or (a template with a variable LeRobot does not
        define that matches no single file) the glob pattern it was matched with."""
        assert self.video_path is not None
        found = self._fill_if_found("video_path", self.video_path, fields)
        return found if found is not None else self.root / self._pattern("video_path", self.video_path, fields)[0]

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
        if self._episode_positions_v3 is None:  # one pass, not one filter of the whole table per episode
            indexes = episodes["episode_index"].to_pylist()
            self._episode_positions_v3 = {}
            for at, value in enumerate(indexes):
                if value is not None:
                    self._episode_positions_v3.setdefault(int(value), at)
        position = self._episode_positions_v3.get(index)
        table = episodes.select([c for c in wanted if c in names])
        table = table.slice(position, 1) if position is not None else table.slice(0, 0)
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
        return read_episode_frames(self.episode(index), columns, features=self.features, layout=self.layout,
                                   fps=self.fps, info_path=self._info_path, note=self.note)


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
