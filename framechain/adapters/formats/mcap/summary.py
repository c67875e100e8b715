"""An MCAP file's summary section as mcap's own ``Summary``, its chunk indexes cut here.

mcap parses a ChunkIndex record field by field in Python, about 35 us each, and a log of camera
images holds one per megabyte of messages: 9,000 in the 10-minute benchmark log, a third of a
second of every command that opens it (and 0.8 s at 30 minutes). Here each is cut with struct in a
few microseconds into mcap's ChunkIndex; every other summary record (schemas, channels, statistics,
attachment and metadata indexes, summary offsets) and the footer are read by mcap itself.
"""

from __future__ import annotations

import io
import struct
from typing import IO, Any

from framechain.adapters.formats.mcap.chunks import RECORD_HEAD

_CHUNK_INDEX_HEAD = struct.Struct("<QQQQI")  # message start and end time, chunk offset and length, offsets' bytes
_CHANNEL_OFFSET = struct.Struct("<HQ")  # channel id, offset of its MessageIndex record
_INDEX_LENGTH_NAME = struct.Struct("<QI")  # message index bytes, compression name length
_SIZES = struct.Struct("<QQ")  # compressed, uncompressed size


def read_summary(f: IO[bytes]) -> Any:
    """The summary section of the MCAP file ``f`` (a ``mcap.summary.Summary``, None when the file has
    none), equal to mcap's ``SeekingReader.get_summary``. A damaged section raises ``McapError``,
    ``struct.error`` or ``ValueError``, as mcap does."""
    from mcap.reader import FOOTER_SIZE
    from mcap.records import Footer
    from mcap.stream_reader import MAGIC_SIZE, StreamReader

    end = f.seek(0, io.SEEK_END)
    f.seek(end - FOOTER_SIZE - MAGIC_SIZE)
    tail = f.read(FOOTER_SIZE + MAGIC_SIZE)
    footer = next(StreamReader(io.BytesIO(tail), skip_magic=True).records)
    if not isinstance(footer, Footer):
        from mcap.exceptions import McapError

        raise McapError(f"expected footer at end of MCAP file, found {type(footer)}")
    if footer.summary_start == 0:
        return None
    f.seek(footer.summary_start)
    section = memoryview(f.read(end - FOOTER_SIZE - MAGIC_SIZE - footer.summary_start))
    chunk_indexes, others = _cut(section)
    # The other records, then the footer (where mcap's reader stops), read by mcap.
    summary = _collected(StreamReader(io.BytesIO(b"".join([*others, tail])), skip_magic=True).records)
    summary.chunk_indexes = chunk_indexes
    return summary


def _cut(section: memoryview) -> tuple[list[Any], list[memoryview]]:
    """The section's chunk indexes (parsed) and its other records (as they are)."""
    from mcap.opcode import Opcode
    from mcap.records import ChunkIndex

    chunk_indexes: list[Any] = []
    others: list[memoryview] = []
    pos, size = 0, len(section)
    while pos < size:
        opcode, length = RECORD_HEAD.unpack_from(section, pos)
        body, pos = pos + RECORD_HEAD.size, pos + RECORD_HEAD.size + length
        if pos > size:
            raise ValueError(f"summary record (opcode {opcode:#x}) of {length} bytes runs past the summary section")
        if opcode != Opcode.CHUNK_INDEX:
            others.append(section[body - RECORD_HEAD.size : pos])
            continue
        start_time, end_time, offset, chunk_length, n = _CHUNK_INDEX_HEAD.unpack_from(section, body)
        at = body + _CHUNK_INDEX_HEAD.size
        offsets = dict(_CHANNEL_OFFSET.iter_unpack(section[at : at + n]))
        at += n
        message_index_length, name_length = _INDEX_LENGTH_NAME.unpack_from(section, at)
        at += _INDEX_LENGTH_NAME.size
        compression = str(section[at : at + name_length], "utf-8")
        compressed_size, uncompressed_size = _SIZES.unpack_from(section, at + name_length)
        if at + name_length + _SIZES.size > pos:  # (trailing bytes are padding, as mcap reads them)
            raise ValueError(f"chunk index at summary byte {body} runs past its record")
        chunk_indexes.append(ChunkIndex(
            message_start_time=start_time, message_end_time=end_time, chunk_start_offset=offset,
            chunk_length=chunk_length, message_index_offsets=offsets, message_index_length=message_index_length,
            compression=compression, compressed_size=compressed_size, uncompressed_size=uncompressed_size,
        ))
    return chunk_indexes, others


def _collected(records: Any) -> Any:
    """A Summary of mcap records, as mcap's reader collects them."""
    from mcap.records import AttachmentIndex, Channel, MetadataIndex, Schema, Statistics
    from mcap.summary import Summary

    summary = Summary()
    for record in records:
        if isinstance(record, Statistics):
            summary.statistics = record
        elif isinstance(record, Schema):
            summary.schemas[record.id] = record
        elif isinstance(record, Channel):
            summary.channels[record.id] = record
        elif isinstance(record, AttachmentIndex):
            summary.attachment_indexes.append(record)
        elif isinstance(record, MetadataIndex):
            summary.metadata_indexes.append(record)
    return summary
