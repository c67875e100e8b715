"""ROS 2 sqlite3 bags read row by row, for bags rosbags cannot open: a .db3 cut short or with
damaged pages (sqlite still reads every row whose pages are intact), a metadata.yaml that is
missing, damaged or stale (the topics and counts are rebuilt from the storage), and messages
compressed one by one where one fails to decompress (that message is dropped and counted).
"""

from __future__ import annotations

import contextlib
import sqlite3
import struct
import tempfile
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from framechain.adapters.errors import CorruptLogError, EmptyLogError, SchemaError
from framechain.adapters.formats.decode_loop import DecodeLoop, ProgressFn, Route
from framechain.adapters.formats.decoders import Decoder, ros_decoder, ros_typename
from framechain.adapters.formats.salvage_report import SalvageReport
from framechain.adapters.messages.collect import Collector
from framechain.adapters.messages.kinds import Kind
from framechain.timeline import LogInfo, TopicInfo

#: Rows fetched per query while the pages read cleanly.
_BATCH = 512
#: Consecutive unreadable row ids after which the rest of the table is taken as lost.
_GAP = 4096


@dataclass(frozen=True)
class _Topic:
    id: int
    name: str
    msgtype: str


def _metadata(bag: Path) -> tuple[dict[str, Any], str]:
    """The parsed metadata.yaml of a bag directory ({} when missing or unusable) and what is wrong with it."""
    meta = bag / "metadata.yaml"
    if not bag.is_dir():
        return {}, ""
    if not meta.is_file():
        return {}, "metadata.yaml is missing"
    try:
        import yaml

        doc = yaml.safe_load(meta.read_text(encoding="utf-8", errors="replace"))
        info = doc["rosbag2_bagfile_information"]
        if not isinstance(info, dict):
            raise TypeError("not a mapping")
        return info, ""
    except Exception as err:
        return {}, f"metadata.yaml cannot be parsed ({type(err).__name__})"


def _storage_files(bag: Path, meta: dict[str, Any]) -> list[Path]:
    if not bag.is_dir():
        return [bag]
    named = [bag / str(p) for p in meta.get("relative_file_paths") or [] if isinstance(p, str)]
    found = [p for p in named if p.is_file()]
    return found or sorted(bag.glob("*.db3"))


def _well_formed(row: Any) -> bool:
    """A messages row with the column types rosbag2 writes (damage can leave NULLs or text)."""
    return (isinstance(row[1], int) and isinstance(row[2], int) and -(1 << 63) <= row[2] < (1 << 63)
            and isinstance(row[3], bytes))


class Rosbag2Salvage:
    """A ROS 2 sqlite3 bag read row by row (the same interface as :class:`RosbagsLog`)."""

    def __init__(self, path: Path, reason: str | None, typestore: Any) -> None:
        """``reason``: why rosbags could not open the bag; None when this reader is simply the one
        for per-message compressed bags (then only damage is noted)."""
        self.path = path
        self.ros1 = False
        self.notes: list[str] = []
        self._store = typestore
        meta, meta_problem = _metadata(path)
        self._files = _storage_files(path, meta)
        if not self._files:
            raise CorruptLogError(path, f"{reason or 'cannot be read'}; and no .db3 storage file to salvage from")
        mode = str(meta.get("compression_mode") or "").lower()
        fmt = str(meta.get("compression_format") or "").lower()
        self._per_message = mode == "message" and fmt == "zstd"
        if mode == "file" and fmt:
            raise CorruptLogError(path, f"{reason or 'cannot be read'}; its storage is compressed per file ({fmt}), "
                                  "which cannot be salvaged row by row: decompress it first")
        size = sum(p.stat().st_size for p in self._files)
        self.salvage = SalvageReport(reason or "damaged rows or messages", size=size, method="row by row")
        self._details: list[str] = [meta_problem] if meta_problem else []
        self._decoders: dict[str, Decoder] = {}
        self._topics: dict[tuple[int, int], _Topic] = {}
        self._counts: Counter[str] = Counter()
        self._first = 0
        self._last = 0
        self._undecompressed: Counter[str] = Counter()
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        if reason is not None:
            self._files = [self._readable_copy(db) for db in self._files]
        for fi, db in enumerate(self._files):
            self._open_topics(fi, db)
        for topic, t, _ in self._messages():
            self._first = t if not self._counts else min(self._first, t)
            self._last = max(self._last, t)
            self._counts[topic.name] += 1
        self.salvage.recovered.update(self._counts)
        self._compare_with_metadata(meta)
        if reason is not None or self.salvage.damaged or self._details:
            self.notes.extend(self.salvage.notes())
            self.notes.extend(self._details)
        self._salvaging = reason is not None

    # -- storage ------------------------------------------------------------------------------
    def _readable_copy(self, db: Path) -> Path:
        """A copy of a cut .db3 that sqlite will read: whole pages only, and a header that says so.

        A file cut short still claims its full page count in its header, and sqlite then calls
        every query "malformed"; with the count of the pages present, the intact ones read.
        """
        data = db.read_bytes()
        if len(data) < 100 or not data.startswith(b"SQLite format 3\x00"):
            return db
        (page,) = struct.unpack_from(">H", data, 16)
        page = 65536 if page == 1 else page
        if page < 512 or page & (page - 1):
            return db
        pages = len(data) // page
        (claimed,) = struct.unpack_from(">I", data, 28)
        if pages == 0 or (pages == claimed and len(data) % page == 0):
            return db
        fixed = bytearray(data[:pages * page])
        struct.pack_into(">I", fixed, 28, pages)
        if self._tmp is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="framechain-salvage-")
        copy = Path(self._tmp.name) / db.name
        copy.write_bytes(bytes(fixed))
        self._details.append(f"{db.name}: cut short inside page {pages + 1} of {claimed}; "
                             f"read the {pages} whole pages")
        return copy

    def _connect(self, db: Path) -> sqlite3.Connection:
        return sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro&immutable=1", uri=True)

    def _open_topics(self, fi: int, db: Path) -> None:
        try:
            with contextlib.closing(self._connect(db)) as con:
                rows = con.execute("SELECT id, name, type FROM topics").fetchall()
                self._register_definitions(con)
        except sqlite3.Error as err:
            self._details.append(f"{db.name}: its topics table cannot be read ({err}); its messages are lost")
            self.salvage.lost_unknown += 1
            return
        for tid, name, msgtype in rows:
            self._topics[(fi, int(tid))] = _Topic(int(tid), str(name), ros_typename(str(msgtype)))

    def _register_definitions(self, con: sqlite3.Connection) -> None:
        """Types the bag defines itself (custom messages) from its message_definitions table, if any."""
        from rosbags.typesys import get_types_from_msg

        try:
            rows = con.execute("SELECT topic_type, encoding, encoded_message_definition FROM message_definitions")
            definitions = rows.fetchall()
        except sqlite3.Error:
            return
        for msgtype, encoding, text in definitions:
            name = ros_typename(str(msgtype))
            if encoding != "ros2msg" or name in self._store.types or not text:
                continue
            try:
                types = get_types_from_msg(str(text), name)
                self._store.register({k: v for k, v in types.items() if k not in self._store.types})
            except Exception:
                continue  # decoding that topic then fails with a named SchemaError

    def _rows(self, db: Path) -> Iterator[tuple[int, int, int, bytes]]:
        """(id, topic id, timestamp, data) of every readable row; a damaged page costs only its rows."""
        try:
            con = self._connect(db)
        except sqlite3.Error as err:
            self._detail(f"{db.name}: cannot be opened ({err})")
            return
        last, skipped, tail = 0, 0, -1
        try:
            while True:
                try:
                    got = 0
                    for row in con.execute(
                            "SELECT id, topic_id, timestamp, data FROM messages WHERE id > ? ORDER BY id LIMIT ?",
                            (last, _BATCH)):
                        got += 1
                        if not isinstance(row[0], int) or row[0] <= last:
                            raise sqlite3.DatabaseError("row ids out of order")
                        last = row[0]
                        if _well_formed(row):
                            yield row
                    if got == 0:
                        break
                    continue
                except sqlite3.Error:
                    pass
                # The pages after ``last`` are damaged: step over them one row id at a time.
                row, failed = None, 0
                for probe in range(last + 1, last + 1 + _GAP):
                    try:
                        row = con.execute("SELECT id, topic_id, timestamp, data FROM messages WHERE id = ?",
                                          (probe,)).fetchone()
                    except sqlite3.Error:
                        failed += 1
                    if row is not None:
                        break
                if row is None:
                    tail = last + 1 if failed else -1
                    break
                skipped += failed
                last = probe
                if _well_formed(row):
                    yield row
        except sqlite3.Error as err:
            self._detail(f"{db.name}: reading stopped after row id {last} ({err})")
        finally:
            con.close()
        if skipped:
            self._detail(f"{db.name}: {skipped} row ids could not be read (damaged pages); their messages are lost")
        if tail >= 0:
            self._detail(f"{db.name}: no row from id {tail} on could be read (the file is cut short or its last "
                         "pages are damaged)")

    def _detail(self, note: str) -> None:
        if note not in self._details:
            self._details.append(note)
            self.salvage.lost_unknown += 1

    def _messages(self) -> Iterator[tuple[_Topic, int, bytes]]:
        decompress: Callable[[bytes], bytes] | None = None
        if self._per_message:
            import zstandard

            decompress = zstandard.ZstdDecompressor().decompress
        counting = not self._counts and not self._undecompressed
        for fi, db in enumerate(self._files):
            for _, tid, t, stored in self._rows(db):
                topic = self._topics.get((fi, tid))
                if topic is None:
                    continue
                data = stored
                if decompress is not None:
                    try:
                        data = decompress(stored)
                    except Exception:
                        if counting:
                            self._undecompressed[topic.name] += 1
                        continue
                yield topic, t, data
        if counting and self._undecompressed:
            self.salvage.lost.update(self._undecompressed)
            n = sum(self._undecompressed.values())
            self._details.append(f"{n} message{'s' if n != 1 else ''} could not be decompressed (zstd) and "
                                 f"were dropped")

    def _compare_with_metadata(self, meta: dict[str, Any]) -> None:
        said: Counter[str] = Counter()
        for entry in meta.get("topics_with_message_count") or []:
            try:
                said[str(entry["topic_metadata"]["name"])] += int(entry["message_count"])
            except (KeyError, TypeError, ValueError):
                continue
        if not said:
            if meta or self.path.is_dir():
                self._details.append("topics and counts rebuilt from the storage (metadata.yaml unusable)")
            return
        missing = said - self._counts - self._undecompressed
        if missing:
            self.salvage.lost.update(missing)
        if said != self._counts + self._undecompressed:
            self._details.append(f"metadata.yaml says {sum(said.values())} messages, the storage holds "
                                 f"{sum(self._counts.values())} readable: counts rebuilt from the storage")

    # -- the RosbagsLog interface ---------------------------------------------------------------------
    def __enter__(self) -> Rosbag2Salvage:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def info(self) -> LogInfo:
        types: dict[str, str] = {}
        for topic in self._topics.values():
            types.setdefault(topic.name, topic.msgtype)
        if not types:
            raise EmptyLogError(self.path, f"{self.salvage.reason}, and no topics could be read from the storage")
        duration = max(self._last - self._first, 0) * 1e-9
        topics = tuple(
            TopicInfo(name, types[name], self._counts[name],
                      (self._counts[name] - 1) / duration if self._counts[name] > 1 and duration > 0 else 0.0, "cdr")
            for name in sorted(types)
        )
        parts = "sqlite3, zstd per message" if self._per_message else "sqlite3"
        if self._salvaging or self.salvage.damaged:
            parts += "; salvaged row by row"
        return LogInfo(format="rosbag2", path=self.path, start_ns=self._first, end_ns=self._last, topics=topics,
                       notes=tuple(self.notes), container=f"rosbag2 ({parts})",
                       message_count=sum(self._counts.values()),
                       salvage=self.salvage.to_dict() if self._salvaging or self.salvage.damaged else None)

    def decoder(self, topic: _Topic) -> Decoder:
        if topic.msgtype not in self._decoders:
            if topic.msgtype not in self._store.types:
                raise SchemaError(self.path, f"no definition for message type {topic.msgtype}", topic=topic.name)
            self._decoders[topic.msgtype] = ros_decoder(self._store, topic.msgtype, ros1=False)
        return self._decoders[topic.msgtype]

    def read(self, selected: dict[str, Kind], col: Collector, progress: ProgressFn | None = None, *,
             skip: Counter[tuple[str, int]] | None = None) -> None:
        """Decode the selected topics into the collector; ``skip``: (topic, log time) already delivered."""
        first: dict[str, _Topic] = {}  # per name, the first topic met: its type decodes the name's messages

        def route(name: str) -> Route | None:
            kind = selected.get(name)
            handle = col.handler(kind) if kind is not None else None
            if kind is None or handle is None:
                return None
            return Route(name, kind, self.decoder(first[name]), handle)  # a SchemaError: the loop notes it

        def messages() -> Iterator[tuple[str, int, bytes]]:
            for topic, t, data in self._messages():
                first.setdefault(topic.name, topic)
                yield topic.name, t, data

        loop = DecodeLoop(col, route, progress, skip=skip)
        loop.run(messages())
        loop.finish(self.notes)

    def fetch(self, topic: str, log_time_ns: int, ordinal: int) -> Any:
        seen = 0
        for top, t, data in self._messages():
            if top.name == topic and t == log_time_ns:
                if seen == ordinal:
                    return self.decoder(top)(data)
                seen += 1
        raise CorruptLogError(self.path, f"message at log time {log_time_ns} ns not found on re-read", topic=topic)
