"""How generated LeRobot episodes are recorded and encoded: a recorder's real-time row stamps, and the videos and
feature specs as LeRobot writes them (fast encoder presets: generation time, not file size, matters here)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from framechain.adapters.lerobot.video import encode_video
from framechain.adapters.lerobot.writer import FeatureSpec
from framechain.arrays import FloatArray

__all__ = ["frames_feature", "realtime_stamps", "write_videos"]


def realtime_stamps(rng: np.random.Generator, duration_s: float, rate_hz: float) -> FloatArray:
    """Capture times (s, from 0) of a recorder whose loop runs at a variable ``rate_hz`` on average.

    Intervals jitter by about 15% around the mean, and one in thirty takes twice as long (a late loop),
    as the rows of a real SO-101 recording do (about 18.6 Hz where 20 fps was asked).
    """
    mean = 1.0 / rate_hz
    count = max(2, round(duration_s * rate_hz))
    intervals = mean * np.clip(1.0 + 0.15 * rng.standard_normal(count - 1), 0.6, 1.6)
    intervals[rng.random(count - 1) < 1.0 / 30.0] *= 2.0
    intervals *= (count - 1) * mean / intervals.sum()  # keep the average rate
    out: FloatArray = np.concatenate([[0.0], np.cumsum(intervals)])
    return out


_CODEC_NAMES = {"libx264": "h264", "libsvtav1": "av1", "mpeg4": "mpeg4", "libx265": "hevc"}
#: Fast encoder presets: generation time, not file size, matters here.
#: One encoder thread: a threaded libx264 codes the same frames differently from run to run (a test would measure
#: another video each time).
_FAST = {"libx264": {"preset": "veryfast", "threads": "1"}, "libx265": {"preset": "veryfast", "threads": "1"},
         "libsvtav1": {"preset": "10"},
         # MPEG-4 Part 2 at the quality of a real recording (a frame sent twice decodes within about a grey level).
         "mpeg4": {"b": "2500000"}}


def frames_feature(width: int, height: int, *, fps: int, codec: str, storage: str) -> FeatureSpec:
    """A camera's feature: an mp4 per key ("video"), or PNG bytes in the Parquet ("image", an HF Image feature)."""
    if storage != "video":
        return FeatureSpec("image", (height, width, 3), ["height", "width", "channels"])
    return FeatureSpec("video", (height, width, 3), ["height", "width", "channels"],
                       {"video.fps": fps, "video.codec": _CODEC_NAMES.get(codec, codec), "video.pix_fmt": "yuv420p",
                        "video.is_depth_map": False})


def write_videos(root: Path, key: str, videos: list[np.ndarray], *, fps: int, codec: str, version: str,
                 options: Sequence[tuple[str, str]] = ()) -> None:
    """One mp4 per episode (v2.1), or the episodes back to back in one file (v3.0, as the writer's metadata says)."""
    chosen = {**_FAST.get(codec, {}), **dict(options)}
    if version == "v2.1":
        for e, frames in enumerate(videos):
            encode_video(root / f"videos/chunk-000/{key}/episode_{e:06d}.mp4", frames, fps=fps, codec=codec,
                         options=chosen)
    else:
        encode_video(root / f"videos/{key}/chunk-000/file-000.mp4", np.concatenate(videos), fps=fps, codec=codec,
                     options=chosen)
