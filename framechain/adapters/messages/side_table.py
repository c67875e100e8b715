"""Detections logged outside the bag: a CSV or Parquet side table.

Columns: ``stamp`` (integer nanoseconds, or float seconds; ``stamp_ns``/``stamp_s`` say which
explicitly), ``frame`` (or ``camera_frame``), ``u``, ``v``; optional ``depth`` (or ``depth_m``,
metres; empty/0 = sample the depth image), ``label``, ``score``, ``obs_id``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.errors import AdapterError
from framechain.timeline import numpy_of

if TYPE_CHECKING:
    import pyarrow as pa


def resolve_side_table(name: str, log_path: Path) -> Path:
    """The side table's path: as given, else beside the log (inside a bag directory, or next to it)."""
    p = Path(name).expanduser()
    if p.is_file() or p.is_absolute():
        return p
    candidates = [log_path / p] if log_path.is_dir() else []
    candidates.append(log_path.parent / p)
    return next((c for c in candidates if c.is_file()), candidates[-1])


def read_side_table(path: Path) -> dict[str, npt.NDArray[Any]]:
    """Columns stamp_ns, frame, u, v, depth_m, label, score, obs_id (strings for ids)."""
    table = _read_table(path)
    cols = {c.lower(): c for c in table.column_names}

    def col(*names: str) -> npt.NDArray[Any] | None:
        for n in names:
            if n in cols:
                return numpy_of(table.column(cols[n]))
        return None

    n = table.num_rows
    stamp_ns = col("stamp_ns")
    if stamp_ns is None:
        seconds = col("stamp_s")
        raw = col("stamp") if seconds is None else seconds
        if raw is None:
            raise AdapterError(path, f"detections side table lacks a stamp column (stamp, stamp_ns or stamp_s); "
                                     f"has {table.column_names}")
        if seconds is not None or raw.dtype.kind == "f":
            stamp_ns = np.rint(raw.astype(np.float64) * 1e9).astype(np.int64)
        else:
            stamp_ns = raw.astype(np.int64)
    frame = col("frame", "camera_frame", "frame_id")
    u, v = col("u"), col("v")
    missing = [name for name, c in (("frame", frame), ("u", u), ("v", v)) if c is None]
    if missing:
        raise AdapterError(path, f"detections side table lacks columns {missing}; has {table.column_names}")
    assert frame is not None
    assert u is not None
    assert v is not None
    depth = col("depth", "depth_m")
    depth_m = np.full(n, np.nan) if depth is None else np.asarray(depth, dtype=np.float64)
    depth_m = np.where(np.isfinite(depth_m) & (depth_m > 0), depth_m, np.nan)
    label = col("label", "class_id")
    score = col("score")
    obs_id = col("obs_id", "id")
    return {
        "stamp_ns": stamp_ns.astype(np.int64),
        "frame": np.asarray(frame, dtype=str),
        "u": np.asarray(u, dtype=np.float64),
        "v": np.asarray(v, dtype=np.float64),
        "depth_m": depth_m,
        "label": np.full(n, "") if label is None else np.asarray(label, dtype=str),
        "score": np.full(n, np.nan) if score is None else np.asarray(score, dtype=np.float64),
        "obs_id": np.full(n, "") if obs_id is None else np.asarray(obs_id).astype(str),
    }


def _read_table(path: Path) -> pa.Table:
    """The side table as Arrow: Parquet by its suffix, else CSV."""
    import pyarrow as pa

    if not path.is_file():
        raise AdapterError(path, "detections side table not found")
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            from framechain.timeline import read_parquet

            return read_parquet(path)
        import pyarrow.csv as pcsv

        return pcsv.read_csv(path)
    except (pa.ArrowInvalid, OSError) as err:
        raise AdapterError(path, f"detections side table cannot be read ({err})") from err
