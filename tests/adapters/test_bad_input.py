"""Every bad input gets one clear line naming the file, topic and what is wrong; what can be
recovered is kept."""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from framechain.adapters import AdapterError, EmptyLogError, UnsupportedLogError, open_log, write_log
from framechain.cli.main import main
from framechain.timeline import CameraTable, Timeline, TransformTable
from tests.helpers.adapter_scene import CHAIN, T0


def _tf_log(path: Path, n: int = 200) -> Path:
    stamps = T0 + np.arange(n, dtype=np.int64) * 10_000_000
    tf = TransformTable.from_rows("odom", "base_link", stamps, np.column_stack([np.arange(n) * 0.01, np.zeros(n),
                                  np.zeros(n)]), np.tile([0, 0, 0, 1.0], (n, 1)), source="/tf")
    return write_log(Timeline(transforms=tf), path, container="mcap-ros2", chain=CHAIN)


def _small_chunks_mcap(path: Path, n: int = 300, compression: str = "") -> Path:
    """An MCAP with many small chunks (so a cut or a corrupt chunk loses only part), stored uncompressed
    or compressed (``zstd``, ``lz4``)."""
    from mcap.writer import CompressionType, Writer

    from framechain.adapters.formats.msgdefs import typestore

    ts = typestore(ros1=False)
    T = ts.types
    text = ts.generate_msgdef("tf2_msgs/msg/TFMessage", ros_version=2)[0]
    with path.open("wb") as f:
        w = Writer(f, chunk_size=2048, compression=CompressionType[compression.upper() or "NONE"])
        w.start(profile="ros2")
        sid = w.register_schema("tf2_msgs/msg/TFMessage", "ros2msg", text.encode())
        cid = w.register_channel("/tf", "cdr", sid)
        for i in range(n):
            t = T0 + i * 10_000_000
            msg = T["tf2_msgs/msg/TFMessage"](transforms=[T["geometry_msgs/msg/TransformStamped"](
                header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=t // 10**9,
                                                nanosec=t % 10**9), frame_id="odom"),
                child_frame_id="base_link",
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=float(i), y=0.0, z=0.0),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))])
            w.add_message(cid, log_time=t, publish_time=t, data=bytes(ts.serialize_cdr(msg, "tf2_msgs/msg/TFMessage")))
        w.finish()
    return path


def test_truncated_mcap_recovers_every_complete_message(tmp_path: Path) -> None:
    src = _small_chunks_mcap(tmp_path / "full.mcap")
    data = src.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    loaded = open_log(cut)
    n = len(loaded.timeline.transforms)
    assert 100 < n < 300
    # Recovered samples are exactly the first n written (x = index), nothing invented.
    assert np.array_equal(loaded.timeline.transforms.translation[:, 0], np.arange(n, dtype=float))
    note = next(x for x in loaded.info.notes if "no usable footer or summary" in x)
    assert f"recovered {n} messages" in note
    assert any("the file is cut short" in x for x in loaded.info.notes)


def test_corrupt_chunk_is_skipped_and_counted(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    src = _small_chunks_mcap(tmp_path / "c.mcap")
    with src.open("rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    victim = sorted(chunks, key=lambda c: c.chunk_start_offset)[2]
    data = bytearray(src.read_bytes())
    # Flip a byte inside the chunk's records (past its 1+8 byte record header and 8+8+8+4 fields).
    data[victim.chunk_start_offset + 9 + 40 + 100] ^= 0xFF
    src.write_bytes(bytes(data))
    loaded = open_log(src)
    # Messages were written at T0 + i * 10 ms: those inside the chunk's time range are the lost ones.
    times = T0 + np.arange(300) * 10_000_000
    lost = int(((times >= victim.message_start_time) & (times <= victim.message_end_time)).sum())
    assert lost > 0
    assert len(loaded.timeline.transforms) == 300 - lost
    note = next(x for x in loaded.info.notes if "CRC mismatch" in x)
    assert f"chunk at byte {victim.chunk_start_offset}" in note
    assert f"{lost} messages lost (/tf {lost})" in note


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_damaged_compressed_chunk_is_skipped_and_counted(tmp_path: Path, compression: str) -> None:
    """A compressed chunk is checked by its decompressor (not its CRC): a damaged frame loses that
    chunk's messages, counted, and nothing else."""
    from mcap.reader import make_reader

    src = _small_chunks_mcap(tmp_path / "c.mcap", compression=compression)
    with src.open("rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    victim = sorted(chunks, key=lambda c: c.chunk_start_offset)[2]
    assert victim.compression == compression
    data = bytearray(src.read_bytes())
    # The chunk record: opcode, length, start and end times, uncompressed size, CRC, compression, records,
    # which start with the frame's magic number.
    records = victim.chunk_start_offset + 9 + 8 + 8 + 8 + 4 + 4 + len(compression) + 8
    data[records : records + 4] = b"\x00\x00\x00\x00"
    src.write_bytes(bytes(data))
    loaded = open_log(src)
    times = T0 + np.arange(300) * 10_000_000
    lost = int(((times >= victim.message_start_time) & (times <= victim.message_end_time)).sum())
    assert lost > 0
    assert len(loaded.timeline.transforms) == 300 - lost
    note = next(x for x in loaded.info.notes if f"chunk at byte {victim.chunk_start_offset}" in x)
    assert "unreadable" in note
    assert f"{lost} messages lost (/tf {lost})" in note


def test_rosbag1_without_index(tmp_path: Path, written: dict[str, Path]) -> None:
    data = written["rosbag1"].read_bytes()
    # The bag header record (after the 13-byte magic) holds index_pos; zero it as an unclosed recorder does.
    header_len = struct.unpack_from("<I", data, 13)[0]
    header = data[17 : 17 + header_len]
    pos = header.index(b"index_pos=") + len(b"index_pos=")
    broken = bytearray(data)
    broken[17 + pos : 17 + pos + 8] = b"\x00" * 8
    bag = tmp_path / "noindex.bag"
    bag.write_bytes(bytes(broken))
    # Salvaged by a linear scan of the chunks: every message, and never "run `rosbag reindex`".
    whole = open_log(written["rosbag1"])
    loaded = open_log(bag)
    assert loaded.info.message_count == whole.info.message_count > 0
    assert {t.name: t.count for t in loaded.info.topics} == {t.name: t.count for t in whole.info.topics}
    assert len(loaded.timeline.transforms.parent) == len(whole.timeline.transforms.parent)
    assert any("the bag has no index" in n and "recovered" in n for n in loaded.info.notes)
    assert not any("reindex" in n for n in loaded.info.notes)


def test_unknown_schema_encoding_is_named(tmp_path: Path) -> None:
    from mcap.writer import Writer

    path = tmp_path / "fb.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("my.Thing", "flatbuffer", b"\x00")
        cid = w.register_channel("/thing", "flatbuffer", sid)
        cid2 = w.register_channel("/tf", "cdr", 0)  # no schema at all
        w.add_message(cid, log_time=1, publish_time=1, data=b"\x01")
        w.add_message(cid2, log_time=2, publish_time=2, data=b"\x01")
        w.finish()
    loaded = open_log(path)
    info = {t.name: t.msgtype for t in loaded.info.topics}
    assert info == {"/thing": "my.Thing", "/tf": "(no schema)"}
    assert len(loaded.timeline.transforms) == 0
    assert loaded.info.notes == (
        "topic /thing: message encoding 'flatbuffer' with schema encoding 'flatbuffer' (my.Thing) is not supported "
        "(cdr/ros2msg, cdr/ros2idl, ros1/ros1msg, protobuf or json); its messages are not read",
        "topic /tf: no schema for message encoding 'cdr', so the message type is unknown; its messages are not read",
    )


def test_schemaless_detections_topic_explains_the_failure(tmp_path: Path, written: dict[str, Path],
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """The chain names /detections, but the file stores it without a schema: say that, not just 'no detections'."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    path = tmp_path / "schemaless.mcap"
    with written["mcap-ros2"].open("rb") as src, path.open("wb") as dst:
        reader = make_reader(src)
        summary = reader.get_summary()
        assert summary is not None
        w = Writer(dst)
        w.start(profile="ros2")
        schema_ids = {sid: w.register_schema(sc.name, sc.encoding, sc.data) for sid, sc in summary.schemas.items()}
        channel_ids = {
            cid: w.register_channel(ch.topic, ch.message_encoding,
                                    0 if ch.topic == CHAIN.topics.detections else schema_ids[ch.schema_id])
            for cid, ch in summary.channels.items()
        }
        for _, channel, message in reader.iter_messages():
            w.add_message(channel_ids[channel.id], log_time=message.log_time, publish_time=message.publish_time,
                          data=message.data)
        w.finish()
    chain = tmp_path / "chain.yaml"
    chain.write_text(CHAIN.to_yaml())
    assert main(["attribute", str(path), "--chain", str(chain), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert str(path) in err
    assert f"topic {CHAIN.topics.detections}: no schema for message encoding 'cdr'" in err


def test_missing_metadata_yaml_reads_the_storage_file(tmp_path: Path, written: dict[str, Path]) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(written["rosbag2-sqlite"], bag)
    (bag / "metadata.yaml").unlink()
    loaded = open_log(bag, CHAIN)
    assert len(loaded.timeline.transforms) == 52
    assert any("no metadata.yaml" in n for n in loaded.info.notes)
    (bag / "second.db3").write_bytes((next(bag.glob("*.db3"))).read_bytes())
    with pytest.raises(UnsupportedLogError, match=r"metadata\.yaml is missing and there are 2 storage files"):
        open_log(bag)


def test_empty_log_and_not_a_bag(tmp_path: Path) -> None:
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(EmptyLogError, match=r"empty\.mcap: the file is empty"):
        open_log(tmp_path / "empty.mcap")
    (tmp_path / "dir").mkdir()
    (tmp_path / "dir" / "notes.txt").write_text("x")
    with pytest.raises(UnsupportedLogError, match="a directory that is not a bag"):
        open_log(tmp_path / "dir")
    (tmp_path / "a.txt").write_text("hello")
    with pytest.raises(UnsupportedLogError, match="not a log framechain can read"):
        open_log(tmp_path / "a.txt")
    from mcap.writer import Writer

    with (tmp_path / "none.mcap").open("wb") as f:
        w = Writer(f)
        w.start()
        w.finish()
    with pytest.raises(EmptyLogError, match="holds no messages"):
        open_log(tmp_path / "none.mcap")
    with pytest.raises(AdapterError, match="no such file"):
        open_log(tmp_path / "missing.bag")


def test_stamps_backwards_nan_transform_and_zero_k(tmp_path: Path) -> None:
    stamps = np.array([T0, T0 + 2, T0 + 1, T0 + 3], dtype=np.int64)
    xyz = np.zeros((4, 3))
    xyz[3, 0] = 0.123  # a unique value to poison below
    tf = TransformTable.from_rows("odom", "base_link", stamps, xyz, np.tile([0, 0, 0, 1.0], (4, 1)),
                                  log_time_ns=T0 + np.arange(4) * 10, source="/tf")
    cams = CameraTable.from_intrinsics("cam", fx=600, fy=600, cx=320, cy=240, width=640, height=480, stamp_ns=T0,
                                       source="/camera/color/camera_info")
    path = write_log(Timeline(transforms=tf, cameras=cams), tmp_path / "b.bag", container="rosbag1", chain=CHAIN)
    # Poison the log: a NaN translation and a camera with K all zero (bytes of the float64 values).
    data = bytearray(path.read_bytes())
    k600 = struct.pack("<d", 600.0)
    first_k = data.index(k600)
    for off in (first_k, data.index(k600, first_k + 8)):
        data[off : off + 8] = struct.pack("<d", 0.0)
    mark = data.index(struct.pack("<d", 0.123))
    data[mark : mark + 8] = struct.pack("<d", float("nan"))
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(data))
    loaded = open_log(bad)
    notes = " | ".join(loaded.info.notes)
    assert "topic /tf: 1 transform odom -> base_link with translation or rotation NaN or Inf dropped" in notes
    assert "topic /camera/color/camera_info: 1 CameraInfo with K all zero" in notes
    assert len(loaded.timeline.transforms) == 3
    assert len(loaded.timeline.cameras) == 0
    clean = open_log(path)
    assert "edge odom -> base_link: header stamps go backwards 1 time in log order" in " ".join(clean.info.notes)
    # With a chain that needs that camera, the zero K is an error naming file and topic.
    with pytest.raises(AdapterError) as err:
        open_log(bad, CHAIN)
    assert str(bad) in str(err.value)
    assert "/camera/color/camera_info" in str(err.value)


def test_cli_reports_one_line_and_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "dir").mkdir()
    assert main(["info", str(tmp_path / "dir")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("framechain info: error:")
    assert "not a bag" in err[0]
    log = _tf_log(tmp_path / "t.mcap")
    assert main(["tf", str(log), "odom", "camera"]) == 1
    assert "frame 'camera' does not exist" in capsys.readouterr().err
    assert main(["tf", str(log), "odom", "base_link", "--at", "100"]) == 1
    err2 = capsys.readouterr().err
    assert "extrapolate into the future on edge odom -> base_link" in err2
    assert "recorded from" in err2
