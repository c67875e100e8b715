"""An episode's detections: per-frame features (``[u, v]`` or ``[u, v, depth_m]``), side tables (Parquet or
CSV, matched to the episode's rows by frame index or timestamp), and markers found in the chain camera's frames.
Each is stamped with its camera's time of the frame; its log time is the frame's row time."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from framechain.adapters.lerobot.dataset_info import DatasetError, EpisodeFrames
from framechain.adapters.lerobot.markers import video_markers
from framechain.arrays import IntArray, StrArray
from framechain.config.chain_cameras import MarkerSpec
from framechain.config.robot import DetectionSource, RobotConfig, RobotConfigError
from framechain.timeline import CameraTable, ImageFrameTable, ObservationTable, numpy_of, read_parquet

__all__ = ["episode_observations", "with_markers"]


def _read_side_table(path: Path) -> pa.Table:
    if not path.is_file():
        raise DatasetError(path, "detections table not found")
    try:
        if path.suffix.lower() == ".csv":
            return pacsv.read_csv(path)
        return read_parquet(path)
    except (OSError, pa.ArrowInvalid) as err:
        raise DatasetError(path, f"cannot read detections table ({err})") from err


def _pick(table: pa.Table, names: Sequence[str]) -> str | None:
    return next((n for n in names if n in table.column_names), None)


def episode_observations(
    sources: Sequence[DetectionSource], cfg: RobotConfig, frames: EpisodeFrames, cam_ns: Mapping[str, IntArray],
    state_ns: IntArray, episode: int, dataset: Path,
) -> ObservationTable:
    parts: list[dict[str, Any]] = []
    n_frames = len(frames)
    for src in sources:
        if src.feature is not None:
            assert src.camera is not None
            arr = np.asarray(frames.columns[src.feature], dtype=float).reshape(n_frames, -1)
            if arr.shape[1] not in (2, 3):
                raise DatasetError(dataset, f"detection feature {src.feature!r} has {arr.shape[1]} values per "
                                   "frame; expected [u, v] or [u, v, depth_m]")
            rows = np.flatnonzero(np.isfinite(arr[:, 0]) & np.isfinite(arr[:, 1]))
            parts.append({
                "camera": np.full(rows.size, src.camera), "stamp": cam_ns[src.camera][rows],
                "log": state_ns[rows], "u": arr[rows, 0], "v": arr[rows, 1],
                "depth": arr[rows, 2] if arr.shape[1] == 3 else np.full(rows.size, np.nan),
                "label": np.full(rows.size, src.camera), "score": np.full(rows.size, np.nan),
                "source": f"{dataset.name}:{src.feature}",
            })
            continue
        assert src.table is not None
        parts.append(_table_observations(src, cfg, frames, cam_ns, state_ns, episode))
    if not parts:
        return ObservationTable.empty()
    counts = [len(p["u"]) for p in parts]
    total = sum(counts)
    cam = np.concatenate([p["camera"] for p in parts]).astype(str)
    frame = np.array([cfg.cameras[c].optical_frame for c in cam], dtype=str) if total else np.array([], dtype=str)
    return ObservationTable(
        obs_id=np.arange(total, dtype=np.int64),
        stamp_ns=np.concatenate([p["stamp"] for p in parts]).astype(np.int64),
        log_time_ns=np.concatenate([p["log"] for p in parts]).astype(np.int64),
        camera_frame=frame,
        u=np.concatenate([p["u"] for p in parts]),
        v=np.concatenate([p["v"] for p in parts]),
        depth_m=np.concatenate([p["depth"] for p in parts]),
        label=np.concatenate([p["label"] for p in parts]).astype(str),
        score=np.concatenate([p["score"] for p in parts]),
        source=np.concatenate([np.full(c, p["source"]) for c, p in zip(counts, parts, strict=True)]).astype(str),
    )


def _table_observations(
    src: DetectionSource, cfg: RobotConfig, frames: EpisodeFrames, cam_ns: Mapping[str, IntArray],
    state_ns: IntArray, episode: int,
) -> dict[str, Any]:
    """The detections of a side table (Parquet or CSV) on this episode's rows."""
    assert src.table is not None
    path = src.table
    table = _read_side_table(path)
    for required in ("u", "v"):
        if required not in table.column_names:
            raise DatasetError(path, f"detections table has no {required!r} column; it has {table.column_names}")
    ep_col = _pick(table, ("episode_index", "episode"))
    if ep_col is not None:
        import pyarrow.compute as pc  # here: its import costs a command reading a log 40 ms

        table = table.filter(pc.equal(table.column(ep_col), episode))
    n = table.num_rows
    cams = _table_cameras(table, src, cfg, path)
    stamp, log = _table_stamps(table, cams, frames, cam_ns, state_ns, episode, path)
    depth_col = _pick(table, ("depth_m", "depth"))
    depth = (np.asarray(numpy_of(table.column(depth_col)), dtype=float)
             if depth_col is not None else np.full(n, np.nan))
    label = (np.asarray(table.column("label").to_pylist(), dtype=str) if "label" in table.column_names
             else cams.copy())
    score = (np.asarray(numpy_of(table.column("score")), dtype=float)
             if "score" in table.column_names else np.full(n, np.nan))
    return {
        "camera": cams, "stamp": stamp, "log": log,
        "u": np.asarray(numpy_of(table.column("u")), dtype=float),
        "v": np.asarray(numpy_of(table.column("v")), dtype=float),
        "depth": depth, "label": label, "score": score, "source": str(path),
    }


def _table_cameras(table: pa.Table, src: DetectionSource, cfg: RobotConfig, path: Path) -> StrArray:
    """Each detection's camera: the table's camera column, else the source's (or robot.yaml's only) camera."""
    n = table.num_rows
    cam_col = _pick(table, ("camera", "camera_name"))
    if cam_col is not None:
        cams = np.asarray(table.column(cam_col).to_pylist(), dtype=str)
    elif src.camera is not None or len(cfg.cameras) == 1:
        cams = np.full(n, src.camera or next(iter(cfg.cameras)))
    else:
        raise DatasetError(path, f"detections table has no camera column and robot.yaml has several cameras "
                           f"{sorted(cfg.cameras)}")
    unknown = sorted(set(cams.tolist()) - set(cfg.cameras))
    if unknown:
        raise DatasetError(path, f"detections name cameras {unknown} that robot.yaml does not calibrate "
                           f"(cameras: {sorted(cfg.cameras)})")
    return cams


def _table_stamps(
    table: pa.Table, cams: StrArray, frames: EpisodeFrames, cam_ns: Mapping[str, IntArray], state_ns: IntArray,
    episode: int, path: Path,
) -> tuple[IntArray, IntArray]:
    """Each detection's camera stamp and its row's time (the state's): by its frame index (stamped with its
    camera's time of that frame), else by its timestamp (the nearest row's)."""
    n = table.num_rows
    frame_col = _pick(table, ("frame_index",))
    ts_col = _pick(table, ("timestamp", "timestamp_s"))
    stamp = np.zeros(n, dtype=np.int64)
    log = np.zeros(n, dtype=np.int64)
    if frame_col is not None:
        fi = numpy_of(table.column(frame_col))
        if fi.size and (fi.dtype.kind not in "iu" or fi.min() < 0 or fi.max() >= len(frames)):
            raise DatasetError(path, f"frame_index must be integers in 0..{len(frames) - 1} for episode {episode}")
        fi = fi.astype(np.int64)
        for name in np.unique(cams):
            sel = cams == name
            stamp[sel] = cam_ns[str(name)][fi[sel]]
        log = state_ns[fi]
    elif ts_col is not None:
        ts = np.asarray(numpy_of(table.column(ts_col)), dtype=float)
        stamp = np.round(ts * 1e9).astype(np.int64)
        nearest = np.clip(np.searchsorted(state_ns, stamp), 0, len(frames) - 1)
        prev = np.clip(nearest - 1, 0, len(frames) - 1)
        nearest = np.where(np.abs(state_ns[prev] - stamp) <= np.abs(state_ns[nearest] - stamp), prev, nearest)
        log = state_ns[nearest]
    else:
        raise DatasetError(path, "detections table needs a frame_index or a timestamp column (seconds)")
    return stamp, log


def with_markers(observations: ObservationTable, images: ImageFrameTable, cameras: CameraTable, cfg: RobotConfig,
                 spec: MarkerSpec, metadata: dict[str, Any]) -> ObservationTable:
    """The markers in the chain camera's frames added as observations (their corners in the metadata)."""
    name = cfg.chain_camera or next((n for n, c in cfg.cameras.items() if c.video_key is not None), None)
    cam = cfg.cameras.get(name or "")
    if cam is None or cam.video_key is None:
        raise RobotConfigError(cfg.source, "evidence.markers are searched in the chain camera's frames: give it a "
                               "video_key")
    found = video_markers(images, cameras, cam.optical_frame, spec, source=cam.video_key)
    metadata["notes"] = [*metadata["notes"], *found.notes]
    r = found.resolved
    first = len(observations)
    table = ObservationTable(
        obs_id=np.arange(first, first + r.stamp_ns.size, dtype=np.int64), stamp_ns=r.stamp_ns,
        log_time_ns=r.log_time_ns, camera_frame=r.camera_frame, u=r.u, v=r.v, depth_m=r.depth_m, label=r.label,
        score=r.score, source=r.source)
    side = dict(r.side)
    position = np.searchsorted(r.detection_index, np.asarray(side.pop("detection"), dtype=np.int64))
    metadata["fiducials"] = {"counts": r.counts, "corners": {"obs_id": (first + position).tolist(), **side}}
    return ObservationTable.concat([observations, table])
