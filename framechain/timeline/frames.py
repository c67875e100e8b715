"""Lazy frame tables: depth images and camera images, their metadata columnar, their pixels loaded
on demand (only the frames a detection or a sink needs are ever decoded)."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

import numpy as np
import numpy.typing as npt

from framechain.arrays import IntArray, StrArray
from framechain.timeline.columns import Column, ColumnTable
from framechain.timeline.errors import TimelineError
from framechain.timeline.tables import normalize_frames

#: Loads depth frame ``i`` of a table as metres, shape (height, width), float32; NaN or 0 = none.
DepthLoader = Callable[[int], npt.NDArray[np.float32]]
#: Pixel windows kept from the read: (frame per window, centre rows, centre cols, half) ->
#: ((k, 2 half + 1, 2 half + 1) metres, (k,) which were kept; the others hold nothing meaningful).
DepthWindows = Callable[[IntArray, IntArray, IntArray, int],
                        "tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]"]


def pixel_windows(image: npt.NDArray[Any], centre_rows: IntArray, centre_cols: IntArray, half: int) -> npt.NDArray[Any]:
    """(k, 2 half + 1, 2 half + 1) windows of ``image`` around the centres, indices clipped to the image.

    Pixels outside the image repeat the border: callers mask them by position.
    """
    h, w = image.shape
    offsets = np.arange(-half, half + 1)
    rows = np.clip(np.asarray(centre_rows, dtype=np.int64)[:, None] + offsets[None, :], 0, h - 1)
    cols = np.clip(np.asarray(centre_cols, dtype=np.int64)[:, None] + offsets[None, :], 0, w - 1)
    windows: npt.NDArray[Any] = image[rows[:, :, None], cols[:, None, :]]
    return windows


_Loaded = TypeVar("_Loaded")


def _rows_loader(base: Callable[[int], _Loaded], rows: IntArray) -> Callable[[int], _Loaded]:
    """A loader of the selected ``rows`` (row ``i`` of the selection is row ``rows[i]`` of ``base``)."""
    return lambda i: base(int(rows[i]))


def _part_of(offsets: IntArray, i: int) -> tuple[int, int]:
    """Which part row ``i`` of a concatenation (parts starting at ``offsets``) is in, and its row there."""
    k = int(np.searchsorted(offsets, i, side="right") - 1)
    return k, i - int(offsets[k])


def _concat_loader(
    loaders: list[Callable[[int], _Loaded] | None], offsets: IntArray, missing: str
) -> Callable[[int], _Loaded]:
    """The loader of a concatenation: each row loaded by its part's loader (``missing``: none there)."""

    def load(i: int) -> _Loaded:
        k, row = _part_of(offsets, i)
        inner = loaders[k]
        if inner is None:
            raise TimelineError(missing)
        return inner(row)

    return load


@dataclass(frozen=True)
class DepthFrameTable(ColumnTable):
    """Depth images: metadata is columnar, pixels are loaded lazily through ``loader``.

    ``encoding`` is the source encoding (``16UC1`` in millimetres, ``32FC1`` in metres,
    ``compressedDepth``); the loader always returns metres so nothing downstream cares.
    """

    COLUMNS: ClassVar[dict[str, Column]] = {
        "frame": Column("str"),
        "stamp_ns": Column("i8"),
        "log_time_ns": Column("i8"),
        "width": Column("i8"),
        "height": Column("i8"),
        "encoding": Column("str"),
        "source": Column("str"),
    }
    frame: StrArray
    stamp_ns: IntArray
    log_time_ns: IntArray
    width: IntArray
    height: IntArray
    encoding: StrArray
    source: StrArray
    loader: DepthLoader | None = field(default=None, compare=False, repr=False)
    #: Windows kept while the log was read (no second read of their frames); None: none kept.
    windows: DepthWindows | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "frame", normalize_frames(self.frame))

    def load(self, index: int) -> npt.NDArray[np.float32]:
        """Depth frame ``index`` in metres."""
        if self.loader is None:
            raise TimelineError("DepthFrameTable has no pixel loader")
        return self.loader(index)

    def load_windows(
        self, frames: IntArray, centre_rows: IntArray, centre_cols: IntArray, half: int
    ) -> npt.NDArray[np.float32]:
        """(k, 2 half + 1, 2 half + 1) metres around each centre in its frame ``frames[i]`` (see
        :func:`pixel_windows`).

        The windows kept at read time where they were, all at once; the others cut from their whole
        frames, each frame loaded once: the same values.
        """
        frames = np.asarray(frames, dtype=np.int64)
        size = 2 * half + 1
        windows = np.empty((frames.size, size, size), dtype=np.float32)
        found = np.zeros(frames.size, dtype=bool)
        if self.windows is not None and frames.size:
            kept, found = self.windows(frames, centre_rows, centre_cols, half)
            windows[found] = kept[found]
        missing = np.flatnonzero(~found)
        missing = missing[np.argsort(frames[missing], kind="stable")]
        of_frame = frames[missing]
        bounds = np.flatnonzero(np.r_[True, of_frame[1:] != of_frame[:-1], True]).tolist() if missing.size else []
        for start, end in itertools.pairwise(bounds):
            mine = missing[start:end]
            windows[mine] = pixel_windows(self.load(int(frames[mine[0]])), centre_rows[mine], centre_cols[mine], half)
        return windows

    def take(self, index: npt.ArrayLike) -> DepthFrameTable:
        """Rows selected; the loader keeps pointing at the original rows."""
        rows = np.arange(len(self))[np.asarray(index)]
        base, base_windows = self.loader, self.windows
        table = super().take(rows)
        if base is None:
            return table
        windows: DepthWindows | None = None
        if base_windows is not None:
            def windows(i: IntArray, r: IntArray, c: IntArray, half: int) -> tuple[npt.NDArray[np.float32],
                                                                                  npt.NDArray[np.bool_]]:
                return base_windows(rows[i], r, c, half)
        return dataclasses.replace(table, loader=_rows_loader(base, rows), windows=windows)

    @classmethod
    def from_arrays(
        cls, frame: str, stamp_ns: npt.ArrayLike, images_m: npt.NDArray[Any], *, source: str = ""
    ) -> DepthFrameTable:
        """In-memory depth frames (N, H, W) in metres: for tests, notebooks and the generator."""
        images = np.asarray(images_m, dtype=np.float32)
        stamps = np.asarray(stamp_ns, dtype=np.int64)
        n, h, w = images.shape
        return cls(
            frame=np.full(n, frame), stamp_ns=stamps, log_time_ns=stamps, width=np.full(n, w),
            height=np.full(n, h), encoding=np.full(n, "32FC1"), source=np.full(n, source),
            loader=lambda i: images[i],
        )

    @classmethod
    def concat(cls, tables: Iterable[DepthFrameTable]) -> DepthFrameTable:
        parts = list(tables)
        merged = super().concat(parts)
        offsets = np.cumsum([0, *[len(t) for t in parts]])
        load = _concat_loader([t.loader for t in parts], offsets, "DepthFrameTable part has no pixel loader")
        kept = [t.windows for t in parts]

        def windows(i: IntArray, r: IntArray, c: IntArray, half: int) -> tuple[npt.NDArray[np.float32],
                                                                              npt.NDArray[np.bool_]]:
            size = 2 * half + 1
            out, found = np.empty((i.size, size, size), dtype=np.float32), np.zeros(i.size, dtype=bool)
            part = np.searchsorted(offsets, i, side="right") - 1
            for k, inner in enumerate(kept):
                mine = np.flatnonzero(part == k)
                if inner is not None and mine.size:
                    out[mine], found[mine] = inner(i[mine] - offsets[k], r[mine], c[mine], half)
            return out, found

        any_kept = any(w is not None for w in kept)
        return dataclasses.replace(merged, loader=load if parts else None, windows=windows if any_kept else None)


ImageLoader = Callable[[int], bytes]

#: Raw encodings an :class:`ImageFrameTable` holds, with (channels, NumPy dtype) of their pixels.
RAW_IMAGE_ENCODINGS: Mapping[str, tuple[int, str]] = {
    "mono8": (1, "u1"), "8UC1": (1, "u1"), "mono16": (1, "<u2"), "16UC1": (1, "<u2"), "32FC1": (1, "<f4"),
    "rgb8": (3, "u1"), "bgr8": (3, "u1"), "rgba8": (4, "u1"), "bgra8": (4, "u1"),
}
#: Encodings of compressed images (the bytes of the file) and of frames of a video file.
COMPRESSED_IMAGE_ENCODINGS = frozenset({"jpeg", "png"})
VIDEO_ENCODING = "video"


@dataclass(frozen=True)
class ImageFrameTable(ColumnTable):
    """Camera images: metadata is columnar, bytes are loaded lazily through ``loader``.

    ``encoding`` is a raw encoding of :data:`RAW_IMAGE_ENCODINGS` (the loader returns the pixels
    packed row after row, little-endian, no row padding), ``jpeg``/``png`` (the loader returns the
    compressed bytes as logged, never decoded), or ``video``: a frame of the video file
    ``video_path`` at ``video_time_ns`` from the file's start (nothing to load; a viewer decodes
    it). ``width``/``height`` are 0 where the log does not say (a compressed image's header is
    read when it is collected).
    """

    COLUMNS: ClassVar[dict[str, Column]] = {
        "frame": Column("str"),
        "stamp_ns": Column("i8"),
        "log_time_ns": Column("i8"),
        "width": Column("i8"),
        "height": Column("i8"),
        "encoding": Column("str"),
        "source": Column("str"),
        "video_path": Column("str"),
        "video_time_ns": Column("i8"),
    }
    frame: StrArray
    stamp_ns: IntArray
    log_time_ns: IntArray
    width: IntArray
    height: IntArray
    encoding: StrArray
    source: StrArray
    video_path: StrArray
    video_time_ns: IntArray
    loader: ImageLoader | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "frame", normalize_frames(self.frame))

    @property
    def video_frames(self) -> npt.NDArray[np.bool_]:
        """Per row: a frame of a video file (``video_time_ns`` -1 is a row its video has no frame for)."""
        out: npt.NDArray[np.bool_] = (self.encoding == VIDEO_ENCODING) & (self.video_time_ns >= 0)
        return out

    def load(self, index: int) -> bytes:
        """The bytes of image ``index`` (packed pixels, or the compressed file as logged)."""
        if str(self.encoding[index]) == VIDEO_ENCODING:
            raise TimelineError(f"image {index} is a frame of the video {self.video_path[index]}: nothing to load")
        if self.loader is None:
            raise TimelineError("ImageFrameTable has no byte loader")
        return self.loader(index)

    def pixels(self, index: int) -> npt.NDArray[Any]:
        """Image ``index`` as an (H, W) or (H, W, C) array of a raw encoding (colour order as encoded)."""
        enc = str(self.encoding[index])
        if enc not in RAW_IMAGE_ENCODINGS:
            raise TimelineError(f"image {index} is {enc!r}, not a raw encoding: decode it with an image library")
        channels, dtype = RAW_IMAGE_ENCODINGS[enc]
        h, w = int(self.height[index]), int(self.width[index])
        flat = np.frombuffer(self.load(index), dtype=dtype)
        if flat.size != h * w * channels:
            raise TimelineError(f"image {index} ({enc}) holds {flat.size} values, not {h}x{w}x{channels}")
        return flat.reshape((h, w) if channels == 1 else (h, w, channels))

    def take(self, index: npt.ArrayLike) -> ImageFrameTable:
        """Rows selected; the loader keeps pointing at the original rows."""
        rows = np.arange(len(self))[np.asarray(index)]
        base = self.loader
        table = super().take(rows)
        if base is None:
            return table
        return dataclasses.replace(table, loader=_rows_loader(base, rows))

    @classmethod
    def from_arrays(
        cls, frame: str, stamp_ns: npt.ArrayLike, images: npt.NDArray[Any], *, encoding: str = "rgb8",
        source: str = "",
    ) -> ImageFrameTable:
        """In-memory raw images (N, H, W[, C]) of one encoding: for tests, notebooks and the generator."""
        if encoding not in RAW_IMAGE_ENCODINGS:
            raise TimelineError(f"ImageFrameTable.from_arrays: {encoding!r} is not a raw encoding")
        channels, dtype = RAW_IMAGE_ENCODINGS[encoding]
        pix = np.ascontiguousarray(images, dtype=dtype)
        if pix.ndim != (3 if channels == 1 else 4) or (channels > 1 and pix.shape[3] != channels):
            raise TimelineError(f"ImageFrameTable.from_arrays: shape {pix.shape} does not fit {encoding}")
        stamps = np.asarray(stamp_ns, dtype=np.int64)
        n, h, w = pix.shape[:3]
        return cls(
            frame=np.full(n, frame), stamp_ns=stamps, log_time_ns=stamps, width=np.full(n, w),
            height=np.full(n, h), encoding=np.full(n, encoding), source=np.full(n, source),
            video_path=np.full(n, ""), video_time_ns=np.zeros(n, dtype=np.int64),
            loader=lambda i: pix[i].tobytes(),
        )

    @classmethod
    def concat(cls, tables: Iterable[ImageFrameTable]) -> ImageFrameTable:
        parts = list(tables)
        merged = super().concat(parts)
        offsets = np.cumsum([0, *[len(t) for t in parts]])
        load = _concat_loader([t.loader for t in parts], offsets, "ImageFrameTable part has no byte loader")
        return dataclasses.replace(merged, loader=load if parts else None)
