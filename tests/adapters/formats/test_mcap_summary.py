"""The summary section framechain reads (its chunk indexes cut with struct) equals mcap's own reading of it.

Files are written by mcap's writer: several channels whose messages fall in different chunks (so chunk
indexes hold different channel sets), each chunk compression, attachments and metadata (their
indexes in the summary), with and without statistics and summary offsets; and the real logs.
"""

from __future__ import annotations

import io
import struct
from pathlib import Path
from typing import Any

import pytest
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

from framechain.adapters.formats.mcap.reader import McapLog
from framechain.adapters.formats.mcap.summary import read_summary


def _write(path: Path, compression: CompressionType, *, summary_extras: bool = True, index: bool = True) -> Path:
    with path.open("wb") as f:
        writer = Writer(f, chunk_size=300, compression=compression, use_statistics=summary_extras,
                        use_summary_offsets=summary_extras,
                        index_types=IndexType.ALL if index else IndexType.NONE)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        channels = [writer.register_channel(f"/topic_{k}", "cdr", schema) for k in range(4)]
        for i in range(120):
            # Channels in runs, so that chunks hold one, two or three of them (channel id sets differ).
            channel = channels[(i // 7) % 4] if i % 5 else channels[(i * 3) % 4]
            writer.add_message(channel, log_time=1_000 + i * 37, publish_time=1_000 + i * 37,
                               data=bytes(range(i % 50)) * 3, sequence=i)
        writer.add_attachment(create_time=5, log_time=6, name="calib.yaml", media_type="text/yaml", data=b"k: 1\n")
        writer.add_metadata("framechain", {"version": "test"})
        writer.finish()
    return path


def _same(path: Path) -> None:
    with path.open("rb") as f:
        ours = read_summary(f)
    with path.open("rb") as f:
        theirs = make_reader(f).get_summary()
    if theirs is None:
        assert ours is None
        return
    for field in ("chunk_indexes", "schemas", "channels", "statistics", "attachment_indexes", "metadata_indexes"):
        assert getattr(ours, field) == getattr(theirs, field), field


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE])
def test_the_summary_equals_mcaps(tmp_path: Path, compression: CompressionType) -> None:
    path = _write(tmp_path / "log.mcap", compression)
    with path.open("rb") as f:
        summary = read_summary(f)
    assert len(summary.chunk_indexes) > 10
    assert len({frozenset(ci.message_index_offsets) for ci in summary.chunk_indexes}) > 2
    assert summary.attachment_indexes
    assert summary.metadata_indexes
    assert summary.statistics is not None
    _same(path)


@pytest.mark.parametrize("extras", [True, False])
def test_a_summary_without_statistics_offsets_or_indexes_equals_mcaps(tmp_path: Path, extras: bool) -> None:
    _same(_write(tmp_path / "bare.mcap", CompressionType.ZSTD, summary_extras=extras, index=False))


def test_the_real_logs_summaries_equal_mcaps(realdata: Path) -> None:
    logs = sorted(realdata.rglob("*.mcap"))
    assert logs
    for path in logs:
        _same(path)


def _chunk_index_at(data: bytes, summary_start: int) -> int:
    pos = summary_start
    while data[pos] != Opcode.CHUNK_INDEX:
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        pos += 9 + length
    return pos


def test_a_damaged_chunk_index_is_an_error_and_the_log_is_salvaged(tmp_path: Path) -> None:
    path = _write(tmp_path / "log.mcap", CompressionType.ZSTD)
    data = bytearray(path.read_bytes())
    with path.open("rb") as f:
        footer_summary_start = _summary_start(f)
    at = _chunk_index_at(bytes(data), footer_summary_start)
    struct.pack_into("<I", data, at + 9 + 32, 10_000)  # its channel offsets said to run far past the record
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    with damaged.open("rb") as f, pytest.raises((ValueError, struct.error)):
        read_summary(f)
    log = McapLog(damaged)
    try:
        assert log.truncated  # read by a linear scan of its chunks instead, as a file without a summary
    finally:
        log.close()


def _summary_start(f: Any) -> int:
    f.seek(-(9 + 20 + 8), io.SEEK_END)  # the footer record (opcode, length, 20 bytes of fields), then the magic
    (start,) = struct.unpack_from("<Q", f.read(9 + 20), 9)
    return int(start)
