"""Depth images: metadata and the windows detections need at read time, whole frames decoded lazily.

Encodings: ``16UC1``/``mono16`` in depth units (millimetres unless the log says otherwise, e.g.
librealsense's ``Depth_Units``), ``32FC1`` in metres, and ``compressedDepth`` (image_transport's
12-byte header, then a PNG of 16-bit depth units or of quantised inverse depth for 32FC1).
Every decoder returns metres as float32; 0 and NaN mean no depth.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Callable, Sequence
from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.messages.locator import FrameFetch, FrameLocator, cached_reader
from framechain.adapters.messages.rows import FrameRows, log_order
from framechain.arrays import IntArray
from framechain.timeline import DepthFrameTable, DepthWindows, TimelineError, normalize_frame

_U16 = frozenset({"16UC1", "mono16", "16SC1"})
_F32 = frozenset({"32FC1"})
#: Decoded frames kept per loader (a replay visits frames in time order; a few suffice).
CACHE_FRAMES = 8
_COMPRESSED_DEPTH_HEADER = 12
#: Windows kept at read time reach this far from their centre (7 x 7; replay's default is 5 x 5).
KEEP_HALF = 3
#: A detection's window is kept for the frames within this of its header stamp (replay's default gap is 50 ms).
KEEP_GAP_NS = 50_000_000
#: How long in log time a frame waits for detections logged after it (and detections for frames).
HORIZON_NS = 2_000_000_000


def depth_metadata(msg: Any) -> tuple[int, int, str] | None:
    """(width, height, encoding) of a depth Image or compressedDepth CompressedImage; None if not depth."""
    fmt = getattr(msg, "format", None)
    if fmt is not None and not hasattr(msg, "encoding"):
        if "compressedDepth" not in fmt:
            return None
        data = bytes(msg.data[: _COMPRESSED_DEPTH_HEADER + 24])
        png = data[_COMPRESSED_DEPTH_HEADER:]
        if png[:8] != b"\x89PNG\r\n\x1a\n" or len(png) < 24:
            return None
        width, height = struct.unpack(">II", png[16:24])
        base = fmt.split(";")[0].strip() or "16UC1"
        return int(width), int(height), f"compressedDepth {base}"
    encoding = str(msg.encoding)
    if encoding not in _U16 and encoding not in _F32:
        return None
    return int(msg.width), int(msg.height), encoding


def decode_depth(msg: Any, units_m: float = 0.001) -> npt.NDArray[np.float32]:
    """Depth in metres (H, W) float32 from an Image or a compressedDepth CompressedImage."""
    fmt = getattr(msg, "format", None)
    if fmt is not None and not hasattr(msg, "encoding"):
        return _decode_compressed_depth(bytes(msg.data), fmt, units_m)
    return pixels_to_metres(raw_depth_pixels(msg), units_m)


def raw_depth_pixels(msg: Any) -> npt.NDArray[Any]:
    """The (H, W) pixels of an uncompressed depth Image as stored (depth units or metres), a view where it can."""
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    encoding = str(msg.encoding)
    given = msg.data
    if isinstance(given, np.ndarray) and given.dtype == np.uint8:  # parse_cdr_image: a view into the message
        data: npt.NDArray[np.uint8] = given
    else:
        data = np.frombuffer(memoryview(given).cast("B"), dtype=np.uint8)  # a view, never a copy
    if encoding in _U16:
        code, size = ("i2" if encoding == "16SC1" else "u2"), 2
    elif encoding in _F32:
        code, size = "f4", 4
    else:
        raise TimelineError(f"depth encoding {encoding!r} is not 16UC1, mono16 or 32FC1")
    dtype = (">" if msg.is_bigendian else "<") + code
    if step == w * size:  # rows without padding (the usual case): the pixels are one run of bytes
        return data[: h * step].view(dtype).reshape(h, w)
    rows = data[: h * step].reshape(h, step)[:, : w * size]
    return np.ascontiguousarray(rows).view(dtype).reshape(h, w)


def pixels_to_metres(raw: npt.NDArray[Any], units_m: float) -> npt.NDArray[np.float32]:
    """Metres from :func:`raw_depth_pixels` (or any part of them: the conversion is per pixel)."""
    if raw.dtype.kind == "f":
        return raw.astype(np.float32)
    metres: npt.NDArray[np.float32] = np.multiply(raw, np.float32(units_m), dtype=np.float32)  # one pass
    return metres


def _decode_compressed_depth(data: bytes, fmt: str, units_m: float) -> npt.NDArray[np.float32]:
    from PIL import Image

    _, quant_a, quant_b = struct.unpack("<iff", data[:_COMPRESSED_DEPTH_HEADER])
    with Image.open(io.BytesIO(data[_COMPRESSED_DEPTH_HEADER:])) as img:
        values = np.asarray(img, dtype=np.uint16) if img.mode.startswith("I") else np.asarray(img)
    values = values.astype(np.float32)
    if fmt.split(";", maxsplit=1)[0].strip() == "32FC1":
        # image_transport: inverse depth quantised as value = quant_a / depth + quant_b.
        out = np.full(values.shape, np.nan, dtype=np.float32)
        ok = values > 0
        out[ok] = np.float32(quant_a) / (values[ok] - np.float32(quant_b))
        return out
    return (values * np.float32(units_m)).astype(np.float32)


def make_depth_loader(
    fetch: FrameFetch, locators: Sequence[FrameLocator], units_m: Sequence[float]
) -> Callable[[int], npt.NDArray[np.float32]]:
    """A DepthLoader that re-reads frame ``i`` from the log on demand (a small LRU cache)."""

    def read(i: int) -> npt.NDArray[np.float32]:
        loc = locators[i]
        return decode_depth(fetch(loc.topic, loc.log_time_ns, loc.ordinal), units_m[i])

    return cached_reader(read, CACHE_FRAMES)


class DepthWindowKeeper:
    """Keeps, while the log is read, the pixel windows around the detections each depth frame may serve.

    Frames (views of their raw pixels) wait up to :data:`HORIZON_NS` of log time for detections
    logged after them; detections wait as long for frames logged after them. A detection pairs with
    every frame of its camera frame within :data:`KEEP_GAP_NS` in header stamp; the replay picks
    the nearest and finds its window here, or cuts it from the frame re-read from the log when it is
    not (a detection logged far from its frame, a larger window, a gap above the kept one).
    Memory: the waiting frames, and per pair a (2 :data:`KEEP_HALF` + 1)^2 float32 window in flat arrays.
    """

    def __init__(self) -> None:
        # Camera frames by a number (comparing numbers, not strings, when frames and detections pair).
        self._frame_codes: dict[str, int] = {}
        self._frames: list[tuple[int, int, int, int, npt.NDArray[Any]]] = []  # row, frame code, stamp, log, raw
        self._obs_frame = np.zeros(0, dtype=np.int64)
        self._obs_stamp = np.zeros(0, dtype=np.int64)
        self._obs_log = np.zeros(0, dtype=np.int64)
        self._obs_rc = np.zeros((0, 2), dtype=np.int64)
        # Kept windows, a part per settle: depth row (read order), centre (row, col), raw values as
        # float32 (depth units and float32 metres convert exactly) and whether they are depth units.
        self._rows: list[IntArray] = []
        self._centres: list[IntArray] = []
        self._windows: list[npt.NDArray[np.float32]] = []
        self._in_units: list[npt.NDArray[np.bool_]] = []

    def add_frame(self, row: int, frame: str, stamp_ns: int, log_ns: int, raw: npt.NDArray[Any]) -> bool:
        """Hold a frame's raw pixels; True when the oldest has waited long enough (call :meth:`settle`)."""
        self._frames.append((row, self._code(frame), stamp_ns, log_ns, raw))
        return log_ns - self._frames[0][3] > HORIZON_NS

    def _code(self, frame: str) -> int:
        return self._frame_codes.setdefault(normalize_frame(frame), len(self._frame_codes))

    def add_observations(self, frame: Sequence[str], stamp_ns: Sequence[int], log_ns: Sequence[int],
                         u: npt.NDArray[np.float64], v: npt.NDArray[np.float64]) -> None:
        """Detections read since the last call (pixels that are not finite are never sampled)."""
        ok = np.isfinite(u) & np.isfinite(v)
        if not ok.any():
            return
        frames = np.asarray([self._code(f) for f in frame], dtype=np.int64)[ok]
        rc = np.stack([np.rint(v[ok]), np.rint(u[ok])], axis=1).astype(np.int64)
        self._obs_frame = np.concatenate([self._obs_frame, frames])
        self._obs_stamp = np.concatenate([self._obs_stamp, np.asarray(stamp_ns, dtype=np.int64)[ok]])
        self._obs_log = np.concatenate([self._obs_log, np.asarray(log_ns, dtype=np.int64)[ok]])
        self._obs_rc = np.concatenate([self._obs_rc, rc])

    def settle(self, *, final: bool) -> None:
        """Cut the windows of the frames that waited long enough (all when ``final``); drop old detections."""
        if not self._frames:
            return
        newest = max(self._frames[-1][3], int(self._obs_log.max()) if self._obs_log.size else self._frames[-1][3])
        due = len(self._frames) if final else sum(1 for f in self._frames if f[3] <= newest - HORIZON_NS // 2)
        settling = self._frames[:due]
        if settling and self._obs_log.size:
            self._cut(settling)
        del self._frames[:due]
        keep = np.zeros(self._obs_log.size, dtype=bool) if final else self._obs_log >= newest - HORIZON_NS
        self._obs_frame, self._obs_stamp = self._obs_frame[keep], self._obs_stamp[keep]
        self._obs_log, self._obs_rc = self._obs_log[keep], self._obs_rc[keep]

    def _cut(self, settling: list[tuple[int, int, int, int, npt.NDArray[Any]]]) -> None:
        """Every (frame, detection) pair at once; then one window cut per frame that has any."""
        stamps = np.asarray([f[2] for f in settling], dtype=np.int64)
        frames = np.asarray([f[1] for f in settling], dtype=np.int64)
        pairs = (np.abs(self._obs_stamp[None, :] - stamps[:, None]) <= KEEP_GAP_NS) & (
            self._obs_frame[None, :] == frames[:, None])
        which, obs = np.nonzero(pairs)  # grouped by frame
        if not which.size:
            return
        # Window pixel indices of every pair, clipped to its frame as pixel_windows clips them.
        shapes = np.asarray([f[4].shape for f in settling], dtype=np.int64).reshape(-1, 2)[which]
        offsets = np.arange(-KEEP_HALF, KEEP_HALF + 1)
        rc = self._obs_rc[obs]
        rows = np.clip(rc[:, :1] + offsets, 0, shapes[:, :1] - 1)[:, :, None]
        cols = np.clip(rc[:, 1:] + offsets, 0, shapes[:, 1:] - 1)[:, None, :]
        flat = rows * shapes[:, 1:, None] + cols  # (pairs, 7, 7) indexes into each frame's pixels in a row
        in_units = np.asarray([f[4].dtype.kind != "f" for f in settling], dtype=bool)[which]
        bounds = np.flatnonzero(np.r_[True, which[1:] != which[:-1], True])
        # Frames are separate buffers: one lookup in each (indexing: np.take copies a frame that is not
        # aligned, as views into a chunk often are); 16-bit integers convert to float32 exactly.
        parts = [settling[i][4].ravel()[flat[start:end]]
                 for i, start, end in zip(which[bounds[:-1]].tolist(), bounds[:-1].tolist(), bounds[1:].tolist(),
                                          strict=True)]
        windows = np.concatenate(parts).astype(np.float32, copy=False)
        self._rows.append(np.asarray([f[0] for f in settling], dtype=np.int64)[which])
        self._centres.append(rc)
        self._windows.append(windows)
        self._in_units.append(in_units)

    def lookup(self, read_rows: Sequence[int], units_m: Sequence[float]) -> DepthWindows:
        """DepthFrameTable.windows for table row i = read row ``read_rows[i]`` in depth units ``units_m[i]``."""
        rows = np.concatenate([np.zeros(0, dtype=np.int64), *self._rows])
        centres = np.concatenate([np.zeros((0, 2), dtype=np.int64), *self._centres])
        size = 2 * KEEP_HALF + 1
        kept = np.concatenate([np.zeros((0, size, size), dtype=np.float32), *self._windows])
        in_units = np.concatenate([np.zeros(0, dtype=bool), *self._in_units])
        self._rows, self._centres, self._windows, self._in_units = [], [], [], []
        read_of = np.asarray(read_rows, dtype=np.int64).reshape(-1)
        units = np.asarray(units_m, dtype=np.float32).reshape(-1)  # as np.float32(units) would round each

        def windows(frames: IntArray, centre_rows: IntArray, centre_cols: IntArray,
                    half: int) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
            out = np.zeros((frames.size, 2 * half + 1, 2 * half + 1), dtype=np.float32)
            if half > KEEP_HALF or not rows.size:
                return out, np.zeros(frames.size, dtype=bool)
            at = _first_match(rows, centres, read_of[frames], centre_rows, centre_cols)
            found = at >= 0
            hit = at[found]
            cut = KEEP_HALF - half
            part = kept[hit, cut : size - cut, cut : size - cut]
            # As pixels_to_metres converts the frame: float32 values times float32 units.
            scaled = in_units[hit]
            part[scaled] = np.multiply(part[scaled], units[frames[found][scaled]][:, None, None], dtype=np.float32)
            out[found] = part
            return out, found

        return windows


def _first_match(rows: IntArray, centres: IntArray, want_rows: IntArray, want_r: IntArray,
                 want_c: IntArray) -> IntArray:
    """Per wanted (read row, centre row, centre col): the first kept window with those, in keeping order (-1: none)."""
    k = rows.size
    key_row = np.concatenate([rows, want_rows])
    key_r = np.concatenate([centres[:, 0], np.asarray(want_r, dtype=np.int64)])
    key_c = np.concatenate([centres[:, 1], np.asarray(want_c, dtype=np.int64)])
    wanted = np.r_[np.zeros(k, dtype=bool), np.ones(want_rows.size, dtype=bool)]
    position = np.r_[np.arange(k), np.arange(want_rows.size)]
    # Equal keys together, kept windows first and in keeping order: a group's first is the match.
    order = np.lexsort((position, wanted, key_c, key_r, key_row))
    r, c, w = key_row[order], key_r[order], key_c[order]
    starts = np.r_[True, (r[1:] != r[:-1]) | (c[1:] != c[:-1]) | (w[1:] != w[:-1])]
    first = order[np.maximum.accumulate(np.where(starts, np.arange(order.size), 0))]
    match = np.full(want_rows.size, -1, dtype=np.int64)
    asks = wanted[order]
    match[position[order][asks]] = np.where(first[asks] < k, first[asks], -1)
    return match


def parse_ros1_image(raw: bytes | memoryview) -> SimpleNamespace:
    """A ROS 1 sensor_msgs/Image parsed field by field, tolerating trailing bytes.

    librealsense writes 4 bytes after the pixel data, which strict deserialisers reject.
    """
    buf = bytes(raw)
    seq, sec, nsec, n = struct.unpack_from("<IIII", buf, 0)
    o = 16
    frame_id = buf[o : o + n].decode("utf-8", "replace")
    o += n
    height, width, n_enc = struct.unpack_from("<III", buf, o)
    o += 12
    encoding = buf[o : o + n_enc].decode("ascii", "replace")
    o += n_enc
    is_bigendian, step, n_data = struct.unpack_from("<BII", buf, o)
    o += 9
    if o + n_data > len(buf):
        raise ValueError(f"image data of {n_data} bytes runs past the message end ({len(buf) - o} bytes left)")
    stamp = SimpleNamespace(sec=sec, nanosec=nsec)
    return SimpleNamespace(
        header=SimpleNamespace(seq=seq, stamp=stamp, frame_id=frame_id), height=height, width=width,
        encoding=encoding, is_bigendian=is_bigendian, step=step, data=memoryview(buf)[o : o + n_data],
    )


def depth_table(rows: FrameRows, fetch: FrameFetch | None, scale_of: Callable[[str], float],
                keeper: DepthWindowKeeper) -> DepthFrameTable:
    """The depth frames read (metadata) in log order, each topic's pixels scaled by ``scale_of(topic)`` when
    fetched, with the windows ``keeper`` cut around the detections (it has seen them all)."""
    table = DepthFrameTable(**rows.columns())
    order = log_order(table.log_time_ns, table.source)
    locators = [rows.locators[i] for i in order.tolist()]
    scales = [scale_of(loc.topic) for loc in locators]
    loader = make_depth_loader(fetch, locators, scales) if fetch is not None else None
    windows = keeper.lookup(order.tolist(), scales) if fetch is not None else None
    return replace(table.take(order), loader=loader, windows=windows)
