"""Attribute on long logs against the decode floor: is the cost linear in the log's length?

For each length (10 and 30 minutes by default) a generated log (framechain.sim: /tf at 100 Hz and
the map drift at 50 Hz, camera at 30 Hz with 640x480 16UC1 depth, camera info, detections and
logged hop points) is written once into the cache folder and reused. Each figure runs in a fresh
process so its peak resident memory is its own:

- floor: mcap's reader over the topics the chain needs, each message decoded by rosbags (the
  least any reader built on these libraries does);
- attribute: ``framechain.pipeline.attribute_log`` (read, replay with depth sampled from the
  images, fit, attribute with 30 bootstrap resamples), as ``framechain attribute`` runs it.

The ratio attribute / floor should stay flat from 10 to 30 minutes (linear cost).

    python benchmarks/run.py scale
    FRAMECHAIN_BENCH_SCALE_MINUTES=10 python benchmarks/run.py scale     # lengths, comma-separated
    FRAMECHAIN_BENCH_SCALE_CACHE=/tmp/framechain-bench-scale              # where the logs are kept

The logs are written by a streaming writer here (not ``write_scene``, which holds every depth
image in memory): the scene comes from ``generate`` without depth images, its detections lose
their depth, and a depth image per camera frame (a floor seen from the tilted camera, with the
object's disc at the detection's pixel carrying the object's measured depth) is merged in by log
time. The replay then samples every detection's depth from an image, as on a real robot.
"""

from __future__ import annotations

import dataclasses
import heapq
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

CACHE = Path(os.environ.get("FRAMECHAIN_BENCH_SCALE_CACHE", "/tmp/framechain-bench-scale"))
MINUTES = tuple(int(m) for m in os.environ.get("FRAMECHAIN_BENCH_SCALE_MINUTES", "10,30").split(","))
DEPTH_TOPIC = "/camera/depth/image_raw"
#: Bumped when the generated log changes, so cached logs are rewritten.
LOG_VERSION = 1


def log_paths(minutes: int) -> tuple[Path, Path]:
    stem = CACHE / f"scale_{minutes}min_v{LOG_VERSION}"
    return stem.with_suffix(".mcap"), stem.with_suffix(".chain.yaml")


def write_long_log(minutes: int) -> tuple[Path, Path]:
    """The cached log of ``minutes`` and its chain file (written on first use)."""
    path, chain_path = log_paths(minutes)
    if path.is_file() and chain_path.is_file():
        return path, chain_path
    from framechain.adapters import write_log
    from framechain.sim import SceneSpec, generate

    CACHE.mkdir(parents=True, exist_ok=True)
    scene = generate(SceneSpec(seed=7, duration_s=60.0 * minutes, depth_images=False))
    obs = scene.timeline.observations
    depth_m = np.asarray(obs.depth_m, dtype=np.float64)
    timeline = scene.timeline.replace(observations=dataclasses.replace(obs, depth_m=np.full(len(obs), np.nan)))
    chain = dataclasses.replace(scene.chain, topics=dataclasses.replace(scene.chain.topics, depth=DEPTH_TOPIC))
    with tempfile.TemporaryDirectory(dir=CACHE) as tmp:
        rest = Path(tmp) / "rest.mcap"
        write_log(timeline, rest, container="mcap-ros2", chain=chain)
        partial = path.with_suffix(".partial")
        _merge_depth(rest, partial, obs, depth_m, scene.spec)
        partial.rename(path)
    chain_path.write_text(chain.to_yaml())
    return path, chain_path


def _depth_messages(obs: Any, depth_m: Any, spec: Any) -> Iterator[tuple[int, bytes]]:
    """(log time, CDR bytes) of one 16UC1 depth image per camera frame, in log-time order."""
    from framechain.adapters.formats.msgdefs import typestore

    ts = typestore(ros1=False)
    T = ts.types
    h, w, f = spec.height, spec.width, spec.focal_px
    rows, cols = np.mgrid[0:h, 0:w]
    pitch = np.deg2rad(spec.mount_pitch_deg)
    order = np.argsort(np.asarray(obs.log_time_ns), kind="stable")
    for k, i in enumerate(order.tolist()):
        tilt = pitch + 0.02 * np.sin(k * 0.01)  # the floor moves a little from frame to frame
        down = (rows - h / 2) / f * np.cos(tilt) + np.sin(tilt)
        with np.errstate(divide="ignore"):
            floor = np.where(down > 1e-3, spec.mount_xyz[2] / down, 0.0)
        floor[(cols - obs.u[i]) ** 2 + (rows - obs.v[i]) ** 2 <= 64.0] = depth_m[i]
        mm = np.clip(np.rint(np.where(floor < 20.0, floor, 0.0) * 1000.0), 0, 65535).astype("<u2")
        sec, nsec = divmod(int(obs.stamp_ns[i]), 1_000_000_000)
        msg = T["sensor_msgs/msg/Image"](
            header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                            frame_id=str(obs.camera_frame[i])),
            height=h, width=w, encoding="16UC1", is_bigendian=0, step=2 * w,
            data=np.frombuffer(mm.tobytes(), dtype=np.uint8),
        )
        yield int(obs.log_time_ns[i]), bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/Image"))


def _merge_depth(rest: Path, out: Path, obs: Any, depth_m: Any, spec: Any) -> None:
    """``rest``'s messages and the depth images, merged by log time into one zstd-chunked MCAP."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    from framechain.adapters.formats.msgdefs import typestore

    text = typestore(ros1=False).generate_msgdef("sensor_msgs/msg/Image", ros_version=2)[0]
    with rest.open("rb") as fin, out.open("wb") as fout:
        reader = make_reader(fin)
        summary = reader.get_summary()
        assert summary is not None
        writer = Writer(fout)
        writer.start(profile="ros2")
        schema_ids = {sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channel_ids = {cid: writer.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id])
                       for cid, c in summary.channels.items()}
        depth_channel = writer.register_channel(
            DEPTH_TOPIC, "cdr", writer.register_schema("sensor_msgs/msg/Image", "ros2msg", text.encode()))
        logged = ((m.log_time, 0, channel_ids[m.channel_id], m.data) for _, _, m in reader.iter_messages())
        depth = ((t, 1, depth_channel, data) for t, data in _depth_messages(obs, depth_m, spec))
        for log_time, _, cid, data in heapq.merge(logged, depth):
            writer.add_message(cid, log_time=log_time, publish_time=log_time, data=data)
        writer.finish()


def _floor(path: str, chain_path: str) -> dict[str, Any]:
    """mcap + rosbags over the topics the chain needs: read and decode, nothing else."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from framechain.adapters import scan_log
    from framechain.adapters.messages.kinds import normalize_msgtype, select_topics
    from framechain.config.chain import ChainConfig

    chain = ChainConfig.from_yaml(chain_path)
    info = scan_log(path)
    topics = set(select_topics({t.name: normalize_msgtype(t.msgtype) for t in info.topics}, chain))
    start, cpu = time.perf_counter(), time.process_time()
    n = 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        stores: dict[int, tuple[Any, str]] = {}
        for schema, _, message in reader.iter_messages(topics=sorted(topics)):
            if schema is None:
                continue
            if schema.id not in stores:
                store = get_typestore(Stores.EMPTY)
                typename = schema.name if "/msg/" in schema.name else schema.name.replace("/", "/msg/")
                store.register(get_types_from_msg(schema.data.decode(), typename))
                stores[schema.id] = (store, typename)
            store, typename = stores[schema.id]
            store.deserialize_cdr(message.data, typename)
            n += 1
    return {"seconds": time.perf_counter() - start, "cpu_s": time.process_time() - cpu, "messages": n,
            "topics": len(topics)}


def _attribute(path: str, chain_path: str) -> dict[str, Any]:
    import framechain.adapters
    import framechain.analysis  # imported before the clock starts, as the floor's libraries are
    from framechain.pipeline import attribute_log

    assert framechain.adapters.open_log is not None
    assert framechain.analysis is not None
    start, cpu = time.perf_counter(), time.process_time()
    run, result = attribute_log(path, chain_path)
    seconds = time.perf_counter() - start
    return {"seconds": seconds, "cpu_s": time.process_time() - cpu, "observations": len(run.timeline.observations),
            "findings": [str(getattr(f, "fault", f)) for f in result.findings], "counts": result.counts()}


def child(argv: list[str]) -> None:
    """In a fresh process: run one figure, print it as JSON with the peak resident memory."""
    import resource

    what, path, chain_path = argv
    figure = _floor(path, chain_path) if what == "floor" else _attribute(path, chain_path)
    figure["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(json.dumps(figure, default=str))


def measure(what: str, path: Path, chain_path: Path) -> dict[str, Any]:
    out = subprocess.run([sys.executable, __file__, what, str(path), str(chain_path)], check=False,
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"bench_scale {what} on {path.name} failed: {out.stderr.strip().splitlines()[-1:]}")
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    rows = []
    for minutes in MINUTES:
        start = time.perf_counter()
        path, chain_path = write_long_log(minutes)
        made = time.perf_counter() - start
        floor = measure("floor", path, chain_path)
        attribute = measure("attribute", path, chain_path)
        rows.append((minutes, path, floor, attribute))
        print(f"   {minutes} min log: {path.stat().st_size / 1e6:.0f} MB ({made:.0f} s to make or find), "
              f"{floor['messages']} messages on {floor['topics']} topics, "
              f"{attribute['observations']} observations", flush=True)
    print("   wall seconds and CPU seconds of the process (CPU is steadier on a shared machine); peak RSS in MB")
    print(f"   {'log':>7}  {'floor s':>8}  {'attribute s':>11}  {'ratio':>6}  {'floor cpu':>9}  {'attr cpu':>8}  "
          f"{'ratio':>6}  {'floor MB':>8}  {'attribute MB':>12}")
    for minutes, _, floor, attribute in rows:
        print(f"   {minutes:>4} min  {floor['seconds']:>8.2f}  {attribute['seconds']:>11.2f}  "
              f"{attribute['seconds'] / floor['seconds']:>6.2f}  {floor['cpu_s']:>9.2f}  {attribute['cpu_s']:>8.2f}  "
              f"{attribute['cpu_s'] / floor['cpu_s']:>6.2f}  {floor['peak_rss_mb']:>8.0f}  "
              f"{attribute['peak_rss_mb']:>12.0f}")


if __name__ == "__main__":
    if len(sys.argv) == 4:
        child(sys.argv[1:])
    else:
        main()
