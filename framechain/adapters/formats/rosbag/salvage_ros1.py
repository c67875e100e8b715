"""ROS 1 bags (format 2.0) read by a linear scan of their records, for bags whose index is missing
or damaged (a recorder killed or a disk filled before ``rosbag`` wrote the index).

The record layout (from the bag format 2.0 specification): after the ``#ROSBAG V2.0\\n`` line,
records of ``u32 header length, header, u32 data length, data``; a header is fields of ``u32
length, name=value``; the ``op`` field says the kind (0x02 message, 0x03 bag header, 0x04 index
data, 0x05 chunk, 0x06 chunk info, 0x07 connection). Chunks hold connection and message records,
uncompressed or compressed with bz2 or lz4 (both stream, so a chunk cut short still gives back
its complete records). After damage the scan resynchronises on the next record that parses.
"""

from __future__ import annotations

import mmap
import struct
from collections import Counter
from collections.abc import Generator, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from framechain.adapters.errors import CorruptLogError, EmptyLogError, SchemaError
from framechain.adapters.formats.decode_loop import DecodeLoop, ProgressFn, Route
from framechain.adapters.formats.decoders import Decoder, ros_decoder, ros_typename
from framechain.adapters.formats.salvage_report import SalvageReport, StreamDecompressor
from framechain.adapters.messages.collect import Collector
from framechain.adapters.messages.kinds import Kind
from framechain.timeline import LogInfo, TopicInfo

MAGIC = b"#ROSBAG V2.0\n"
OP_MESSAGE, OP_BAG_HEADER, OP_INDEX, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION = 0x02, 0x03, 0x04, 0x05, 0x06, 0x07
_OPS = frozenset({OP_MESSAGE, OP_BAG_HEADER, OP_INDEX, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION})
_U32 = struct.Struct("<I")
#: Record headers are a few fields (a connection's holds its topic): longer ones are damage.
_MAX_HEADER = 1 << 16
#: How far before an ``op=`` field a record may start (header length field, other fields first).
_BACK = 1024
_FEED = 1 << 20


class _MalformedError(Exception):
    """A record does not parse."""


@dataclass(frozen=True)
class Connection:
    id: int
    topic: str
    msgtype: str  # pkg/msg/Type
    msgdef: str
    md5sum: str


@dataclass(frozen=True)
class Message:
    conn: int
    time_ns: int
    data: bytes


def _fields(buf: bytes, off: int, end: int) -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    while off < end:
        if off + 4 > end:
            raise _MalformedError("field length past the header end")
        (n,) = _U32.unpack_from(buf, off)
        off += 4
        if off + n > end:
            raise _MalformedError("field past the header end")
        name, sep, value = buf[off:off + n].partition(b"=")
        if not sep:
            raise _MalformedError("field without '='")
        out[name.decode("latin-1")] = value
        off += n
    return out


def _u32(fields: dict[str, bytes], name: str) -> int:
    value = fields.get(name)
    if value is None or len(value) != 4:
        raise _MalformedError(f"field {name!r} missing or not 4 bytes")
    return int(_U32.unpack(value)[0])


def _time_ns(fields: dict[str, bytes]) -> int:
    value = fields.get("time")
    if value is None or len(value) != 8:
        raise _MalformedError("message time missing or not 8 bytes")
    sec, nsec = struct.unpack("<II", value)
    return int(sec) * 1_000_000_000 + int(nsec)


def _connection(fields: dict[str, bytes], data: bytes) -> Connection:
    conn = _u32(fields, "conn")
    info = _fields(data, 0, len(data))
    topic = (fields.get("topic") or info.get("topic") or b"").decode("utf-8", "replace")
    msgtype = info.get("type", b"").decode("utf-8", "replace")
    if not topic or not msgtype:
        raise _MalformedError("connection without topic or type")
    msgdef = info.get("message_definition", b"").decode("utf-8", "replace")
    return Connection(conn, topic, ros_typename(msgtype), msgdef, info.get("md5sum", b"").decode("ascii", "replace"))


def _record_at(buf: bytes | mmap.mmap, pos: int, size: int) -> tuple[dict[str, bytes], int, int, int]:
    """(header fields, op, data start, data length) of the record at ``pos``; the data may run past the end."""
    if pos + 4 > size:
        raise _MalformedError("record header length cut short")
    (hlen,) = _U32.unpack_from(buf, pos)
    if hlen > _MAX_HEADER or hlen < 5:
        raise _MalformedError(f"implausible record header length {hlen}")
    if pos + 4 + hlen + 4 > size:
        raise _MalformedError("record header cut short")
    fields = _fields(bytes(buf[pos + 4:pos + 4 + hlen]), 0, hlen)
    op_value = fields.get("op")
    if op_value is None or len(op_value) != 1 or op_value[0] not in _OPS:
        raise _MalformedError("record without a known op")
    (dlen,) = _U32.unpack_from(buf, pos + 4 + hlen)
    return fields, op_value[0], pos + 8 + hlen, dlen


def _inner(data: bytes) -> tuple[list[tuple[dict[str, bytes], int, bytes]], int]:
    """The complete records at the start of a chunk's uncompressed data, and the bytes they span."""
    out: list[tuple[dict[str, bytes], int, bytes]] = []
    pos, size = 0, len(data)
    while pos < size:
        try:
            fields, op, start, dlen = _record_at(data, pos, size)
        except _MalformedError:
            break
        if start + dlen > size:
            break
        out.append((fields, op, data[start:start + dlen]))
        pos = start + dlen
    return out, pos


Scan = Generator["Connection | Message", None, int]


class Rosbag1Scanner:
    """Every connection and message of a ROS 1 bag in file order, however damaged the file."""

    def __init__(self, buf: mmap.mmap | bytes, reason: str) -> None:
        self.buf = buf
        self.size = len(buf)
        self.report = SalvageReport(reason, size=self.size)
        self.connections: dict[int, Connection] = {}
        #: Where the chunk the last message came from starts (-1: not in a chunk).
        self.chunk_at = -1

    def records(self, start: int | None = None) -> Iterator[Connection | Message]:
        """From the first record (or the record at ``start``) to the end of the file."""
        pos = len(MAGIC) if start is None else start
        while pos < self.size:
            try:
                fields, op, start, dlen = _record_at(self.buf, pos, self.size)
            except _MalformedError as err:
                if self.size - pos < 4 + 5 + 4:
                    self.report.cut(pos, "a record header cut short")
                    return
                pos = self._resync(pos, pos + 1, f"a record that does not parse ({err})")
                continue
            end = start + dlen
            if end > self.size:
                if op == OP_CHUNK:
                    self.chunk_at = pos
                    yield from self._partial_chunk(pos, fields, start)
                    return
                pos = self._resync(pos, pos + 1, "a record whose data runs past the end of the file")
                continue
            if op == OP_CHUNK:
                self.chunk_at = pos
                why = yield from self._chunk(fields, start, end)
                if why:
                    pos = self._after_bad_chunk(pos, end, why)
                    continue
            elif op in (OP_CONNECTION, OP_MESSAGE):
                try:
                    yield from self._emit([(fields, op, bytes(self.buf[start:end]))])
                except _MalformedError as err:
                    pos = self._resync(pos, pos + 1, f"a malformed record ({err})")
                    continue
            pos = end

    def _emit(self, records: list[tuple[dict[str, bytes], int, bytes]]) -> Iterator[Connection | Message]:
        """Connections and messages of ``records``; a malformed one raises before any is yielded."""
        parsed: list[Connection | Message] = []
        for fields, op, data in records:
            if op == OP_CONNECTION:
                parsed.append(_connection(fields, data))
            elif op == OP_MESSAGE:
                parsed.append(Message(_u32(fields, "conn"), _time_ns(fields), data))
        for rec in parsed:
            if isinstance(rec, Connection):
                self.connections.setdefault(rec.id, rec)
            else:
                conn = self.connections.get(rec.conn)
                self.report.recovered[conn.topic if conn else f"connection {rec.conn}"] += 1
            yield rec

    def _chunk(self, fields: dict[str, bytes], start: int, end: int) -> Generator[Connection | Message, None, str]:
        compression = fields.get("compression", b"?").decode("latin-1")
        try:
            size = _u32(fields, "size")
            data = bytes(self.buf[start:end])
            if compression == "none":
                out = data
            elif compression == "bz2":
                import bz2

                out = bz2.decompress(data)
            elif compression == "lz4":
                import lz4.frame

                out = bytes(lz4.frame.decompress(data))
            else:
                return f"unknown compression {compression!r}"
            if len(out) != size:
                return "its uncompressed size does not match its header"
            records, used = _inner(out)
            if used != len(out):
                return "the records inside do not parse"
            yield from self._emit(records)
        except _MalformedError as err:
            return str(err)
        except Exception as err:
            return f"{compression} data unreadable ({type(err).__name__})"
        return ""

    def _after_bad_chunk(self, pos: int, end: int, why: str) -> int:
        """Skip a damaged chunk; the index data records after it say how many messages it held."""
        lost: Counter[str] = Counter()
        nxt = end
        while nxt < self.size:
            try:
                fields, op, start, dlen = _record_at(self.buf, nxt, self.size)
                if op != OP_INDEX or start + dlen > self.size:
                    break
                conn = _u32(fields, "conn")
                count = _u32(fields, "count")
            except _MalformedError:
                break
            known = self.connections.get(conn)
            lost[known.topic if known else f"connection {conn}"] += count
            nxt = start + dlen
        if lost:
            self.report.lost.update(lost)
        else:
            self.report.lost_unknown += 1
        self.report.skip(pos, end, f"a damaged chunk ({why})")
        return end

    def _partial_chunk(self, pos: int, fields: dict[str, bytes], start: int) -> Iterator[Connection | Message]:
        compression = fields.get("compression", b"?").decode("latin-1")
        stream = StreamDecompressor("none" if compression == "none" else compression)
        if compression not in ("none", "bz2", "lz4"):
            self.report.cut(pos, f"a chunk cut short with unknown compression {compression!r}")
            return
        out = bytearray()
        off = start
        while off < self.size and not stream.eof and not stream.failed:
            piece = bytes(self.buf[off:min(off + _FEED, self.size)])
            out += stream.feed(piece)
            off += len(piece)
        records, _ = _inner(bytes(out))
        kept = 0
        try:
            for rec in self._emit(records):
                kept += isinstance(rec, Message)
                yield rec
        except _MalformedError:
            pass
        label = "an uncompressed" if compression == "none" else f"a {compression}"
        why = f"{label} chunk cut short ({kept} complete messages kept from it)"
        if stream.failed:
            why += f"; {stream.failed}"
        self.report.cut(pos, why)

    def _resync(self, bad: int, start: int, why: str) -> int:
        """The first record start after ``start`` that parses and is followed by a plausible record."""
        buf, size = self.buf, self.size
        at = buf.find(b"op=", start + 8)
        while at != -1:
            for p in range(max(start, at - _BACK), at - 7):
                if self._plausible(p):
                    self.report.skip(bad, p, why + "; resynchronised on the next record")
                    return p
            at = buf.find(b"op=", at + 1)
        self.report.cut(bad, why)
        return size

    def _plausible(self, p: int) -> bool:
        try:
            fields, op, start, dlen = _record_at(self.buf, p, self.size)
        except _MalformedError:
            return False
        end = start + dlen
        if end > self.size:
            return op == OP_CHUNK  # a chunk cut by the end of the file still gives back its records
        if op == OP_MESSAGE:
            conn = fields.get("conn", b"")
            if len(conn) != 4 or _U32.unpack(conn)[0] not in self.connections:
                return False
        if end == self.size:
            return True
        try:
            _record_at(self.buf, end, self.size)
        except _MalformedError:
            return False
        return True


class Rosbag1Salvage:
    """A ROS 1 bag read by a linear scan (the same interface as :class:`RosbagsLog`)."""

    def __init__(self, path: Path, reason: str, typestore: Any) -> None:
        self.path = path
        self.ros1 = True
        self.notes: list[str] = []
        self._reason = reason
        self._f = path.open("rb")
        size = path.stat().st_size
        self._buf: mmap.mmap | bytes = mmap.mmap(self._f.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
        self._store = typestore
        self._decoders: dict[str, Decoder] = {}
        self.connections: dict[int, Connection] = {}
        self._counts: Counter[int] = Counter()
        self._first = 0
        self._last = 0
        self.salvage: SalvageReport | None = None
        self._where: dict[tuple[str, int], list[int]] | None = None
        scanner = self._scan()
        for rec in scanner.records():
            if isinstance(rec, Message):
                self._first = rec.time_ns if not self._counts else min(self._first, rec.time_ns)
                self._last = max(self._last, rec.time_ns)
                self._counts[rec.conn] += 1
        self.connections = dict(scanner.connections)
        self.salvage = scanner.report
        self.notes.extend(scanner.report.notes())

    def _scan(self) -> Rosbag1Scanner:
        if bytes(self._buf[:len(MAGIC)]) != MAGIC:
            raise CorruptLogError(self.path, "not a ROS 1 bag (bad magic at the start)")
        return Rosbag1Scanner(self._buf, self._reason)

    def __enter__(self) -> Rosbag1Salvage:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if isinstance(self._buf, mmap.mmap) and not self._buf.closed:
            self._buf.close()
        self._f.close()

    def info(self) -> LogInfo:
        counts: Counter[str] = Counter()
        types: dict[str, str] = {}
        for cid, conn in self.connections.items():
            counts[conn.topic] += self._counts.get(cid, 0)
            types.setdefault(conn.topic, conn.msgtype)
        total = sum(counts.values())
        if total == 0 and not self.connections:
            raise EmptyLogError(self.path, f"{self._reason}, and a linear scan found no messages")
        duration = max(self._last - self._first, 0) * 1e-9
        topics = tuple(
            TopicInfo(t, types[t], n, (n - 1) / duration if n > 1 and duration > 0 else 0.0, "ros1")
            for t, n in sorted(counts.items())
        )
        return LogInfo(format="rosbag1", path=self.path, start_ns=self._first, end_ns=self._last, topics=topics,
                       notes=tuple(self.notes), container="rosbag1 (salvaged by a linear scan)",
                       message_count=total, salvage=self.salvage.to_dict() if self.salvage is not None else None)

    def decoder(self, conn: Connection) -> Decoder:
        if conn.msgtype not in self._decoders:
            if conn.msgtype not in self._store.types and conn.msgdef:
                from rosbags.typesys import get_types_from_msg

                try:
                    types = get_types_from_msg(conn.msgdef, conn.msgtype)
                    # Types the store already has (std_msgs/Header...) keep their definition.
                    self._store.register({k: v for k, v in types.items() if k not in self._store.types})
                except Exception as err:
                    raise SchemaError(self.path, f"cannot parse the message definition of {conn.msgtype} ({err})",
                                      topic=conn.topic) from err
            if conn.msgtype not in self._store.types:
                raise SchemaError(self.path, f"no definition for message type {conn.msgtype}", topic=conn.topic)
            self._decoders[conn.msgtype] = ros_decoder(self._store, conn.msgtype, ros1=True)
        return self._decoders[conn.msgtype]

    def _messages(self, start: int | None = None) -> Iterator[tuple[Connection, Message, int]]:
        """(connection, message, where its chunk starts) in file order, from ``start`` if given."""
        scanner = self._scan()
        scanner.connections.update(self.connections)
        for rec in scanner.records(start):
            if isinstance(rec, Message):
                conn = scanner.connections.get(rec.conn)
                if conn is not None:
                    yield conn, rec, scanner.chunk_at

    def read(self, selected: dict[str, Kind], col: Collector, progress: ProgressFn | None = None, *,
             skip: Counter[tuple[str, int]] | None = None) -> None:
        """Decode the selected topics into the collector; ``skip``: (topic, log time) already delivered."""
        loop = DecodeLoop(col, lambda conn: self._route(conn, selected, col), progress, skip=skip)
        loop.run((conn, msg.time_ns, msg.data) for conn, msg, _ in self._messages())
        loop.finish(self.notes)

    def _route(self, conn: Connection, selected: dict[str, Kind], col: Collector) -> Route | None:
        kind = selected.get(conn.topic)
        handle = col.handler(kind) if kind is not None else None
        if kind is None or handle is None:
            return None
        return Route(conn.topic, kind, self.decoder(conn), handle)  # a SchemaError: the loop notes the topic

    def fetch(self, topic: str, log_time_ns: int, ordinal: int) -> Any:
        """One message, decoded: the first call indexes where each message's chunk starts, so a
        fetch decompresses one chunk rather than the whole bag (depth frames are fetched one by one)."""
        if self._where is None:
            self._where = {}
            for conn, msg, chunk in self._messages():
                self._where.setdefault((conn.topic, msg.time_ns), []).append(chunk)
        chunks = self._where.get((topic, log_time_ns), [])
        if ordinal < len(chunks):
            chunk = chunks[ordinal]
            seen = chunks[:ordinal].count(chunk)  # equal times earlier in the same chunk
            for conn, msg, at in self._messages(chunk if chunk >= 0 else None):
                if at != chunk and chunk >= 0:
                    break
                if conn.topic == topic and msg.time_ns == log_time_ns:
                    if seen == 0:
                        return self.decoder(conn)(msg.data)
                    seen -= 1
        raise CorruptLogError(self.path, f"message at log time {log_time_ns} ns not found on re-read", topic=topic)
