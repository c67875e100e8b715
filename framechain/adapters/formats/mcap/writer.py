"""MCAP files written: a Timeline's messages as a ROS 1 or ROS 2 MCAP (:func:`write_mcap_ros2`,
:func:`write_mcap_ros1`, for :func:`framechain.adapters.formats.log_writer.write_log`), and a log's messages
copied into a new MCAP with messages of other schemas beside them (an export).

The log's own messages keep their bytes, schemas and encodings: an MCAP is copied record for
record; a ROS 1 bag becomes ``ros1`` messages with ``ros1msg`` schemas, a ROS 2 bag ``cdr`` messages
with ``ros2msg``/``ros2idl`` schemas (the definitions stored in the bag), so Foxglove and Rerun read
the copy as they read the original. A LeRobot dataset (or a saved timeline) has no messages to copy
(:func:`copies_messages`): its content comes as added messages. The added messages
come already serialised with their schema (protobuf: a ``FileDescriptorSet``), one channel per topic.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from framechain import __version__
from framechain.adapters.api import detect
from framechain.adapters.errors import AdapterError
from framechain.adapters.formats.mcap import MCAP_MAGIC
from framechain.adapters.formats.msgdefs import OutMessage

#: The name of the MCAP metadata record that marks a file framechain wrote (not a recording to analyse).
FRAMECHAIN_METADATA = "framechain"
#: The MCAP header's ``library`` of framechain's exports (older exports carry it without the metadata).
FRAMECHAIN_LIBRARY = "framechain"
#: The bytes of an MCAP footer record (opcode, length, summary start, summary offset start, CRC).
FOOTER_BYTES = 1 + 8 + 8 + 8 + 4


class ExtraMessage(Protocol):
    """A serialised message to add: topic, schema (name, encoding, data), message encoding, times."""

    @property
    def topic(self) -> str: ...
    @property
    def schema_name(self) -> str: ...
    @property
    def schema_encoding(self) -> str: ...
    @property
    def schema_data(self) -> bytes: ...
    @property
    def message_encoding(self) -> str: ...
    @property
    def log_time_ns(self) -> int: ...
    @property
    def publish_time_ns(self) -> int: ...
    @property
    def data(self) -> bytes: ...


@dataclass(frozen=True)
class ExportCounts:
    """Messages copied from the log and added, per topic."""

    copied: dict[str, int]
    added: dict[str, int]


def copies_messages(source: str | Path) -> bool:
    """Whether the log ``source`` has messages of its own to copy (a LeRobot dataset, a saved timeline: no)."""
    from framechain.adapters.lerobot.adapter import is_lerobot_dataset

    path = Path(source)
    return not (path.is_dir() and (is_lerobot_dataset(path) or (path / "timeline.json").is_file()))


def write_mcap_with(source: str | Path | None, out: str | Path, extra: Iterable[ExtraMessage]) -> ExportCounts:
    """Write ``out``: every message of the log ``source`` (None: none) and the ``extra`` messages.

    ``out`` must not be the source itself.
    """
    target = Path(out)
    if source is not None and Path(source).resolve() == target.resolve():
        raise AdapterError(str(out), "the export would overwrite the log it reads; choose another --out")
    copied: dict[str, int] = {}
    added: dict[str, int] = {}
    extra_list = sorted(extra, key=lambda m: m.log_time_ns)
    target.parent.mkdir(parents=True, exist_ok=True)
    partial = target.with_name(f".{target.name}.{os.getpid()}.part")  # a failed export leaves no half file
    try:
        _write(partial, source, extra_list, copied, added)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    os.replace(partial, target)
    return ExportCounts(copied=copied, added=added)


def _write(path: Path, source: str | Path | None, extra: list[ExtraMessage], copied: dict[str, int],
           added: dict[str, int]) -> None:
    from mcap.writer import CompressionType, Writer

    with path.open("wb") as f:
        writer: Any = Writer(f, compression=CompressionType.ZSTD)
        writer.start(profile="", library=FRAMECHAIN_LIBRARY)
        # Marks the file as framechain's output: batch and folder discovery skip it (it holds a log's copy).
        writer.add_metadata(FRAMECHAIN_METADATA, {"version": __version__, "command": "export",
                                                  "source": "" if source is None else str(source)})
        if source is not None:
            _copy_log(Path(source), writer, copied)
        schemas: dict[tuple[str, str], int] = {}
        channels: dict[str, int] = {}
        for m in extra:
            key = (m.schema_name, m.schema_encoding)
            if key not in schemas:
                schemas[key] = writer.register_schema(m.schema_name, m.schema_encoding, m.schema_data)
            if m.topic not in channels:
                channels[m.topic] = writer.register_channel(m.topic, m.message_encoding, schemas[key])
            writer.add_message(channels[m.topic], log_time=m.log_time_ns, publish_time=m.publish_time_ns,
                               data=m.data)
            added[m.topic] = added.get(m.topic, 0) + 1
        writer.finish()


def _copy_log(source: Path, writer: Any, copied: dict[str, int]) -> None:
    if not copies_messages(source):
        return  # a dataset of Parquet and video files, a saved timeline: no messages to copy
    fmt, target, _ = detect(source)
    if fmt == "mcap":
        _copy_mcap(target, writer, copied)
    else:
        _copy_rosbag(target, writer, copied)


def _copy_mcap(path: Path, writer: Any, copied: dict[str, int]) -> None:
    from mcap.reader import make_reader

    w = writer
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.id not in channel_ids:
                if schema is not None and schema.id not in schema_ids:
                    schema_ids[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
                channel_ids[channel.id] = w.register_channel(
                    channel.topic, channel.message_encoding, schema_ids[schema.id] if schema is not None else 0,
                    metadata=dict(channel.metadata))
            w.add_message(channel_ids[channel.id], log_time=message.log_time,
                          publish_time=message.publish_time, data=message.data, sequence=message.sequence)
            copied[channel.topic] = copied.get(channel.topic, 0) + 1


def _copy_rosbag(path: Path, writer: Any, copied: dict[str, int]) -> None:
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import MessageDefinitionFormat

    w = writer
    with AnyReader([path]) as reader:
        ros1 = reader.is2 is False
        channel_ids: dict[int, int] = {}
        schema_ids: dict[str, int] = {}
        for conn in reader.connections:
            text = conn.msgdef.data
            if ros1:
                name, encoding, message_encoding = conn.msgtype.replace("/msg/", "/"), "ros1msg", "ros1"
            else:
                idl = conn.msgdef.format == MessageDefinitionFormat.IDL
                name, encoding, message_encoding = conn.msgtype, "ros2idl" if idl else "ros2msg", "cdr"
            if name not in schema_ids:
                schema_ids[name] = w.register_schema(name, encoding, text.encode())
            channel_ids[conn.id] = w.register_channel(conn.topic, message_encoding,
                                                      schema_ids[name])
        for conn, t, raw in reader.messages():
            w.add_message(channel_ids[conn.id], log_time=t, publish_time=t, data=bytes(raw))
            copied[conn.topic] = copied.get(conn.topic, 0) + 1


def _metadata_names(f: Any) -> list[str] | None:
    """The names in the summary's metadata index group, found through the footer's summary offsets (the
    summary's chunk indexes, thousands on a long log, are not parsed: every log read is asked this); None
    when the file has no summary offsets."""
    import io
    import struct

    from mcap.data_stream import ReadDataStream
    from mcap.opcode import Opcode
    from mcap.records import Footer, MetadataIndex, SummaryOffset
    from mcap.stream_reader import StreamReader

    f.seek(-(FOOTER_BYTES + len(MCAP_MAGIC)), io.SEEK_END)
    footer = next(StreamReader(f, skip_magic=True).records)
    if not isinstance(footer, Footer) or footer.summary_offset_start == 0:
        return None
    f.seek(footer.summary_offset_start)
    offsets = [r for r in _records_until_footer(StreamReader(f, skip_magic=True)) if isinstance(r, SummaryOffset)]
    group = next((o for o in offsets if o.group_opcode == Opcode.METADATA_INDEX), None)
    if group is None:
        return []
    f.seek(group.group_start)
    data = f.read(group.group_length)
    names, at = [], 0
    while at + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, at)
        if opcode == Opcode.METADATA_INDEX:
            names.append(MetadataIndex.read(ReadDataStream(io.BytesIO(data[at + 9:at + 9 + length]))).name)
        at += 9 + length
    return names


def _records_until_footer(reader: Any) -> Iterable[Any]:
    from mcap.records import Footer

    for record in reader.records:
        if isinstance(record, Footer):
            return
        yield record


def framechain_output(path: str | Path) -> str | None:
    """What framechain wrote ``path`` as (``framechain 0.1 export of /logs/run.bag``), or None for a file it
    did not write: the ``framechain`` metadata record of an MCAP (its header's library, for exports older
    than the record). Reads the header and the summary only; a file that cannot be read is None."""
    from mcap.reader import make_reader

    p = Path(path)
    try:
        if not p.is_file():
            return None
        with p.open("rb") as f:
            if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                return None
            f.seek(0)
            reader = make_reader(f)
            library = reader.get_header().library
            names = _metadata_names(f)
            if names is None:  # no summary offsets to go by: the whole summary
                summary = reader.get_summary()
                names = [i.name for i in summary.metadata_indexes] if summary is not None else []
            marked = FRAMECHAIN_METADATA in names
            record = next((m.metadata for m in reader.iter_metadata() if m.name == FRAMECHAIN_METADATA), None) \
                if marked else None
    except Exception:  # a damaged file is not ours to diagnose here: the reader says what is wrong with it
        return None
    if record is not None:
        source = f" of {record['source']}" if record.get("source") else ""
        return f"framechain {record.get('version', '?')} {record.get('command', 'output')}{source}"
    return "a framechain export" if library == FRAMECHAIN_LIBRARY else None


def _to_plain(obj: Any) -> Any:
    """rosbags message object -> nested dicts (uint8 arrays as bytes) for mcap_ros2's encoder."""
    if hasattr(obj, "__dataclass_fields__"):
        return {k: _to_plain(getattr(obj, k)) for k in obj.__dataclass_fields__ if k != "__msgtype__"}
    if isinstance(obj, np.ndarray):
        return obj.tobytes() if obj.dtype == np.uint8 else obj.tolist()
    if isinstance(obj, list):
        return [_to_plain(v) for v in obj]
    return obj


def write_mcap_ros2(path: Path, messages: list[OutMessage], ts: Any) -> None:
    """``messages`` into a ROS 2 MCAP with mcap_ros2's writer (``ts``: the rosbags typestore that made them)."""
    from mcap_ros2.writer import Writer

    schemas: dict[str, Any] = {}
    with path.open("wb") as f:
        writer = Writer(f)
        for m in messages:
            if m.msgtype not in schemas:
                text = ts.generate_msgdef(m.msgtype, ros_version=2)[0]
                schemas[m.msgtype] = writer.register_msgdef(m.msgtype, text)
            writer.write_message(m.topic, schemas[m.msgtype], _to_plain(m.msg), log_time=m.log_time_ns,
                                 publish_time=m.log_time_ns)
        writer.finish()  # type: ignore[no-untyped-call]


def write_mcap_ros1(path: Path, messages: list[OutMessage], ts: Any) -> None:
    """``messages`` into a ROS 1 MCAP with mcap_ros1's writer (``ts``: the rosbags typestore that made them)."""
    from mcap_ros1.writer import Writer

    classes: dict[str, type] = {}

    def wrap(m: OutMessage) -> Any:
        if m.msgtype not in classes:
            name = m.msgtype.replace("/msg/", "/")
            text = ts.generate_msgdef(m.msgtype, ros_version=1)[0]

            def serialize(self: Any, buff: Any) -> None:
                buff.write(bytes(ts.serialize_ros1(self.msg, self.rostype)))

            classes[m.msgtype] = type(
                "Ros1Message", (), {"_type": name, "_full_text": text, "serialize": serialize,
                                    "rostype": m.msgtype, "__init__": lambda self, msg: setattr(self, "msg", msg)},
            )
        return classes[m.msgtype](m.msg)

    with path.open("wb") as f:
        writer = Writer(f)
        for m in messages:
            writer.write_message(m.topic, wrap(m), log_time=m.log_time_ns, publish_time=m.log_time_ns)
        writer.finish()  # type: ignore[no-untyped-call]
