"""Standalone MCAP files: ROS 2 (cdr), ROS 1 (ros1) and Foxglove (protobuf, JSON) encodings.

Reading is one pass, chunk by chunk through the chunk index: topics nobody asked for are skipped
without decompression where the index allows, each chunk is decompressed once (an uncompressed
one has its CRC checked with zlib-ng's crc32, a compressed one is checked by its decompressor),
and a corrupt chunk is skipped and counted (from its message index) instead of ending the read.
Messages of types :mod:`fast_cdr` knows (TFMessage, CameraInfo, PointStamped,
Detection2DArray) are decoded many at a time by their byte layout. The pixel
windows the detections need are cut from the depth frames during the pass (the collector's
DepthWindowKeeper); a frame whose window was not kept is fetched later by its location (chunk
and offset, from the message index records, found by a binary search on log time), its chunk
decompressed again without a scan of the index. A file whose footer
or summary is missing (a recording cut short) is salvaged by a linear scan of its records: every
complete message before the cut is recovered and counted.
"""

from __future__ import annotations

import io
import struct
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.errors import CorruptLogError, EmptyLogError, SchemaError
from framechain.adapters.formats.decode_loop import Batched, DecodeLoop, ProgressFn, Route
from framechain.adapters.formats.decoders import Decoder, DecoderBuildError
from framechain.adapters.formats.fast_cdr import FEEDERS
from framechain.adapters.formats.mcap import MCAP_MAGIC
from framechain.adapters.formats.mcap.channels import Channel, RosType, channel_decoder, undecodable
from framechain.adapters.formats.mcap.chunks import (
    MESSAGE_HEAD,
    OPCODE_MESSAGE,
    ChunkDecompressor,
    RawMessage,
    chunk_messages,
    decompressed_ahead,
    message_offsets,
)
from framechain.adapters.formats.mcap.chunks import RECORD_HEAD as _RECORD_HEAD
from framechain.adapters.formats.mcap.salvage import ChannelRecord, McapScanner, SchemaRecord
from framechain.adapters.formats.mcap.summary import read_summary
from framechain.adapters.formats.salvage_report import SalvageReport
from framechain.adapters.messages.collect import Collector
from framechain.adapters.messages.kinds import Kind, normalize_msgtype
from framechain.timeline import LogInfo, TopicInfo

_FOXGLOVE_KINDS = frozenset({Kind.TF, Kind.TRANSFORM, Kind.CAMERA_INFO})


class McapLog:
    """One MCAP file opened for reading (a context manager).

    ``summary``: the file's summary section as an earlier reader of the same file parsed it (a
    reader that re-opens the file to fetch frames need not parse it again).
    """

    def __init__(self, path: Path, summary: Any = None) -> None:
        from mcap.exceptions import McapError

        self.path = path
        self._f = path.open("rb")
        self.notes: list[str] = []
        head = self._f.read(8)
        if head != MCAP_MAGIC:
            self._f.close()
            raise CorruptLogError(path, "not an MCAP file (bad magic at the start)")
        self._f.seek(0)
        self.summary: Any = None
        self.truncated = False
        self.channels: dict[int, Channel] = {}
        self._counts: Counter[int] = Counter()
        self._first: dict[int, int] = {}
        self._last: dict[int, int] = {}
        self.profile = ""
        try:
            from mcap.reader import SeekingReader

            self.profile = SeekingReader(self._f).get_header().profile
            self.summary = summary if summary is not None else read_summary(self._f)
        except (McapError, struct.error, ValueError, OSError):
            self.truncated = True
            self.summary = None
        if self.summary is not None:
            for ch in self.summary.channels.values():
                self._add_channel(ch, self.summary.schemas.get(ch.schema_id))
        self._decoders: dict[int, Decoder] = {}
        #: Per ROS channel: its typestore, type name (rosbags' spelling) and whether it is ROS 1.
        self._stores: dict[int, RosType] = {}
        self._scanned = False
        self._where: dict[str, _Locations] = {}
        #: The chunk indexes in file order, with their (first, last) log times (built on the first fetch).
        self._chunk_order: tuple[list[Any], npt.NDArray[np.uint64]] | None = None
        self._fetch_chunk: tuple[int, bytes] | None = None
        self._chunks = ChunkDecompressor()  # the fetches' own: the read decompresses on a thread
        #: What a linear scan salvaged and lost (None until one ran, or when nothing was damaged).
        self.salvage: SalvageReport | None = None

    def __enter__(self) -> McapLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._f.close()

    def _add_channel(self, ch: Any, schema: Any) -> None:
        """Keep a channel, and say at once when its messages cannot be decoded whatever they hold."""
        if schema is None:
            channel = Channel(ch.id, ch.topic, ch.message_encoding, "", "", b"")
        else:
            channel = Channel(ch.id, ch.topic, ch.message_encoding, schema.name, schema.encoding, bytes(schema.data))
        self.channels[ch.id] = channel
        problem = undecodable(channel)
        if problem:
            note = f"topic {channel.topic}: {problem}; its messages are not read"
            if note not in self.notes:
                self.notes.append(note)

    # -- what the file holds --------------------------------------------------------------
    @property
    def indexed(self) -> bool:
        return self.summary is not None and bool(self.summary.chunk_indexes)

    def info(self) -> LogInfo:
        stats = self.summary.statistics if self.summary is not None else None
        if stats is not None and self.indexed:
            counts = dict(stats.channel_message_counts)
            start, end = int(stats.message_start_time), int(stats.message_end_time)
        else:
            if not self._scanned:
                for _ in self._linear(wanted=None):
                    pass
            counts = dict(self._counts)
            start = min(self._first.values(), default=0)
            end = max(self._last.values(), default=0)
        duration = max(end - start, 0) * 1e-9
        topics: dict[str, TopicInfo] = {}
        for cid, ch in sorted(self.channels.items()):
            n = int(counts.get(cid, 0))
            if ch.topic in topics:  # several channels of one topic
                prev = topics[ch.topic]
                n += prev.count
            rate = (n - 1) / duration if n > 1 and duration > 0 else 0.0
            topics[ch.topic] = TopicInfo(ch.topic, self._msgtype(ch), n, rate, ch.encoding)
        total = sum(t.count for t in topics.values())
        if total == 0 and not self.truncated:
            raise EmptyLogError(self.path, "the MCAP file holds no messages")
        encodings = sorted({c.encoding for c in self.channels.values()})
        container = f"mcap ({', '.join(encodings) or 'no channels'})"
        return LogInfo(format="mcap", path=self.path, start_ns=start, end_ns=end,
                       topics=tuple(sorted(topics.values(), key=lambda t: t.name)), notes=tuple(self.notes),
                       container=container, message_count=total,
                       salvage=self.salvage.to_dict() if self.salvage is not None else None)

    @staticmethod
    def _msgtype(ch: Channel) -> str:
        return ch.schema_name or "(no schema)"

    # -- decoding -----------------------------------------------------------------------------
    def decoder(self, cid: int) -> Decoder:
        if cid in self._decoders:
            return self._decoders[cid]
        ch = self.channels[cid]
        try:
            dec, ros = channel_decoder(ch)
        except DecoderBuildError as err:
            raise SchemaError(self.path, str(err), topic=ch.topic) from err
        if ros is not None:
            self._stores[ch.id] = ros
        self._decoders[cid] = dec
        return dec

    # -- reading ----------------------------------------------------------------------------------
    def read(self, selected: dict[str, Kind], col: Collector, progress: ProgressFn | None = None) -> None:
        """Decode the selected topics into the collector.

        Topics of a type :data:`fast_cdr.FEEDERS` knows are gathered and decoded many messages at
        a time by their byte layout; messages no layout fits go through rosbags one by one.
        """
        messages: Iterable[tuple[int, int, bytes | memoryview]]
        if self.indexed:
            wanted = {cid for cid, ch in self.channels.items() if ch.topic in selected}
            messages = self._indexed(wanted)
        else:
            messages = ((rec.channel_id, rec.log_time, rec.data) for rec in self._linear(wanted=selected))
        loop = DecodeLoop(col, lambda cid: self._route(cid, selected, col), progress)
        loop.run(messages)
        loop.finish(self.notes)

    def _route(self, cid: int, selected: dict[str, Kind], col: Collector) -> Route | None:
        """Where a channel's messages go (None: not selected, or a Foxglove schema of a kind not read)."""
        ch = self.channels.get(cid)
        kind = selected.get(ch.topic) if ch else None
        if ch is None or kind is None:
            return None
        fox = ch.schema_name.startswith("foxglove.")
        if fox and kind not in _FOXGLOVE_KINDS:
            return None
        decode = self.decoder(cid)  # a SchemaError: the loop notes the topic as skipped
        handle = col.handler(kind, foxglove=fox)
        if handle is None:
            return None
        batched = None
        feeder = FEEDERS.get((kind, normalize_msgtype(ch.schema_name))) if cid in self._stores else None
        if feeder is not None:
            store, typename, ros1 = self._stores[cid]
            batched = Batched(store, typename, ros1, feeder)
        return Route(ch.topic, kind, decode, handle, batched)

    def _indexed(self, wanted: set[int]) -> Iterator[RawMessage]:
        """The wanted channels' messages, chunk by chunk in file order; each chunk decompressed once, on a
        thread ahead of the decoding (:mod:`.chunks`)."""
        chunks = [ci for ci in sorted(self.summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
                  if not ci.message_index_offsets or set(ci.message_index_offsets) & wanted]
        for ci, data, err in decompressed_ahead(self.path, chunks):
            if err is not None or data is None:
                self._note_bad_chunk(ci.chunk_start_offset, err or ValueError(), self._index_counts(ci))
                continue
            yield from chunk_messages(data, wanted)

    def _chunk_data(self, ci: Any, *, check_crc: bool = True) -> bytes:
        """The decompressed records of a chunk, checked for damage (an exception when damaged)."""
        self._f.seek(ci.chunk_start_offset + _RECORD_HEAD.size)
        return self._chunks.records(self._f.read(ci.chunk_length - _RECORD_HEAD.size), check_crc=check_crc)

    def _index_counts(self, ci: Any) -> Counter[int]:
        """Messages per channel in a chunk, from the message index records that follow it."""
        from mcap.records import MessageIndex
        from mcap.stream_reader import StreamReader

        counts: Counter[int] = Counter()
        if not ci.message_index_length:
            return counts
        try:
            self._f.seek(ci.chunk_start_offset + ci.chunk_length)
            blob = self._f.read(ci.message_index_length)
            for rec in StreamReader(io.BytesIO(blob), skip_magic=True).records:
                if isinstance(rec, MessageIndex):
                    counts[rec.channel_id] += len(rec.records)
        except Exception:
            return counts
        return counts

    def _note_bad_chunk(self, offset: int, err: Exception, counts: Counter[int] | None) -> None:
        from mcap.stream_reader import CRCValidationError

        what = "CRC mismatch" if isinstance(err, CRCValidationError) else f"unreadable ({type(err).__name__})"
        if counts:
            per_topic: Counter[str] = Counter()
            for cid, n in counts.items():
                per_topic[self.channels[cid].topic if cid in self.channels else f"channel {cid}"] += n
            lost = sum(per_topic.values())
            detail = ", ".join(f"{t} {n}" for t, n in sorted(per_topic.items()))
            self.notes.append(
                f"chunk at byte {offset}: {what}; skipped, {lost} message{'s' if lost != 1 else ''} lost ({detail})"
            )
        else:
            self.notes.append(f"chunk at byte {offset}: {what}; skipped, its messages are lost (count unknown)")

    def _linear(self, wanted: dict[str, Kind] | None) -> Iterator[Any]:
        """Every message in file order, salvaging around damage (see :mod:`salvage_mcap`)."""
        import mmap

        schemas: dict[int, SchemaRecord] = {}
        counting = not self._scanned
        size = self.path.stat().st_size
        if size <= len(MCAP_MAGIC):
            buf: mmap.mmap | bytes = b""
        else:
            buf = mmap.mmap(self._f.fileno(), 0, access=mmap.ACCESS_READ)
        scanner = McapScanner(buf, lambda cid: self.channels[cid].topic if cid in self.channels else None)
        try:
            for rec in scanner.records():
                if isinstance(rec, SchemaRecord):
                    schemas[rec.id] = rec
                elif isinstance(rec, ChannelRecord):
                    if rec.id not in self.channels:
                        self._add_channel(rec, schemas.get(rec.schema_id))
                else:
                    if counting:
                        self._count(rec)
                    if wanted is not None:
                        ch = self.channels.get(rec.channel_id)
                        if ch is not None and ch.topic in wanted:
                            yield rec
        finally:
            if isinstance(buf, mmap.mmap):
                buf.close()
        if counting:
            self._scanned = True
            report = scanner.report
            if self.truncated or report.damaged:
                report.reason = ("the file has no usable footer or summary" if self.truncated
                                 else "the file has no chunk index")
                self.salvage = report
                self.notes.extend(n for n in report.notes() if n not in self.notes)

    def _count(self, msg: Any) -> None:
        cid = msg.channel_id
        self._counts[cid] += 1
        t = int(msg.log_time)
        if cid not in self._first or t < self._first[cid]:
            self._first[cid] = t
        if cid not in self._last or t > self._last[cid]:
            self._last[cid] = t

    # -- lazy fetch --------------------------------------------------------------------------------
    def fetch(self, topic: str, log_time_ns: int, ordinal: int) -> Any:
        """The decoded message of ``topic`` at ``log_time_ns`` (the ordinal-th of equal times)."""
        if not self.indexed:
            return self._fetch_linear(topic, log_time_ns, ordinal)
        chunk, start = self._locate(topic, log_time_ns, ordinal)
        chunk_offset = int(chunk.chunk_start_offset)
        if self._fetch_chunk is None or self._fetch_chunk[0] != chunk_offset:
            # Frames are asked for in time order and neighbours share chunks: keep the last one.
            # The read that found this frame checked the chunk's CRC: a re-read does not again.
            # (zstd's streaming reader could stop at the frame, but measured 7x slower than one call.)
            self._fetch_chunk = (chunk_offset, self._chunk_data(chunk, check_crc=False))
        data = self._fetch_chunk[1]
        body = start + _RECORD_HEAD.size + MESSAGE_HEAD.size
        if body > len(data):
            raise CorruptLogError(self.path, f"message at log time {log_time_ns} ns is past its chunk's end",
                                  topic=topic)
        opcode, length = _RECORD_HEAD.unpack_from(data, start)
        cid, _, log_time, _ = MESSAGE_HEAD.unpack_from(data, start + _RECORD_HEAD.size)
        end = start + _RECORD_HEAD.size + length
        if opcode != OPCODE_MESSAGE or log_time != log_time_ns or end > len(data):
            raise CorruptLogError(self.path, f"message at log time {log_time_ns} ns not where its index says",
                                  topic=topic)
        return self.decoder(cid)(memoryview(data)[body:end])

    def _locate(self, topic: str, log_time_ns: int, ordinal: int) -> tuple[Any, int]:
        """The chunk holding the ``ordinal``-th message of ``topic`` at ``log_time_ns`` (equal times in
        file order) and the message's offset in it.

        Only the chunks whose time range holds that time are looked at, through their message index
        records (a chunk written without them is searched once decompressed): a fetch reads a few
        small records, not the index of the whole topic.
        """
        if self._chunk_order is None:
            chunks = sorted(self.summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
            spans = np.array([(c.message_start_time, c.message_end_time) for c in chunks], dtype=np.uint64)
            self._chunk_order = (chunks, spans.reshape(-1, 2))
        chunks, spans = self._chunk_order
        cids = {cid for cid, ch in self.channels.items() if ch.topic == topic}
        t = np.uint64(log_time_ns)
        candidates = np.flatnonzero((spans[:, 0] <= t) & (spans[:, 1] >= t)).tolist()
        found: list[tuple[int, int]] = []  # (chunk, offset in it), in file order
        for k in candidates:
            found.extend((k, int(offset)) for offset in self._offsets_at(chunks[k], cids, log_time_ns))
        found.sort()
        if ordinal >= len(found):
            raise CorruptLogError(self.path, f"message at log time {log_time_ns} ns not found on re-read",
                                  topic=topic)
        k, offset = found[ordinal]
        return chunks[k], offset

    def _offsets_at(self, ci: Any, cids: set[int], log_time_ns: int) -> npt.NDArray[np.int64]:
        """Offsets in chunk ``ci`` of the channels' messages logged at ``log_time_ns``."""
        if not ci.message_index_offsets:  # written without message indexes: find them in the chunk
            try:
                found = message_offsets(self._chunk_data(ci, check_crc=False), cids)
            except Exception:  # noted when the read met it
                return np.zeros(0, dtype=np.int64)
            at_time: npt.NDArray[np.int64] = found[found[:, 0] == log_time_ns, 1]
            return at_time
        offsets: list[npt.NDArray[np.int64]] = [np.zeros(0, dtype=np.int64)]
        for cid, off in ci.message_index_offsets.items():
            if cid in cids:
                pairs = self._index_pairs(off)
                offsets.append(pairs[pairs[:, 0] == log_time_ns, 1])
        return np.concatenate(offsets)

    def _index_pairs(self, offset: int) -> npt.NDArray[np.int64]:
        """The (log time, offset in chunk) pairs of the message index record at file ``offset``, shape (n, 2)."""
        # A MessageIndex record: opcode, length, channel id, entries length, (log time, offset) pairs.
        self._f.seek(offset)
        head = self._f.read(_RECORD_HEAD.size + 6)
        if len(head) < _RECORD_HEAD.size + 6:
            return np.zeros((0, 2), dtype=np.int64)
        (entries_len,) = struct.unpack_from("<I", head, _RECORD_HEAD.size + 2)
        entries = np.frombuffer(self._f.read(entries_len), dtype="<u8")
        return entries[: entries.size // 2 * 2].reshape(-1, 2).astype(np.int64)

    def _locations(self, topic: str) -> _Locations:
        """Where each message of a topic lives (chunk, offset in it), sorted by log time then file order.

        Built once per topic from the message index records that follow the chunks: nothing is
        decompressed, and each fetch is then a binary search instead of a scan of the chunk index.
        """
        if topic in self._where:
            return self._where[topic]
        cids = {cid for cid, ch in self.channels.items() if ch.topic == topic}
        times: list[npt.NDArray[np.int64]] = []
        chunks: list[npt.NDArray[np.int64]] = []
        offsets: list[npt.NDArray[np.int64]] = []
        for ci in sorted(self.summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            if not ci.message_index_offsets:  # written without message indexes: find them in the chunk once
                try:
                    found = message_offsets(self._chunk_data(ci, check_crc=False), cids)
                except Exception:  # noted when the read met it
                    continue
                times.append(found[:, 0])
                offsets.append(found[:, 1])
                chunks.append(np.full(found.shape[0], int(ci.chunk_start_offset), dtype=np.int64))
                continue
            for cid, off in ci.message_index_offsets.items():
                if cid not in cids:
                    continue
                pairs = self._index_pairs(off)
                times.append(pairs[:, 0])
                offsets.append(pairs[:, 1])
                chunks.append(np.full(pairs.shape[0], int(ci.chunk_start_offset), dtype=np.int64))
        time_arr = np.concatenate(times) if times else np.zeros(0, dtype=np.int64)
        chunk_arr = np.concatenate(chunks) if chunks else np.zeros(0, dtype=np.int64)
        offset_arr = np.concatenate(offsets) if offsets else np.zeros(0, dtype=np.int64)
        order = np.lexsort((offset_arr, chunk_arr, time_arr))
        where = _Locations(time_arr[order], chunk_arr[order], offset_arr[order])
        self._where[topic] = where
        return where

    def _fetch_linear(self, topic: str, log_time_ns: int, ordinal: int) -> Any:
        """A file without a chunk index: scan it (salvage reads are rare and small)."""
        seen = 0
        for rec in self._linear(wanted={topic: Kind.DEPTH}):
            # A linear scan meets the channel records on the way: look the topic up as it goes.
            channel = self.channels.get(rec.channel_id)
            if channel is not None and channel.topic == topic and rec.log_time == log_time_ns:
                if seen == ordinal:
                    return self.decoder(rec.channel_id)(rec.data)
                seen += 1
        raise CorruptLogError(self.path, f"message at log time {log_time_ns} ns not found on re-read", topic=topic)


@dataclass(frozen=True)
class _Locations:
    """Per message of one topic, sorted by log time: its chunk's file offset and its offset in the chunk."""

    log_time_ns: npt.NDArray[np.int64]
    chunk_offset: npt.NDArray[np.int64]
    record_offset: npt.NDArray[np.int64]
