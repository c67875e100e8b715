"""Layout (numpy) decoding agrees with rosbags' deserialisers, row for row, on real serialised bytes.

Messages are serialised by rosbags (CDR little- and big-endian, ROS 1) and written with the real
MCAP writer; the collector rows that the fast path makes must equal the rows its own handlers
make from rosbags' decoded messages, float for float.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from framechain.adapters import open_log
from framechain.adapters.formats import decode_loop, fast_cdr
from framechain.adapters.formats.fast_cdr import (
    FEEDERS,
    LayoutError,
    decode_batches,
    layout_of,
    parse_cdr_compressed_image,
    parse_cdr_image,
)
from framechain.adapters.formats.mcap import reader as mcap_log
from framechain.adapters.formats.msgdefs import typestore
from framechain.adapters.messages.collect import Collector
from framechain.adapters.messages.kinds import Kind
from framechain.replay.depth import _median_of_good

NS = 1_000_000_000
TF = "tf2_msgs/msg/TFMessage"
INFO = "sensor_msgs/msg/CameraInfo"
POINT = "geometry_msgs/msg/PointStamped"
DETS = "vision_msgs/msg/Detection2DArray"
ENCODINGS = ("cdr-le", "cdr-be", "ros1")


class Msgs:
    """rosbags message objects of one ROS version, with odd-length strings on purpose."""

    def __init__(self, ros1: bool) -> None:
        self.ros1 = ros1
        self.ts = typestore(ros1=ros1)
        self.T = self.ts.types

    def header(self, stamp_ns: int, frame: str) -> Any:
        sec, nsec = divmod(stamp_ns, NS)
        t = self.T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=7, stamp=t, frame_id=frame)
        return self.T["std_msgs/msg/Header"](stamp=t, frame_id=frame)

    def tf(self, i: int, edges: list[tuple[str, str]]) -> Any:
        T = self.T
        return T[TF](transforms=[
            T["geometry_msgs/msg/TransformStamped"](
                header=self.header(1_700_000_000 * NS + i * 10_000_001 + k, parent), child_frame_id=child,
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=0.1 * i, y=-1.5 + k, z=np.pi * i),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.6 * np.sin(i), z=0.8 * np.sin(i),
                                                               w=np.cos(i)),
                ),
            ) for k, (parent, child) in enumerate(edges)
        ])

    def camera_info(self, i: int, d: list[float]) -> Any:
        T = self.T
        k = np.array([600.0 + i, 0, 320.5, 0, 601.0, 240.25, 0, 0, 1])
        fields: dict[str, Any] = {"header": self.header(5 * NS + i, "cam_optical"), "height": 480, "width": 641,
                                  "distortion_model": "plumb_bob" if d else "", "binning_x": 0, "binning_y": 0,
                                  "roi": T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0,
                                                                                width=0, do_rectify=False)}
        names = ("D", "K", "R", "P") if self.ros1 else ("d", "k", "r", "p")
        fields.update(dict(zip(names, (np.asarray(d, dtype=np.float64), k, np.eye(3).reshape(9),
                                       np.zeros(12)), strict=True)))
        return T[INFO](**fields)

    def point(self, i: int, frame: str) -> Any:
        return self.T[POINT](header=self.header(3 * NS + i, frame),
                             point=self.T["geometry_msgs/msg/Point"](x=1.0 / (i + 1), y=-2.0 * i, z=1e-9 * i))

    def detections(self, i: int, dets: list[tuple[str, str, float]]) -> Any:
        """Detection2DArray; each detection (id, class_id, depth z), an empty class_id meaning no results."""
        T = self.T
        out = []
        for k, (ident, label, z) in enumerate(dets):
            pose = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=z),
                                                 orientation=T["geometry_msgs/msg/Quaternion"](x=0, y=0, z=0, w=1)),
                covariance=np.zeros(36))
            results = [T["vision_msgs/msg/ObjectHypothesisWithPose"](
                hypothesis=T["vision_msgs/msg/ObjectHypothesis"](class_id=label, score=0.5 + 0.01 * i), pose=pose,
            )] if label else []
            center = T["vision_msgs/msg/Pose2D"](position=T["vision_msgs/msg/Point2D"](x=10.5 + i, y=20.25 + k),
                                                 theta=0.0)
            own_stamp = 0 if k % 2 else 9 * NS + i  # 0: the array's stamp is used
            out.append(T["vision_msgs/msg/Detection2D"](
                header=self.header(own_stamp, "" if k % 2 else "cam_optical"), results=results,
                bbox=T["vision_msgs/msg/BoundingBox2D"](center=center, size_x=4.0, size_y=3.0), id=ident))
        return T[DETS](header=self.header(8 * NS + i, "cam_optical"), detections=out)


def serialise(msgs: Msgs, msg: Any, typename: str, encoding: str) -> bytes:
    if encoding == "ros1":
        return bytes(msgs.ts.serialize_ros1(msg, typename))
    return bytes(msgs.ts.serialize_cdr(msg, typename, little_endian=encoding == "cdr-le"))


def deserialise(msgs: Msgs, raw: bytes, typename: str, encoding: str) -> Any:
    if encoding == "ros1":
        return msgs.ts.deserialize_ros1(raw, typename)
    return msgs.ts.deserialize_cdr(raw, typename)


def _plain(value: Any) -> Any:
    """NaN as a marker (NaN != NaN would fail equal rows), lists as tuples (sortable)."""
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    if isinstance(value, (list, tuple)):
        return tuple(_plain(v) for v in value)
    return value


def collector_rows(col: Collector) -> dict[str, Any]:
    """The collector's rows per table, each row one tuple, sorted (batches append layout by layout)."""
    tf, cam, obs, pt = col.transforms, col.cameras, col.observations, col.points
    tf_log = np.repeat(np.asarray(tf.message_log_ns, dtype=np.int64), tf.message_rows).tolist()
    vals = np.asarray(tf.values, dtype=np.float64).reshape(-1, 7).tolist()
    uvd = np.asarray(obs.uvd, dtype=np.float64).reshape(-1, 3).tolist()
    pts = np.asarray(pt.values, dtype=np.float64).reshape(-1, 7).tolist()
    tables = {
        "tf": zip(tf_log, tf.parent, tf.child, tf.stamp_ns, vals, strict=True),
        "tf_messages": zip(tf.message_log_ns, tf.message_rows, tf.message_static, tf.message_topic,
                           tf.message_kind, strict=True),
        "cameras": zip(zip(cam.frame, cam.stamp_ns, cam.log_time_ns, cam.width, cam.height, cam.model, cam.topic,
                           strict=True), cam.k, cam.d, strict=True),
        "observations": zip(obs.log_time_ns, obs.id_text, obs.stamp_ns, obs.frame, uvd, obs.label, obs.score,
                            obs.topic, strict=True),
        "points": zip(pt.log_time_ns, pt.frame, pt.stamp_ns, pts, pt.topic, strict=True),
    }
    rows: dict[str, Any] = {name: sorted(_plain(list(rows)), key=repr) for name, rows in tables.items()}
    rows["depth_from_pose"] = dict(col.depth_from_pose)
    return rows


def both_ways(msgs: Msgs, kind: Kind, typename: str, objects: list[Any], encoding: str,
              topic: str = "/topic") -> tuple[dict[str, Any], dict[str, Any], int]:
    """Collector rows from rosbags + the collector's handler, from the layout path, and leftovers."""
    raws = [serialise(msgs, m, typename, encoding) for m in objects]
    log_ns = np.arange(len(raws), dtype=np.int64) * 1000 + 5
    slow = Collector()
    handler = slow.handler(kind)
    assert handler is not None
    for t, raw in zip(log_ns.tolist(), raws, strict=True):
        handler(topic, t, deserialise(msgs, raw, typename, encoding))
    fast = Collector()
    batches, rest = decode_batches(msgs.ts, typename, raws, ros1=msgs.ros1)
    feeder = FEEDERS[(kind, typename.replace("/msg/", "/"))]
    for batch in batches:
        feeder(fast, topic, log_ns[batch.rows], batch)
    for row in rest.tolist():  # what read() does with leftovers
        fast_handler = fast.handler(kind)
        assert fast_handler is not None
        fast_handler(topic, int(log_ns[row]), deserialise(msgs, raws[row], typename, encoding))
    return collector_rows(slow), collector_rows(fast), int(rest.size)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_tf_rows_equal_rosbags_including_mixed_layouts(encoding: str) -> None:
    msgs = Msgs(ros1=encoding == "ros1")
    edge_sets = [[("odom", "base_link")], [("map", "odom"), ("odom", "base_link")], [],
                 [("a", "bc")], [("ab", "c")]]  # equal lengths, different strings; an empty TFMessage
    objects = [msgs.tf(i, edge_sets[i % len(edge_sets)]) for i in range(40)]
    slow, fast, rest = both_ways(msgs, Kind.TF, TF, objects, encoding)
    assert fast == slow
    assert rest == 0
    assert len(fast["tf"]) == sum(len(edge_sets[i % 5]) for i in range(40))


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("distortion", [[], [0.1, -0.2, 0.001, 0.002, 0.05], [1.0] * 3])
def test_camera_info_rows_equal_rosbags(encoding: str, distortion: list[float]) -> None:
    msgs = Msgs(ros1=encoding == "ros1")
    slow, fast, rest = both_ways(msgs, Kind.CAMERA_INFO, INFO, [msgs.camera_info(i, distortion) for i in range(6)],
                                 encoding)
    assert fast == slow
    assert rest == 0
    assert fast["cameras"][0][2] == tuple(distortion)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_point_rows_equal_rosbags(encoding: str) -> None:
    msgs = Msgs(ros1=encoding == "ros1")
    frames = ["map", "odom", "base_link", "x"]  # 3, 4, 9, 1 characters: every CDR padding
    slow, fast, _ = both_ways(msgs, Kind.POINT, POINT, [msgs.point(i, frames[i % 4]) for i in range(12)], encoding)
    assert fast == slow
    assert fast["points"][0][3][3:] == ("nan",) * 4  # a point has no rotation


@pytest.mark.parametrize("encoding", ["cdr-le", "cdr-be"])
def test_detection_rows_equal_rosbags(encoding: str) -> None:
    msgs = Msgs(ros1=False)
    shapes = [
        [("7", "cup", 1.25)],
        [("12", "mug", 0.0), ("13", "", 0.0)],  # no depth given; a detection without results
        [],
        [("abc", "bottle", float("nan")), ("x", "cup", 2.5), ("", "ab", -1.0)],
    ]
    objects = [msgs.detections(i, [(f"{ident}{i}" if ident else "", label, z) for ident, label, z in shapes[i % 4]])
               for i in range(24)]
    slow, fast, _ = both_ways(msgs, Kind.DETECTIONS, DETS, objects, encoding)
    assert fast == slow
    assert len(slow["observations"]) == 6 * (1 + 2 + 0 + 3)
    assert slow["depth_from_pose"]["/topic"] == 6 + 6  # shapes 0 and 3 (one each) over 24 messages


def test_a_message_that_does_not_fit_the_template_is_left_to_rosbags(monkeypatch: pytest.MonkeyPatch) -> None:
    msgs = Msgs(ros1=False)
    objects = [msgs.tf(i, [("a", "bc")] if i % 2 else [("ab", "c")]) for i in range(10)]
    monkeypatch.setattr(fast_cdr, "MAX_TEMPLATES_PER_LENGTH", 1)
    slow, fast, rest = both_ways(msgs, Kind.TF, TF, objects, "cdr-le")
    assert rest == 5
    assert fast == slow


def test_truncated_message_is_a_layout_error() -> None:
    msgs = Msgs(ros1=False)
    raw = serialise(msgs, msgs.tf(1, [("odom", "base_link")]), TF, "cdr-le")
    with pytest.raises(LayoutError):
        layout_of(msgs.ts, TF, raw[:-9], ros1=False)
    batches, rest = decode_batches(msgs.ts, TF, [raw[:-9], raw], ros1=False)
    assert rest.tolist() == [0]
    assert [b.rows.tolist() for b in batches] == [[1]]


@pytest.mark.parametrize("encoding", ["16UC1", "mono8", "32FC1", "8UC3x"])
@pytest.mark.parametrize("frame", ["", "c", "camera_depth_optical_frame"])
@pytest.mark.parametrize("little_endian", [True, False])
def test_image_parse_equals_rosbags(encoding: str, frame: str, little_endian: bool) -> None:
    msgs = Msgs(ros1=False)
    T = msgs.T
    data = np.arange(3 * 5 * 2, dtype=np.uint8) if encoding != "8UC3x" else np.zeros(0, dtype=np.uint8)
    msg = T["sensor_msgs/msg/Image"](header=msgs.header(123 * NS + 456, frame), height=3, width=5,
                                     encoding=encoding, is_bigendian=1, step=10, data=data)
    raw = bytes(msgs.ts.serialize_cdr(msg, "sensor_msgs/msg/Image", little_endian=little_endian))
    ours, theirs = parse_cdr_image(raw), msgs.ts.deserialize_cdr(raw, "sensor_msgs/msg/Image")
    for name in ("height", "width", "encoding", "is_bigendian", "step"):
        assert getattr(ours, name) == getattr(theirs, name)
    assert (ours.header.frame_id, ours.header.stamp.sec, ours.header.stamp.nanosec) == \
        (theirs.header.frame_id, theirs.header.stamp.sec, theirs.header.stamp.nanosec)
    np.testing.assert_array_equal(ours.data, theirs.data)
    with pytest.raises(LayoutError):
        parse_cdr_image(raw[: len(raw) - 1 - data.size // 2] if data.size else raw[:20])


@pytest.mark.parametrize("fmt", ["jpeg", "", "rgb8; jpeg compressed bgr8"])
@pytest.mark.parametrize("frame", ["", "c", "camera_color_optical_frame"])
@pytest.mark.parametrize("size", [0, 1, 7])
@pytest.mark.parametrize("little_endian", [True, False])
def test_compressed_image_parse_equals_rosbags(fmt: str, frame: str, size: int, little_endian: bool) -> None:
    msgs = Msgs(ros1=False)
    data = np.arange(size, dtype=np.uint8) + 200
    msg = msgs.T["sensor_msgs/msg/CompressedImage"](header=msgs.header(123 * NS + 456, frame), format=fmt, data=data)
    raw = bytes(msgs.ts.serialize_cdr(msg, "sensor_msgs/msg/CompressedImage", little_endian=little_endian))
    ours, theirs = parse_cdr_compressed_image(raw), msgs.ts.deserialize_cdr(raw, "sensor_msgs/msg/CompressedImage")
    assert (ours.format, ours.header.frame_id, ours.header.stamp.sec, ours.header.stamp.nanosec) == \
        (theirs.format, theirs.header.frame_id, theirs.header.stamp.sec, theirs.header.stamp.nanosec)
    np.testing.assert_array_equal(ours.data, theirs.data)
    for cut in (1, size + 1, len(raw) - 12):  # into the data, its length, the format
        with pytest.raises(LayoutError):
            parse_cdr_compressed_image(raw[: len(raw) - cut])


def _write_mcap(path: Path, msgs: Msgs, n: int) -> None:
    from mcap.writer import Writer

    defs = {t: msgs.ts.generate_msgdef(t, ros_version=2)[0] for t in (TF, POINT, INFO)}
    with path.open("wb") as f:
        w = Writer(f, chunk_size=4096)  # many chunks: batches cross chunk boundaries
        w.start(profile="ros2")
        ids = {t: w.register_schema(t, "ros2msg", text.encode()) for t, text in defs.items()}
        ch = {topic: w.register_channel(topic, "cdr", ids[t])
              for topic, t in (("/tf", TF), ("/camera/camera_info", INFO), ("/evidence/world", POINT))}
        for i in range(n):
            t = 1_700_000_000 * NS + i * 5_000_000
            edges = [("map", "odom"), ("odom", "base_link")] if i % 3 else [("odom", "base_link")]
            w.add_message(ch["/tf"], log_time=t, publish_time=t, data=serialise(msgs, msgs.tf(i, edges), TF, "cdr-le"))
            if i % 4 == 0:
                w.add_message(ch["/camera/camera_info"], log_time=t, publish_time=t,
                              data=serialise(msgs, msgs.camera_info(i, [0.0] * 5), INFO, "cdr-le"))
                w.add_message(ch["/evidence/world"], log_time=t, publish_time=t,
                              data=serialise(msgs, msgs.point(i, "map"), POINT, "cdr-le"))
        w.finish()


def test_open_log_gives_the_same_timeline_with_and_without_layout_decoding(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "many.mcap"
    _write_mcap(path, Msgs(ros1=False), 3000)
    monkeypatch.setattr(decode_loop, "BATCH_MESSAGES", 500)  # several flushes per channel
    fast = open_log(path).timeline
    monkeypatch.setattr(mcap_log, "FEEDERS", {})
    slow = open_log(path).timeline
    for name in ("transforms", "cameras"):
        a, b = getattr(fast, name), getattr(slow, name)
        assert len(a) == len(b) > 0
        for column in type(a).COLUMNS:
            np.testing.assert_array_equal(getattr(a, column), getattr(b, column), err_msg=f"{name}.{column}")
    assert len(fast.transforms) == 3000 + 2000


def test_window_median_equals_numpy_nanmedian() -> None:
    rng = np.random.default_rng(3)
    values = rng.uniform(0.1, 5.0, size=(500, 25))
    good = rng.uniform(size=values.shape) < 0.6
    good[np.arange(500), rng.integers(0, 25, 500)] = True  # one good value at least per row
    expected = np.nanmedian(np.where(good, values, np.nan), axis=1)
    np.testing.assert_array_equal(_median_of_good(values, good), expected)


@pytest.mark.parametrize("container", ["mcap-ros2", "mcap-ros1", "rosbag1", "rosbag2-sqlite"])
def test_every_container_reads_the_same_with_and_without_layout_decoding(
    container: str, written: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    from framechain.adapters.formats.rosbag import reader as rosbag_log
    from tests.helpers.adapter_scene import CHAIN

    fast = open_log(written[container], CHAIN).timeline
    monkeypatch.setattr(mcap_log, "FEEDERS", {})
    monkeypatch.setattr(rosbag_log, "FEEDERS", {})
    slow = open_log(written[container], CHAIN).timeline
    for name in ("transforms", "cameras", "observations", "points"):
        a, b = getattr(fast, name), getattr(slow, name)
        assert len(a) == len(b) > 0, name
        for column in type(a).COLUMNS:
            np.testing.assert_array_equal(getattr(a, column), getattr(b, column), err_msg=f"{name}.{column}")


@pytest.mark.parametrize("index", ["message indexes", "chunk index only"])
def test_depth_frames_fetched_by_location_equal_the_written_ones(
    index: str, scene: Any, written: dict[str, Path], tmp_path: Path
) -> None:
    from mcap.reader import make_reader
    from mcap.writer import IndexType, Writer

    from tests.helpers.adapter_scene import CHAIN

    path = written["mcap-ros2"]
    if index == "chunk index only":  # the same messages, no message index records to find them by
        path = tmp_path / "no_message_index.mcap"
        with written["mcap-ros2"].open("rb") as fin, path.open("wb") as fout:
            reader = make_reader(fin)
            summary = reader.get_summary()
            assert summary is not None
            w = Writer(fout, index_types=IndexType.CHUNK, chunk_size=2048)
            w.start(profile="ros2")
            schemas = {i: w.register_schema(s.name, s.encoding, s.data) for i, s in summary.schemas.items()}
            channels = {i: w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id])
                        for i, c in summary.channels.items()}
            for _, _, m in reader.iter_messages():
                w.add_message(channels[m.channel_id], log_time=m.log_time, publish_time=m.publish_time, data=m.data)
            w.finish()
    depth = open_log(path, CHAIN).timeline.depth_frames
    expected = scene.depth_frames
    assert len(depth) == len(expected) == 3
    if index == "chunk index only":
        from mcap.reader import make_reader as reader_of

        with path.open("rb") as f:
            assert not any(ci.message_index_offsets for ci in reader_of(f).get_summary().chunk_indexes)
    for i in (2, 0, 1):  # out of time order too
        # 16UC1 millimetres: the written metres rounded to the millimetre.
        want = np.where(np.isfinite(expected.load(i)) & (expected.load(i) > 0), np.rint(expected.load(i) * 1000), 0)
        np.testing.assert_array_equal(depth.load(i), (want * np.float32(0.001)).astype(np.float32))


@pytest.mark.parametrize("index", ["message indexes", "chunk index only"])
def test_fetch_finds_each_of_equal_log_times_across_chunks(index: str, tmp_path: Path) -> None:
    """Messages sharing a log time, in several chunks and beside another topic at the same times:
    the ordinal-th fetched at a time is the ordinal-th written at it (file order)."""
    from mcap.writer import IndexType, Writer

    msgs = Msgs(ros1=False)
    text = msgs.ts.generate_msgdef(POINT, ros_version=2)[0]
    path = tmp_path / "equal_times.mcap"
    written: list[tuple[int, float]] = []
    with path.open("wb") as f:
        w = Writer(f, chunk_size=512, index_types=IndexType.ALL if index == "message indexes" else IndexType.CHUNK)
        w.start(profile="ros2")
        sid = w.register_schema(POINT, "ros2msg", text.encode())
        wanted, other = w.register_channel("/wanted", "cdr", sid), w.register_channel("/other", "cdr", sid)
        for i in range(60):
            t = NS + (i // 7) * 1000  # runs of 7 messages at one log time, spanning chunks
            for channel, k in ((other, 100 + i), (wanted, i)):
                data = msgs.ts.serialize_cdr(msgs.point(k, "cam"), POINT)
                w.add_message(channel, log_time=t, publish_time=t, data=bytes(data))
            written.append((t, 1.0 / (i + 1)))
        w.finish()
    log = mcap_log.McapLog(path)
    try:
        assert len(log.summary.chunk_indexes) > 5
        assert any(ci.message_index_offsets for ci in log.summary.chunk_indexes) == (index == "message indexes")
        for i in (59, 0, 13, 14, 20, 6, 7, 33):  # out of order too
            t = written[i][0]
            ordinal = sum(1 for s, _ in written[:i] if s == t)
            assert log.fetch("/wanted", t, ordinal).point.x == written[i][1]
        with pytest.raises(mcap_log.CorruptLogError, match="not found on re-read"):
            log.fetch("/wanted", written[0][0], 7)
        with pytest.raises(mcap_log.CorruptLogError, match="not found on re-read"):
            log.fetch("/wanted", NS + 1, 0)
    finally:
        log.close()


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_layouts_met_before_are_not_walked_again_and_batch_the_same(encoding: str,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A read flushes a topic hundreds of times: the layouts it met are looked up, not walked again, and
    every flush's batches (rows, layout, bytes) are those a fresh walk gives."""
    msgs = Msgs(ros1=encoding == "ros1")
    edge_sets = [[("odom", "base_link")], [("map", "odom"), ("odom", "base_link")], [],
                 [("a", "bc")], [("ab", "c")]]  # two of one length with different strings
    raws = [serialise(msgs, msgs.tf(i, edge_sets[i % len(edge_sets)]), TF, encoding) for i in range(60)]
    raws.insert(17, raws[3][:-5])  # a damaged one: no layout, left over every time
    walked: list[int] = []
    walk = fast_cdr.layout_of

    def counting(*args: Any, **kwargs: Any) -> Any:
        walked.append(1)
        return walk(*args, **kwargs)

    monkeypatch.setattr(fast_cdr, "layout_of", counting)
    known: fast_cdr.KnownLayouts = {}
    for k, flush in enumerate((raws[:20], raws[20:40], raws[40:])):
        before = len(walked)
        fresh, fresh_rest = decode_batches(msgs.ts, TF, flush, ros1=msgs.ros1)
        walks_fresh = len(walked) - before
        before = len(walked)
        cached, cached_rest = decode_batches(msgs.ts, TF, flush, ros1=msgs.ros1, known=known)
        walks_cached = len(walked) - before
        assert [_batch(b) for b in cached] == [_batch(b) for b in fresh]
        assert cached_rest.tolist() == fresh_rest.tolist()
        if k:  # every layout was met in the first flush (which also held the damaged message)
            assert walks_fresh > 0
            assert walks_cached == 0
    assert sum(len(v) for v in known.values()) == len(edge_sets)


def _batch(b: Any) -> tuple[Any, ...]:
    layout = b.layout
    return (b.rows.tolist(), layout.length, layout.leaves, layout.strings, layout.counts, layout.structure.tolist(),
            b.data.tobytes())
