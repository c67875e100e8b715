"""Depth windows kept during the one read pass give the same replay depths, bit for bit, as re-reading frames.

Logs are written by the real writers (mcap_ros2 through write_log, rosbags for ROS 1 and ROS 2
bags); each is replayed twice: with the windows kept at read time and with them dropped (every
window then comes from the frame fetched again from the log). The fetch is counted, so a test
also shows which path it took.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from framechain.adapters import open_log, write_log
from framechain.adapters.messages.depth import HORIZON_NS
from framechain.config.chain import ChainConfig
from framechain.replay import ReplayOptions, ReplayResult, replay
from framechain.sim.scene import Scene, SceneSpec, generate
from framechain.timeline import DepthFrameTable, Timeline


def _scene() -> Scene:
    return generate(SceneSpec(seed=5, duration_s=4.0, width=160, height=120, focal_px=150.0, depth_images=True))


def _counting(depth: DepthFrameTable, *, keep_windows: bool) -> tuple[DepthFrameTable, list[int]]:
    """The table with its loader counting calls; without the kept windows when ``keep_windows`` is False."""
    calls: list[int] = []
    base = depth.loader
    assert base is not None

    def load(i: int) -> npt.NDArray[np.float32]:
        calls.append(i)
        return base(i)

    return dataclasses.replace(depth, loader=load, windows=depth.windows if keep_windows else None), calls


def _replay_both(timeline: Timeline, chain: ChainConfig) -> tuple[ReplayResult, ReplayResult, list[int], list[int]]:
    with_kept, kept_calls = _counting(timeline.depth_frames, keep_windows=True)
    without, fetch_calls = _counting(timeline.depth_frames, keep_windows=False)
    frames = chain.frames
    a = replay(timeline.replace(depth_frames=with_kept), frames)
    b = replay(timeline.replace(depth_frames=without), frames)
    return a, b, kept_calls, fetch_calls


def _same_depths(a: ReplayResult, b: ReplayResult) -> None:
    da, db = a.depth_m, b.depth_m
    assert da.tobytes() == db.tobytes()  # bit for bit, NaNs included
    assert np.array_equal(a.status, b.status)
    assert np.array_equal(a.depth_stamp_ns, b.depth_stamp_ns)


@pytest.mark.parametrize(("container", "name", "encoding"), [
    ("mcap-ros2", "log.mcap", "16UC1"), ("mcap-ros2", "log.mcap", "32FC1"), ("rosbag1", "log.bag", "16UC1"),
    ("rosbag2-sqlite", "log_bag", "16UC1"),
])
def test_kept_windows_give_the_fetched_depths(tmp_path: Path, container: str, name: str, encoding: str) -> None:
    scene = _scene()
    path = write_log(scene.timeline, tmp_path / name, container=container, depth_encoding=encoding,
                     chain=scene.chain)
    loaded = open_log(path, scene.chain)
    assert loaded.timeline.depth_frames.windows is not None
    a, b, kept_calls, fetch_calls = _replay_both(loaded.timeline, scene.chain)
    _same_depths(a, b)
    sampled = np.isfinite(b.depth_m)
    assert sampled.sum() > 20  # the scene's detections found depth in the images
    assert not kept_calls  # every window was kept: no frame was read again
    assert fetch_calls  # the other replay did read frames
    # Independent of both paths: the 5x5 median around the pixel of the frame decoded whole.
    depth = loaded.timeline.depth_frames
    obs = b.observations
    for k in np.flatnonzero(sampled)[:10].tolist():
        row = int(np.flatnonzero(depth.stamp_ns == b.depth_stamp_ns[k])[0])
        image = depth.load(row).astype(np.float64)
        r, c = int(np.rint(obs.v[k])), int(np.rint(obs.u[k]))
        box = image[max(r - 2, 0) : r + 3, max(c - 2, 0) : c + 3]
        good = box[np.isfinite(box) & (box > 0)]
        assert a.depth_m[k] == pytest.approx(float(np.median(good)), abs=1e-12)


def test_windows_not_kept_fall_back_to_the_frame(tmp_path: Path) -> None:
    """Detections logged long after their frames (beyond the read's horizon): their windows are fetched."""
    scene = _scene()
    timeline = scene.timeline
    late = dataclasses.replace(timeline.observations,
                               log_time_ns=timeline.observations.log_time_ns + 3 * HORIZON_NS)
    path = write_log(timeline.replace(observations=late), tmp_path / "late.mcap", container="mcap-ros2",
                     chain=scene.chain)
    loaded = open_log(path, scene.chain)
    a, b, kept_calls, fetch_calls = _replay_both(loaded.timeline, scene.chain)
    _same_depths(a, b)
    assert np.isfinite(a.depth_m).sum() > 20
    # The early frames had left the read's horizon before their detections came: read again.
    assert kept_calls
    assert set(kept_calls) <= set(fetch_calls)


def test_a_larger_window_than_kept_is_cut_from_the_frame(tmp_path: Path) -> None:
    scene = _scene()
    path = write_log(scene.timeline, tmp_path / "log.mcap", container="mcap-ros2",
                     chain=scene.chain)
    loaded = open_log(path, scene.chain)
    with_kept, kept_calls = _counting(loaded.timeline.depth_frames, keep_windows=True)
    without, _ = _counting(loaded.timeline.depth_frames, keep_windows=False)
    opts = ReplayOptions(depth_window=9)
    frames = scene.chain.frames
    a = replay(loaded.timeline.replace(depth_frames=with_kept), frames, options=opts)
    b = replay(loaded.timeline.replace(depth_frames=without), frames, options=opts)
    _same_depths(a, b)
    assert kept_calls  # 9 x 9 is more than the read kept


def test_kept_windows_are_the_frames_cut_whole_wherever_they_were_kept() -> None:
    """The keeper's windows for many frames at once (repeated centres, centres at the border, frames in
    depth units and in metres, frames at odd addresses, windows never kept) equal the windows cut from
    the converted frames."""
    from framechain.adapters.messages.depth import DepthWindowKeeper, pixels_to_metres
    from framechain.timeline import pixel_windows

    rng = np.random.default_rng(3)
    h, w, n = 12, 16, 6
    raws = [rng.integers(0, 5000, (h, w)).astype(np.uint16) if i % 2 else rng.random((h, w)).astype(np.float32)
            for i in range(n)]
    raws[1], raws[2] = _unaligned(raws[1]), _unaligned(raws[2])  # as frames inside a decompressed chunk often are
    keeper = DepthWindowKeeper()
    for i, raw in enumerate(raws):
        keeper.add_frame(i, "cam", 1000 * i, 1000 * i, raw)
    # Per frame two detections at its stamp (one at the image's corner), and one repeated.
    u = np.array([[3.0, 15.4, 3.0][k] for _ in range(n) for k in range(3)])
    v = np.array([[5.0, 0.2, 5.0][k] for _ in range(n) for k in range(3)])
    stamps = [1000 * i for i in range(n) for _ in range(3)]
    keeper.add_observations(["cam"] * len(stamps), stamps, stamps, u, v)
    keeper.settle(final=True)
    read_rows = [4, 2, 0, 1, 3, 5]  # table row -> read row
    units = [0.001, 0.002, 0.001, 0.003, 0.001, 0.001]
    windows = keeper.lookup(read_rows, units)
    frames = np.array([0, 0, 1, 5, 5, 3, 3, 2, 4, 4])
    rows = np.array([5, 0, 5, 0, 7, 5, 5, 0, 5, 0])  # (7, 15) and (0, 3) were never kept
    cols = np.array([3, 15, 3, 15, 15, 3, 3, 15, 3, 3])
    for half in (0, 2, 3, 4):
        got, found = windows(frames, rows, cols, half)
        assert found.tolist() == ([half <= 3] * 4 + [False] + [half <= 3] * 4 + [False])
        for k in np.flatnonzero(found).tolist():
            table_row = int(frames[k])
            image = pixels_to_metres(raws[read_rows[table_row]], units[table_row])
            want = pixel_windows(image, rows[k : k + 1], cols[k : k + 1], half)[0]
            assert got[k].tobytes() == want.tobytes()


def _unaligned(a: npt.NDArray[Any]) -> npt.NDArray[Any]:
    """``a`` copied to an odd address (a view into a byte buffer, not aligned to its item size)."""
    buf = np.zeros(a.nbytes + 1, dtype=np.uint8)[1:]
    buf[:] = np.ascontiguousarray(a).view(np.uint8).reshape(-1)
    out = buf.view(a.dtype).reshape(a.shape)
    assert not out.flags.aligned
    return out


@pytest.mark.parametrize("encoding", ["16UC1", "16SC1", "32FC1"])
@pytest.mark.parametrize("big_endian", [False, True])
@pytest.mark.parametrize("padding", [0, 6])
@pytest.mark.parametrize("container", [bytes, memoryview, "view"])
def test_raw_depth_pixels_are_the_image_as_written(encoding: str, big_endian: bool, padding: int,
                                                   container: Any) -> None:
    """Rows padded or not, either byte order, from bytes or from a view into a message: the pixels written."""
    from types import SimpleNamespace

    from framechain.adapters.messages.depth import raw_depth_pixels

    h, w = 5, 7
    dtype = np.dtype({"16UC1": "u2", "16SC1": "i2", "32FC1": "f4"}[encoding]).newbyteorder(">" if big_endian else "<")
    image = (np.arange(h * w).reshape(h, w) * 37 - (0 if encoding == "16UC1" else 300)).astype(dtype)
    step = w * dtype.itemsize + padding
    rows = np.full((h, step), 0xAB, dtype=np.uint8)  # padding bytes that are not pixels
    rows[:, : w * dtype.itemsize] = image.view(np.uint8).reshape(h, -1)
    written = b"\x00" + rows.tobytes()  # one byte before: the pixels start at an odd offset
    data: Any = {bytes: written[1:], memoryview: memoryview(written)[1:],
                 "view": np.frombuffer(written, dtype=np.uint8)[1:]}[container]
    msg = SimpleNamespace(height=h, width=w, step=step, encoding=encoding, is_bigendian=int(big_endian), data=data)
    got = raw_depth_pixels(msg)
    assert got.shape == (h, w)
    np.testing.assert_array_equal(got.astype(np.float64), image.astype(np.float64))
