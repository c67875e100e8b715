"""ROS 1 bags (format 2.0, plain, bz2 or lz4 chunks) and ROS 2 bags (a directory with
metadata.yaml and .db3 or .mcap storage, uncompressed or zstd per file or per message, or a bare
.db3), read with rosbags. Type definitions come from the bag itself."""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path
from typing import Any

from framechain.adapters.errors import AdapterError, CorruptLogError, EmptyLogError, SchemaError
from framechain.adapters.formats.decode_loop import Batched, DecodeLoop, ProgressFn, Route
from framechain.adapters.formats.decoders import Decoder, ros_decoder
from framechain.adapters.formats.fast_cdr import FEEDERS
from framechain.adapters.formats.rosbag.salvage_ros1 import Rosbag1Salvage
from framechain.adapters.formats.rosbag.salvage_ros2 import Rosbag2Salvage
from framechain.adapters.formats.salvage_report import SalvageReport
from framechain.adapters.messages.collect import Collector
from framechain.adapters.messages.kinds import Kind, normalize_msgtype
from framechain.timeline import LogInfo, TopicInfo


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
        by_id = {c.id: c for c in conns}
        loop = DecodeLoop(col, lambda cid: self._route(by_id[cid], selected[by_id[cid].topic], col), progress,
                          count_delivered=True)
        for c in conns:  # every connection's schema checked (and noted) before the first message
            loop.route(c.id)
        try:
            loop.run((conn.id, t, raw) for conn, t, raw in self.reader.messages(connections=conns))
        except Exception as err:
            if isinstance(err, AdapterError):
                raise
            loop.flush()
            self._read_past_damage(err, selected, col, loop.delivered)
        loop.finish()

    def _route(self, conn: Any, kind: Kind, col: Collector) -> Route | None:
        """Where a connection's messages go; types fast_cdr knows are decoded many at a time by layout."""
        handle = col.handler(kind)
        if handle is None:
            return None
        decode = self.decoder(conn.msgtype, conn.topic)  # a SchemaError: the loop notes the topic as skipped
        store = self.reader.typestore
        feeder = FEEDERS.get((kind, normalize_msgtype(conn.msgtype)))
        if feeder is None or conn.msgtype not in store.fielddefs:
            return Route(conn.topic, kind, decode, handle)
        return Route(conn.topic, kind, decode, handle, Batched(store, conn.msgtype, self.ros1, feeder))

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
