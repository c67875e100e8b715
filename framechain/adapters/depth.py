"""Depth images: metadata at read time, pixels decoded lazily (only frames an observation needs).

Encodings: ``16UC1``/``mono16`` in depth units (millimetres unless the log says otherwise, e.g.
librealsense's ``Depth_Units``), ``32FC1`` in metres, and ``compressedDepth`` (image_transport's
12-byte header, then a PNG of 16-bit depth units or of quantised inverse depth for 32FC1).
Every decoder returns metres as float32; 0 and NaN mean no depth.
"""

from __future__ import annotations

import io
import struct
from collections import OrderedDict
from collections.abc import Callable, Sequence
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from framechain.timeline import TimelineError

if TYPE_CHECKING:
    from framechain.adapters.collect import DepthLocator

#: Fetches the decoded message at (topic, log_time_ns, ordinal among equal log times).
DepthFetch = Callable[[str, int, int], Any]

_U16 = frozenset({"16UC1", "mono16", "16SC1"})
_F32 = frozenset({"32FC1"})
#: Decoded frames kept per loader (a replay visits frames in time order; a few suffice).
CACHE_FRAMES = 8
_COMPRESSED_DEPTH_HEADER = 12


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
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    encoding = str(msg.encoding)
    data = np.frombuffer(memoryview(msg.data).cast("B"), dtype=np.uint8)  # a view, never a copy
    if encoding in _U16:
        kind = ">" if msg.is_bigendian else "<"
        code = "i2" if encoding == "16SC1" else "u2"
        rows = data[: h * step].reshape(h, step)[:, : w * 2]
        raw = np.ascontiguousarray(rows).view(kind + code).reshape(h, w)
        metres: npt.NDArray[np.float32] = np.multiply(raw, np.float32(units_m), dtype=np.float32)  # one pass
        return metres
    if encoding in _F32:
        kind = ">" if msg.is_bigendian else "<"
        rows = data[: h * step].reshape(h, step)[:, : w * 4]
        return np.ascontiguousarray(rows).view(kind + "f4").reshape(h, w).astype(np.float32)
    raise TimelineError(f"depth encoding {encoding!r} is not 16UC1, mono16 or 32FC1")


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
    fetch: DepthFetch, locators: Sequence[DepthLocator], units_m: Sequence[float]
) -> Callable[[int], npt.NDArray[np.float32]]:
    """A DepthLoader that re-reads frame ``i`` from the log on demand (a small LRU cache)."""
    cache: OrderedDict[int, npt.NDArray[np.float32]] = OrderedDict()

    def load(i: int) -> npt.NDArray[np.float32]:
        if i in cache:
            cache.move_to_end(i)
            return cache[i]
        loc = locators[i]
        image = decode_depth(fetch(loc.topic, loc.log_time_ns, loc.ordinal), units_m[i])
        cache[i] = image
        if len(cache) > CACHE_FRAMES:
            cache.popitem(last=False)
        return image

    return load


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
