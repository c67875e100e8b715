"""Attribute on long logs against the decode floor, in process and as a user runs the command.

For each length (10 and 30 minutes by default) a generated log is written once into the cache
folder and reused: what a mobile robot records over that time (framechain.sim: /tf at 100 Hz with
the map drift at 50 Hz, and at the camera's 30 Hz the camera info, 640x480 16UC1 depth, JPEG colour
images, detections and the robot's logged hop points), with a 30 ms latency in the robot's chain
so that the report has a finding, its sensitivity and the camera crops to show. Each figure runs in
a fresh process so that its peak resident memory is its own:

- floor: mcap's reader over the topics the chain needs, each message decoded by rosbags (the
  least any reader built on these libraries does); its clock starts after its imports, and the
  process is also timed from start to exit;
- in-process: ``framechain.pipeline.attribute_log`` (read, replay with depth sampled from the
  images, fit, attribute with 30 bootstrap resamples) after its imports, no reports written;
- end to end: ``framechain attribute LOG --chain C --out D`` from process start to exit, reports
  (json, md, html) written, against the floor's process from start to exit (both pay the
  interpreter's start and their imports).

The ratios should stay flat from 10 to 30 minutes (linear cost). Wall seconds are what a user
waits; CPU seconds are steadier on a shared machine. The three figures run in turn for a few
rounds and each figure's least is kept: another process's load only ever adds time. Children run
with one BLAS thread, as the command sets for itself.

    python benchmarks/run.py scale
    FRAMECHAIN_BENCH_SCALE_MINUTES=10 python benchmarks/run.py scale     # lengths, comma-separated
    FRAMECHAIN_BENCH_SCALE_ROUNDS=1 python benchmarks/run.py scale       # rounds (default 5), least kept
    FRAMECHAIN_BENCH_SCALE_CACHE=/tmp/framechain-bench-scale              # where the logs are kept

The logs are written by a streaming writer here (not ``write_scene``, which holds every image in
memory): the scene comes from ``generate`` without images, its detections lose their depth, and
per camera frame a depth image (a floor seen from the tilted camera, with the object's disc at the
detection's pixel carrying the object's measured depth) and a JPEG of the same view (floor tiles,
the object's red disc) are merged in by log time. The replay then samples every detection's depth
from an image, as on a real robot, and the report crops the colour images.
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
#: Rounds of the three figures, taken in turn; each figure's least is reported (a shared machine's load
#: only adds, and on a 2-core VM the same process varies by a third from run to run: five rounds, not
#: three, so that the least of each is as near its own floor as the other's).
ROUNDS = max(1, int(os.environ.get("FRAMECHAIN_BENCH_SCALE_ROUNDS", "5")))
DEPTH_TOPIC = "/camera/depth/image_raw"
COLOR_TOPIC = "/camera/color/image_raw/compressed"
#: Bumped when the generated log changes, so cached logs are rewritten.
LOG_VERSION = 2


def log_paths(minutes: int) -> tuple[Path, Path]:
    stem = CACHE / f"scale_{minutes}min_v{LOG_VERSION}"
    return stem.with_suffix(".mcap"), stem.with_suffix(".chain.yaml")


def write_long_log(minutes: int) -> tuple[Path, Path]:
    """The cached log of ``minutes`` and its chain file (written on first use)."""
    path, chain_path = log_paths(minutes)
    if path.is_file() and chain_path.is_file():
        return path, chain_path
    from framechain.adapters import write_log
    from framechain.catalogue import Fault
    from framechain.sim import InjectedFault, SceneSpec, generate

    CACHE.mkdir(parents=True, exist_ok=True)
    # A log worth debugging: the robot used a pose 30 ms late, so the report has a finding to show.
    fault = InjectedFault(Fault.LATENCY, "robot", {"offset_s": 0.03})
    scene = generate(SceneSpec(seed=7, duration_s=60.0 * minutes, depth_images=False, faults=(fault,)))
    obs = scene.timeline.observations
    depth_m = np.asarray(obs.depth_m, dtype=np.float64)
    timeline = scene.timeline.replace(observations=dataclasses.replace(obs, depth_m=np.full(len(obs), np.nan)))
    chain = dataclasses.replace(scene.chain, topics=dataclasses.replace(scene.chain.topics, depth=DEPTH_TOPIC,
                                                                          image=COLOR_TOPIC))
    with tempfile.TemporaryDirectory(dir=CACHE) as tmp:
        rest = Path(tmp) / "rest.mcap"
        write_log(timeline, rest, container="mcap-ros2", chain=chain)
        partial = path.with_suffix(".partial")
        _merge_camera(rest, partial, obs, depth_m, scene.spec)
        partial.rename(path)
    chain_path.write_text(chain.to_yaml())
    return path, chain_path


def _camera_messages(obs: Any, depth_m: Any, spec: Any) -> Iterator[tuple[int, int, bytes]]:
    """(log time, stream, CDR bytes) per camera frame, in log-time order: the 16UC1 depth image
    (stream 0) and the JPEG colour image the detection came from (stream 1), both stamped as it."""
    import io

    from PIL import Image

    from framechain.adapters.formats.msgdefs import typestore

    ts = typestore(ros1=False)
    T = ts.types
    h, w, f = spec.height, spec.width, spec.focal_px
    rows, cols = np.arange(h, dtype=float)[:, None], np.arange(w, dtype=float)[None, :]
    across = ((cols - w / 2) / f).astype(np.float32)
    pitch = np.deg2rad(spec.mount_pitch_deg)
    # light tile, dark tile, sky (as framechain.sim's colour images), the object
    palette = [150, 150, 140, 95, 100, 95, 190, 210, 235, 220, 40, 40]
    order = np.argsort(np.asarray(obs.log_time_ns), kind="stable")
    for k, i in enumerate(order.tolist()):
        tilt = pitch + 0.02 * np.sin(k * 0.01)  # the floor moves a little from frame to frame
        down = (rows - h / 2) / f * np.cos(tilt) + np.sin(tilt)  # (h, 1): a floor's depth depends on the row
        with np.errstate(divide="ignore"):
            floor_row = np.where(down > 1e-3, spec.mount_xyz[2] / down, 0.0)
        seen_row = (floor_row > 0.0) & (floor_row < 20.0)
        mm_row = np.clip(np.rint(np.where(seen_row, floor_row, 0.0) * 1000.0), 0, 65535)
        mm = np.repeat(mm_row.astype("<u2"), w, axis=1)
        # the object's disc (radius 8 px) at the detection, in a window around it
        u, v = (float(obs.u[i]), float(obs.v[i])) if np.isfinite([obs.u[i], obs.v[i]]).all() else (-99.0, -99.0)
        r0, r1 = max(0, int(v) - 9), max(0, min(h, int(v) + 10))
        c0, c1 = max(0, int(u) - 9), max(0, min(w, int(u) + 10))
        disc = (cols[:, c0:c1] - u) ** 2 + (rows[r0:r1] - v) ** 2 <= 64.0
        mm[r0:r1, c0:c1][disc] = np.clip(np.rint(depth_m[i] * 1000.0), 0, 65535) if depth_m[i] < 20.0 else 0
        sec, nsec = divmod(int(obs.stamp_ns[i]), 1_000_000_000)
        header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                          frame_id=str(obs.camera_frame[i]))
        depth = T["sensor_msgs/msg/Image"](
            header=header, height=h, width=w, encoding="16UC1", is_bigendian=0, step=2 * w,
            data=np.frombuffer(mm.tobytes(), dtype=np.uint8),
        )
        yield int(obs.log_time_ns[i]), 0, bytes(ts.serialize_cdr(depth, "sensor_msgs/msg/Image"))
        # 0.5 m floor tiles sliding under the moving robot, sky beyond 20 m, the object as a red disc
        ahead = np.floor((floor_row + 0.013 * k) * 2.0).astype(np.int32)
        side = np.floor(across * (floor_row * 2.0).astype(np.float32)).astype(np.int32)
        tile = np.where(seen_row, (ahead + side) & 1, 2).astype(np.uint8)
        tile[r0:r1, c0:c1][disc] = 3
        picture = Image.fromarray(tile, "P")
        picture.putpalette(palette)
        jpeg = io.BytesIO()
        picture.convert("RGB").save(jpeg, format="JPEG", quality=85)
        color = T["sensor_msgs/msg/CompressedImage"](
            header=header, format="rgb8; jpeg compressed bgr8", data=np.frombuffer(jpeg.getvalue(), dtype=np.uint8))
        yield int(obs.log_time_ns[i]), 1, bytes(ts.serialize_cdr(color, "sensor_msgs/msg/CompressedImage"))


def _merge_camera(rest: Path, out: Path, obs: Any, depth_m: Any, spec: Any) -> None:
    """``rest``'s messages, the depth and the colour images, merged by log time into one zstd-chunked MCAP."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    from framechain.adapters.formats.msgdefs import typestore

    store = typestore(ros1=False)
    with rest.open("rb") as fin, out.open("wb") as fout:
        reader = make_reader(fin)
        summary = reader.get_summary()
        assert summary is not None
        writer = Writer(fout)
        writer.start(profile="ros2")
        schema_ids = {sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channel_ids = {cid: writer.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id])
                       for cid, c in summary.channels.items()}
        camera_channels = [
            writer.register_channel(topic, "cdr", writer.register_schema(
                msgtype, "ros2msg", store.generate_msgdef(msgtype, ros_version=2)[0].encode()))
            for topic, msgtype in ((DEPTH_TOPIC, "sensor_msgs/msg/Image"),
                                   (COLOR_TOPIC, "sensor_msgs/msg/CompressedImage"))
        ]
        logged = ((m.log_time, 0, channel_ids[m.channel_id], m.data) for _, _, m in reader.iter_messages())
        camera = ((t, 1 + stream, camera_channels[stream], data)
                  for t, stream, data in _camera_messages(obs, depth_m, spec))
        for log_time, _, cid, data in heapq.merge(logged, camera):
            writer.add_message(cid, log_time=log_time, publish_time=log_time, data=data)
        writer.finish()


def chain_topics(path: Path, chain_path: Path) -> list[str]:
    """The topics the chain needs (what ``framechain attribute`` decodes), as the floor reads them."""
    from framechain.adapters import scan_log
    from framechain.adapters.messages.kinds import normalize_msgtype, select_topics
    from framechain.config.chain import ChainConfig

    chain = ChainConfig.from_yaml(chain_path)
    info = scan_log(path)
    return sorted(select_topics({t.name: normalize_msgtype(t.msgtype) for t in info.topics}, chain))


def _floor(path: str, topics: list[str]) -> dict[str, Any]:
    """mcap + rosbags over ``topics``: read and decode, nothing else (and no framechain import, so
    that the process's own time is the floor a user's script would pay)."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    start, cpu = time.perf_counter(), time.process_time()
    n = 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        stores: dict[int, tuple[Any, str]] = {}
        for schema, _, message in reader.iter_messages(topics=topics):
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
    """In a fresh process: run one in-process figure and print it as JSON."""
    what, path, arg = argv
    figure = _floor(path, arg.split(",")) if what == "floor" else _attribute(path, arg)
    print(json.dumps(figure, default=str))


@dataclasses.dataclass(frozen=True)
class Process:
    """One process from start to exit: wall and CPU seconds, peak resident memory, what it printed."""

    wall_s: float
    cpu_s: float
    peak_rss_mb: float
    stdout: str

    def figure(self) -> dict[str, Any]:
        """The JSON an in-process child printed last."""
        out: dict[str, Any] = json.loads(self.stdout.strip().splitlines()[-1])
        return out


def run_process(argv: list[str], what: str) -> Process:
    """Run ``argv`` to its exit; its own rusage (os.wait4), so that each figure's memory is its own."""
    env = dict(os.environ)
    for variable in _blas_thread_variables():  # as the command sets them for itself
        env.setdefault(variable, "1")
    # An installed package has its bytecode cached; a shell that forbids writing it (some sandboxes and
    # CI images set this) would have the command compile its 150 modules on every run, the floor none.
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        start = time.perf_counter()
        proc = subprocess.Popen(argv, stdout=out, stderr=err, env=env, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        if proc.returncode != 0:
            raise RuntimeError(f"bench_scale {what} failed ({proc.returncode}): {err.read().strip().splitlines()[-3:]}")
        return Process(wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0, out.read())


def _blas_thread_variables() -> tuple[str, ...]:
    import framechain.cli.main

    return tuple(getattr(framechain.cli.main, "BLAS_THREAD_VARIABLES", ()))


def _command() -> list[str]:
    """``framechain`` as a user runs it: the console script beside this interpreter."""
    script = Path(sys.executable).with_name("framechain")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "framechain.cli.main"]


def measure(path: Path, chain_path: Path) -> dict[str, list[Process]]:
    """The floor, attribute in-process and the command end to end, one fresh process each, side by side;
    :data:`ROUNDS` rounds, the three in turn in each (so that the machine's load falls on all alike)."""
    topics = chain_topics(path, chain_path)
    out: dict[str, list[Process]] = {"floor": [], "attribute": [], "command": []}
    # As pip does on install: framechain's bytecode cached before the first timed run (the libraries'
    # already is), so that no round pays for compiling.
    import framechain

    run_process([sys.executable, "-m", "compileall", "-q", str(Path(framechain.__file__).parent)], "compileall")
    for _ in range(ROUNDS):
        out["floor"].append(run_process([sys.executable, __file__, "floor", str(path), ",".join(topics)],
                                        f"floor on {path.name}"))
        out["attribute"].append(run_process([sys.executable, __file__, "attribute", str(path), str(chain_path)],
                                            f"attribute on {path.name}"))
        with tempfile.TemporaryDirectory(dir=CACHE) as tmp:
            report = Path(tmp) / "out"
            out["command"].append(run_process([*_command(), "attribute", str(path), "--chain", str(chain_path),
                                               "--out", str(report), "-q"], f"framechain attribute on {path.name}"))
            missing = [n for n in ("attribution.json", "report.md", "report.html") if not (report / n).is_file()]
            if missing:
                raise RuntimeError(f"framechain attribute on {path.name} wrote no {', '.join(missing)}")
    return out


def main() -> None:
    rows = []
    for minutes in MINUTES:
        start = time.perf_counter()
        path, chain_path = write_long_log(minutes)
        made = time.perf_counter() - start
        runs = measure(path, chain_path)
        floor = [p.figure() for p in runs["floor"]]
        attribute = [p.figure() for p in runs["attribute"]]
        rows.append((minutes, runs, floor, attribute))
        print(f"   {minutes} min log: {path.stat().st_size / 1e6:.0f} MB ({made:.0f} s to make or find), "
              f"{floor[0]['messages']} messages on {floor[0]['topics']} topics, "
              f"{attribute[0]['observations']} observations, findings {attribute[0]['findings']}", flush=True)
    print("   floor: mcap + rosbags over the chain's topics; in-process: attribute_log after imports, no reports;\n"
          "   end to end: `framechain attribute LOG --chain C --out D` from process start to exit (reports written)\n"
          "   against the floor's process from start to exit (interpreter and imports included in both);\n"
          f"   each figure the least of {ROUNDS} rounds (CPU s: the process tree's user + system time, steadier\n"
          "   than wall s on a shared machine); peak RSS the most of the rounds")
    for unit, key, process_key in (("wall s", "seconds", "wall_s"), ("CPU s", "cpu_s", "cpu_s")):
        print(f"   {unit:<6} {'floor':>7} {'in-process':>10} {'ratio':>6}   {'floor':>7} {'end to end':>10} "
              f"{'ratio':>6}   peak RSS MB (floor / in-process / end to end)")
        for minutes, runs, floor, attribute in rows:
            floor_in, attribute_in = min(f[key] for f in floor), min(a[key] for a in attribute)
            floor_p, command = (min(getattr(p, process_key) for p in runs[k]) for k in ("floor", "command"))
            peak = " / ".join(f"{max(p.peak_rss_mb for p in runs[k]):.0f}" for k in ("floor", "attribute", "command"))
            print(f"   {minutes:>2} min {floor_in:>7.2f} {attribute_in:>10.2f} {attribute_in / floor_in:>6.2f}"
                  f"   {floor_p:>7.2f} {command:>10.2f} {command / floor_p:>6.2f}   {peak}")


if __name__ == "__main__":
    if len(sys.argv) == 4:
        child(sys.argv[1:])
    else:
        main()
