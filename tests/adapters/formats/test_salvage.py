"""Damaged logs give back everything before the damage: cut copies of logs written with the real
writers (mcap, rosbags) and of the real logs, checked against the messages of the uncut file read
by the mcap library and rosbags (never by the salvage code)."""

from __future__ import annotations

import sqlite3
import struct
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from rosbags.rosbag1 import Reader as Rosbag1Reader

from framechain.adapters.api import TREE_KINDS, open_log, scan_log
from framechain.adapters.formats.mcap.salvage import ChannelRecord, McapScanner, MessageRecord
from framechain.adapters.formats.rosbag.salvage_ros1 import Message, Rosbag1Scanner
from tests.helpers.realdata import FRANKA_BAG, HUSKY_BAG, NAV2_MCAP
from tests.helpers.ros1_bags import tf_typestore

Msg = tuple[str, int, bytes]


# -- writers ---------------------------------------------------------------------------------------
def _tf(store: Any, i: int, ros1: bool) -> Any:
    t = store.types
    stamp = t["builtin_interfaces/msg/Time"](sec=100 + i // 10, nanosec=(i % 10) * 100_000_000)
    header = t["std_msgs/msg/Header"](seq=i, stamp=stamp, frame_id="odom") if ros1 else \
        t["std_msgs/msg/Header"](stamp=stamp, frame_id="odom")
    tf = t["geometry_msgs/msg/Transform"](
        translation=t["geometry_msgs/msg/Vector3"](x=0.01 * i, y=-0.02 * i, z=0.5),
        rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    ts = t["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id="base_link", transform=tf)
    return t["tf2_msgs/msg/TFMessage"](transforms=[ts])


def _write_mcap(path: Path, compression: str, n: int = 600) -> None:
    from mcap.writer import CompressionType, Writer

    store = tf_typestore(ros1=False)
    text = store.generate_msgdef("tf2_msgs/msg/TFMessage", ros_version=2)[0]
    kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "": CompressionType.NONE}
    with path.open("wb") as f:
        w = Writer(f, chunk_size=4096, compression=kinds[compression])
        w.start(profile="ros2")
        sid = w.register_schema("tf2_msgs/msg/TFMessage", "ros2msg", text.encode())
        cid = w.register_channel("/tf", "cdr", sid)
        for i in range(n):
            data = bytes(store.serialize_cdr(_tf(store, i, ros1=False), "tf2_msgs/msg/TFMessage"))
            w.add_message(cid, log_time=1_000_000_000 + i * 10_000_000, publish_time=0, data=data)
        w.finish()


def _write_bag(path: Path, compression: str, n: int = 600) -> None:
    from rosbags.rosbag1 import Writer

    store = tf_typestore(ros1=True)
    w = Writer(path)
    if compression:
        w.set_compression(Writer.CompressionFormat[compression.upper()])
    w.chunk_threshold = 4096
    with w:
        conn = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        for i in range(n):
            w.write(conn, 1_000_000_000 + i * 10_000_000,
                    bytes(store.serialize_ros1(_tf(store, i, ros1=True), "tf2_msgs/msg/TFMessage")))


# -- independent readers ------------------------------------------------------------------------------
def _mcap_original(path: Path) -> list[Msg]:
    from mcap.reader import make_reader

    with path.open("rb") as f:
        return [(c.topic, m.log_time, bytes(m.data)) for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


def _bag_original(path: Path) -> list[Msg]:
    from rosbags.rosbag1 import Reader

    with Reader(path) as r:
        return [(c.topic, t, bytes(raw)) for c, t, raw in r.messages()]


def _mcap_salvaged(data: bytes) -> list[Msg]:
    topics: dict[int, str] = {}
    out: list[Msg] = []
    for rec in McapScanner(data, topics.get).records():
        if isinstance(rec, ChannelRecord):
            topics[rec.id] = rec.topic
        elif isinstance(rec, MessageRecord):
            out.append((topics[rec.channel_id], rec.log_time, rec.data))
    return out


def _bag_salvaged(data: bytes) -> list[Msg]:
    scanner = Rosbag1Scanner(data, "test")
    return [(scanner.connections[r.conn].topic, r.time_ns, r.data) for r in scanner.records()
            if isinstance(r, Message)]


def _mcap_complete_before(path: Path, cut: int) -> int:
    """Messages whose chunk ends before ``cut``, or (uncompressed chunks) whose own record does."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    n = 0
    with path.open("rb") as f:
        for ci in summary.chunk_indexes:
            end = ci.chunk_start_offset + ci.chunk_length
            f.seek(ci.chunk_start_offset + ci.chunk_length)
            index = f.read(ci.message_index_length)
            # A message index record: opcode, length, channel id, u32 byte length, (time, offset) pairs.
            offsets = [struct.unpack_from("<QQ", index, 9 + 6 + 16 * k)[1]
                       for k in range((struct.unpack_from("<I", index, 11)[0]) // 16)]
            if end <= cut:
                n += len(offsets)
            elif ci.compression == "":
                # Records start after the chunk header: opcode, length, 3 u64, u32 crc, compression, u64.
                data_start = ci.chunk_start_offset + 9 + 8 * 3 + 4 + 4 + 8
                f.seek(data_start)
                blob = f.read(ci.uncompressed_size)
                n += sum(1 for off in offsets
                         if data_start + off + 9 + struct.unpack_from("<Q", blob, off + 1)[0] <= cut)
    return n


def _check_cuts(original: list[Msg], data: bytes, salvage: Any, step: int,
                expected: Any = None) -> None:
    previous = 0
    originals = Counter(original)
    for cut in [*range(1, len(data), step), len(data)]:
        got = salvage(data[:cut])
        assert len(got) >= previous, f"cut at {cut}: fewer messages than at an earlier cut"
        previous = len(got)
        assert not Counter(got) - originals, f"cut at {cut}: a recovered message differs from the original"
        assert got == original[:len(got)], f"cut at {cut}: not the messages before the cut, in order"
        if expected is not None:
            assert len(got) >= expected(cut), f"cut at {cut}: a complete message before the cut was lost"
    assert previous == len(original)


# -- MCAP --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
def test_cut_mcap_gives_back_every_message_before_the_cut(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "tf.mcap"
    _write_mcap(path, compression)
    original = _mcap_original(path)
    assert len(original) == 600
    expected = (lambda cut: _mcap_complete_before(path, cut)) if compression == "" else None
    _check_cuts(original, path.read_bytes(), _mcap_salvaged, 397, expected)


def test_cut_zstd_chunk_is_streamed(tmp_path: Path) -> None:
    """A single chunk cut in half: the complete records of its first half come back."""
    from mcap.writer import CompressionType, Writer

    store = tf_typestore(ros1=False)
    path = tmp_path / "one_chunk.mcap"
    text = store.generate_msgdef("tf2_msgs/msg/TFMessage", ros_version=2)[0]
    with path.open("wb") as f:
        w = Writer(f, chunk_size=10 << 20, compression=CompressionType.ZSTD)
        w.start(profile="ros2")
        cid = w.register_channel("/tf", "cdr", w.register_schema("tf2_msgs/msg/TFMessage", "ros2msg", text.encode()))
        for i in range(3000):
            w.add_message(cid, log_time=i, publish_time=i,
                          data=bytes(store.serialize_cdr(_tf(store, i, ros1=False), "tf2_msgs/msg/TFMessage")))
        w.finish()
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    (chunk,) = summary.chunk_indexes
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:chunk.chunk_start_offset + chunk.chunk_length // 2])
    info = scan_log(cut)
    # zstd streams out whole blocks: half the compressed bytes give back a good part of the 3000.
    assert 600 < info.message_count < 3000
    note = next(n for n in info.notes if "zstd chunk cut short" in n)
    assert f"({info.message_count} complete messages kept from it)" in note
    loaded = open_log(cut, kinds=TREE_KINDS)
    assert len(loaded.timeline.transforms.parent) == info.message_count
    assert any("recovered" in n and "/tf" in n for n in loaded.info.notes)


def test_corrupt_chunk_is_skipped_and_the_scan_resynchronises(tmp_path: Path) -> None:
    path = tmp_path / "tf.mcap"
    _write_mcap(path, "zstd")
    original = _mcap_original(path)
    data = bytearray(path.read_bytes())
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    victim = chunks[len(chunks) // 2]
    # Damage its length field (so it runs past the end of the file), and cut the summary away.
    struct.pack_into("<Q", data, victim.chunk_start_offset + 1, 1 << 40)
    cut_at = chunks[-1].chunk_start_offset + chunks[-1].chunk_length
    got = _mcap_salvaged(bytes(data[:cut_at]))
    # The chunk's zstd frame is whole: its stream ends where the chunk does, and every message comes back.
    assert got == original
    scanner = McapScanner(bytes(data[:cut_at]), lambda cid: None)
    list(scanner.records())
    assert scanner.report.details == [
        f"the chunk at byte {victim.chunk_start_offset} has a damaged length field; its data was read up to "
        f"where its stream ends (byte {victim.chunk_start_offset + victim.chunk_length})"]
    # A zeroed block in the next chunk: that chunk is lost whole, the scan goes on after it.
    nxt = chunks[len(chunks) // 2 + 1]
    data[nxt.chunk_start_offset + 60:nxt.chunk_start_offset + 120] = bytes(60)
    scanner = McapScanner(bytes(data[:cut_at]), lambda cid: "/tf")
    got = [(("/tf"), r.log_time, r.data) for r in scanner.records() if isinstance(r, MessageRecord)]
    in_next = [m for m in original if nxt.message_start_time <= m[1] <= nxt.message_end_time]
    assert got == [m for m in original if m not in in_next]
    assert scanner.report.lost == Counter({"/tf": len(in_next)})
    assert [(r.start, r.end) for r in scanner.report.skipped] == [
        (nxt.chunk_start_offset, nxt.chunk_start_offset + nxt.chunk_length)]


def test_crc_mismatch_chunk_counts_its_lost_messages(tmp_path: Path) -> None:
    path = tmp_path / "tf.mcap"
    _write_mcap(path, "")
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    victim = chunks[1]
    data = bytearray(path.read_bytes())
    data[victim.chunk_start_offset + victim.chunk_length - 5] ^= 0x40  # inside its last message's payload
    no_summary = bytes(data[:chunks[-1].chunk_start_offset])  # as if cut before the last chunk
    original = _mcap_original(path)
    in_victim = [m for m in original if victim.message_start_time <= m[1] <= victim.message_end_time]
    in_kept_chunks = [m for m in original if m[1] < chunks[-1].message_start_time]
    scanner = McapScanner(no_summary, lambda cid: "/tf")
    got = [r for r in scanner.records() if isinstance(r, MessageRecord)]
    assert scanner.report.lost == Counter({"/tf": len(in_victim)})
    assert len(got) == len(in_kept_chunks) - len(in_victim)
    assert any("CRC mismatch" in r.why for r in scanner.report.skipped)


# -- ROS 1 bags ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("compression", ["", "bz2", "lz4"])
def test_cut_rosbag1_gives_back_every_message_before_the_cut(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "tf.bag"
    _write_bag(path, compression)
    original = sorted(_bag_original(path), key=lambda m: m[1])
    assert len(original) == 600
    _check_cuts(original, path.read_bytes(), _bag_salvaged, 331)


def test_cut_rosbag1_opens_without_reindex(tmp_path: Path) -> None:
    path = tmp_path / "tf.bag"
    _write_bag(path, "")
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[:len(data) * 2 // 3])
    loaded = open_log(cut, kinds=TREE_KINDS)
    expected = _bag_salvaged(data[:len(data) * 2 // 3])
    assert 300 < len(expected) < 600
    assert loaded.info.message_count == len(expected)
    assert len(loaded.timeline.transforms.parent) == len(expected)
    # Translations are those written: x = 0.01 i for the i-th message.
    xs = sorted(float(v) for v in loaded.timeline.transforms.translation[:, 0])
    assert xs == pytest.approx([0.01 * i for i in range(len(expected))])
    text = " ".join(loaded.info.notes)
    assert "reindex" not in text
    assert f"recovered {len(expected)} messages" in text
    assert "cut short" in text


def test_damaged_chunk_in_an_indexed_rosbag1_costs_only_that_chunk(tmp_path: Path) -> None:
    path = tmp_path / "tf.bag"
    _write_bag(path, "bz2")
    data = bytearray(path.read_bytes())
    original = sorted(_bag_original(path), key=lambda m: m[1])
    # The third chunk record (op 0x05) from the start: damage the middle of its bz2 data.
    pos, chunks = 13, []
    while pos + 4 <= len(data):
        hlen = struct.unpack_from("<I", data, pos)[0]
        dlen = struct.unpack_from("<I", data, pos + 4 + hlen)[0]
        if b"op=\x05" in data[pos + 4:pos + 4 + hlen]:
            chunks.append((pos + 8 + hlen, dlen))
        pos += 8 + hlen + dlen
    start, dlen = chunks[2]
    data[start + dlen // 2:start + dlen // 2 + 16] = bytes(16)
    bag = tmp_path / "damaged.bag"
    bag.write_bytes(bytes(data))
    loaded = open_log(bag, kinds=TREE_KINDS)
    times = loaded.timeline.transforms.log_time_ns.tolist()
    assert len(times) == len(set(times))  # nothing given twice when the salvage takes over
    # Messages of the damaged chunk (and only those) are lost.
    with Rosbag1Reader(path) as reader:
        lost = {t for _, t, _ in reader.messages()} - set(times)
    assert 0 < len(lost) < 600 // (len(chunks) - 2)
    assert len(times) + len(lost) == len(original)
    assert any("reading stopped at damage" in n for n in loaded.info.notes)
    assert any("damaged chunk" in n for n in loaded.info.notes)


# -- ROS 2 bags ---------------------------------------------------------------------------------------------
def _write_ros2(path: Path, *, per_message: bool, n: int = 300) -> None:
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, Writer

    store = tf_typestore(ros1=False)
    w = Writer(path, version=8)
    if per_message:
        w.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with w:
        conn = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        for i in range(n):
            w.write(conn, 1_000_000_000 + i * 10_000_000,
                    bytes(store.serialize_cdr(_tf(store, i, ros1=False), "tf2_msgs/msg/TFMessage")))


def test_ros2_message_that_fails_to_decompress_is_dropped_and_counted(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    _write_ros2(bag, per_message=True)
    db = next(bag.glob("*.db3"))
    with sqlite3.connect(db) as con:
        con.execute("UPDATE messages SET data = ? WHERE id = 17", (b"not zstd at all",))
    loaded = open_log(bag, kinds=TREE_KINDS)
    assert len(loaded.timeline.transforms.parent) == 299
    xs = {round(float(v), 6) for v in loaded.timeline.transforms.translation[:, 0]}
    assert round(0.01 * 16, 6) not in xs  # row id 17 is the 17th message written (i = 16)
    assert round(0.01 * 15, 6) in xs
    assert any("1 message could not be decompressed" in n for n in loaded.info.notes)


def test_ros2_cut_db3_and_stale_metadata(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    _write_ros2(bag, per_message=False, n=2000)
    db = next(bag.glob("*.db3"))
    with sqlite3.connect(db) as con:
        original = {int(t): bytes(d) for t, d in con.execute("SELECT timestamp, data FROM messages")}
    data = db.read_bytes()
    db.write_bytes(data[:len(data) * 3 // 5])
    info = scan_log(bag)
    assert 0 < info.message_count < 2000
    assert any("cut short inside page" in n for n in info.notes)
    loaded = open_log(bag, kinds=TREE_KINDS)
    assert len(loaded.timeline.transforms.parent) == info.message_count
    assert set(loaded.timeline.transforms.log_time_ns.tolist()) <= set(original)
    # A metadata.yaml naming a storage file that is not there: rebuilt from the storage.
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace(db.name, "gone.db3"))
    assert scan_log(bag).message_count == info.message_count


# -- the real logs, cut at half ------------------------------------------------------------------------------
@pytest.mark.parametrize(("name", "at_least"), [
    (NAV2_MCAP, 5000),
    (FRANKA_BAG, 300),
    (HUSKY_BAG, 6000),
])
def test_real_logs_cut_at_half(realdata: Path, tmp_path: Path, name: str, at_least: int) -> None:
    src = realdata / name
    if not src.is_file():
        pytest.skip(f"{src} not present")
    data = src.read_bytes()
    half = data[:len(data) // 2]
    mcap = src.suffix == ".mcap"
    original = Counter(_mcap_original(src) if mcap else _bag_original(src))
    got = _mcap_salvaged(half) if mcap else _bag_salvaged(half)
    assert len(got) >= at_least
    assert not Counter(got) - original
    cut = tmp_path / src.name
    cut.write_bytes(half)
    info = scan_log(cut)
    assert info.message_count == len(got)
    assert any("cut short" in n for n in info.notes)


def test_salvage_is_said_in_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from framechain.cli.main import main

    path = tmp_path / "tf.bag"
    _write_bag(path, "")
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[:len(data) // 2])
    expected = _bag_salvaged(data[:len(data) // 2])
    assert main(["info", str(cut), "--json"]) == 0
    salvage = json.loads(capsys.readouterr().out)["salvage"]
    assert salvage["recovered"] == {"/tf": len(expected)}
    assert salvage["cut_at"] is not None
    assert salvage["skipped_bytes"][-1]["end"] == len(data) // 2
    assert main(["tf", str(cut), "odom", "base_link", "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["salvage"]["recovered_total"] == len(expected)
    assert f"recovered {len(expected)} messages" in out.err


def test_salvaged_rosbag1_fetches_one_message(tmp_path: Path) -> None:
    from framechain.adapters.formats.rosbag.reader import RosbagsLog

    path = tmp_path / "tf.bag"
    _write_bag(path, "lz4")
    data = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[:len(data) * 2 // 3])
    with RosbagsLog(cut) as log:
        assert log.salvaged is not None
        for i in (0, 7, 250):
            msg = log.fetch("/tf", 1_000_000_000 + i * 10_000_000, 0)
            assert msg.transforms[0].transform.translation.x == pytest.approx(0.01 * i)
        from framechain.adapters.errors import CorruptLogError

        with pytest.raises(CorruptLogError):
            log.fetch("/tf", 1_000_000_000 + 599 * 10_000_000, 0)  # after the cut
