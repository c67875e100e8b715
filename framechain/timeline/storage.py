"""A Timeline's tables as Parquet files in a directory, and back, losslessly; and the one way framechain reads
a Parquet file (:func:`read_parquet`).

Depth pixels are stored as float32 bytes in ``depth_pixels.parquet`` and image bytes in
``image_bytes.parquet``; both are read back lazily, row by row.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.parquet as pq

from framechain.timeline.columns import ColumnTable, arrow_array, numpy_of
from framechain.timeline.errors import TimelineError
from framechain.timeline.frames import VIDEO_ENCODING, DepthFrameTable, ImageFrameTable

_FORMAT = "framechain/timeline@1"


def write_tables(tables: Mapping[str, ColumnTable], metadata: Mapping[str, Any], directory: str | Path) -> None:
    """One Parquet file per table, the frames' pixels beside them, and ``timeline.json``."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    for name, table in tables.items():
        pq.write_table(table.to_arrow(), out / f"{name}.parquet")
    depth = tables["depth_frames"]
    assert isinstance(depth, DepthFrameTable)
    blobs = []
    for i in range(len(depth)):
        image = np.ascontiguousarray(depth.load(i), dtype=np.float32)
        expected = (int(depth.height[i]), int(depth.width[i]))
        if image.shape != expected:
            raise TimelineError(
                f"depth frame {i} ({depth.frame[i]} at {int(depth.stamp_ns[i])} ns) is {image.shape}, "
                f"its row says height x width {expected}"
            )
        blobs.append(image.tobytes())
    pq.write_table(pa.table({"pixels_f32": pa.array(blobs, type=pa.binary())}), out / "depth_pixels.parquet")
    images = tables["image_frames"]
    assert isinstance(images, ImageFrameTable)
    image_blobs = [b"" if str(images.encoding[i]) == VIDEO_ENCODING else bytes(images.load(i))
                   for i in range(len(images))]
    pq.write_table(pa.table({"bytes": pa.array(image_blobs, type=pa.binary())}), out / "image_bytes.parquet")
    meta = {"format": _FORMAT, "metadata": dict(metadata)}
    try:
        text = json.dumps(meta, indent=2, sort_keys=True, default=_json_scalar, allow_nan=True)
    except (TypeError, ValueError) as err:
        raise TimelineError(f"timeline metadata must be JSON-serialisable: {err}") from err
    (out / "timeline.json").write_text(text)


def _json_scalar(value: Any) -> Any:
    """NumPy scalars (an adapter's ``np.int64`` stamp) as the Python numbers they equal."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"object of type {type(value).__name__} is not JSON serialisable")


def read_tables(
    directory: str | Path, types: Mapping[str, type[ColumnTable]]
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Inverse of :func:`write_tables`: ``(tables by name, metadata)``; frame pixels load lazily."""
    src = Path(directory)
    header = src / "timeline.json"
    if not header.is_file():
        raise TimelineError(f"{src}: not a saved timeline (no timeline.json)")
    meta = json.loads(header.read_text())
    if meta.get("format") != _FORMAT:
        raise TimelineError(f"{src}: unknown timeline format {meta.get('format')!r}")
    tables: dict[str, Any] = {}
    for name, cls in types.items():
        if name == "image_frames" and not (src / f"{name}.parquet").is_file():
            continue  # saved before images were collected
        tables[name] = cls.from_arrow(read_parquet(src / f"{name}.parquet"))
    depth: DepthFrameTable = tables["depth_frames"]
    if len(depth):
        pixels = read_parquet(src / "depth_pixels.parquet").column("pixels_f32")
        heights, widths = depth.height.copy(), depth.width.copy()

        def load(i: int) -> npt.NDArray[np.float32]:
            raw = pixels[i].as_py()
            return np.frombuffer(raw, dtype=np.float32).reshape(int(heights[i]), int(widths[i]))

        tables["depth_frames"] = dataclasses.replace(depth, loader=load)
    images: ImageFrameTable | None = tables.get("image_frames")
    if images is not None and len(images):
        image_bytes = read_parquet(src / "image_bytes.parquet").column("bytes")

        def load_image(i: int) -> bytes:
            raw: bytes = image_bytes[i].as_py()
            return raw

        tables["image_frames"] = dataclasses.replace(images, loader=load_image)
    return tables, dict(meta["metadata"])


def read_parquet(path: str | Path, columns: list[str] | None = None, *, where_equal: tuple[str, int] | None = None
                 ) -> pa.Table:
    """A Parquet file's table (only ``columns``: None reads all), and with ``where_equal`` (a column and a value) only
    its rows holding that value, from the row groups whose statistics allow it (a LeRobot v3 data file holds many
    episodes). Read through :class:`pyarrow.parquet.ParquetFile`: ``pq.read_table`` goes through pyarrow.dataset,
    whose import brings pandas (0.15 s of every command, and its teardown at exit). Raises what pyarrow raises
    (OSError, ArrowException) for the caller to name the file."""
    wanted = None if columns is None or where_equal is None or where_equal[0] in columns \
        else [*columns, where_equal[0]]
    with pq.ParquetFile(path) as file:
        if where_equal is None:
            return file.read(columns=columns)
        name, value = where_equal
        metadata = file.metadata
        groups = [i for i in range(metadata.num_row_groups) if _may_hold(metadata.row_group(i), name, value)]
        table = file.read_row_groups(groups, columns=wanted or columns)
    if name not in table.column_names:
        raise pa.ArrowInvalid(f"no column {name!r}")
    table = table.filter(arrow_array(np.asarray(numpy_of(table.column(name)) == value)))
    return table.drop_columns([name]) if wanted else table


def _may_hold(group: pq.RowGroupMetaData, name: str, value: int) -> bool:
    """Whether a row group's statistics of column ``name`` allow ``value`` (True when it keeps none)."""
    for k in range(group.num_columns):
        column = group.column(k)
        if column.path_in_schema == name:
            stats = column.statistics
            if stats is None or not stats.has_min_max:
                return True
            return bool(stats.min <= value <= stats.max)
    return True
