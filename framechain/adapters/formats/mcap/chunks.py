"""MCAP chunk records: a chunk's body parsed and its records decompressed and checked, and the chunks
of a read decompressed ahead on a thread.

On a log of camera images, decompressing its chunks is about a third of reading it. zstd and lz4
decompress in C with the GIL released, while decoding the messages is Python that holds it, so a
thread decompresses the next chunks while the messages of this one are decoded. On two cores the
10-minute benchmark log reads in 3.9-4.6 s instead of 5.6-6.1 s; in phases of a shared machine where
two busy threads slow each other down, about 0.5 s faster than one thread. The thread stays a few
chunks ahead (a bounded queue, a few tens of megabytes of depth images) and reads the file through
its own handle, a span of neighbouring chunks per read; a damaged chunk reaches the reader as its
error, in file order, so it is noted and skipped as before.
"""

from __future__ import annotations

import contextlib
import queue
import struct
import threading
from collections.abc import Generator, Iterator, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

RECORD_HEAD = struct.Struct("<BQ")  # opcode, record length
CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, uncompressed CRC, compression name length
#: Chunks decompressed ahead of the reader, at most (a chunk of depth images is about a megabyte).
AHEAD_CHUNKS = 8
#: Neighbouring chunks are read from the file together up to this many bytes (one read, one GIL release).
SPAN_BYTES = 4 << 20
#: Bytes between two wanted chunks (message indexes, a chunk not wanted) still read rather than sought past.
GAP_BYTES = 64 << 10


class ChunkDecompressor:
    """Decompresses chunk records; its zstd context is reused, so one per thread."""

    def __init__(self) -> None:
        self._zstd: Any = None

    def records(self, body: bytes | memoryview, *, check_crc: bool = True) -> bytes:
        """The decompressed records of a chunk record's ``body`` (the record less its opcode and length),
        checked for damage (an exception when damaged).

        A chunk stored uncompressed has its CRC checked (CRCValidationError): nothing else would see
        damage. A compressed one is checked by its decompressor, which rejects a damaged frame; its CRC
        is not computed, as mcap's own readers do not by default: over a log of depth images it cost a
        tenth of the read. (The salvage scan of a file without a usable index checks every CRC.)
        """
        compression, raw, uncompressed_size, crc = _parse(body)
        if compression == "zstd":
            if self._zstd is None:
                import zstandard

                self._zstd = zstandard.ZstdDecompressor()
            data: bytes = self._zstd.decompress(raw, max_output_size=uncompressed_size)
        elif compression == "":
            data = bytes(raw)
        elif compression == "lz4":
            import lz4.frame

            data = bytes(lz4.frame.decompress(raw))
        else:
            from mcap.exceptions import UnsupportedCompressionError

            raise UnsupportedCompressionError(compression)
        if check_crc and not compression and crc != 0 and crc32(data) != crc:
            from mcap.records import Chunk
            from mcap.stream_reader import CRCValidationError

            chunk = Chunk(compression=compression, data=b"", message_end_time=0, message_start_time=0,
                          uncompressed_crc=crc, uncompressed_size=uncompressed_size)
            raise CRCValidationError(expected=crc, actual=crc32(data), record=chunk)
        return data


def _parse(body: bytes | memoryview) -> tuple[str, memoryview, int, int]:
    """(compression, compressed records, uncompressed size, uncompressed CRC) of a chunk record's body."""
    _, _, uncompressed_size, crc, name_len = CHUNK_HEAD.unpack_from(body, 0)
    pos = CHUNK_HEAD.size
    compression = bytes(body[pos : pos + name_len]).decode("utf-8", "replace")
    pos += name_len
    (records_len,) = struct.unpack_from("<Q", body, pos)
    pos += 8
    if pos + records_len > len(body):
        raise ValueError(f"chunk records run past the chunk ({records_len} bytes at {pos} of {len(body)})")
    return compression, memoryview(body)[pos : pos + records_len], uncompressed_size, crc


def crc32(data: bytes | bytearray | memoryview) -> int:
    """CRC-32 as MCAP defines it (zlib's), by zlib-ng where installed (several times faster)."""
    try:
        from zlib_ng import zlib_ng

        return int(zlib_ng.crc32(data))
    except ImportError:  # pragma: no cover - zlib-ng is a dependency; zlib gives the same number
        import zlib

        return zlib.crc32(data)


_DONE = object()


#: (chunk index, its decompressed records or None, the error that damaged it or None)
ChunkItem = tuple[Any, bytes | None, Exception | None]


def decompressed_ahead(path: Path, chunks: Sequence[Any]) -> Generator[ChunkItem, None, None]:
    """A :data:`ChunkItem` per chunk of ``chunks`` (mcap ChunkIndex records, in file order), decompressed
    on a thread ahead of the caller."""
    if not chunks:
        return
    items: queue.Queue[Any] = queue.Queue(maxsize=AHEAD_CHUNKS)
    stop = threading.Event()
    worker = threading.Thread(target=_decompress_all, args=(path, chunks, items, stop), daemon=True,
                              name="framechain-mcap-chunks")
    worker.start()
    try:
        while (item := items.get()) is not _DONE:
            if isinstance(item, BaseException):  # the thread failed outside any one chunk
                raise item
            yield item
    finally:
        stop.set()
        while worker.is_alive():  # a thread blocked on a full queue sees the stop once there is room
            with contextlib.suppress(queue.Empty):
                items.get(timeout=0.05)
        worker.join()


def _decompress_all(path: Path, chunks: Sequence[Any], items: queue.Queue[Any], stop: threading.Event) -> None:
    decompressor = ChunkDecompressor()
    try:
        with path.open("rb") as f:
            for span in _spans(chunks):
                if stop.is_set():
                    return
                start = span[0].chunk_start_offset
                f.seek(start)
                blob = memoryview(f.read(span[-1].chunk_start_offset + span[-1].chunk_length - start))
                for ci in span:
                    at = ci.chunk_start_offset - start + RECORD_HEAD.size
                    item: ChunkItem
                    try:
                        item = (ci, decompressor.records(blob[at : ci.chunk_start_offset - start + ci.chunk_length]),
                                None)
                    except Exception as err:
                        item = (ci, None, err)
                    items.put(item)
                    if stop.is_set():
                        return
    except BaseException as err:  # an unreadable file: the reader raises it
        items.put(err)
    finally:
        items.put(_DONE)


def _spans(chunks: Sequence[Any]) -> Iterator[list[Any]]:
    """Runs of neighbouring chunks (gaps under GAP_BYTES) of at most SPAN_BYTES, each read at once."""
    span: list[Any] = []
    for ci in chunks:
        if span:
            first, last = span[0], span[-1]
            gap = ci.chunk_start_offset - (last.chunk_start_offset + last.chunk_length)
            length = ci.chunk_start_offset + ci.chunk_length - first.chunk_start_offset
            if gap < 0 or gap > GAP_BYTES or length > SPAN_BYTES:
                yield span
                span = []
        span.append(ci)
    if span:
        yield span


# -- message records in a decompressed chunk ---------------------------------------------------
class RawMessage(NamedTuple):
    """A message record inside a decompressed chunk (the fields a reader uses)."""

    channel_id: int
    log_time: int
    data: memoryview


MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
OPCODE_MESSAGE = 0x05


def message_offsets(data: bytes, cids: set[int]) -> npt.NDArray[np.int64]:
    """(log time, record offset) of the channels' messages in a decompressed chunk, shape (n, 2)."""
    rows: list[tuple[int, int]] = []
    pos, end = 0, len(data)
    while pos + RECORD_HEAD.size <= end:
        opcode, length = RECORD_HEAD.unpack_from(data, pos)
        body = pos + RECORD_HEAD.size
        if opcode == OPCODE_MESSAGE and body + MESSAGE_HEAD.size <= end:
            cid, _, log_time, _ = MESSAGE_HEAD.unpack_from(data, body)
            if cid in cids:
                rows.append((log_time, pos))
        pos = body + length
    return np.asarray(rows, dtype=np.int64).reshape(-1, 2)


def chunk_messages(data: bytes, wanted: set[int]) -> Iterator[RawMessage]:
    """The wanted channels' message records of a decompressed chunk, in order."""
    view = memoryview(data)
    unpack_record = RECORD_HEAD.unpack_from
    unpack_message = MESSAGE_HEAD.unpack_from
    head, msg_head = RECORD_HEAD.size, MESSAGE_HEAD.size
    pos, end = 0, len(data)
    while pos + head <= end:
        opcode, length = unpack_record(data, pos)
        body = pos + head
        if body + length > end:
            raise ValueError(f"a record of {length} bytes runs past the end of its chunk")
        if opcode == OPCODE_MESSAGE:
            cid, _, log_time, _ = unpack_message(data, body)
            if cid in wanted:
                yield RawMessage(cid, log_time, view[body + msg_head : body + length])
        pos = body + length
