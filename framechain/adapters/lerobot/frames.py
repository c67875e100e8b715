"""One episode's frames from its Parquet data file: the index columns checked against the episode's metadata,
the timestamps checked against ``frame_index / fps``, the columns asked for as arrays.

:meth:`framechain.adapters.lerobot.reader.DatasetReader.read` is the way in; this is what it does with the
episode's metadata and the dataset's features.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.parquet as pq

from framechain.adapters.lerobot.dataset_info import (
    TIMESTAMP_TOLERANCE_S,
    DatasetError,
    EpisodeFrames,
    EpisodeInfo,
    FeatureInfo,
    Layout,
)
from framechain.arrays import FloatArray, IntArray
from framechain.errors import one_line
from framechain.timeline import numpy_of, read_parquet

__all__ = ["read_episode_frames"]

#: Where a harmless inconsistency goes (the reader's notes; raised with ``strict=True``).
Note = Callable[[Path, str], None]


def read_episode_frames(
    ep: EpisodeInfo, columns: Sequence[str], *, features: Mapping[str, FeatureInfo], layout: Layout, fps: float,
    info_path: Path, note: Note,
) -> EpisodeFrames:
    """Episode ``ep``'s frames: timestamps, frame and global indices, and ``columns`` as arrays.

    Vector features come back as ``(T, *shape)``, scalars as ``(T,)``. Only the columns asked
    for (plus the index columns) are read from the Parquet file.
    """
    index, path = ep.index, ep.data_file
    table, present = _episode_table(ep, columns, features=features, layout=layout, info_path=info_path)
    n = table.num_rows
    global_index = (numpy_of(table.column("index")).astype(np.int64) if "index" in present
                    else np.arange(n, dtype=np.int64))
    if ep.from_index is not None and ep.to_index is not None and (
        ep.to_index - ep.from_index != n or int(global_index[0]) != ep.from_index
    ):
        raise DatasetError(path, f"episode {index} rows have index {global_index[0]}..{global_index[-1]} but "
                           f"the episodes parquet declares [{ep.from_index}, {ep.to_index})")
    if "frame_index" in present:
        frame_index = numpy_of(table.column("frame_index")).astype(np.int64)
        if not np.array_equal(frame_index, np.arange(n)):
            note(path, f"frame_index of episode {index} is not 0..{n - 1}")
    else:
        frame_index = global_index - global_index[0]
        note(path, "no frame_index column: frame indices derived from index")
    ts = _timestamps(table, path, index, frame_index, fps, note)
    out: dict[str, npt.NDArray[Any]] = {}
    for col in columns:
        arr = _column(table.column(col), path, col)
        feat = features.get(col)
        if feat is not None and feat.shape and feat.size > 1 and arr.ndim >= 2 and arr[0].size == feat.size:
            arr = arr.reshape((n, *feat.shape))
        out[col] = arr
    return EpisodeFrames(episode=ep, timestamp_s=ts, frame_index=frame_index, index=global_index,
                         columns=out)


def _episode_table(
    ep: EpisodeInfo, columns: Sequence[str], *, features: Mapping[str, FeatureInfo], layout: Layout, info_path: Path,
) -> tuple[pa.Table, set[str]]:
    """The episode's rows of its data file (the index columns and ``columns``), sorted by ``index`` and checked to
    be its rows, as many as its metadata declares; and the file's column names."""
    index, path = ep.index, ep.data_file
    if not path.is_file():
        raise DatasetError(path, f"data file of episode {index} is missing")
    try:
        schema = pq.read_schema(path)
    except (OSError, pa.ArrowException) as err:
        raise DatasetError(path, f"cannot read Parquet ({one_line(err)})") from err
    present = set(schema.names)
    for col in columns:
        if col in features and features[col].is_video:
            raise DatasetError(info_path, f"feature {col!r} is a video: it has no Parquet column")
        if col not in present:
            declared = "declared in info.json but " if col in features else ""
            raise DatasetError(path, f"column {col!r} is {declared}not in this file; it has {sorted(present)}")
    index_cols = [c for c in ("timestamp", "frame_index", "episode_index", "index") if c in present]
    read_cols = list(dict.fromkeys([*index_cols, *columns]))
    only = ("episode_index", index) if layout is Layout.V3 and "episode_index" in present else None
    try:
        table = read_parquet(path, read_cols, where_equal=only)
    except (OSError, pa.ArrowException) as err:
        raise DatasetError(path, f"cannot read Parquet ({one_line(err)})") from err
    if "index" in present:
        table = table.sort_by("index")
    n = table.num_rows
    if n == 0:
        raise DatasetError(path, f"holds no rows of episode {index}")
    if "episode_index" in present:
        eps = np.unique(numpy_of(table.column("episode_index")))
        if eps.tolist() != [index]:
            raise DatasetError(path, f"expected rows of episode {index}, found episode_index {eps.tolist()}")
    if n != ep.length:
        raise DatasetError(path, f"episode {index} has {n} rows but its metadata declares length {ep.length}")
    return table, present


def _timestamps(table: pa.Table, path: Path, index: int, frame_index: IntArray, fps: float, note: Note
                ) -> FloatArray:
    """The episode's timestamps (s), checked: finite, increasing, near ``frame_index / fps`` (else a note);
    derived from ``frame_index / fps`` when the file has none."""
    n = table.num_rows
    if "timestamp" not in table.column_names:
        note(path, "no timestamp column: timestamps derived from frame_index / fps")
        derived: FloatArray = frame_index / fps
        return derived
    ts: FloatArray = _column(table.column("timestamp"), path, "timestamp").astype(np.float64).reshape(n)
    if not np.isfinite(ts).all():
        raise DatasetError(path, f"episode {index} has non-finite timestamps")
    if n > 1 and not (np.diff(ts) > 0).all():
        k = int(np.flatnonzero(np.diff(ts) <= 0)[0])
        raise DatasetError(path, f"timestamps of episode {index} do not increase at frame {k + 1} "
                           f"({ts[k]:.6f} s then {ts[k + 1]:.6f} s)")
    dev = ts - frame_index / fps
    if np.abs(dev).max() > TIMESTAMP_TOLERANCE_S:
        if np.ptp(dev) <= TIMESTAMP_TOLERANCE_S:
            note(path, f"timestamps start at {ts[0]:.6g} s, not 0: offset {dev[0]:+.6g} s "
                 f"from frame_index / fps ({fps:g} fps)")
        else:
            note(path, f"timestamps depart from frame_index / fps by up to "
                 f"{np.abs(dev).max():.6g} s (variable rate)")
    return ts


def _column(col: pa.ChunkedArray, path: Path, name: str) -> npt.NDArray[Any]:
    """An Arrow column as NumPy: scalars (T,); lists and fixed-size lists (T, n) or (T, n, m)."""
    arr = col.combine_chunks()
    n = len(arr)
    shape: list[int] = [n]
    while pa.types.is_list(arr.type) or pa.types.is_fixed_size_list(arr.type) or pa.types.is_large_list(arr.type):
        if arr.null_count:
            raise DatasetError(path, f"column {name!r} has null rows")
        import pyarrow.compute as pc

        lengths = numpy_of(pc.list_value_length(arr))
        width = int(lengths[0]) if lengths.size else 0
        if lengths.size and not (lengths == width).all():
            raise DatasetError(path, f"column {name!r} holds lists of different lengths "
                               f"({int(lengths.min())}..{int(lengths.max())})")
        shape.append(width)
        arr = arr.flatten()
    if pa.types.is_struct(arr.type) or pa.types.is_binary(arr.type) or pa.types.is_string(arr.type):
        return np.asarray(arr.to_pylist(), dtype=object).reshape(shape)
    return numpy_of(arr).reshape(shape)  # nulls as NaN
