"""Camera images: metadata at read time, bytes fetched lazily (only the frames a sink shows).

``sensor_msgs/Image`` in a raw encoding (mono8, mono16, rgb8, bgr8, rgba8, bgra8, 16UC1, 32FC1)
is repacked without row padding, little-endian; ``CompressedImage`` (JPEG, PNG) keeps its bytes as
logged: nothing here decodes a picture.
"""

from __future__ import annotations

import functools
import io
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from framechain.adapters.messages.locator import FrameFetch, FrameLocator, cached_reader
from framechain.adapters.messages.rows import FrameRows, log_order
from framechain.timeline import ImageFrameTable, TimelineError
from framechain.timeline.frames import RAW_IMAGE_ENCODINGS, ImageLoader

#: Fetched images kept per loader (a sink visits a few frames, in time order).
CACHE_IMAGES = 4
_JPEG_MAGIC = b"\xff\xd8\xff"
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: JPEG markers without a length (fill, TEM, RSTn, SOI, EOI): none belongs before the scan.
_STANDALONE_MARKERS = frozenset({0x00, 0x01, 0xFF, *range(0xD0, 0xDA)})
_ALIASES = {"8uc1": "mono8", "8uc3": "bgr8", "16uc1": "16UC1", "32fc1": "32FC1", "8uc4": "bgra8"}


def raw_encoding(name: str) -> str | None:
    """The table's name of a ROS raw encoding (``8UC3`` is OpenCV's bgr8), None if not one."""
    low = name.strip().lower()
    if low in _ALIASES:
        return _ALIASES[low]
    for known in RAW_IMAGE_ENCODINGS:
        if known.lower() == low:
            return known
    return None


def image_metadata(msg: Any) -> tuple[int, int, str] | None:
    """(width, height, encoding) of an Image or a JPEG/PNG CompressedImage; None if neither.

    A compressed image's size comes from its header (PIL reads only the header, not the pixels).
    """
    fmt = getattr(msg, "format", None)
    if fmt is not None and not hasattr(msg, "encoding"):
        if "compresseddepth" in str(fmt).lower():
            return None
        data = memoryview(msg.data).cast("B")  # not copied: a JPEG is sized from its first few hundred bytes
        kind = "jpeg" if data[:3] == _JPEG_MAGIC else "png" if data[:8] == _PNG_MAGIC else None
        if kind is None:
            return None
        # A camera's JPEGs share their header (tables, size): Pillow sizes each header once.
        header = _jpeg_header(data) if kind == "jpeg" else None
        size = _header_size(header if header is not None else bytes(data))
        return None if size is None else (*size, kind)
    encoding = raw_encoding(str(msg.encoding))
    if encoding is None:
        return None
    return int(msg.width), int(msg.height), encoding


@functools.lru_cache(maxsize=8)
def _header_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) of a JPEG or PNG as Pillow reads it from the header; None if it cannot."""
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as img:
            width, height = img.size
    except (OSError, ValueError):
        return None
    return int(width), int(height)


def _jpeg_header(data: memoryview) -> bytes | None:
    """A JPEG's bytes up to the end of its start-of-scan segment: all Pillow reads to size it (None when
    the markers before the scan are not plain length-prefixed segments: Pillow then reads it all)."""
    pos, end = 2, len(data)
    while pos + 4 <= end:
        marker = data[pos + 1]
        if data[pos] != 0xFF or marker in _STANDALONE_MARKERS:
            return None
        segment_end = pos + 2 + ((data[pos + 2] << 8) | data[pos + 3])
        if segment_end <= pos + 3:
            return None
        if marker == 0xDA:  # start of scan
            return bytes(data[:segment_end]) if segment_end <= end else None
        pos = segment_end
    return None


def image_bytes(msg: Any, encoding: str) -> bytes:
    """The bytes the table holds for ``msg``: compressed as logged, raw packed little-endian."""
    if encoding not in RAW_IMAGE_ENCODINGS:
        return bytes(msg.data)
    channels, dtype = RAW_IMAGE_ENCODINGS[encoding]
    item = np.dtype(dtype).itemsize
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * channels * item
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if step < row or data.size < h * step:
        raise TimelineError(f"image {w}x{h} {encoding}: step {step} and {data.size} bytes do not hold it")
    rows = np.ascontiguousarray(data[: h * step].reshape(h, step)[:, :row])
    if item > 1 and bool(msg.is_bigendian):
        rows = rows.view(">" + dtype.lstrip("<")).astype(dtype)
    return rows.tobytes()


def make_image_loader(fetch: FrameFetch, locators: Sequence[FrameLocator],
                      encodings: Sequence[str]) -> ImageLoader:
    """An ImageLoader that re-reads image ``i`` from the log on demand (a small LRU cache)."""

    def read(i: int) -> bytes:
        loc = locators[i]
        return image_bytes(fetch(loc.topic, loc.log_time_ns, loc.ordinal), encodings[i])

    return cached_reader(read, CACHE_IMAGES)


def image_table(rows: FrameRows, fetch: FrameFetch | None) -> ImageFrameTable:
    """The camera images read (metadata) in log order; their pixels are fetched from the log when shown."""
    n = len(rows)
    table = ImageFrameTable(**rows.columns(), video_path=np.full(n, ""), video_time_ns=np.zeros(n, dtype=np.int64))
    order = log_order(table.log_time_ns, table.source)
    locators = [rows.locators[i] for i in order.tolist()]
    encodings = [str(e) for e in table.encoding[order]]
    loader = make_image_loader(fetch, locators, encodings) if fetch is not None else None
    return replace(table.take(order), loader=loader)
