"""LeRobot video frames with PyAV: each row's frame, decoded once, and the video's health.

Videos are encoded here with PyAV's own encoders (H.264, AV1, MPEG-4 Part 2, HEVC); every frame
carries its index in pixel blocks, so a decoded frame tells which one it is whatever the codec
did to the rest of it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from framechain.adapters.lerobot.reader import DatasetError
from framechain.adapters.lerobot.video import (
    VideoError,
    encode_video,
    episode_frame_times_ns,
    probe_video,
    read_frames,
    video_health,
)

pytest.importorskip("av")

FPS = 30
SIZE = 64
CODECS = ("libx264", "libsvtav1", "mpeg4", "libx265")
DECODERS = {"libx264": "h264", "libsvtav1": "libdav1d", "mpeg4": "mpeg4", "libx265": "hevc"}


def numbered_frames(n: int, seed: int = 0) -> npt.NDArray[np.uint8]:
    """(n, 64, 64, 3) frames: textured, with frame k's index in eight 8x8 blocks of the top row (bit = white)."""
    rng = np.random.default_rng(seed)
    base = rng.integers(60, 200, (n + SIZE, n + SIZE, 3), dtype=np.uint8)
    out = np.stack([base[k:k + SIZE, k:k + SIZE] for k in range(n)])
    for k in range(n):
        for bit in range(8):
            out[k, :8, bit * 8:(bit + 1) * 8] = 255 if (k >> bit) & 1 else 0
    return out


def frame_number(grey: npt.NDArray[np.uint8]) -> int:
    """The index a frame of :func:`numbered_frames` carries (block means above mid-grey are ones)."""
    blocks = grey[2:6].reshape(4, 8, 8)[:, :, 2:6].mean(axis=(0, 2))
    return int(sum(1 << bit for bit in range(8) if blocks[bit] > 128))


@pytest.fixture(scope="module")
def videos(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("videos")
    frames = numbered_frames(90)
    return {codec: encode_video(root / f"{codec}.mp4", frames, fps=FPS, codec=codec) for codec in CODECS}


@pytest.mark.parametrize("codec", CODECS)
def test_each_row_gets_its_own_frame_in_every_codec(videos: dict[str, Path], codec: str) -> None:
    info = probe_video(videos[codec])
    assert (info.codec, info.width, info.height, info.frames, info.fps) == (DECODERS[codec], SIZE, SIZE, 90, FPS)
    assert info.duration_s == pytest.approx(3.0, abs=1e-6)
    timestamps = (np.arange(90) / FPS).astype(np.float32)  # as LeRobot stores them
    got = read_frames(videos[codec], episode_frame_times_ns(timestamps))
    assert not got.missing.any()
    assert [frame_number(got.image(k)) for k in range(90)] == list(range(90))
    assert np.abs(got.frame_time_ns - np.round(np.arange(90) / FPS * 1e9)).max() < 1e3
    assert got.decoded == 90
    assert got.images.shape == (90, SIZE, SIZE)


def test_rgb_frames_keep_their_colours(tmp_path: Path) -> None:
    # Red left, blue right (4:2:0 keeps colour at this scale): channel order survives the round trip.
    frame = np.zeros((SIZE, SIZE, 3), dtype=np.uint8)
    frame[:, : SIZE // 2, 0] = 200
    frame[:, SIZE // 2:, 2] = 200
    path = encode_video(tmp_path / "colours.mp4", np.stack([frame] * 3), fps=FPS)
    got = read_frames(path, episode_frame_times_ns([1 / FPS]), pixel_format="rgb24")
    assert got.images.shape == (1, SIZE, SIZE, 3)
    image = got.image(0).astype(float)
    assert np.abs(image[8:-8, 8:24] - frame[8:-8, 8:24]).max() < 12
    assert np.abs(image[8:-8, 40:56] - frame[8:-8, 40:56]).max() < 12


def test_a_late_window_decodes_from_its_key_frame_only(tmp_path: Path) -> None:
    # Key frames every 10 frames: rows 60..69 need the frames from the key frame before frame 59 (the
    # nearest candidate before row 60's time) on, and none after frame 70.
    path = encode_video(tmp_path / "gop.mp4", numbered_frames(120), fps=FPS, codec="libx264",
                        options={"g": "10", "keyint_min": "10", "sc_threshold": "0", "bf": "0"})
    got = read_frames(path, episode_frame_times_ns(np.arange(10) / FPS, from_timestamp_s=2.0))
    assert [frame_number(got.image(k)) for k in range(10)] == list(range(60, 70))
    assert got.decoded <= 10 + 10 + 1


def test_far_apart_rows_reseek_instead_of_decoding_the_gap(tmp_path: Path) -> None:
    path = encode_video(tmp_path / "gop.mp4", numbered_frames(240), fps=FPS, codec="libx264",
                        options={"g": "10", "keyint_min": "10", "sc_threshold": "0", "bf": "0"})
    got = read_frames(path, episode_frame_times_ns(np.array([0.0, 0.0333333, 7.0])))
    assert [frame_number(got.image(k)) for k in range(3)] == [0, 1, 210]
    assert got.decoded <= 3 + 10 + 2  # frames 0..2, then from the key frame at 200 to 211


def test_v3_rows_are_found_at_from_timestamp_plus_timestamp(videos: dict[str, Path]) -> None:
    # An episode that starts 1.5 s into the shared file: its row k is frame 45 + k.
    timestamps = (np.arange(20) / FPS).astype(np.float32)
    got = read_frames(videos["libsvtav1"], episode_frame_times_ns(timestamps, from_timestamp_s=1.5))
    assert [frame_number(got.image(k)) for k in range(20)] == list(range(45, 65))


def test_rows_between_frames_take_the_nearest_and_beyond_the_tolerance_none(videos: dict[str, Path]) -> None:
    # 10 ms after frame 30 -> frame 30; 20 ms after -> frame 31 (13 ms away); after the end -> missing.
    times = np.array([1.0 + 0.010, 1.0 + 0.020, 3.2])
    got = read_frames(videos["libx264"], episode_frame_times_ns(times))
    assert frame_number(got.image(0)) == 30
    assert frame_number(got.image(1)) == 31
    assert got.missing.tolist() == [False, False, True]
    strict = read_frames(videos["libx264"], episode_frame_times_ns(times[:2]), tolerance_s=1e-4)
    assert strict.missing.tolist() == [True, True]


def test_health_names_missing_repeated_and_black_frames(tmp_path: Path) -> None:
    frames = numbered_frames(60)
    frames[:4] = 0  # a camera that delivered nothing at first
    frames[20] = frames[19]  # resent frames: pixel for pixel the previous one
    frames[33] = frames[32]
    frames[34] = frames[32]
    path = encode_video(tmp_path / "health.mp4", frames, fps=FPS, codec="libx264")
    # The dataset has 62 rows at 30 fps: the last two have no frame.
    got = read_frames(path, episode_frame_times_ns(np.arange(62) / FPS))
    health = video_health(got, np.arange(62), "observation.images.wrist")
    assert health.missing == (60, 61)
    assert health.black == (0, 1, 2, 3)
    assert health.duplicated == (1, 2, 3, 20, 33, 34)
    assert got.usable.sum() == 62 - 2 - 4 - 3
    notes = health.notes()
    assert notes[0].startswith("video observation.images.wrist: 2 of 62 frames missing: frame_index 60, 61")
    assert "6 of 62 frames duplicated" in notes[1]
    assert "4 of 62 frames black" in notes[2]


def test_a_repeat_coded_with_a_residual_needs_a_repeat_level(tmp_path: Path) -> None:
    # MPEG-4 Part 2 codes frame 33, sent twice, with a small residual: not pixel for pixel (PyAV 18.1).
    frames = numbered_frames(60)
    frames[:4] = 0
    frames[20] = frames[19]
    frames[33] = frames[32]
    path = encode_video(tmp_path / "residual.mp4", frames, fps=FPS, codec="mpeg4")
    times = episode_frame_times_ns(np.arange(60) / FPS)
    exact = read_frames(path, times)
    tolerant = read_frames(path, times, repeat_level=1.0)
    residual = np.abs(exact.image(33).astype(int) - exact.image(32).astype(int)).mean()
    assert 0 < residual <= 1.0
    assert not exact.duplicate[33]
    assert np.flatnonzero(tolerant.duplicate).tolist() == [1, 2, 3, 20, 33]


def test_rows_sharing_a_frame_are_duplicates_and_it_is_decoded_once(videos: dict[str, Path]) -> None:
    # A 60 Hz dataset over a 30 fps video: every other row repeats the frame before.
    got = read_frames(videos["mpeg4"], episode_frame_times_ns(np.arange(12) / 60.0))
    numbers = [frame_number(got.image(k)) for k in range(12)]
    assert numbers[0] == 0
    assert numbers[-1] in (5, 6)
    assert np.all(np.diff(numbers) >= 0)
    assert np.all(np.diff(numbers) <= 1)
    assert len(set(numbers)) == got.images.shape[0] == 6 or len(set(numbers)) == got.images.shape[0] == 7
    repeats = np.flatnonzero(np.diff(numbers) == 0) + 1
    assert np.flatnonzero(got.duplicate).tolist() == repeats.tolist()


def test_unsorted_rows_get_their_frames(videos: dict[str, Path]) -> None:
    order = np.array([50, 3, 27, 3, 88])
    got = read_frames(videos["libx265"], episode_frame_times_ns(order / FPS))
    assert [frame_number(got.image(k)) for k in range(5)] == order.tolist()


def test_row_images_stack_every_row(videos: dict[str, Path]) -> None:
    got = read_frames(videos["libx264"], episode_frame_times_ns(np.array([0.5, 9.0, 0.6])))
    stack = got.row_images()
    assert stack.shape == (3, SIZE, SIZE)
    assert frame_number(stack[0]) == 15
    assert frame_number(stack[2]) == 18
    assert stack[1].max() == 0


def test_unreadable_video_is_one_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "cut.mp4"
    bad.write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"\x00" * 40)
    with pytest.raises(VideoError, match=r"cut\.mp4: cannot open video") as err:
        read_frames(bad, [0])
    assert isinstance(err.value, DatasetError)
    with pytest.raises(VideoError, match="cannot open video"):
        probe_video(tmp_path / "absent.mp4")


@pytest.mark.parametrize(("codec", "pixel_format", "width"), [
    ("libx264", "yuv420p", 226),  # rows padded past the width
    ("mpeg4", "yuv420p", 224),
    ("mjpeg", "yuvj420p", 160),  # full range: the luma as it is
    ("libx264", "yuv444p", 96),
    ("libx264rgb", "rgb24", 64),  # no luma plane: libswscale's conversion
])
def test_grey_frames_are_libswscales_pixel_for_pixel(tmp_path: Path, codec: str, pixel_format: str,
                                                     width: int) -> None:
    """read_frames takes grey from the luma plane where it can: every frame as PyAV's own conversion gives it."""
    import av

    rng = np.random.default_rng(3)
    frames = rng.integers(0, 256, (6, 48, width, 3), dtype=np.uint8)
    path = encode_video(tmp_path / f"{codec}.mp4" if codec != "mjpeg" else tmp_path / "m.mkv", frames, fps=10,
                        codec=codec, pixel_format=pixel_format)
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        decoded = [(round(float(f.pts * stream.time_base) * 1e9), f.to_ndarray(format="gray"))
                   for f in container.decode(stream)]
    got = read_frames(path, np.array([t for t, _ in decoded], dtype=np.int64))
    assert got.images.shape[0] == len(decoded)
    for k, (_time, expected) in enumerate(decoded):
        np.testing.assert_array_equal(got.image(k), expected)


def test_full_range_av1_opening_on_a_black_frame_is_grey_as_libswscale_reads_it(tmp_path: Path) -> None:
    """dav1d returns full-range AV1 as yuv420p marked JPEG range, whose luma is already grey; a black first frame
    reads the same rescaled or not, so it cannot be what decides (it once did: 20 grey levels off after it)."""
    import av

    path = tmp_path / "full.mp4"
    frames = np.random.default_rng(0).integers(0, 256, (6, 64, 64, 3), dtype=np.uint8)
    frames[0] = 0
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libsvtav1", rate=10)
        stream.width, stream.height, stream.pix_fmt = 64, 64, "yuv420p"
        stream.codec_context.color_range = 2  # JPEG: full range
        stream.options = {"svtav1-params": "log-level=0"}
        for i, pixels in enumerate(frames):
            frame = av.VideoFrame.from_ndarray(pixels, format="rgb24").reformat(format="yuv420p", dst_color_range=2)
            frame.pts = i
            container.mux(stream.encode(frame))
        container.mux(stream.encode())
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        decoded = [(round(float(f.pts * stream.time_base) * 1e9), f.to_ndarray(format="gray"), int(f.color_range))
                   for f in container.decode(stream)]
    assert {range_ for _t, _g, range_ in decoded} == {2}
    got = read_frames(path, np.array([t for t, _g, _r in decoded], dtype=np.int64))
    for k, (_time, expected, _range) in enumerate(decoded):
        np.testing.assert_array_equal(got.image(k), expected)
