"""ROS 1 bags (format 2.0, plain, bz2 or lz4 chunks) and ROS 2 bags (a directory with
metadata.yaml and .db3 or .mcap storage, uncompressed or zstd per file or per message, or a bare
.db3), read with rosbags. Type definitions come from the bag itself."""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from framechain.adapters.errors import AdapterError, CorruptLogError, EmptyLogError, SchemaError
from framechain.adapters.formats.decoders import Decoder, ros_decoder
from framechain.adapters.formats.fast_cdr import FEEDERS, Feeder, LayoutError, decode_batches
from framechain.adapters.formats.rosbag.salvage_ros1 import Rosbag1Salvage
from framechain.adapters.formats.rosbag.salvage_ros2 import Rosbag2Salvage
from framechain.adapters.formats.salvage_report import SalvageReport
from framechain.adapters.messages.collect import OBSERVATION_KINDS, Collector
from framechain.adapters.messages.kinds import Kind, normalize_msgtype
from framechain.adapters.model import LogInfo, TopicInfo

ProgressFn = Callable[[int], None]
#: Messages of a connection gathered before they are decoded together (bounds the memory they hold).
BATCH_MESSAGES = 8192


def _default_typestore(ros1: bool) -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if not ros1:
        return get_typestore(Stores.ROS2_HUMBLE)
    store = get_typestore(Stores.ROS1_NOETIC)
    # ROS1_NOETIC has no tf2_msgs; its md5 with this text is the real one (94810edd...).
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return store


def _explain(path: Path, err: Exception) -> AdapterError:
    text = " ".join(str(a) for a in err.args) or type(err).__name__
    text = re.sub(r"""\((['"])(.*?)\1,\)""", r"\2", text)  # rosbags formats a nested error's args tuple
    low = text.lower()
    if "metadata" in low:
        return CorruptLogError(path, f"the ROS 2 bag's metadata.yaml cannot be used: {text}")
    if "hash mismatch" in low or ("type" in low and "definition" in low):
        return SchemaError(path, f"message definitions in the bag are inconsistent: {text}")
    return CorruptLogError(path, f"cannot be read as a bag: {text}")


def _sqlite_storage(path: Path) -> bool:
    """A ROS 2 bag stored in sqlite3 (a .db3 file, or a directory holding .db3 files and no .mcap)."""
    if path.is_dir():
        return any(path.glob("*.db3")) and not any(path.glob("*.mcap"))
    return path.suffix == ".db3"


class RosbagsLog:
    """A ROS 1 or ROS 2 bag opened with rosbags' AnyReader (a context manager)."""

    def __init__(self, path: Path) -> None:
        from rosbags.highlevel import AnyReader

        self.path = path
        self.ros1 = path.suffix == ".bag"
        self.notes: list[str] = []
        #: Set when a ROS 1 bag's index is missing or damaged: the bag is read by a linear scan.
        self.salvaged: Rosbag1Salvage | Rosbag2Salvage | None = None
        self._decoders: dict[str, Decoder] = {}
        try:
            self.reader = AnyReader([path], default_typestore=_default_typestore(self.ros1))
            self.reader.open()
        except FileNotFoundError as err:
            raise AdapterError(path, f"not found ({err})") from err
        except Exception as err:
            self.salvaged = self._salvage(err)
            self.notes = self.salvaged.notes
            return
        if not self.ros1 and _sqlite_storage(path) and self._container().endswith("zstd per message)"):
            # One message that fails to decompress would end rosbags' read: read row by row instead.
            store = self.reader.typestore  # closing the reader empties it
            self.reader.close()
            self.salvaged = Rosbag2Salvage(path, None, store)
            self.notes = self.salvaged.notes

    def __enter__(self) -> RosbagsLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _salvage(self, err: Exception, why: str = "") -> Rosbag1Salvage | Rosbag2Salvage:
        """A reader that salvages what rosbags could not read (or the one-line error saying why not)."""
        path = self.path
        explained = _explain(path, err)
        reason = explained.what.removeprefix("cannot be read as a bag: ")
        try:
            if self.ros1 and path.is_file():
                # A recorder killed or a disk filled before the index was written: scan the records.
                low = reason.lower()
                why = why or ("the bag has no index (the recording was not closed cleanly)"
                              if "not indexed" in low or "reindex" in low
                              else f"the bag's index cannot be used ({reason})")
                return Rosbag1Salvage(path, why, _default_typestore(ros1=True))
            if not self.ros1 and _sqlite_storage(path):
                return Rosbag2Salvage(path, why or f"rosbags cannot open the bag ({reason})",
                                      _default_typestore(ros1=False))
        except AdapterError:
            raise
        except Exception as salvage_err:  # damage the salvage did not foresee: still one line, never a traceback
            raise CorruptLogError(path, f"{reason}; a salvage read failed too ({type(salvage_err).__name__}: "
                                  f"{salvage_err})") from salvage_err
        raise explained from err

    @property
    def salvage(self) -> SalvageReport | None:
        return self.salvaged.salvage if self.salvaged is not None else None

    def close(self) -> None:
        if self.salvaged is not None:
            self.salvaged.close()
        if getattr(getattr(self, "reader", None), "stack", None) is not None:
            self.reader.close()

    # -- what the bag holds ------------------------------------------------------------------------
    def info(self) -> LogInfo:
        if self.salvaged is not None:
            return self.salvaged.info()
        r = self.reader
        counts: Counter[str] = Counter()
        types: dict[str, str] = {}
        for c in r.connections:
            counts[c.topic] += int(c.msgcount)
            types.setdefault(c.topic, c.msgtype)
        total = sum(counts.values())
        if total == 0:
            raise EmptyLogError(self.path, "the bag holds no messages")
        start, end = int(r.start_time), int(r.end_time) - 1
        duration = max(end - start, 0) * 1e-9
        topics = tuple(
            TopicInfo(t, types[t], n, (n - 1) / duration if n > 1 and duration > 0 else 0.0,
                      "ros1" if self.ros1 else "cdr")
            for t, n in sorted(counts.items())
        )
        return LogInfo(format="rosbag1" if self.ros1 else "rosbag2", path=self.path, start_ns=start, end_ns=end,
                       topics=topics, notes=tuple(self.notes), container=self._container(),
                       message_count=total)

    def _container(self) -> str:
        if self.ros1:
            return "rosbag1"
        reader = self.reader.readers[0]
        if self.path.is_dir():
            storage = "mcap" if any(self.path.glob("*.mcap")) else "sqlite3"
        else:
            storage = "mcap" if self.path.suffix == ".mcap" else "sqlite3"
        parts = [storage]
        mode = getattr(reader, "compression_mode", None)
        if mode:
            parts.append(f"{getattr(reader, 'compression_format', '')} per {mode}")
        return f"rosbag2 ({', '.join(parts)})"

    # -- decoding ---------------------------------------------------------------------------------
    def decoder(self, msgtype: str, topic: str) -> Decoder:
        if msgtype not in self._decoders:
            store = self.reader.typestore
            if msgtype not in store.types:
                raise SchemaError(self.path, f"no definition for message type {msgtype}", topic=topic)
            self._decoders[msgtype] = ros_decoder(store, msgtype, ros1=self.ros1)
        return self._decoders[msgtype]

    def read(self, selected: dict[str, Kind], col: Collector, progress: ProgressFn | None = None) -> None:
        if self.salvaged is not None:
            self.salvaged.read(selected, col, progress)
            return
        conns = [c for c in self.reader.connections if c.topic in selected]
        if not conns:
            return
        handlers: dict[int, tuple[Decoder, Callable[[str, int, Any], None]] | None] = {}
        for c in conns:
            handler = col.handler(selected[c.topic])
            try:
                handlers[c.id] = (self.decoder(c.msgtype, c.topic), handler) if handler is not None else None
            except SchemaError as err:
                col.notes.append(f"{err.what}: topic {c.topic} skipped")
                handlers[c.id] = None
        failures: Counter[str] = Counter()
        first_error: dict[str, str] = {}
        done = 0
        delivered: Counter[tuple[str, int]] = Counter()
        # Types fast_cdr knows are gathered per connection and decoded many at a time by layout.
        gathered: dict[int, tuple[Feeder, list[int], list[bytes]]] = {}
        for c in conns:
            feeder = FEEDERS.get((selected[c.topic], normalize_msgtype(c.msgtype)))
            if handlers.get(c.id) is not None and feeder is not None and c.msgtype in self.reader.typestore.fielddefs:
                gathered[c.id] = (feeder, [], [])
        by_id = {c.id: c for c in conns}

        def handle(topic: str, t: int, raw: bytes | memoryview, entry: tuple[Decoder, Any]) -> None:
            try:
                entry[1](topic, t, entry[0](raw))
            except Exception as err:  # one undecodable message must not end the read
                failures[topic] += 1
                first_error.setdefault(topic, f"{type(err).__name__}: {err}")

        def flush(cid: int) -> None:
            feeder, times, payloads = gathered[cid]
            if not payloads:
                return
            conn, entry = by_id[cid], handlers[cid]
            assert entry is not None
            log_times = np.asarray(times, dtype=np.int64)
            batches, rest = decode_batches(self.reader.typestore, conn.msgtype, payloads, ros1=self.ros1)
            slow = [rest]
            for b in batches:
                try:
                    feeder(col, conn.topic, log_times[b.rows], b)
                except (KeyError, LayoutError):  # a layout without the fields the feeder reads
                    slow.append(b.rows)
            for row in np.sort(np.concatenate(slow)).tolist():
                handle(conn.topic, int(log_times[row]), payloads[row], entry)
            times.clear()
            payloads.clear()

        def flush_observations() -> None:
            for cid in gathered:
                if selected.get(by_id[cid].topic) in OBSERVATION_KINDS:
                    flush(cid)

        col.flush_observations = flush_observations
        try:
            for conn, t, raw in self.reader.messages(connections=conns):
                entry = handlers.get(conn.id)
                if entry is None:
                    continue
                if not isinstance(t, int):  # a damaged sqlite row: its timestamp is not a number
                    failures[conn.topic] += 1
                    first_error.setdefault(conn.topic, f"damaged row: its timestamp {bytes(t)[:16]!r} is not a number"
                                           if isinstance(t, bytes | bytearray | memoryview) else
                                           f"damaged row: its timestamp {t!r} is not a number")
                    continue
                delivered[(conn.topic, t)] += 1
                waiting = gathered.get(conn.id)
                if waiting is not None:
                    waiting[1].append(t)
                    waiting[2].append(bytes(raw))
                    if len(waiting[2]) >= BATCH_MESSAGES:
                        flush(conn.id)
                else:
                    handle(conn.topic, t, raw, entry)
                done += 1
                if progress is not None and done % 4096 == 0:
                    progress(4096)
        except Exception as err:
            if isinstance(err, AdapterError):
                raise
            for cid in gathered:
                flush(cid)
            col.flush_observations = None
            self._read_past_damage(err, selected, col, delivered)
        finally:
            col.flush_observations = None
        for cid in gathered:
            flush(cid)
        for topic, n in failures.items():
            col.notes.append(
                f"topic {topic}: {n} message{'s' if n != 1 else ''} could not be decoded "
                f"({first_error[topic]}); skipped"
            )

    def _read_past_damage(self, err: Exception, selected: dict[str, Kind], col: Collector,
                          delivered: Counter[tuple[str, int]]) -> None:
        """rosbags stopped at damage inside the bag: a salvage read gives back the messages after it."""
        what = _explain(self.path, err).what
        try:
            self.salvaged = self._salvage(err, f"reading stopped at damage ({what})")
        except AdapterError:
            col.notes.append(f"reading stopped early ({what}); the data before it is kept")
            return
        self.notes.extend(n for n in self.salvaged.notes if n not in self.notes)
        self.salvaged.read(selected, col, None, skip=delivered)

    # -- lazy fetch ---------------------------------------------------------------------------------
    def fetch(self, topic: str, log_time_ns: int, ordinal: int) -> Any:
        if self.salvaged is not None:
            return self.salvaged.fetch(topic, log_time_ns, ordinal)
        conns = [c for c in self.reader.connections if c.topic == topic]
        seen = 0
        for conn, t, raw in self.reader.messages(connections=conns, start=log_time_ns, stop=log_time_ns + 1):
            if t != log_time_ns:
                continue
            if seen == ordinal:
                return self.decoder(conn.msgtype, topic)(raw)
            seen += 1
        raise CorruptLogError(self.path, f"message at log time {log_time_ns} ns not found on re-read", topic=topic)
