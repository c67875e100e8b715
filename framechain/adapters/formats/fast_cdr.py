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
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.messages.kinds import Kind

if TYPE_CHECKING:
    from framechain.adapters.messages.collect import Collector

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
    strings: dict[FieldPath, tuple[int, int]]  # (offset, length in bytes) of each string's text
    counts: dict[FieldPath, int]  # sequence lengths
    #: Byte positions that are neither numbers nor string text (string lengths, sequence counts,
    #: padding, the header): they must match for a message to share this layout.
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

    def strings(self, path: FieldPath) -> list[str]:
        """The string at ``path`` of every message (decoded once per distinct value)."""
        offset, size = self.layout.strings[path]
        if size == 0:
            return [""] * len(self)
        block = np.ascontiguousarray(self.data[:, offset : offset + size]).view(f"V{size}")[:, 0]
        texts: dict[bytes, str] = {}
        out = []
        for raw in block.tolist():  # (a batch holds few distinct strings: each decoded once)
            text = texts.get(raw)
            if text is None:
                text = texts[raw] = raw.decode("utf-8", "replace")
            out.append(text)
        return out

    def string(self, path: FieldPath) -> str:
        """The string at ``path``, equal in every message (LayoutError when it is not)."""
        values = set(self.strings(path))
        if len(values) != 1:
            raise LayoutError(f"field {'.'.join(map(str, path))} differs between messages")
        return values.pop()

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
        self.strings: dict[FieldPath, tuple[int, int]] = {}
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
        if not self.ros1:  # CDR strings end in a NUL that is not part of the text
            if n == 0 or self.buf[at + n - 1] != 0:
                raise LayoutError(f"field {'.'.join(map(str, path))}: CDR string without its terminating NUL")
            n -= 1
        self.strings[path] = (at, n)

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
    free = np.zeros(len(raw), dtype=bool)  # bytes that may differ between messages of one layout
    for leaf in walker.leaves.values():
        free[leaf.offset : leaf.offset + np.dtype(leaf.dtype).itemsize * leaf.count] = True
    for offset, size in walker.strings.values():
        free[offset : offset + size] = True
    return Layout(len(raw), walker.leaves, walker.strings, walker.counts, np.flatnonzero(~free))


#: The layouts a route has met, by message length: each with the structure bytes of the message it was
#: walked from (a message whose structure bytes are those has that layout: walking it again would find it).
KnownLayouts = dict[int, list[tuple[Layout, npt.NDArray[np.uint8]]]]


def decode_batches(
    store: Any, typename: str, payloads: Sequence[bytes | memoryview], *, ros1: bool,
    known: KnownLayouts | None = None,
) -> tuple[list[Batch], npt.NDArray[np.intp]]:
    """Split ``payloads`` into batches of one layout each, and the rows no template fits.

    Rows that fail to walk (too short, not this type) are among the leftovers too, so the
    caller's slow path meets them and reports them as it would any undecodable message.
    ``known``: the layouts met in earlier calls for this type, looked up before walking a message
    (and added to): a read flushes a topic's messages hundreds of times, and a walk is Python.
    """
    sizes = [len(p) for p in payloads]
    lengths = np.array(sizes, dtype=np.int64)
    batches: list[Batch] = []
    leftover: list[npt.NDArray[np.intp]] = []
    for length in sorted(set(sizes)):  # (np.unique costs more than the few lengths of a flush)
        rows = np.flatnonzero(lengths == length)
        data = np.frombuffer(b"".join(bytes(payloads[i]) for i in rows.tolist()), dtype=np.uint8)
        data = data.reshape(rows.size, length) if length else np.zeros((rows.size, 0), dtype=np.uint8)
        pending = np.ones(rows.size, dtype=bool)
        for _ in range(MAX_TEMPLATES_PER_LENGTH):
            open_rows = np.flatnonzero(pending)
            if open_rows.size == 0:
                break
            first = int(open_rows[0])
            layout = _known_layout(known, data[first]) if known is not None else None
            if layout is None:
                try:
                    layout = layout_of(store, typename, data[first].tobytes(), ros1=ros1)
                except (LayoutError, KeyError, UnicodeDecodeError):
                    break
                if known is not None and len(known.setdefault(length, [])) < MAX_TEMPLATES_PER_LENGTH:
                    known[length].append((layout, data[first, layout.structure].copy()))
            same = (data[open_rows][:, layout.structure] == data[first, layout.structure]).all(axis=1)
            members = open_rows[same]
            batches.append(Batch(rows[members], layout, data[members]))
            pending[members] = False
        leftover.append(rows[pending])
    rest = np.sort(np.concatenate(leftover)) if leftover else np.zeros(0, dtype=np.intp)
    return batches, rest.astype(np.intp)


def _known_layout(known: KnownLayouts, message: npt.NDArray[np.uint8]) -> Layout | None:
    """The known layout of a message of that length whose structure bytes are the message's, if any."""
    for layout, structure in known.get(message.shape[0], ()):
        if np.array_equal(message[layout.structure], structure):
            return layout
    return None


def parse_cdr_image(raw: bytes | memoryview) -> SimpleNamespace:
    """A ROS 2 ``sensor_msgs/msg/Image`` (CDR) with its pixels as a view into ``raw``, not a copy.

    Reading a depth frame's metadata then costs nothing per pixel, and a frame re-read for its
    pixels is not copied before it is decoded. Fields and values as rosbags gives them.
    """
    buf, order, header, pos = _cdr_header(raw, "image")
    size = len(buf)
    if pos + 12 > size:
        raise LayoutError("image message ends inside its size fields")
    height, width, n = struct.unpack_from(order + "III", buf, pos)
    pos += 12
    end = pos + n
    if end + 1 > size:
        raise LayoutError("image message ends inside its encoding")
    encoding = bytes(buf[pos : end - 1]).decode("utf-8", "replace") if n else ""
    is_bigendian = int(buf[end])
    pos = (end + 1 + 3) & -4
    if pos + 8 > size:
        raise LayoutError("image message ends inside its step")
    step, n = struct.unpack_from(order + "II", buf, pos)
    pos += 8
    if pos + n > size:
        raise LayoutError(f"image data of {n} bytes runs past the message end ({size - pos} bytes left)")
    return SimpleNamespace(header=header, height=height, width=width, encoding=encoding,
                           is_bigendian=is_bigendian, step=step, data=np.frombuffer(buf[pos : pos + n], dtype=np.uint8))


def parse_cdr_compressed_image(raw: bytes | memoryview) -> SimpleNamespace:
    """A ROS 2 ``sensor_msgs/msg/CompressedImage`` (CDR), its bytes a view into ``raw`` as in
    :func:`parse_cdr_image` (a JPEG is sized from its header; nothing copies the rest)."""
    buf, order, header, pos = _cdr_header(raw, "compressed image")
    size = len(buf)
    if pos + 4 > size:
        raise LayoutError("compressed image message ends inside its format's length")
    (n,) = struct.unpack_from(order + "I", buf, pos)
    pos += 4
    end = pos + n
    if end > size:
        raise LayoutError("compressed image message ends inside its format")
    fmt = bytes(buf[pos : end - 1]).decode("utf-8", "replace") if n else ""
    pos = (end + 3) & -4
    if pos + 4 > size:
        raise LayoutError("compressed image message ends inside its data length")
    (n,) = struct.unpack_from(order + "I", buf, pos)
    pos += 4
    if pos + n > size:
        raise LayoutError(f"compressed image data of {n} bytes runs past the message end ({size - pos} bytes left)")
    return SimpleNamespace(header=header, format=fmt, data=np.frombuffer(buf[pos : pos + n], dtype=np.uint8))


def _cdr_header(raw: bytes | memoryview, what: str) -> tuple[memoryview, str, SimpleNamespace, int]:
    """(the message, its byte order, its std_msgs/Header, where the next field's length starts)."""
    buf = memoryview(raw)
    if len(buf) < 16:
        raise LayoutError(f"{what} message shorter than its header")
    order = "<" if buf[1] & 1 else ">"
    sec, nanosec, n = struct.unpack_from(order + "iII", buf, 4)
    pos = 16 + n
    if pos > len(buf):
        raise LayoutError(f"{what} message ends inside its frame_id")
    frame_id = bytes(buf[16 : pos - 1]).decode("utf-8", "replace") if n else ""
    header = SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec), frame_id=frame_id)
    return buf, order, header, (pos + 3) & -4  # offsets count the 4-byte header: 4-aligned is 4-aligned


# -- feeding the collector from batches -------------------------------------------------------------
NS = 1_000_000_000
_XYZ = ("x", "y", "z")
_XYZW = ("x", "y", "z", "w")


def _stamp_ns(batch: Batch, path: FieldPath) -> npt.NDArray[np.int64]:
    sec = batch.column((*path, "sec")).astype(np.int64)
    nanosec = batch.column((*path, "nanosec")).astype(np.int64)
    stamp: npt.NDArray[np.int64] = sec * NS + nanosec
    return stamp


def _message_major(columns: list[list[str]], n: int) -> list[str]:
    """Per-element columns (one list of n per sequence element) as rows message after message."""
    return [column[i] for i in range(n) for column in columns]


def feed_tf(col: Collector, topic: str, log_ns: npt.NDArray[np.int64], batch: Batch) -> None:
    """tf2_msgs/TFMessage rows as :meth:`Collector.tf` appends them, message after message."""
    n, m = len(batch), batch.count(("transforms",))
    stamps = np.empty((n, m), dtype=np.int64)
    vals = np.empty((n, m, 7))
    parents: list[list[str]] = []
    children: list[list[str]] = []
    for j in range(m):
        base: FieldPath = ("transforms", j)
        stamps[:, j] = _stamp_ns(batch, (*base, "header", "stamp"))
        for k, axis in enumerate(_XYZ):
            vals[:, j, k] = batch.column((*base, "transform", "translation", axis))
        for k, axis in enumerate(_XYZW):
            vals[:, j, 3 + k] = batch.column((*base, "transform", "rotation", axis))
        parents.append(batch.strings((*base, "header", "frame_id")))
        children.append(batch.strings((*base, "child_frame_id")))
    col.transforms.extend_messages(
        topic, log_ns.tolist(), m, parent=_message_major(parents, n), child=_message_major(children, n),
        stamp_ns=stamps.reshape(-1).tolist(), values=vals.reshape(-1).tolist(),
        static=topic.rstrip("/").endswith("tf_static"))


def feed_point(col: Collector, topic: str, log_ns: npt.NDArray[np.int64], batch: Batch) -> None:
    """geometry_msgs/PointStamped or PoseStamped as :meth:`Collector.point` appends them."""
    n = len(batch)
    leaves = batch.layout.leaves
    if ("point", "x") in leaves:
        xyz = [batch.column(("point", a)) for a in _XYZ]
        quat = [np.full(n, np.nan)] * 4
    else:
        xyz = [batch.column(("pose", "position", a)) for a in _XYZ]
        quat = [batch.column(("pose", "orientation", a)) for a in _XYZW]
    frames = batch.strings(("header", "frame_id"))
    stamps = _stamp_ns(batch, ("header", "stamp")).tolist()
    # every field read before the first row is added
    col.points.extend(topic, log_ns.tolist(), frame=frames, stamp_ns=stamps,
                      values=np.column_stack([*xyz, *quat]).astype(np.float64).reshape(-1).tolist())


def feed_camera_info(col: Collector, topic: str, log_ns: npt.NDArray[np.int64], batch: Batch) -> None:
    """sensor_msgs/CameraInfo (ROS 2 ``k``/``d``, ROS 1 ``K``/``D``) as :meth:`Collector.camera_info`."""
    leaves = batch.layout.leaves
    k_name, d_name = ("k", "d") if ("k",) in leaves else ("K", "D")
    k = batch.column((k_name,)).astype(np.float64).tolist()
    d = batch.column((d_name,)).astype(np.float64).tolist()
    frames = batch.strings(("header", "frame_id"))
    models = batch.strings(("distortion_model",))
    stamps = _stamp_ns(batch, ("header", "stamp")).tolist()
    widths = batch.column(("width",)).tolist()
    heights = batch.column(("height",)).tolist()
    col.cameras.extend(topic, log_ns.tolist(), frame=frames, stamp_ns=stamps, width=[int(w) for w in widths],
                       height=[int(h) for h in heights], model=models, k=k, d=d)


def feed_detections(col: Collector, topic: str, log_ns: npt.NDArray[np.int64], batch: Batch) -> None:
    """vision_msgs/Detection2DArray (ROS 2 >= 4, older ROS 2, ROS 1) as :meth:`Collector.detections`."""
    n, d = len(batch), batch.count(("detections",))
    leaves, strings = batch.layout.leaves, batch.layout.strings
    outer_stamp = _stamp_ns(batch, ("header", "stamp"))
    outer_frame = batch.strings(("header", "frame_id"))
    u, v, depth, score = (np.full((n, d), np.nan) for _ in range(4))
    stamp = np.empty((n, d), dtype=np.int64)
    ident: list[list[str]] = []
    label: list[list[str]] = []
    frame: list[list[str]] = []
    for j in range(d):
        det: FieldPath = ("detections", j)
        center: FieldPath = (*det, "bbox", "center")
        if (*center, "position", "x") in leaves:  # vision_msgs >= 4: Pose2D{position: Point2D, theta}
            center = (*center, "position")
        u[:, j] = batch.column((*center, "x"))
        v[:, j] = batch.column((*center, "y"))
        own = _stamp_ns(batch, (*det, "header", "stamp"))
        stamp[:, j] = np.where(own == 0, outer_stamp, own)
        frame.append([f or o for f, o in zip(batch.strings((*det, "header", "frame_id")), outer_frame, strict=True)])
        if (*det, "id") in strings:
            ident.append(batch.strings((*det, "id")))
        elif (*det, "id") in leaves:
            ident.append([str(x) for x in batch.column((*det, "id")).tolist()])
        elif (*det, "tracking_id") in strings:
            ident.append(batch.strings((*det, "tracking_id")))
        else:
            ident.append([""] * n)
        if batch.count((*det, "results")):
            r0: FieldPath = (*det, "results", 0)
            if (*r0, "hypothesis", "score") in leaves:  # vision_msgs >= 3
                label.append(batch.strings((*r0, "hypothesis", "class_id")))
                score[:, j] = batch.column((*r0, "hypothesis", "score"))
            else:  # ROS 1 (int64 id) and vision_msgs 2 (string id)
                label.append(batch.strings((*r0, "id")) if (*r0, "id") in strings
                             else [str(x) for x in batch.column((*r0, "id")).tolist()])
                score[:, j] = batch.column((*r0, "score"))
            z = batch.column((*r0, "pose", "pose", "position", "z")).astype(np.float64)
            with np.errstate(invalid="ignore"):
                given = np.isfinite(z) & (z > 0)
            depth[given, j] = z[given]
        else:
            label.append([""] * n)
    given_count = int(np.isfinite(depth).sum())
    if given_count:
        col.depth_from_pose[topic] = col.depth_from_pose.get(topic, 0) + given_count

    col.observations.extend(
        topic, id_text=_message_major(ident, n), stamp_ns=stamp.reshape(-1).tolist(),
        log_time_ns=np.repeat(log_ns, d).tolist(), frame=_message_major(frame, n),
        uvd=np.stack([u, v, depth], axis=2).reshape(-1).tolist(), label=_message_major(label, n),
        score=score.reshape(-1).tolist())


Feeder = Callable[["Collector", str, npt.NDArray[np.int64], Batch], None]
#: Message types read in batches, by their normalised name, and what feeds their rows.
FEEDERS: dict[tuple[Kind, str], Feeder] = {
    (Kind.TF, "tf2_msgs/TFMessage"): feed_tf,
    (Kind.TF, "tf/tfMessage"): feed_tf,
    (Kind.POINT, "geometry_msgs/PointStamped"): feed_point,
    (Kind.POINT, "geometry_msgs/PoseStamped"): feed_point,
    (Kind.CAMERA_INFO, "sensor_msgs/CameraInfo"): feed_camera_info,
    (Kind.DETECTIONS, "vision_msgs/Detection2DArray"): feed_detections,
}
