"""Chunks decompressed ahead on a thread: the same messages in the same order as mcap's own reader,
over spans of neighbouring chunks and a queue that fills; a reader that stops early stops the thread."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from framechain.adapters.formats.mcap import chunks as chunks_module
from framechain.adapters.formats.mcap.chunks import AHEAD_CHUNKS, chunk_messages, decompressed_ahead


def _write(path: Path, compression: CompressionType) -> None:
    rng = np.random.default_rng(3)
    with path.open("wb") as f:
        writer = Writer(f, chunk_size=2048, compression=compression)
        writer.start()
        schema = writer.register_schema("blob", "jsonschema", b"{}")
        channels = [writer.register_channel(f"/topic{k}", "json", schema) for k in range(3)]
        for i in range(600):
            size = int(rng.integers(1, 600))
            writer.add_message(channels[i % 3], log_time=1_000 * i, publish_time=1_000 * i, sequence=i,
                               data=rng.integers(0, 255, size, dtype=np.uint8).tobytes())
        writer.finish()


def _summary(path: Path) -> Any:
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return summary


def _chunk_indexes(path: Path) -> list[Any]:
    return sorted(_summary(path).chunk_indexes, key=lambda c: c.chunk_start_offset)


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE])
def test_chunks_decompressed_ahead_hold_mcap_s_messages_in_order(tmp_path: Path, compression: CompressionType,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "log.mcap"
    _write(path, compression)
    indexes = _chunk_indexes(path)
    assert len(indexes) > 4 * AHEAD_CHUNKS  # the queue fills and the reader waits on the thread
    monkeypatch.setattr(chunks_module, "SPAN_BYTES", 5000)  # a few chunks per read of the file
    wanted = {c.id for c in _summary(path).channels.values() if c.topic in ("/topic0", "/topic1")}
    ours, order = [], []
    for ci, data, err in decompressed_ahead(path, indexes):
        order.append(ci.chunk_start_offset)
        assert err is None
        assert data is not None
        ours += [(m.channel_id, m.log_time, bytes(m.data)) for m in chunk_messages(data, wanted)]
    with path.open("rb") as f:
        theirs = [(c.id, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages(log_time_order=False)
                  if c.topic in ("/topic0", "/topic1")]
    assert len(theirs) == 400
    assert order == [ci.chunk_start_offset for ci in indexes]
    assert ours == theirs


def test_a_reader_that_stops_early_stops_the_thread(tmp_path: Path) -> None:
    path = tmp_path / "log.mcap"
    _write(path, CompressionType.ZSTD)
    items = decompressed_ahead(path, _chunk_indexes(path))
    next(items)
    assert [t for t in threading.enumerate() if t.name == "framechain-mcap-chunks"]
    items.close()
    assert not [t for t in threading.enumerate() if t.name == "framechain-mcap-chunks"]
