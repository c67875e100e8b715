"""The decode loop every reader shares: a message that does not decode is counted per topic and
noted once, and the read goes on, in each reader path (MCAP indexed and scanned, rosbags' reader
for ROS 1 and ROS 2, the ROS 1 and ROS 2 salvage readers). Logs are written with the real writers;
the expected rows are the values written."""

from __future__ import annotations

import sqlite3
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from framechain.adapters.api import TREE_KINDS, open_log
from tests.helpers.ros1_bags import tf_typestore

N = 60
BAD = (5, 17, 40)  # messages written as three bytes: no type decodes from them
T0 = 1_000_000_000
STEP = 10_000_000


def _payload(store: Any, i: int, ros1: bool) -> bytes:
    if i in BAD:
        return b"\x01\x02\x03"
    t = store.types
    stamp = t["builtin_interfaces/msg/Time"](sec=1 + i // 100, nanosec=(i % 100) * STEP)
    header = (t["std_msgs/msg/Header"](seq=i, stamp=stamp, frame_id="odom") if ros1
              else t["std_msgs/msg/Header"](stamp=stamp, frame_id="odom"))
    transform = t["geometry_msgs/msg/Transform"](
        translation=t["geometry_msgs/msg/Vector3"](x=0.01 * i, y=0.0, z=0.5),
        rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    msg = t["tf2_msgs/msg/TFMessage"](transforms=[
        t["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id="base_link", transform=transform)])
    name = "tf2_msgs/msg/TFMessage"
    return bytes(store.serialize_ros1(msg, name) if ros1 else store.serialize_cdr(msg, name))


def _mcap(path: Path, *, indexed: bool = True) -> Path:
    from mcap.writer import IndexType, Writer

    store = tf_typestore(ros1=False)
    text = store.generate_msgdef("tf2_msgs/msg/TFMessage", ros_version=2)[0]
    options: dict[str, Any] = {} if indexed else {"index_types": IndexType.NONE, "use_summary_offsets": False,
                                                  "use_statistics": False}
    with path.open("wb") as f:
        w = Writer(f, chunk_size=1024, **options)
        w.start(profile="ros2")
        cid = w.register_channel("/tf", "cdr", w.register_schema("tf2_msgs/msg/TFMessage", "ros2msg", text.encode()))
        for i in range(N):
            w.add_message(cid, log_time=T0 + i * STEP, publish_time=T0 + i * STEP, data=_payload(store, i, False))
        w.finish()
    return path


def _bag(path: Path, *, index: bool = True) -> Path:
    from rosbags.rosbag1 import Writer

    store = tf_typestore(ros1=True)
    with Writer(path) as w:
        conn = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        for i in range(N):
            w.write(conn, T0 + i * STEP, _payload(store, i, True))
    if not index:  # cut where the index starts (the bag header's index_pos): every chunk kept
        data = path.read_bytes()
        (index_pos,) = struct.unpack_from("<Q", data, data.index(b"index_pos=") + len(b"index_pos="))
        path.write_bytes(data[:index_pos])
    return path


def _ros2(path: Path, *, per_message: bool = False) -> Path:
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, Writer

    store = tf_typestore(ros1=False)
    w = Writer(path, version=8)
    if per_message:  # read row by row (one message failing to decompress must not end the read)
        w.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with w:
        conn = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
        for i in range(N):
            w.write(conn, T0 + i * STEP, _payload(store, i, False))
    return path


def _ros2_bad_metadata(path: Path) -> Path:
    _ros2(path)
    (path / "metadata.yaml").write_text("rosbag2_bagfile_information: [")  # rosbags cannot open it
    return path


LOGS: dict[str, Callable[[Path], Path]] = {
    "mcap indexed": lambda tmp: _mcap(tmp / "tf.mcap"),
    "mcap scanned": lambda tmp: _mcap(tmp / "tf.mcap", indexed=False),
    "rosbag1": lambda tmp: _bag(tmp / "tf.bag"),
    "rosbag1 salvaged": lambda tmp: _bag(tmp / "tf.bag", index=False),
    "rosbag2": lambda tmp: _ros2(tmp / "bag"),
    "rosbag2 row by row": lambda tmp: _ros2(tmp / "bag", per_message=True),
    "rosbag2 salvaged": lambda tmp: _ros2_bad_metadata(tmp / "bag"),
}


@pytest.mark.parametrize("layout", list(LOGS))
def test_undecodable_messages_are_counted_per_topic_and_the_read_goes_on(tmp_path: Path, layout: str) -> None:
    loaded = open_log(LOGS[layout](tmp_path), kinds=TREE_KINDS)
    good = [i for i in range(N) if i not in BAD]
    tf = loaded.timeline.transforms
    np.testing.assert_array_equal(tf.log_time_ns, [T0 + i * STEP for i in good])
    np.testing.assert_allclose(tf.translation[:, 0], [0.01 * i for i in good])
    failed = [n for n in loaded.info.notes if "could not be decoded" in n]
    assert len(failed) == 1, loaded.info.notes
    assert failed[0].startswith(f"topic /tf: {len(BAD)} messages could not be decoded (")
    assert failed[0].endswith("); skipped")


def test_a_row_whose_timestamp_is_not_a_number_is_counted_with_the_undecodable(tmp_path: Path) -> None:
    bag = _ros2(tmp_path / "bag")
    with sqlite3.connect(next(bag.glob("*.db3"))) as con:
        con.execute("UPDATE messages SET timestamp = 'abc' WHERE id = 31")  # row ids count from 1: i = 30
    loaded = open_log(bag, kinds=TREE_KINDS)
    good = [i for i in range(N) if i not in BAD and i != 30]
    np.testing.assert_array_equal(loaded.timeline.transforms.log_time_ns, [T0 + i * STEP for i in good])
    failed = [n for n in loaded.info.notes if "could not be decoded" in n]
    assert failed == ["topic /tf: 4 messages could not be decoded (damaged row: its timestamp 'abc' is not a "
                      "number); skipped"]


def test_a_schema_that_does_not_parse_skips_its_topic_with_one_note(tmp_path: Path) -> None:
    """Two channels of /tf with a definition that does not parse: /tf is skipped (one note), /tf_static read."""
    from mcap.writer import Writer

    store = tf_typestore(ros1=False)
    text = store.generate_msgdef("tf2_msgs/msg/TFMessage", ros_version=2)[0]
    path = tmp_path / "tf.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start(profile="ros2")
        broken = w.register_schema("tf2_msgs/msg/TFMessage", "ros2msg", b"geometry_msgs/TransformStamped[ transforms")
        good = w.register_schema("tf2_msgs/msg/TFMessage", "ros2msg", text.encode())
        channels = [w.register_channel("/tf", "cdr", broken), w.register_channel("/tf", "cdr", broken),
                    w.register_channel("/tf_static", "cdr", good)]
        for i in range(N):
            if i not in BAD:
                w.add_message(channels[i % 3], log_time=T0 + i * STEP, publish_time=T0 + i * STEP,
                              data=_payload(store, i, False))
        w.finish()
    loaded = open_log(path, kinds=TREE_KINDS)
    static = [i for i in range(N) if i not in BAD and i % 3 == 2]
    np.testing.assert_array_equal(loaded.timeline.transforms.log_time_ns, [T0 + i * STEP for i in static])
    skipped = [n for n in loaded.info.notes if n.endswith(" skipped") and "could not be decoded" not in n]
    assert len(skipped) == 1, loaded.info.notes
    assert skipped[0].startswith("cannot parse the message definition of tf2_msgs/msg/TFMessage (")
    assert skipped[0].endswith(": topic /tf skipped")
