"""An episode's camera frames: the rows of a video paired with its frames by the video's clock (not decoded),
the image bytes an ``image`` feature stores in the Parquet, and depth arrays stored as a feature."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import numpy.typing as npt

from framechain.adapters.lerobot.clock import (
    VIDEO_REFERENCE_NUDGE_NS,
    VideoClock,
    episode_frame_times_s,
    video_clock,
)
from framechain.adapters.lerobot.dataset_info import DatasetError, EpisodeFrames
from framechain.arrays import IntArray
from framechain.config.calibration import CameraCalibration
from framechain.config.robot import RobotConfig
from framechain.timeline import DepthFrameTable, ImageFrameTable
from framechain.timeline.frames import VIDEO_ENCODING

__all__ = ["camera_frames", "depth_frames", "episode_clock"]


def camera_frames(
    cfg: RobotConfig, frames: EpisodeFrames, cam_ns: Mapping[str, IntArray], state_ns: IntArray, fps: float,
    root: Path,
) -> tuple[ImageFrameTable, dict[str, VideoClock]]:
    """Every camera's frames of the episode (its video's, or the image bytes stored in the Parquet) and each
    video's clock, by camera name."""
    clocks = {cam.name: episode_clock(cam.video_key, frames, fps, cam.timing.pairing) for cam in cfg.cameras.values()
              if cam.video_key is not None and cam.video_key in frames.episode.video_files}
    images = ImageFrameTable.concat([
        *(_video_frames(cam, frames, cam_ns[cam.name], state_ns, clocks[cam.name]) for cam in cfg.cameras.values()
          if cam.name in clocks),
        *(_stored_frames(cam, frames, cam_ns[cam.name], state_ns, root) for cam in cfg.cameras.values()
          if cam.video_key is not None and cam.video_key in frames.columns),
    ])
    return images, clocks


def depth_frames(
    cam: CameraCalibration, frames: EpisodeFrames, cam_ns: IntArray, state_ns: IntArray
) -> DepthFrameTable:
    """One row per frame of ``cam``'s depth feature (height, width), scaled to metres when a frame is loaded."""
    assert cam.depth is not None
    images = np.asarray(frames.columns[cam.depth.feature])
    if images.ndim != 3:
        raise DatasetError(frames.episode.data_file, f"depth feature {cam.depth.feature!r} has shape "
                           f"{list(images.shape[1:])} per frame; expected (height, width)")
    n, h, w = images.shape
    scale = cam.depth.scale_m
    encoding = "32FC1" if images.dtype.kind == "f" else f"{images.dtype.itemsize * 8}UC1"

    def load(i: int) -> npt.NDArray[np.float32]:
        out: npt.NDArray[np.float32] = (images[i].astype(np.float64) * scale).astype(np.float32)
        return out

    return DepthFrameTable(
        frame=np.full(n, cam.optical_frame), stamp_ns=cam_ns, log_time_ns=state_ns, width=np.full(n, w),
        height=np.full(n, h), encoding=np.full(n, encoding), source=np.full(n, cam.depth.feature), loader=load,
    )


def episode_clock(key: str, frames: EpisodeFrames, fps: float, forced: str | None = None) -> VideoClock:
    """How video ``key``'s frames pair with the episode's rows (:mod:`framechain.adapters.lerobot.clock`)."""
    from_s = float(frames.episode.video_from_s.get(key, 0.0))
    to_s = frames.episode.video_to_s.get(key)
    if to_s is None and frames.episode.video_from_s:  # v3.0 without to_timestamp: the rows' nominal span
        to_s = from_s + len(frames) / fps
    times = episode_frame_times_s(frames.episode.video_files[key], from_s, to_s)
    return video_clock(key, times, frames.timestamp_s, frames.frame_index, fps=fps, from_s=from_s, to_s=to_s,
                       forced=forced)


def _video_frames(
    cam: CameraCalibration, frames: EpisodeFrames, cam_ns: IntArray, state_ns: IntArray, clock: VideoClock
) -> ImageFrameTable:
    """One row per row of the episode: the mp4 and the time in it of the frame the clock pairs with the row (not
    decoded; -1: the row has no frame). v3.0 concatenates episodes in one file (from_timestamp is where the
    episode starts in it), v2.1 has one file per episode."""
    assert cam.video_key is not None
    path = frames.episode.video_files[cam.video_key]
    in_file = clock.file_times_ns(frames.timestamp_s)
    n = len(frames)
    size = cam.camera_table()
    width, height = (int(size.width[0]), int(size.height[0])) if len(size) else (0, 0)
    return ImageFrameTable(
        frame=np.full(n, cam.optical_frame), stamp_ns=cam_ns, log_time_ns=state_ns,
        width=np.full(n, width), height=np.full(n, height),
        encoding=np.full(n, VIDEO_ENCODING), source=np.full(n, cam.video_key), video_path=np.full(n, str(path)),
        video_time_ns=np.where(in_file >= 0, in_file + VIDEO_REFERENCE_NUDGE_NS, -1),
    )


_MAGIC = {b"\xff\xd8\xff": "jpeg", b"\x89PNG\r\n\x1a\n": "png"}


def _stored_frames(
    cam: CameraCalibration, frames: EpisodeFrames, cam_ns: IntArray, state_ns: IntArray, root: Path
) -> ImageFrameTable:
    """One row per frame of an image feature: the PNG/JPEG bytes stored in the Parquet (HF ``Image``: a struct
    of ``bytes`` and ``path``; a path is read relative to the dataset when there are no bytes)."""
    assert cam.video_key is not None
    cells = frames.columns[cam.video_key].reshape(len(frames))
    encoded: list[bytes] = []
    for k, cell in enumerate(cells.tolist()):
        data = cell.get("bytes") if isinstance(cell, dict) else cell if isinstance(cell, bytes) else None
        if not data and isinstance(cell, dict) and cell.get("path"):
            file = root / str(cell["path"])
            data = file.read_bytes() if file.is_file() else None
        if not data:
            raise DatasetError(frames.episode.data_file, f"image feature {cam.video_key!r} has no bytes at frame {k}")
        encoded.append(bytes(data))
    kinds = [next((kind for magic, kind in _MAGIC.items() if data.startswith(magic)), "") for data in encoded]
    if "" in kinds:
        k = kinds.index("")
        raise DatasetError(frames.episode.data_file, f"image feature {cam.video_key!r} holds neither PNG nor JPEG at "
                           f"frame {k}")
    n = len(frames)
    size = cam.camera_table()
    width, height = (int(size.width[0]), int(size.height[0])) if len(size) else (0, 0)
    return ImageFrameTable(
        frame=np.full(n, cam.optical_frame), stamp_ns=cam_ns, log_time_ns=state_ns, width=np.full(n, width),
        height=np.full(n, height), encoding=np.array(kinds), source=np.full(n, cam.video_key),
        video_path=np.full(n, ""), video_time_ns=np.zeros(n, dtype=np.int64), loader=lambda i: encoded[i],
    )
