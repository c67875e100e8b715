"""ROS 1 and ROS 2 bags written with rosbags' writers: a Timeline's messages (for
:func:`framechain.adapters.formats.log_writer.write_log`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from framechain.adapters.errors import AdapterError
from framechain.adapters.formats.msgdefs import OutMessage


def write_rosbag1(path: Path, messages: list[OutMessage], ts: Any, compression: str | None) -> None:
    """``messages`` into a ROS 1 bag with rosbags' writer (``compression``: bz2 or lz4 chunks)."""
    from rosbags.rosbag1 import Writer

    writer = Writer(path)
    if compression:
        fmt = {"bz2": Writer.CompressionFormat.BZ2, "lz4": Writer.CompressionFormat.LZ4}.get(compression)
        if fmt is None:
            raise AdapterError(path, f"rosbag1 compression must be bz2 or lz4, not {compression!r}")
        writer.set_compression(fmt)
    conns: dict[str, Any] = {}
    with writer:
        for m in messages:
            if m.topic not in conns:
                conns[m.topic] = writer.add_connection(m.topic, m.msgtype, typestore=ts)
            writer.write(conns[m.topic], m.log_time_ns, bytes(ts.serialize_ros1(m.msg, m.msgtype)))


def write_rosbag2(path: Path, messages: list[OutMessage], ts: Any, compression: str | None, *, mcap: bool) -> None:
    """``messages`` into a ROS 2 bag (sqlite3 or MCAP storage) with rosbags' writer (``compression``: zstd-file or
    zstd-message)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP if mcap else StoragePlugin.SQLITE3)
    if compression:
        mode = {"zstd-file": CompressionMode.FILE, "zstd-message": CompressionMode.MESSAGE}.get(compression)
        if mode is None:
            raise AdapterError(path, f"rosbag2 compression must be zstd-file or zstd-message, not {compression!r}")
        writer.set_compression(mode, CompressionFormat.ZSTD)
    conns: dict[str, Any] = {}
    with writer:
        for m in messages:
            if m.topic not in conns:
                conns[m.topic] = writer.add_connection(m.topic, m.msgtype, typestore=ts)
            writer.write(conns[m.topic], m.log_time_ns, bytes(ts.serialize_cdr(m.msg, m.msgtype)))
