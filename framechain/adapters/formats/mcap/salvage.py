"""A linear MCAP record scanner that gives back everything before (and after) the damage.

The mcap library's stream reader stops at the first record it cannot parse and throws away a
chunk it cannot finish; a recording cut short usually ends inside its last chunk, which may hold
most of the messages (one 362 KB zstd chunk held 5,441 of the TurtleBot log's 8,197). Here:

- a chunk cut short is decompressed as far as its stream goes (zstd and lz4 both stream) and
  every complete record in it is kept;
- a complete chunk whose CRC, compression or lengths do not check out is skipped whole (its
  message index, when it follows, says how many messages per channel were lost);
- after a record that does not parse, the scan resynchronises on the next byte where a record
  parses and the record after it starts plausibly, and the bytes skipped are reported.
"""

from __future__ import annotations

import mmap
import re
import struct
from collections import Counter
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass

from framechain.adapters.formats.mcap.chunks import crc32
from framechain.adapters.formats.salvage_report import SalvageReport, StreamDecompressor

MAGIC = b"\x89MCAP0\r\n"
HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07
DATA_END = 0x0F
_OPCODES = frozenset(range(HEADER, DATA_END + 1))
_OPCODE_BYTES = re.compile(rb"[\x01-\x0f]")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_RECORD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_CHUNK_HEAD = struct.Struct("<QQQI")  # start time, end time, uncompressed size, uncompressed crc
_COMPRESSIONS = frozenset({"", "zstd", "lz4"})
#: Bytes fed to a decompressor at a time (a partial chunk is streamed, never held twice whole).
_FEED = 1 << 20


class _MalformedError(Exception):
    """A record's content does not parse (lengths run past its end, bad text)."""


@dataclass(frozen=True)
class SchemaRecord:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class ChannelRecord:
    id: int
    schema_id: int
    topic: str
    message_encoding: str


@dataclass(frozen=True)
class MessageRecord:
    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: bytes


Record = SchemaRecord | ChannelRecord | MessageRecord


def _text(buf: bytes, off: int, end: int) -> tuple[str, int]:
    if off + 4 > end:
        raise _MalformedError("string length past the record end")
    (n,) = _U32.unpack_from(buf, off)
    off += 4
    if off + n > end:
        raise _MalformedError("string past the record end")
    try:
        return buf[off:off + n].decode("utf-8"), off + n
    except UnicodeDecodeError as err:
        raise _MalformedError("string is not UTF-8") from err


def _parse(op: int, content: bytes) -> Record | None:
    """The record of ``op`` in ``content`` (None for records salvage does not need)."""
    end = len(content)
    if op == MESSAGE:
        if end < _MESSAGE_HEAD.size:
            raise _MalformedError("message shorter than its header")
        cid, seq, log_time, pub_time = _MESSAGE_HEAD.unpack_from(content, 0)
        return MessageRecord(cid, seq, log_time, pub_time, content[_MESSAGE_HEAD.size:])
    if op == SCHEMA:
        if end < 2:
            raise _MalformedError("schema shorter than its header")
        (sid,) = _U16.unpack_from(content, 0)
        name, off = _text(content, 2, end)
        encoding, off = _text(content, off, end)
        if off + 4 > end:
            raise _MalformedError("schema data length past the record end")
        (n,) = _U32.unpack_from(content, off)
        if off + 4 + n != end:
            raise _MalformedError("schema data length does not match the record")
        return SchemaRecord(sid, name, encoding, bytes(content[off + 4:end]))
    if op == CHANNEL:
        if end < 4:
            raise _MalformedError("channel shorter than its header")
        cid, sid = struct.unpack_from("<HH", content, 0)
        topic, off = _text(content, 4, end)
        encoding, off = _text(content, off, end)
        if off + 4 > end:
            raise _MalformedError("channel metadata length past the record end")
        (n,) = _U32.unpack_from(content, off)
        if off + 4 + n != end:
            raise _MalformedError("channel metadata length does not match the record")
        return ChannelRecord(cid, sid, topic, encoding)
    return None


@dataclass(frozen=True)
class _ChunkHead:
    uncompressed_size: int
    crc: int
    compression: str
    data_start: int  # offset of the compressed records in the chunk's content
    data_len: int


def _chunk_head(content: bytes, total: int) -> _ChunkHead:
    """The header of a chunk whose content (``total`` bytes long) starts with ``content``."""
    end = min(len(content), total)
    if end < _CHUNK_HEAD.size + 4:
        raise _MalformedError("chunk shorter than its header")
    _, _, size, crc = _CHUNK_HEAD.unpack_from(content, 0)
    compression, off = _text(content, _CHUNK_HEAD.size, end)
    if compression not in _COMPRESSIONS:
        raise _MalformedError(f"unknown chunk compression {compression!r}")
    if off + 8 > end:
        raise _MalformedError("chunk records length past the record end")
    (data_len,) = _U64.unpack_from(content, off)
    return _ChunkHead(size, crc, compression, off + 8, data_len)


#: Bytes of a chunk's content that hold its header (compression names are short).
_CHUNK_HEAD_BYTES = _CHUNK_HEAD.size + 4 + 64 + 8


def _inner_records(data: bytes) -> tuple[list[Record], int]:
    """The complete records at the start of a chunk's uncompressed data, and the bytes they span."""
    out: list[Record] = []
    pos, size = 0, len(data)
    while pos + 9 <= size:
        op, length = _RECORD.unpack_from(data, pos)
        if op not in _OPCODES or pos + 9 + length > size:
            break
        try:
            rec = _parse(op, data[pos + 9:pos + 9 + length])
        except _MalformedError:
            break
        if rec is not None:
            out.append(rec)
        pos += 9 + length
    return out, pos


def _decompress(compression: str, data: bytes) -> bytes:
    if compression == "zstd":
        import zstandard

        out: bytes = zstandard.ZstdDecompressor().decompressobj().decompress(data)
        return out
    if compression == "lz4":
        import lz4.frame

        return bytes(lz4.frame.decompress(data))
    return data


Scan = Generator[Record, None, int]


class McapScanner:
    """Every schema, channel and message of an MCAP file in file order, however damaged the file.

    ``topic_of`` names a channel's topic for the report (None while its channel is unknown).
    """

    def __init__(self, buf: mmap.mmap | bytes, topic_of: Callable[[int], str | None]) -> None:
        self.buf = buf
        self.size = len(buf)
        self._topic_of = topic_of
        self.report = SalvageReport("no usable footer or summary", size=self.size)
        self.channels: set[int] = set()

    # -- the scan -----------------------------------------------------------------------------
    def records(self) -> Iterator[Record]:
        buf, size = self.buf, self.size
        pos = len(MAGIC)
        while pos < size:
            if size - pos < 9:
                self.report.cut(pos, "a record header cut short")
                return
            op, length = _RECORD.unpack_from(buf, pos)
            end = pos + 9 + length
            if op == FOOTER and end <= size:
                return
            if op not in _OPCODES:
                pos = self._resync(pos, pos + 1, f"unknown opcode 0x{op:02x}")
            elif end > size and op == CHUNK:
                resume = yield from self._partial_chunk(pos)
                if resume < 0:
                    return
                self.report.details.append(f"the chunk at byte {pos} has a damaged length field; its data "
                                           f"was read up to where its stream ends (byte {resume})")
                pos = self._resync(resume, resume, "a chunk whose length runs past the end of the file")
            elif end > size:
                pos = self._resync(pos, pos + 1,
                                   f"a record (opcode 0x{op:02x}) whose length runs past the end of the file")
            elif op == CHUNK:
                why = yield from self._chunk(pos, end)
                pos = self._after_bad_chunk(pos, end, why) if why else end
            else:
                try:
                    rec = _parse(op, bytes(buf[pos + 9:end]))
                except _MalformedError as err:
                    pos = self._resync(pos, pos + 1, f"a malformed record (opcode 0x{op:02x}: {err})")
                    continue
                if rec is not None:
                    yield from self._emit([rec])
                pos = end

    def _emit(self, records: list[Record]) -> Iterator[Record]:
        for rec in records:
            if isinstance(rec, MessageRecord):
                topic = self._topic_of(rec.channel_id)
                self.report.recovered[topic if topic is not None else f"channel {rec.channel_id}"] += 1
            elif isinstance(rec, ChannelRecord):
                self.channels.add(rec.id)
            yield rec

    # -- chunks ---------------------------------------------------------------------------------
    def _chunk(self, pos: int, end: int) -> Generator[Record, None, str]:
        """A complete chunk's records; what is wrong with it ('' when nothing) when it does not check out."""
        compression = "?"
        try:
            head = _chunk_head(bytes(self.buf[pos + 9:pos + 9 + _CHUNK_HEAD_BYTES]), end - pos - 9)
            compression = head.compression
            if pos + 9 + head.data_start + head.data_len != end:
                raise _MalformedError("its records length does not match its length")
            if head.uncompressed_size > max(64 * head.data_len, 1 << 20):
                raise _MalformedError("its uncompressed size is implausible")
            out = _decompress(head.compression, bytes(self.buf[pos + 9 + head.data_start:end]))
            if len(out) != head.uncompressed_size:
                raise _MalformedError("its uncompressed size does not match its header")
            if head.crc and crc32(out) != head.crc:
                raise _MalformedError("CRC mismatch")
            records, used = _inner_records(out)
            if used != len(out):
                raise _MalformedError("the records inside do not parse")
        except Exception as err:  # any damage makes the whole chunk untrustworthy
            return str(err) if isinstance(err, _MalformedError) else f"{compression} data unreadable " \
                f"({type(err).__name__})"
        yield from self._emit(records)
        return ""

    def _after_bad_chunk(self, pos: int, end: int, why: str) -> int:
        """Skip a damaged chunk whose length fits; count what its message index says was lost."""
        lost, nxt = self._index_counts(end)
        if lost:
            for cid, n in lost.items():
                topic = self._topic_of(cid)
                self.report.lost[topic if topic is not None else f"channel {cid}"] += n
        else:
            self.report.lost_unknown += 1
        self.report.skip(pos, end, f"a damaged chunk ({why})")
        if not self._next_plausible(end):
            return self._resync(end, end, "after a damaged chunk")
        return nxt

    def _index_counts(self, pos: int) -> tuple[Counter[int], int]:
        """Messages per channel in the message index records starting at ``pos``, and where they end."""
        counts: Counter[int] = Counter()
        buf, size = self.buf, self.size
        while pos + 9 + 6 <= size:
            op, length = _RECORD.unpack_from(buf, pos)
            if op != MESSAGE_INDEX or pos + 9 + length > size or length < 6:
                break
            cid, n = struct.unpack_from("<HI", buf, pos + 9)
            if 6 + n != length or n % 16:
                break
            counts[cid] += n // 16
            pos += 9 + length
        return counts, pos

    def _partial_chunk(self, pos: int) -> Scan:
        """Complete records of a chunk that runs past the end of the file.

        Returns where the scan goes on: -1 when the file was cut inside the chunk, else the byte
        where the chunk's stream ended (its length field was damaged, not the file cut).
        """
        try:
            head = _chunk_head(bytes(self.buf[pos + 9:pos + 9 + _CHUNK_HEAD_BYTES]), self.size - pos - 9)
        except _MalformedError:
            self.report.cut(pos, "a chunk cut short before its records began")
            return -1
        start = pos + 9 + head.data_start
        stop = min(start + head.data_len, self.size)
        stream = StreamDecompressor(head.compression)
        out = bytearray()
        off = start
        while off < stop and not stream.eof and not stream.failed and len(out) <= head.uncompressed_size:
            piece = bytes(self.buf[off:min(off + _FEED, stop)])
            out += stream.feed(piece)
            off += len(piece)
        if stream.eof and (len(out) != head.uncompressed_size or (head.crc and crc32(out) != head.crc)):
            # The whole stream is there but does not check out: the chunk is damaged, not cut.
            self.report.lost_unknown += 1
            self.report.skip(pos, off - stream.unused, "a damaged chunk (its data does not match its CRC or size)")
            return off - stream.unused
        records, _ = _inner_records(bytes(out))
        yield from self._emit(records)
        if stream.eof:
            return off - stream.unused
        if head.compression == "" and start + head.data_len <= self.size:
            return start + head.data_len
        kept = sum(1 for r in records if isinstance(r, MessageRecord))
        why = f"a {head.compression or 'uncompressed'} chunk cut short ({kept} complete messages kept from it)"
        if stream.failed:
            why += f"; {stream.failed}"
        self.report.cut(pos, why)
        return -1

    # -- resynchronisation ---------------------------------------------------------------------------
    def _resync(self, bad: int, start: int, why: str) -> int:
        """The first byte from ``start`` where a record parses and the next starts plausibly."""
        for match in _OPCODE_BYTES.finditer(self.buf, start):
            p = match.start()
            if self._plausible(p):
                self.report.skip(bad, p, why + "; resynchronised on the next record")
                return p
        self.report.cut(bad, why)
        return self.size

    def _plausible(self, p: int) -> bool:
        buf, size = self.buf, self.size
        if p + 9 > size:
            return False
        op, length = _RECORD.unpack_from(buf, p)
        end = p + 9 + length
        if end > size or op == HEADER or not self._next_plausible(end):
            return False
        if op == MESSAGE:
            return length >= _MESSAGE_HEAD.size and int(_U16.unpack_from(buf, p + 9)[0]) in self.channels
        try:
            if op == CHUNK:
                head = _chunk_head(bytes(buf[p + 9:p + 9 + _CHUNK_HEAD_BYTES]), length)
                return bool(head.data_start + head.data_len == length)
            if op in (SCHEMA, CHANNEL):
                _parse(op, bytes(buf[p + 9:end]))
        except _MalformedError:
            return False
        return True

    def _next_plausible(self, end: int) -> bool:
        buf, size = self.buf, self.size
        if end == size or buf[end:end + 8] == MAGIC[:size - end]:
            return True
        if end + 9 > size:
            return False
        op, length = _RECORD.unpack_from(buf, end)
        return bool(op in _OPCODES and end + 9 + length <= size)
