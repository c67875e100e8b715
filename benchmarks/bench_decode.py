"""Decode rate of the same 100k tf2_msgs/TFMessage (2 transforms each) in every candidate decoder.

Candidates (ROS 2, CDR): rosbags' generated deserialiser; mcap_ros2's dynamic decoder; end to end
through ``open_log`` (the path framechain uses: mcap's chunk reader + rosbags + the collector) and
through rosbags' AnyReader; raw chunk reading with no decode as the floor. ROS 1: rosbags'
``deserialize_ros1`` against mcap_ros1's genpy decoder. Figures are messages per second.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

N_MESSAGES = 100_000


def _rate(fn: Callable[[], int]) -> float:
    t0 = time.perf_counter()
    n = fn()
    return n / (time.perf_counter() - t0)


def _write_fixture(path: Path, n: int) -> list[bytes]:
    """One MCAP (ROS 2, zstd chunks) of n TFMessage; returns the serialised payloads too."""
    from mcap.writer import Writer

    from framechain.adapters.formats.msgdefs import typestore

    ts = typestore(ros1=False)
    T = ts.types
    payloads: list[bytes] = []
    text = ts.generate_msgdef("tf2_msgs/msg/TFMessage", ros_version=2)[0]
    with path.open("wb") as f:
        w = Writer(f)
        w.start(profile="ros2")
        sid = w.register_schema("tf2_msgs/msg/TFMessage", "ros2msg", text.encode())
        cid = w.register_channel("/tf", "cdr", sid)
        for i in range(n):
            stamp = T["builtin_interfaces/msg/Time"](sec=1_700_000_000 + i // 100, nanosec=(i % 100) * 10_000_000)
            tfs = [
                T["geometry_msgs/msg/TransformStamped"](
                    header=T["std_msgs/msg/Header"](stamp=stamp, frame_id=parent), child_frame_id=child,
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=T["geometry_msgs/msg/Vector3"](x=0.1 * i, y=1.0, z=2.0),
                        rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                    ),
                )
                for parent, child in (("odom", "base_link"), ("map", "odom"))
            ]
            raw = bytes(ts.serialize_cdr(T["tf2_msgs/msg/TFMessage"](transforms=tfs), "tf2_msgs/msg/TFMessage"))
            payloads.append(raw)
            t = 1_700_000_000_000_000_000 + i * 10_000_000
            w.add_message(cid, log_time=t, publish_time=t, data=raw)
        w.finish()
    return payloads


def main() -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    from framechain.adapters import open_log
    from framechain.adapters.formats.msgdefs import typestore

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tf100k.mcap"
        payloads = _write_fixture(path, N_MESSAGES)
        ts = typestore(ros1=False)
        results: dict[str, float] = {}

        def rosbags_only() -> int:
            de = ts.deserialize_cdr
            for raw in payloads:
                de(raw, "tf2_msgs/msg/TFMessage")
            return len(payloads)

        def mcap_ros2_only() -> int:
            with path.open("rb") as f:
                reader = make_reader(f)
                summary = reader.get_summary()
                schema = next(iter(summary.schemas.values()))
            decode = DecoderFactory().decoder_for("cdr", schema)
            assert decode is not None
            for raw in payloads:
                decode(raw)
            return len(payloads)

        def raw_read() -> int:
            n = 0
            with path.open("rb") as f:
                for _ in make_reader(f).iter_messages():
                    n += 1
            return n

        def e2e_mcap_ros2() -> int:
            n = 0
            with path.open("rb") as f:
                for _ in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
                    n += 1
            return n

        def e2e_anyreader() -> int:
            n = 0
            with AnyReader([path]) as r:
                for c, _, raw in r.messages():
                    r.deserialize(raw, c.msgtype)
                    n += 1
            return n

        def e2e_open_log() -> int:
            loaded = open_log(path)
            assert len(loaded.timeline.transforms) == 2 * N_MESSAGES
            return N_MESSAGES

        for name, fn in (
            ("decode only: rosbags deserialize_cdr", rosbags_only),
            ("decode only: mcap_ros2 DecoderFactory", mcap_ros2_only),
            ("read only: mcap iter_messages, no decode", raw_read),
            ("e2e: mcap iter_decoded_messages (mcap_ros2)", e2e_mcap_ros2),
            ("e2e: rosbags AnyReader + deserialize", e2e_anyreader),
            ("e2e: framechain open_log (own chunk reader, layout decoding, tables)", e2e_open_log),
        ):
            results[name] = _rate(fn)
        results.update(_ros1_rates(ts, payloads[:20_000]))
    print(f"bench_decode: {N_MESSAGES} tf2_msgs/TFMessage (2 transforms each), messages per second")
    width = max(len(k) for k in results)
    for name, rate in results.items():
        print(f"  {name:<{width}}  {rate:>10,.0f}")


def _ros1_rates(ts2: Any, payloads: list[bytes]) -> dict[str, float]:
    """ROS 1 encoding: rosbags deserialize_ros1 against mcap_ros1's genpy classes (20k messages)."""
    from mcap_ros1._vendor.genpy.dynamic import generate_dynamic

    from framechain.adapters.formats.msgdefs import typestore

    ts1 = typestore(ros1=True)
    raws1 = []
    for raw in payloads:
        msg = ts2.deserialize_cdr(raw, "tf2_msgs/msg/TFMessage")
        for t in msg.transforms:
            t.header = ts1.types["std_msgs/msg/Header"](seq=0, stamp=t.header.stamp, frame_id=t.header.frame_id)
        raws1.append(bytes(ts1.serialize_ros1(msg, "tf2_msgs/msg/TFMessage")))
    text = ts1.generate_msgdef("tf2_msgs/msg/TFMessage", ros_version=1)[0]
    cls = generate_dynamic("tf2_msgs/TFMessage", text)["tf2_msgs/TFMessage"]

    def rosbags1() -> int:
        for raw in raws1:
            ts1.deserialize_ros1(raw, "tf2_msgs/msg/TFMessage")
        return len(raws1)

    def genpy1() -> int:
        for raw in raws1:
            cls().deserialize(raw)
        return len(raws1)

    return {"ROS 1 decode only: rosbags deserialize_ros1": _rate(rosbags1),
            "ROS 1 decode only: mcap_ros1 genpy": _rate(genpy1)}


if __name__ == "__main__":
    main()
