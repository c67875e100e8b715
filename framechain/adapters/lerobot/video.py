"""LeRobot videos decoded with PyAV: each dataset row's frame, and the video's health.

LeRobot stores camera frames as mp4 (H.264, AV1, which LeRobot v3 writes by default, MPEG-4
Part 2, HEVC). A row's frame is the one shown at its time in the file: v3.0 concatenates the
episodes of a key in one file, so the time is ``from_timestamp + timestamp`` (the episode's
``videos/<key>/from_timestamp``); v2.1 has one file per episode and the time is ``timestamp``
(:func:`episode_frame_times_ns`).

:func:`read_frames` seeks to the key frame before the first wanted time, decodes forward, and
converts only the frames some row wants, each once; it seeks again over gaps longer than
``reseek_s``. A row takes the frame whose presentation time is nearest its time, within
``tolerance_s`` (default: half the stream's frame period); a row with none (or a negative time: no frame
paired with it) is missing. A row
whose frame repeats the previous row's is duplicated (real recordings resend a frame when the
camera is late: it shows an earlier moment than its stamp), and a frame with hardly a pixel
above ``black_level`` is black (a camera that delivered nothing). "Repeats" means pixel for
pixel by default, as H.264, HEVC and AV1 return a frame sent twice; an encoder may instead code a
small residual for it (MPEG-4 Part 2 did here: 0.7 grey levels on average), which
``repeat_level`` (mean absolute difference) tolerates, at the price of taking a nearly still
scene (a static camera watching a small arm: 0.4 levels) for repeats.
:func:`video_health` counts them by ``frame_index``.

:func:`encode_video` writes frames as an mp4 with PyAV (tests, the scene generator).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from framechain.adapters.lerobot.reader import DatasetError
from framechain.arrays import BoolArray, IntArray
from framechain.vision.opencv import bright_shares, mean_abs_differences, require_cv2

__all__ = [
    "VideoError",
    "VideoFrames",
    "VideoHealth",
    "VideoInfo",
    "encode_video",
    "episode_frame_times_ns",
    "probe_video",
    "read_frames",
    "video_health",
]

#: A frame is black when fewer than this share of its pixels exceed ``BLACK_LEVEL`` (a camera that delivered nothing).
BLACK_SHARE = 0.01
BLACK_LEVEL = 32

PixelFormat = Literal["gray", "rgb24"]


class VideoError(DatasetError):
    """A video file cannot be opened or decoded: names the file and what failed."""


@dataclass(frozen=True)
class VideoInfo:
    """The first video stream of a file: codec, size, nominal rate, frame count and duration."""

    path: str
    codec: str
    width: int
    height: int
    fps: float
    frames: int
    duration_s: float


@dataclass(frozen=True)
class VideoFrames:
    """One video's frames matched to rows (a dataset episode's, in order), each frame decoded once.

    Per row: ``time_ns`` the wanted time in the file, ``frame_time_ns`` the matched frame's
    presentation time (-1: missing), ``image_index`` its index into ``images`` (-1: missing),
    ``duplicate`` (the previous row's frame again) and ``black``. ``decoded`` counts every
    frame decoded, converted or not.
    """

    path: str
    time_ns: IntArray
    frame_time_ns: IntArray
    image_index: IntArray
    images: npt.NDArray[np.uint8]  # (K, H, W) grey or (K, H, W, 3) RGB
    duplicate: BoolArray
    black: BoolArray
    decoded: int

    @property
    def missing(self) -> BoolArray:
        out: BoolArray = self.image_index < 0
        return out

    @property
    def usable(self) -> BoolArray:
        """Rows with a frame of their own: present, not a repeat, not black."""
        out: BoolArray = ~self.missing & ~self.duplicate & ~self.black
        return out

    def image(self, row: int) -> npt.NDArray[np.uint8]:
        """The pixels of row ``row``'s frame."""
        index = int(self.image_index[row])
        if index < 0:
            raise VideoError(self.path, f"row {row} has no frame within the tolerance of {self.time_ns[row]} ns")
        out: npt.NDArray[np.uint8] = self.images[index]
        return out

    def row_images(self) -> npt.NDArray[np.uint8]:
        """Every row's frame stacked (missing rows black): ``(N, H, W[, 3])``."""
        blank = np.zeros((1, *self.images.shape[1:]), dtype=np.uint8)
        stack = np.concatenate([self.images, blank]) if self.images.size else blank
        out: npt.NDArray[np.uint8] = stack[np.where(self.image_index < 0, stack.shape[0] - 1, self.image_index)]
        return out


@dataclass(frozen=True)
class VideoHealth:
    """Frames missing, duplicated or black, by ``frame_index``, and the worst time mismatch."""

    key: str
    rows: int
    missing: tuple[int, ...]
    duplicated: tuple[int, ...]
    black: tuple[int, ...]
    max_mismatch_ms: float

    def notes(self) -> list[str]:
        """One line per kind of problem, naming the video key and the first frames."""
        out = []
        for what, frames in (("missing", self.missing), ("duplicated (a repeat of the previous frame)",
                                                         self.duplicated), ("black", self.black)):
            if frames:
                shown = ", ".join(str(f) for f in frames[:8]) + (", ..." if len(frames) > 8 else "")
                out.append(f"video {self.key}: {len(frames)} of {self.rows} frames {what}: frame_index {shown}")
        return out


def episode_frame_times_ns(timestamp_s: npt.ArrayLike, from_timestamp_s: float = 0.0) -> IntArray:
    """Each row's time in its video file: ``from_timestamp + timestamp`` (v3.0; v2.1: ``from`` is 0)."""
    times = float(from_timestamp_s) + np.asarray(timestamp_s, dtype=np.float64)
    out: IntArray = np.round(times * 1e9).astype(np.int64)
    return out


def _open(path: str | Path) -> Any:
    import av

    try:
        container = av.open(str(path))
    except (OSError, av.FFmpegError) as err:
        raise VideoError(path, f"cannot open video ({err})") from err
    if not container.streams.video:
        container.close()
        raise VideoError(path, "holds no video stream")
    return container


def probe_video(path: str | Path) -> VideoInfo:
    """Codec, size, nominal frame rate, frame count and duration of the first video stream."""
    with _open(path) as container:
        stream = container.streams.video[0]
        rate = stream.average_rate or stream.guessed_rate or 0
        duration = float(stream.duration * stream.time_base) if stream.duration else float(
            (container.duration or 0) / 1e6)
        return VideoInfo(path=str(path), codec=str(stream.codec_context.name), width=int(stream.codec_context.width),
                         height=int(stream.codec_context.height), fps=float(rate), frames=int(stream.frames or 0),
                         duration_s=duration)


def read_frames(
    path: str | Path,
    time_ns: npt.ArrayLike,
    *,
    tolerance_s: float | None = None,
    pixel_format: PixelFormat = "gray",
    black_level: int = BLACK_LEVEL,
    repeat_level: float = 0.0,
    reseek_s: float = 2.0,
) -> VideoFrames:
    """The frame of each wanted time (ns from the file's start), decoded once; see the module text."""
    wanted = np.asarray(time_ns, dtype=np.int64)
    with _open(path) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        rate = float(stream.average_rate or stream.guessed_rate or 30)
        tolerance = round((0.5 / rate if tolerance_s is None else tolerance_s) * 1e9)
        # A negative time is a row without a frame (a clock that pairs it with none): missing, never decoded.
        order = np.argsort(wanted, kind="stable")
        order = order[wanted[order] >= 0]
        matcher = _Matcher(wanted[order], tolerance, pixel_format)
        try:
            for start, stop in _segments(wanted[order], int(reseek_s * 1e9)):
                _decode_segment(container, stream, matcher, start, stop)
        except (OSError, ValueError) as err:  # av errors derive from these
            raise VideoError(path, f"cannot decode video ({err})") from err
    picked = np.full(wanted.size, -1, dtype=np.int64)
    picked[order] = matcher.picked
    frame_time = np.full(wanted.size, -1, dtype=np.int64)
    frame_time[order] = matcher.picked_time
    images = matcher.images()
    return VideoFrames(path=str(path), time_ns=wanted, frame_time_ns=frame_time, image_index=picked, images=images,
                       duplicate=_duplicates(picked, images, repeat_level),
                       black=_black(picked, images, black_level),
                       decoded=matcher.decoded)


def _segments(wanted: IntArray, gap_ns: int) -> list[tuple[int, int]]:
    """Index ranges of sorted wanted times with no gap longer than ``gap_ns`` (each decoded after one seek)."""
    if wanted.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(wanted) > gap_ns) + 1
    bounds = np.concatenate([[0], cuts, [wanted.size]])
    return [(int(a), int(b)) for a, b in itertools.pairwise(bounds)]


class _Matcher:
    """Assigns decoded frames to sorted wanted times (nearest within the tolerance), converting each once."""

    def __init__(self, wanted: IntArray, tolerance_ns: int, pixel_format: PixelFormat) -> None:
        self.wanted = wanted
        self.tolerance = tolerance_ns
        self.pixel_format = pixel_format
        self.next = 0  # the first wanted time not yet assigned
        self.picked = np.full(wanted.size, -1, dtype=np.int64)
        self.picked_time = np.full(wanted.size, -1, dtype=np.int64)
        # The converted frames, written into one array as they come (at most one per wanted time): a list stacked at
        # the end would copy every frame once more (0.1 s of 450 frames at 640x480).
        self._images: npt.NDArray[np.uint8] | None = None
        self._count = 0
        self.decoded = 0
        self._previous: tuple[int, Any] | None = None  # (time, frame) of the last decoded frame
        self._converted: dict[int, int] = {}  # frame time -> image index
        self._grey = _Grey()

    def seek_to(self, index: int) -> None:
        self.next = max(self.next, index)
        self._previous = None

    def offer(self, time_ns: int, frame: Any) -> bool:
        """Take one decoded frame; False once every wanted time of the segment is behind it."""
        self.decoded += 1
        while self.next < self.wanted.size and self.wanted[self.next] <= time_ns:
            target = int(self.wanted[self.next])
            before = self._previous
            if before is not None and target - before[0] <= time_ns - target:
                self._assign(self.next, *before)
            else:
                self._assign(self.next, time_ns, frame)
            self.next += 1
        self._previous = (time_ns, frame)
        return self.next < self.wanted.size and time_ns <= int(self.wanted[-1]) + self.tolerance

    def finish(self, stop: int) -> None:
        """Wanted times after the last decoded frame take it if it is within the tolerance."""
        while self.next < stop and self._previous is not None:
            self._assign(self.next, *self._previous)
            self.next += 1
        self.next = max(self.next, stop)

    def _assign(self, index: int, time_ns: int, frame: Any) -> None:
        if abs(int(self.wanted[index]) - time_ns) > self.tolerance:
            return
        if time_ns not in self._converted:
            self._converted[time_ns] = self._count
            if self.pixel_format == "gray":
                self._grey.of(frame, self._slot((frame.height, frame.width)))
            else:
                image = np.asarray(frame.to_ndarray(format=self.pixel_format), dtype=np.uint8)
                self._slot(image.shape)[...] = image
            self._count += 1
        self.picked[index] = self._converted[time_ns]
        self.picked_time[index] = time_ns

    def _slot(self, shape: tuple[int, ...]) -> npt.NDArray[np.uint8]:
        """Where the next converted frame goes (ValueError for a frame of another size than the first)."""
        if self._images is None:
            self._images = np.empty((self.wanted.size, *shape), dtype=np.uint8)
        if self._images.shape[1:] != shape:
            raise ValueError(f"a frame of {shape} after frames of {self._images.shape[1:]}")
        slot: npt.NDArray[np.uint8] = self._images[self._count]
        return slot

    def images(self) -> npt.NDArray[np.uint8]:
        """The converted frames, (N, H, W[, 3])."""
        return np.zeros((0, 0, 0), dtype=np.uint8) if self._images is None else self._images[: self._count]


#: 8-bit planar YUV formats whose first plane is the luma a grey conversion rescales.
_LUMA_FIRST = frozenset({"yuv420p", "yuv422p", "yuv444p", "yuvj420p", "yuvj422p", "yuvj444p", "nv12", "nv21"})
#: Limited-range luma (16..235) to full-range grey, as libswscale's conversion to gray rounds it.
_LIMITED_TO_FULL = np.clip(np.round((np.arange(256) - 16) * 255.0 / 219.0), 0, 255).astype(np.uint8)


#: libswscale's colour range of a frame said to be JPEG (full) range.
_FULL_RANGE = 2
#: A frame is compared with libswscale's conversion only when its luma takes this many levels: a black or flat
#: frame looks the same rescaled or not.
_LEVELS_TO_COMPARE = 64


class _Grey:
    """A frame's grey pixels: its luma plane, rescaled by a lookup table from limited range (a third of libswscale's
    cost at 224 px), once a frame with enough grey levels showed it agrees with libswscale's conversion pixel for
    pixel; libswscale's own conversion until then, for other formats, and for good after a disagreement."""

    def __init__(self) -> None:
        self.fast: bool | None = None  # None: not yet compared

    def of(self, frame: Any, out: npt.NDArray[np.uint8]) -> None:
        """The frame's grey pixels written into ``out`` (H, W)."""
        if self.fast is False or frame.format.name not in _LUMA_FIRST:
            out[...] = frame.to_ndarray(format="gray")
            return
        plane = frame.planes[0]
        rows = np.frombuffer(plane, dtype=np.uint8, count=plane.line_size * frame.height)
        luma = rows.reshape(frame.height, plane.line_size)[:, : frame.width]  # each row padded to line_size
        full = frame.format.name.startswith("yuvj") or int(frame.color_range) == _FULL_RANGE
        if full:
            out[...] = luma
        else:
            require_cv2().LUT(luma, _LIMITED_TO_FULL, dst=out)
        if self.fast is None:
            reference = np.asarray(frame.to_ndarray(format="gray"), dtype=np.uint8)
            if np.count_nonzero(np.bincount(luma.ravel(), minlength=256)) >= _LEVELS_TO_COMPARE:
                self.fast = bool(np.array_equal(out, reference))
            out[...] = reference


def _decode_segment(container: Any, stream: Any, matcher: _Matcher, start: int, stop: int) -> None:
    """Seek to the key frame before ``wanted[start]`` and decode until ``wanted[stop - 1]`` is passed."""
    first = int(matcher.wanted[start]) - matcher.tolerance
    container.seek(max(int(Fraction(first, 1_000_000_000) / stream.time_base), 0), stream=stream, backward=True,
                   any_frame=False)
    matcher.seek_to(start)
    for frame in container.decode(stream):
        if frame.pts is None:
            continue
        # Presentation time as lerobot's decoders read it (pts * time_base, no start offset removed).
        time_ns = round(float(frame.pts * stream.time_base) * 1e9)
        if time_ns < first - matcher.tolerance and matcher.next == start:
            matcher.decoded += 1
            continue
        if not matcher.offer(time_ns, frame) or matcher.next >= stop:
            break
    matcher.finish(stop)


def _duplicates(picked: IntArray, images: npt.NDArray[np.uint8], level: float) -> BoolArray:
    """Rows whose frame is the previous present row's frame, or within ``level`` of it (mean absolute difference)."""
    out = np.zeros(picked.size, dtype=bool)
    present = np.flatnonzero(picked >= 0)
    if present.size < 2:
        return out
    a, b = picked[present[:-1]], picked[present[1:]]
    same = a == b
    differ = ~same
    if differ.any():
        same[differ] = mean_abs_differences(images, a[differ], b[differ]) <= level
    out[present[1:]] = same
    return out


def _black(picked: IntArray, images: npt.NDArray[np.uint8], level: int) -> BoolArray:
    if images.size == 0:
        return np.zeros(picked.size, dtype=bool)
    dark = bright_shares(images, level) < BLACK_SHARE
    out: BoolArray = (picked >= 0) & dark[np.maximum(picked, 0)]
    return out


def video_health(frames: VideoFrames, frame_index: npt.ArrayLike, key: str) -> VideoHealth:
    """Missing, duplicated and black rows by ``frame_index`` (one per row of ``frames``)."""
    index = np.asarray(frame_index, dtype=np.int64)
    present = frames.frame_time_ns >= 0
    mismatch = np.abs(frames.frame_time_ns - frames.time_ns)[present]
    return VideoHealth(
        key=key, rows=int(index.size), missing=tuple(index[frames.missing].tolist()),
        duplicated=tuple(index[frames.duplicate].tolist()), black=tuple(index[frames.black].tolist()),
        max_mismatch_ms=float(mismatch.max() / 1e6) if mismatch.size else float("nan"),
    )


def encode_video(
    path: str | Path,
    frames: Sequence[npt.NDArray[np.uint8]] | npt.NDArray[np.uint8],
    *,
    fps: int,
    codec: str = "libx264",
    pixel_format: str = "yuv420p",
    options: Mapping[str, str] | None = None,
) -> Path:
    """Write RGB frames ``(N, H, W, 3)`` as an mp4 at ``fps``, frame k at ``k / fps``, and return the path.

    ``codec`` is a PyAV encoder: ``libx264`` (H.264), ``libsvtav1`` (AV1), ``mpeg4`` (MPEG-4 Part 2),
    ``libx265`` (HEVC).
    """
    import av
    from av.video.stream import VideoStream

    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    time_base = Fraction(1, fps * 1000)
    with av.open(str(out), "w") as container:
        stream = container.add_stream(codec, rate=fps)
        if not isinstance(stream, VideoStream):
            raise VideoError(out, f"{codec} is not a video encoder")
        height, width = frames[0].shape[:2]
        stream.width, stream.height, stream.pix_fmt = width, height, pixel_format
        stream.codec_context.time_base = time_base
        quiet = {"libx265": {"x265-params": "log-level=error"}, "libsvtav1": {"svtav1-params": "log-level=0"}}
        stream.options = {**quiet.get(codec, {}), **(options or {})}
        for i, pixels in enumerate(frames):
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(pixels, dtype=np.uint8), format="rgb24")
            frame.pts = round(Fraction(i, fps) / time_base)
            frame.time_base = time_base
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return out
