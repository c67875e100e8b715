"""A camera's rows as grey pixels: frames of one or more videos, raw images, and rows without a frame.

Videos are encoded here with PyAV (lossless-enough MPEG-4 of flat grey frames whose level is their index), so
each decoded row says which frame it got; raw images are grey levels of their own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from framechain.adapters.lerobot.video import encode_video
from framechain.adapters.messages.egomotion_frames import decode_grey
from framechain.timeline.frames import ImageFrameTable

pytest.importorskip("av")

FPS = 10


def _levelled(n: int, size: int, first: int) -> np.ndarray:
    """(n, size, size, 3) flat frames, frame k at grey level ``first + 10 k``."""
    levels = first + 10 * np.arange(n)
    return np.broadcast_to(levels[:, None, None, None], (n, size, size, 3)).astype(np.uint8).copy()


def _video_rows(path: Path, frame_times_s: list[float]) -> ImageFrameTable:
    n = len(frame_times_s)
    stamps = (np.array(frame_times_s) * 1e9).astype(np.int64)
    return ImageFrameTable(frame=["cam"] * n, stamp_ns=stamps, log_time_ns=stamps, width=[32] * n, height=[32] * n,
                           encoding=["video"] * n, source=["observation.images.cam"] * n, video_path=[str(path)] * n,
                           video_time_ns=stamps, loader=lambda i: b"")


def _level(grey: np.ndarray) -> float:
    return float(grey[8:-8, 8:-8].mean())


def test_one_video_with_a_frame_for_every_row_is_its_frames_in_order(tmp_path: Path) -> None:
    path = encode_video(tmp_path / "a.mp4", _levelled(6, 32, 40), fps=FPS, codec="mpeg4")
    images = _video_rows(path, [k / FPS for k in range(6)])
    grey, missing, decoded = decode_grey(images, np.arange(6))
    assert grey.shape == (6, 32, 32)
    assert not missing.any()
    assert decoded == 6
    assert [round(_level(g)) for g in grey] == pytest.approx([40, 50, 60, 70, 80, 90], abs=2)


def test_rows_in_another_order_rows_without_a_frame_and_raw_images(tmp_path: Path) -> None:
    video = encode_video(tmp_path / "a.mp4", _levelled(6, 32, 40), fps=FPS, codec="mpeg4")
    other = encode_video(tmp_path / "b.mp4", _levelled(3, 48, 150), fps=FPS, codec="mpeg4")  # another size
    raw = ImageFrameTable.from_arrays("cam", [10_000_000_000], np.full((1, 32, 32), 222, np.uint8), encoding="mono8")
    images = ImageFrameTable.concat([_video_rows(video, [0.3, 0.1, 9.0]), _video_rows(other, [0.0]), raw])
    # Rows: frame 3, frame 1, a time past the video's end, the other video's frame, the raw image.
    grey, missing, _decoded = decode_grey(images, np.arange(5))
    assert grey.shape == (5, 32, 32)  # the first row's size; the other video's frame does not fit it
    assert missing.tolist() == [False, False, True, True, False]
    assert round(_level(grey[0])) == pytest.approx(70, abs=2)
    assert round(_level(grey[1])) == pytest.approx(50, abs=2)
    assert not grey[2].any()
    assert not grey[3].any()
    assert _level(grey[4]) == 222


def test_every_row_from_one_video_in_another_order_and_rows_of_two_videos(tmp_path: Path) -> None:
    video = encode_video(tmp_path / "a.mp4", _levelled(4, 32, 40), fps=FPS, codec="mpeg4")
    other = encode_video(tmp_path / "b.mp4", _levelled(2, 32, 150), fps=FPS, codec="mpeg4")  # the same size
    reordered = _video_rows(video, [0.2, 0.0, 0.3, 0.1])
    grey, missing, _decoded = decode_grey(reordered, np.arange(4))
    assert not missing.any()
    assert [round(_level(g)) for g in grey] == pytest.approx([60, 40, 70, 50], abs=2)
    both = ImageFrameTable.concat([_video_rows(video, [0.1, 0.2]), _video_rows(other, [0.1, 0.0])])
    grey, missing, decoded = decode_grey(both, np.array([2, 0, 3, 1]))
    assert not missing.any()
    assert decoded >= 4
    assert [round(_level(g)) for g in grey] == pytest.approx([160, 50, 150, 60], abs=2)
    assert grey.flags.writeable


def test_one_raw_row_comes_back_writeable(tmp_path: Path) -> None:
    raw = ImageFrameTable.from_arrays("cam", [0], np.full((1, 8, 8), 90, np.uint8), encoding="mono8")
    grey, missing, _decoded = decode_grey(raw, np.arange(1))
    assert not missing.any()
    assert grey.flags.writeable  # a copy, not a view of the table's bytes
    assert (grey[0] == 90).all()
