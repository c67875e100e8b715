"""Many messages of one type decoded at once with numpy, by their fixed byte layout.

A ROS message's byte layout (where each number sits) depends only on its strings and sequence
lengths. Messages of a topic usually repeat them (the same frame names, the same number of
transforms), so one message walked field by field (the *template*) gives the offset of every
number, and every other message of the same length whose non-number bytes (string lengths and
contents, sequence counts, CDR padding, the encapsulation header) equal the template's has its
numbers at the same offsets: each field is then one strided numpy read over all of them.
Messages that differ from every template are left to the caller (rosbags' deserialiser).

Both ROS 2 CDR (little- or big-endian, with the 4-byte encapsulation header and alignment of
each primitive to its size, counted from the end of that header) and ROS 1 serialisation (no
header, no alignment, strings without the terminating NUL) are walked from the definitions in a
rosbags typestore, so any type the log defines is understood the same way rosbags does.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
import numpy.typing as npt

#: Field path inside a message: names and sequence/array indexes, e.g. ("transforms", 0, "header").
FieldPath = tuple[str | int, ...]

_SIZES = {
    "bool": 1, "byte": 1, "char": 1, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2, "int32": 4, "uint32": 4,
    "int64": 8, "uint64": 8, "float32": 4, "float64": 8,
}
_CODES = {
    "bool": "u1", "byte": "u1", "char": "u1", "int8": "i1", "uint8": "u1", "int16": "i2", "uint16": "u2",
    "int32": "i4", "uint32": "u4", "int64": "i8", "uint64": "u8", "float32": "f4", "float64": "f8",
}
#: Templates tried per message length before the rest are left to the slow path.
MAX_TEMPLATES_PER_LENGTH = 4
_NODE_BASE, _NODE_NAME, _NODE_ARRAY, _NODE_SEQUENCE = 1, 2, 3, 4


class LayoutError(ValueError):
    """A message is shorter than its definition says, or its definition is not understood."""


@dataclass(frozen=True)
class Leaf:
    """A run of numbers in a message: ``count`` values of ``dtype`` from byte ``offset``."""

    offset: int
    dtype: str  # numpy dtype with byte order, e.g. "<f8"
    count: int
    array: bool  # a fixed array or sequence (a column of shape (n, count)), else a scalar (n,)


@dataclass(frozen=True)
class Layout:
    """Where every field of one message sits; see the module docstring."""

    length: int
    leaves: dict[FieldPath, Leaf]
    strings: dict[FieldPath, str]
    counts: dict[FieldPath, int]  # sequence lengths
    #: Byte positions that are not numbers: they must match for a message to share this layout.
    structure: npt.NDArray[np.intp]


@dataclass(frozen=True)
class Batch:
    """Messages (``rows`` of the input) sharing one layout; ``column(path)`` gives a field of all."""

    rows: npt.NDArray[np.intp]
    layout: Layout
    data: npt.NDArray[np.uint8]  # (len(rows), layout.length)

    def column(self, path: FieldPath) -> npt.NDArray[Any]:
        leaf = self.layout.leaves[path]
        size = np.dtype(leaf.dtype).itemsize
        block = np.ascontiguousarray(self.data[:, leaf.offset : leaf.offset + size * leaf.count])
        values = block.view(leaf.dtype)
        return values if leaf.array else values[:, 0]

    def string(self, path: FieldPath) -> str:
        return self.layout.strings[path]

    def count(self, path: FieldPath) -> int:
        return self.layout.counts[path]

    def __len__(self) -> int:
        return int(self.rows.size)


class _Walker:
    """Walks one serialised message along its definition, recording where each field is."""

    def __init__(self, store: Any, buf: bytes, *, ros1: bool) -> None:
        self.store = store
        self.buf = buf
        self.ros1 = ros1
        if ros1:
            self.pos, self.origin, self.order = 0, 0, "<"
        else:
            if len(buf) < 4:
                raise LayoutError("shorter than the CDR encapsulation header")
            self.order = "<" if buf[1] & 1 else ">"
            self.pos, self.origin = 4, 4
        self.leaves: dict[FieldPath, Leaf] = {}
        self.strings: dict[FieldPath, str] = {}
        self.counts: dict[FieldPath, int] = {}

    def _align(self, size: int) -> None:
        if not self.ros1 and size > 1:
            rel = self.pos - self.origin
            self.pos = self.origin + ((rel + size - 1) & -size)

    def _take(self, size: int) -> int:
        start = self.pos
        self.pos += size
        if self.pos > len(self.buf):
            raise LayoutError(f"message ends at byte {len(self.buf)}, field needs {self.pos}")
        return start

    def _u32(self) -> int:
        self._align(4)
        at = self._take(4)
        return int(struct.unpack_from(self.order + "I", self.buf, at)[0])

    def _string(self, path: FieldPath) -> None:
        n = self._u32()
        at = self._take(n)
        raw = self.buf[at : at + n]
        if not self.ros1:
            raw = raw[:-1] if raw.endswith(b"\x00") else raw
        self.strings[path] = raw.decode("utf-8", "replace")

    def _primitives(self, path: FieldPath, name: str, count: int, *, array: bool) -> None:
        size = _SIZES[name]
        if count:
            self._align(size)
        at = self._take(size * count)
        self.leaves[path] = Leaf(at, self.order + _CODES[name], count, array)

    def message(self, typename: str, path: FieldPath = ()) -> None:
        for name, desc in self.store.fielddefs[typename][1]:
            self.field((*path, name), desc)

    def field(self, path: FieldPath, desc: Any) -> None:
        node = int(desc[0])
        if node == _NODE_NAME:
            self.message(desc[1], path)
        elif node == _NODE_BASE:
            base = desc[1][0]
            if base == "string":
                self._string(path)
            elif base in _SIZES:
                self._primitives(path, base, 1, array=False)
            else:
                raise LayoutError(f"field {'.'.join(map(str, path))}: type {base} is not understood")
        elif node in (_NODE_ARRAY, _NODE_SEQUENCE):
            sub, length = desc[1]
            if node == _NODE_SEQUENCE:
                length = self._u32()
                self.counts[path] = length
            if int(sub[0]) == _NODE_BASE and sub[1][0] != "string":
                self._primitives(path, sub[1][0], length, array=True)
            else:
                for i in range(length):
                    self.field((*path, i), sub)
        else:
            raise LayoutError(f"field {'.'.join(map(str, path))}: node type {node} is not understood")


def layout_of(store: Any, typename: str, raw: bytes, *, ros1: bool) -> Layout:
    """The layout of one serialised message of ``typename`` (defined in ``store``, rosbags' spelling)."""
    walker = _Walker(store, raw, ros1=ros1)
    walker.message(typename)
    if walker.pos != len(raw) and not (not ros1 and len(raw) - walker.pos < 4):
        # CDR may end with up to 3 bytes of padding; anything else is not this type.
        raise LayoutError(f"{len(raw) - walker.pos} bytes left after the message")
    numeric = np.zeros(len(raw), dtype=bool)
    for leaf in walker.leaves.values():
        numeric[leaf.offset : leaf.offset + np.dtype(leaf.dtype).itemsize * leaf.count] = True
    return Layout(len(raw), walker.leaves, walker.strings, walker.counts, np.flatnonzero(~numeric))


def decode_batches(
    store: Any, typename: str, payloads: Sequence[bytes | memoryview], *, ros1: bool
) -> tuple[list[Batch], npt.NDArray[np.intp]]:
    """Split ``payloads`` into batches of one layout each, and the rows no template fits.

    Rows that fail to walk (too short, not this type) are among the leftovers too, so the
    caller's slow path meets them and reports them as it would any undecodable message.
    """
    lengths = np.fromiter((len(p) for p in payloads), dtype=np.int64, count=len(payloads))
    batches: list[Batch] = []
    leftover: list[npt.NDArray[np.intp]] = []
    for length in np.unique(lengths).tolist():
        rows = np.flatnonzero(lengths == length)
        data = np.frombuffer(b"".join(bytes(payloads[i]) for i in rows.tolist()), dtype=np.uint8)
        data = data.reshape(rows.size, length) if length else np.zeros((rows.size, 0), dtype=np.uint8)
        pending = np.ones(rows.size, dtype=bool)
        for _ in range(MAX_TEMPLATES_PER_LENGTH):
            open_rows = np.flatnonzero(pending)
            if open_rows.size == 0:
                break
            first = int(open_rows[0])
            try:
                layout = layout_of(store, typename, data[first].tobytes(), ros1=ros1)
            except (LayoutError, KeyError, UnicodeDecodeError):
                break
            same = (data[open_rows][:, layout.structure] == data[first, layout.structure]).all(axis=1)
            members = open_rows[same]
            batches.append(Batch(rows[members], layout, data[members]))
            pending[members] = False
        leftover.append(rows[pending])
    rest = np.sort(np.concatenate(leftover)) if leftover else np.zeros(0, dtype=np.intp)
    return batches, rest.astype(np.intp)


def parse_cdr_image(raw: bytes | memoryview) -> SimpleNamespace:
    """A ROS 2 ``sensor_msgs/msg/Image`` (CDR) with its pixels as a view into ``raw``, not a copy.

    Reading a depth frame's metadata then costs nothing per pixel, and a frame re-read for its
    pixels is not copied before it is decoded. Fields and values as rosbags gives them.
    """
    buf = memoryview(raw)
    if len(buf) < 4:
        raise LayoutError("shorter than the CDR encapsulation header")
    order = "<" if buf[1] & 1 else ">"
    pos = 4

    def u32() -> int:
        nonlocal pos
        pos = 4 + ((pos - 4 + 3) & -4)
        if pos + 4 > len(buf):
            raise LayoutError("image message ends inside a field")
        (value,) = struct.unpack_from(order + "I", buf, pos)
        pos += 4
        return int(value)

    def string() -> str:
        nonlocal pos
        n = u32()
        if pos + n > len(buf):
            raise LayoutError("image message ends inside a string")
        text = bytes(buf[pos : pos + n]).rstrip(b"\x00").decode("utf-8", "replace")
        pos += n
        return text

    sec = u32()
    nanosec = u32()
    if sec >= 1 << 31:  # builtin_interfaces/Time.sec is int32
        sec -= 1 << 32
    frame_id = string()
    height = u32()
    width = u32()
    encoding = string()
    if pos >= len(buf):
        raise LayoutError("image message ends before is_bigendian")
    is_bigendian = int(buf[pos])
    pos += 1
    step = u32()
    n = u32()
    if pos + n > len(buf):
        raise LayoutError(f"image data of {n} bytes runs past the message end ({len(buf) - pos} bytes left)")
    header = SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec), frame_id=frame_id)
    return SimpleNamespace(header=header, height=height, width=width, encoding=encoding,
                           is_bigendian=is_bigendian, step=step, data=np.frombuffer(buf[pos : pos + n], dtype=np.uint8))
