"""Fuzz framechain with damaged copies of real logs: no traceback, no hang, no memory blow-up.

Every case takes one real log (``../shared/realdata``: MCAP files, ROS 1 bags, ROS 2 bag
directories), damages a copy (a cut at a record boundary or at a random offset, bit flips, a
zeroed block, a huge length field, a duplicated block; for ROS 2 bags also a missing or damaged
metadata.yaml) and runs one of ``info``, ``tf``, ``replay`` and ``attribute`` on it in a worker
process. A case fails on a traceback (an exception escaping the CLI), a hang (over ``--timeout``
seconds), memory beyond ``--max-rss-mb`` or an exit code other than 0 or 1.

Then the cut property: for every top-level record boundary and some random offsets of each MCAP
and ROS 1 log, the messages a salvage gives back never decrease as the cut moves later, each one
equals a message of the uncut log (read by the mcap library or rosbags), and every message whose
chunk is complete before the cut (or whose record ends before it in an uncompressed chunk) is
given back.

    python tools/fuzz.py --cases 10000 --seed 0          # what `make fuzz` runs
    python tools/fuzz.py --cases 40 --seed 1 --json      # the short fixed-seed run of the tests

Cases are numbered and reproducible: ``--only N`` reruns case N (its damaged file is kept with
``--keep DIR``).

``--config-cases N`` adds N cases of mutated configuration files (CHAIN.yaml, calibration files,
robot.yaml) through the commands that read them: ``tools/fuzz_config.py``, the same verdicts.
``--dataset-cases N`` adds N damaged LeRobot datasets (generated v3.0 and v2.1 ones with video, and
the real ones) through ``info``, ``info --episode``, ``tf`` and ``attribute``: ``tools/fuzz_datasets.py``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import random
import resource
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import traceback
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
REALDATA = ROOT.parent / "shared" / "realdata"
COMMANDS = ("info", "tf", "replay", "attribute")
MUTATIONS = ("cut_boundary", "cut_random", "bit_flips", "zeroed_block", "huge_length", "duplicated_block",
             "ros2_metadata")


class CaseTimeoutError(BaseException):
    """A case ran past its time (a BaseException, so no ``except Exception`` in the code swallows it)."""


# -- the logs and their record boundaries -----------------------------------------------------------
@dataclass(frozen=True)
class Source:
    path: Path  # a file, or a ROS 2 bag directory
    kind: str  # mcap, bag, ros2
    frames: tuple[str, str]  # a (target, source) pair for `framechain tf`


def find_logs(root: Path) -> list[Path]:
    logs = sorted(p for p in root.rglob("*") if p.is_file() and p.suffix in (".mcap", ".bag"))
    logs += sorted(p.parent for p in root.rglob("metadata.yaml") if "lerobot" not in p.parts)
    return logs


def kind_of(path: Path) -> str:
    return "ros2" if path.is_dir() else ("mcap" if path.suffix == ".mcap" else "bag")


def frame_pair(path: Path) -> tuple[str, str]:
    from framechain.adapters.api import TREE_KINDS, open_log

    try:
        transforms = open_log(path, kinds=TREE_KINDS).timeline.transforms
        if len(transforms.parent):
            return str(transforms.parent[0]), str(transforms.child[0])
    except Exception:
        pass
    return "map", "base_link"


def boundaries(data: bytes, kind: str) -> list[int]:
    """Byte offsets where a top-level record (MCAP, ROS 1) or an sqlite page (ROS 2) starts."""
    out: list[int] = []
    if kind == "mcap":
        pos = 8
        while pos + 9 <= len(data):
            out.append(pos)
            pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
    elif kind == "bag":
        pos = 13
        while pos + 4 <= len(data):
            out.append(pos)
            hlen = struct.unpack_from("<I", data, pos)[0]
            if pos + 8 + hlen > len(data):
                break
            pos += 8 + hlen + struct.unpack_from("<I", data, pos + 4 + hlen)[0]
    else:
        page = struct.unpack_from(">H", data, 16)[0] if len(data) > 18 else 4096
        page = 65536 if page == 1 else max(page, 512)
        out = list(range(page, len(data), page))
    return [b for b in out if 0 < b < len(data)]


def storage_file(src: Path) -> Path:
    if not src.is_dir():
        return src
    return sorted(src.glob("*.db3"))[0] if list(src.glob("*.db3")) else sorted(src.glob("*.mcap"))[0]


# -- mutations --------------------------------------------------------------------------------------
def mutate(data: bytes, kind: str, mutation: str, rng: random.Random) -> tuple[bytes, str]:
    """A damaged copy of ``data`` and a description of the damage."""
    n = len(data)
    cuts = boundaries(data, kind)
    if mutation == "cut_boundary" and cuts:
        at = rng.choice(cuts)
        return data[:at], f"cut at record boundary {at}"
    if mutation in ("cut_boundary", "cut_random"):
        at = rng.randrange(1, n)
        return data[:at], f"cut at byte {at}"
    out = bytearray(data)
    if mutation == "bit_flips":
        flips = [rng.randrange(8, n * 8) for _ in range(rng.choice((1, 1, 2, 8, 64)))]
        for bit in flips:
            out[bit // 8] ^= 1 << (bit % 8)
        return bytes(out), f"{len(flips)} bit flips from byte {min(flips) // 8}"
    if mutation == "zeroed_block":
        size = min(rng.choice((1, 8, 64, 512, 4096, 65536)), n - 16)
        at = rng.randrange(16, n - size) if n - size > 16 else 16
        out[at:at + size] = bytes(len(out[at:at + size]))
        return bytes(out), f"{size} bytes zeroed at {at}"
    if mutation == "huge_length":
        if cuts and kind != "ros2":
            at = rng.choice(cuts)
            field_at, width = (at + 1, 8) if kind == "mcap" else (at + rng.choice((0, 4)), 4)
        else:
            field_at, width = rng.randrange(16, n - 8), rng.choice((2, 4, 8))
        value = min(rng.choice((2 ** (8 * width) - 1, 2 ** (8 * width - 1), n * 2, n + 1)), 2 ** (8 * width) - 1)
        out[field_at:field_at + width] = value.to_bytes(width, "little" if kind != "ros2" else "big")
        return bytes(out), f"length field at {field_at} set to {value}"
    size = rng.choice((9, 64, 1024, 16384))
    at = rng.randrange(8, max(n - size, 9))
    block = data[at:at + size]
    to = rng.randrange(8, n)
    return data[:to] + block + data[to:], f"{len(block)} bytes from {at} duplicated at {to}"


def materialise(source: Source, index: int, seed: int, workdir: Path) -> tuple[Path, str, str]:
    """The damaged copy of case ``index`` (a file or a bag directory), its mutation and its description."""
    rng = random.Random(f"{seed}:{index}")
    mutations = MUTATIONS if source.kind == "ros2" else MUTATIONS[:-1]
    mutation = mutations[(index // 7) % len(mutations)] if rng.random() < 0.5 else rng.choice(mutations)
    storage = storage_file(source.path)
    kind = "mcap" if storage.suffix == ".mcap" else source.kind
    if source.kind != "ros2":
        target = workdir / f"case{index}{source.path.suffix}"
        damaged, what = mutate(storage.read_bytes(), kind, mutation, rng)
        target.write_bytes(damaged)
        return target, mutation, what
    target = workdir / f"case{index}"
    shutil.copytree(source.path, target)
    meta = target / "metadata.yaml"
    if mutation == "ros2_metadata":
        choice = rng.choice(("missing", "cut", "flips", "other storage"))
        if choice == "missing":
            meta.unlink()
        elif choice == "cut":
            text = meta.read_bytes()
            meta.write_bytes(text[:rng.randrange(0, len(text))])
        elif choice == "flips":
            damaged, _ = mutate(meta.read_bytes(), "ros2", "bit_flips", rng)
            meta.write_bytes(damaged)
        else:
            meta.write_text(meta.read_text().replace(storage.name, "missing.db3"))
        return target, mutation, f"metadata.yaml {choice}"
    stored = target / storage.name
    damaged, what = mutate(stored.read_bytes(), kind, mutation, rng)
    stored.write_bytes(damaged)
    return target, mutation, f"{storage.name}: {what}"


def argv_for(command: str, log: Path, source: Source, out: Path, variant: int) -> list[str]:
    if command == "info":
        return ["info", str(log), "--json"] if variant % 2 else ["info", str(log)]
    if command == "tf":
        target, child = source.frames
        extra = ["--series", "--json"] if variant % 2 else []
        return ["tf", str(log), target, child, *extra]
    if command == "replay":
        return ["replay", "-q", "--save", str(out / "replay.rrd"), "--max-images", "2", str(log),
                *(["--no-attribute"] if variant % 2 else [])]
    return ["attribute", "-q", "--out", str(out / "attr"), "--format", "json", "--bootstrap", "0", str(log)]


# -- the worker: cases in one process ---------------------------------------------------------------------
#: Cases one worker process runs before a fresh one takes over (see :func:`worker`).
CASES_PER_WORKER = 200


def _on_alarm(signum: int, frame: Any) -> None:
    raise CaseTimeoutError


def run_cases(sources: list[Source], seed: int, indices: list[int], timeout: float, max_rss_mb: int,
              keep: Path | None) -> Iterator[dict[str, Any]]:
    from framechain.cli.main import main

    signal.signal(signal.SIGALRM, _on_alarm)
    for index in indices:
        source = sources[index % len(sources)]
        command = COMMANDS[(index // len(sources)) % len(COMMANDS)]
        with tempfile.TemporaryDirectory(prefix="fuzz") as tmp:
            workdir = Path(tmp)
            log, mutation, what = materialise(source, index, seed, workdir)
            argv = argv_for(command, log, source, workdir, index // (len(sources) * len(COMMANDS)))
            result: dict[str, Any] = {"case": index, "log": source.path.name, "mutation": mutation,
                                      "what": what, "command": command}
            out, err = io.StringIO(), io.StringIO()
            start = time.perf_counter()
            signal.setitimer(signal.ITIMER_REAL, timeout)
            try:
                with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                    code = main(argv)
                result["status"] = "ok" if code in (0, 1) else "bad exit"
                result["exit"] = code
            except CaseTimeoutError:
                result["status"] = "hang"
            except MemoryError:
                result["status"] = "memory"
            except SystemExit as exc:
                result["status"] = "ok" if exc.code in (0, 1, None) else "bad exit"
                result["exit"] = exc.code
            except BaseException:
                result["status"] = "traceback"
                result["traceback"] = traceback.format_exc(limit=-8)
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            result["seconds"] = round(time.perf_counter() - start, 3)
            rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            result["max_rss_mb"] = round(rss_mb)
            if result["status"] == "ok" and rss_mb > max_rss_mb:
                result["status"] = "memory"
            if result["status"] != "ok":
                result["stderr"] = err.getvalue()[-2000:]
                if keep is not None:
                    keep.mkdir(parents=True, exist_ok=True)
                    dest = keep / f"case{index}{log.suffix}"
                    if log.is_dir():
                        shutil.copytree(log, dest, dirs_exist_ok=True)
                    else:
                        shutil.copyfile(log, dest)
        yield result
        if result["status"] == "memory":
            return  # the high-water mark stays: a fresh worker takes the next case


def worker(args: argparse.Namespace) -> int:
    sources = [Source(Path(p), k, (a, b)) for p, k, a, b in json.loads(args.sources)]
    limit = args.max_rss_mb * 4 * 1024 * 1024
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    vm_kb = next((int(line.split()[1]) for line in Path("/proc/self/status").read_text().splitlines()
                  if line.startswith("VmSize:")), 0)
    with contextlib.suppress(ValueError):
        resource.setrlimit(resource.RLIMIT_AS, (vm_kb * 1024 + limit, hard))
    del soft
    indices = [int(i) for i in args.indices.split(",")] if args.indices else []
    # A worker retires after CASES_PER_WORKER cases and the parent starts a fresh one on the rest:
    # Rerun 0.41 keeps two native threads per blueprint stream for the life of a process, and under
    # the address-space bound above a long-lived worker would run out of thread stacks.
    indices = indices[:CASES_PER_WORKER]
    keep = Path(args.keep) if args.keep else None
    for result in run_cases(sources, args.seed, indices, args.timeout, args.max_rss_mb, keep):
        print(json.dumps(result), flush=True)
    return 0


def run_workers(sources: list[Source], seed: int, indices: list[int], args: argparse.Namespace) -> list[dict[str, Any]]:
    """Run the cases in worker processes; a worker that dies or stalls costs its case, not the run."""
    spec = json.dumps([[str(s.path), s.kind, *s.frames] for s in sources])
    results: list[dict[str, Any]] = []
    pending = list(indices)
    jobs = max(1, args.jobs)
    shares = [pending[i::jobs] for i in range(jobs)]
    procs: list[tuple[subprocess.Popen[str], list[int]]] = []
    last_line: dict[int, float] = {}

    def start(share: list[int]) -> None:
        if not share:
            return
        cmd = [sys.executable, __file__, "--worker", "--seed", str(seed), "--sources", spec,
               "--indices", ",".join(map(str, share)), "--timeout", str(args.timeout),
               "--max-rss-mb", str(args.max_rss_mb), *(["--keep", args.keep] if args.keep else [])]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        procs.append((proc, list(share)))
        last_line[id(proc)] = time.monotonic()

    with contextlib.ExitStack() as stack:
        log_file = stack.enter_context(Path(args.results).open("a")) if args.results else None
        deadline = time.monotonic() + args.max_seconds if args.max_seconds else None
        for share in shares:
            start(share)
        while procs:
            if deadline is not None and time.monotonic() > deadline:
                for proc, _ in procs:
                    proc.kill()
                    proc.wait()
                break
            streams = {proc.stdout: (proc, share) for proc, share in procs if proc.stdout is not None}
            ready, _, _ = select.select(list(streams), [], [], 1.0)
            now = time.monotonic()
            for stream, (proc, share) in list(streams.items()):
                line = stream.readline() if stream in ready else ""
                if line:
                    result = json.loads(line)
                    results.append(result)
                    if log_file is not None:
                        log_file.write(line)
                        log_file.flush()
                    share.remove(result["case"])
                    last_line[id(proc)] = now
                    if args.progress and len(results) % 250 == 0:
                        bad = sum(r["status"] != "ok" for r in results)
                        print(f"  {len(results)} cases, {bad} failures", file=sys.stderr, flush=True)
                    continue
                stalled = now - last_line[id(proc)] > args.timeout * 2 + 60
                if stream not in ready and not stalled:
                    continue
                if proc.poll() is None:
                    proc.kill()
                proc.wait()
                procs.remove((proc, share))
                if share and (stalled or proc.returncode != 0):
                    dead = share.pop(0)  # the case the worker was on when it died or stalled
                    results.append({"case": dead, "status": "hang" if stalled else "crash",
                                    "what": f"worker {'stalled' if stalled else f'died (exit {proc.returncode})'}",
                                    "log": sources[dead % len(sources)].path.name})
                start(share)  # a worker that stopped itself after a memory failure goes on afresh
    return sorted(results, key=lambda r: int(r["case"]))


# -- the cut property -------------------------------------------------------------------------------
def original_messages(path: Path, kind: str) -> Counter[tuple[str, int, bytes]]:
    """Every message of the uncut log, read by the mcap library or rosbags (not the salvage code)."""
    out: Counter[tuple[str, int, bytes]] = Counter()
    if kind == "mcap":
        from mcap.reader import make_reader

        with path.open("rb") as f:
            for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
                out[(channel.topic, int(message.log_time), bytes(message.data))] += 1
    else:
        from rosbags.rosbag1 import Reader

        with Reader(path) as reader:
            for conn, t, raw in reader.messages():
                out[(conn.topic, int(t), bytes(raw))] += 1
    return out


def salvaged_messages(data: bytes, kind: str) -> list[tuple[str, int, bytes]]:
    from framechain.adapters.formats.mcap.salvage import ChannelRecord, McapScanner, MessageRecord
    from framechain.adapters.formats.rosbag.salvage_ros1 import Message, Rosbag1Scanner

    out: list[tuple[str, int, bytes]] = []
    if kind == "mcap":
        topics: dict[int, str] = {}
        scanner = McapScanner(data, topics.get)
        for rec in scanner.records():
            if isinstance(rec, ChannelRecord):
                topics.setdefault(rec.id, rec.topic)
            elif isinstance(rec, MessageRecord) and rec.channel_id in topics:
                out.append((topics[rec.channel_id], rec.log_time, rec.data))
        return out
    bag = Rosbag1Scanner(data, "cut")
    for item in bag.records():
        if isinstance(item, Message) and item.conn in bag.connections:
            out.append((bag.connections[item.conn].topic, item.time_ns, item.data))
    return out


def complete_before(data: bytes, kind: str, cut: int) -> int:
    """Messages of the uncut file a salvage of ``data[:cut]`` must give back: those of records (chunks)
    that end before the cut, and in the chunk the cut falls in, those whose record ends before it
    (uncompressed) or comes out whole from decompressing the chunk's bytes before it (zstd, lz4, bz2:
    each decompressor of the standard libraries, fed the cut stream)."""
    count = 0
    layout = _mcap_layout(data) if kind == "mcap" else _bag_layout(data)
    for rec_end, n_msgs, inner_ends, partial in layout:
        if rec_end <= cut:
            count += n_msgs
        elif inner_ends is not None:
            count += sum(1 for end in inner_ends if end <= cut)
        elif partial is not None:
            count += partial(cut)
    return count


Partial = Callable[[int], int] | None


def _streamed(compression: str, blob: bytes) -> bytes:
    """What a streaming decompressor gives for the first bytes of a compressed stream."""
    try:
        if compression == "zstd":
            import zstandard

            return bytes(zstandard.ZstdDecompressor().decompressobj().decompress(blob))
        if compression == "lz4":
            import lz4.frame

            return bytes(lz4.frame.LZ4FrameDecompressor().decompress(blob))
        if compression == "bz2":
            import bz2

            return bz2.BZ2Decompressor().decompress(blob)
    except Exception:
        return b""
    return blob


def _mcap_messages_in(raw: bytes) -> int:
    """Whole message records at the start of a chunk's uncompressed records."""
    n, inner = 0, 0
    while inner + 9 <= len(raw):
        iop, ilen = struct.unpack_from("<BQ", raw, inner)
        if inner + 9 + ilen > len(raw):
            break
        inner += 9 + ilen
        n += iop == 0x05
    return n


def _mcap_layout(data: bytes) -> Iterator[tuple[int, int, list[int] | None, Partial]]:
    """(record end, messages in it, end offsets of its messages when stored uncompressed, messages
    whole in its first bytes when compressed) per top-level record."""
    from mcap.data_stream import ReadDataStream
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk

    for pos in boundaries(data, "mcap"):
        op, length = struct.unpack_from("<BQ", data, pos)
        end = pos + 9 + length
        if op == 0x05:
            yield end, 1, None, None
        elif op == 0x06:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(data[pos + 9:end])))
            messages = [r for r in breakup_chunk(chunk) if isinstance(r, Message)]
            start = end - len(chunk.data)
            ends: list[int] | None = None
            partial: Partial = None
            if chunk.compression == "":
                ends, inner = [], 0
                while inner + 9 <= len(chunk.data):
                    iop, ilen = struct.unpack_from("<BQ", chunk.data, inner)
                    inner += 9 + ilen
                    if iop == 0x05:
                        ends.append(start + inner)
            else:
                def partial(cut: int, start: int = start, compression: str = chunk.compression) -> int:
                    return _mcap_messages_in(_streamed(compression, data[start:cut])) if cut > start else 0
            yield end, len(messages), ends, partial


def _bag_messages_in(raw: bytes) -> int:
    n, inner = 0, 0
    while inner + 8 <= len(raw):
        ih = struct.unpack_from("<I", raw, inner)[0]
        if inner + 8 + ih > len(raw):
            break
        idl = struct.unpack_from("<I", raw, inner + 4 + ih)[0]
        if inner + 8 + ih + idl > len(raw):
            break
        n += b"op=\x02" in raw[inner + 4:inner + 4 + ih]
        inner += 8 + ih + idl
    return n


def _bag_layout(data: bytes) -> Iterator[tuple[int, int, list[int] | None, Partial]]:
    import bz2

    for pos in boundaries(data, "bag"):
        hlen = struct.unpack_from("<I", data, pos)[0]
        header = data[pos + 4:pos + 4 + hlen]
        dlen = struct.unpack_from("<I", data, pos + 4 + hlen)[0]
        start, end = pos + 8 + hlen, pos + 8 + hlen + dlen
        if b"op=\x05" not in header:
            continue
        blob = data[start:end]
        raw = blob if b"compression=none" in header else (bz2.decompress(blob) if b"compression=bz2" in header
                                                          else _lz4(blob))
        ends: list[int] = []
        inner = 0
        while inner + 4 <= len(raw):
            ih = struct.unpack_from("<I", raw, inner)[0]
            idl = struct.unpack_from("<I", raw, inner + 4 + ih)[0]
            is_message = b"op=\x02" in raw[inner + 4:inner + 4 + ih]
            inner += 8 + ih + idl
            if is_message:
                ends.append(start + inner)
        if b"compression=none" in header:
            yield end, len(ends), ends, None
        else:
            compression = "bz2" if b"compression=bz2" in header else "lz4"

            def partial(cut: int, start: int = start, compression: str = compression) -> int:
                return _bag_messages_in(_streamed(compression, data[start:cut])) if cut > start else 0

            yield end, len(ends), None, partial


def _lz4(blob: bytes) -> bytes:
    import lz4.frame

    return bytes(lz4.frame.decompress(blob))


def check_cuts(path: Path, kind: str, rng: random.Random, random_cuts: int, max_boundaries: int = 0) -> dict[str, Any]:
    """The cut property over every record boundary and some random offsets of one log."""
    data = path.read_bytes()
    original = original_messages(path, kind)
    every = boundaries(data, kind)
    if max_boundaries and len(every) > max_boundaries:  # each cut rescans the file: keep the run bounded
        every = [every[round(i * (len(every) - 1) / (max_boundaries - 1))] for i in range(max_boundaries)]
    cuts = sorted(set(every) | {rng.randrange(1, len(data)) for _ in range(random_cuts)} | {len(data)})
    problems: list[str] = []
    previous = 0
    for cut in cuts:
        got = salvaged_messages(data[:cut], kind)
        if len(got) < previous:
            problems.append(f"cut at {cut}: {len(got)} messages, fewer than {previous} at an earlier cut")
        previous = len(got)
        extra = Counter(got) - original
        if extra:
            problems.append(f"cut at {cut}: {sum(extra.values())} messages differ from the uncut log")
        expected = complete_before(data, kind, cut)
        if len(got) < expected:
            problems.append(f"cut at {cut}: {len(got)} messages, {expected} complete before the cut")
    return {"log": str(path), "cuts": len(cuts), "messages": sum(original.values()), "problems": problems[:10],
            "problem_count": len(problems)}


# -- the command line ------------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--cases", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per case before it counts as a hang")
    parser.add_argument("--max-rss-mb", type=int, default=2048, help="memory bound of a worker")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--realdata", default=str(REALDATA))
    parser.add_argument("--logs", default="", help="comma-separated names: only these logs")
    parser.add_argument("--only", default="", help="comma-separated case numbers to rerun")
    parser.add_argument("--keep", default="", help="directory for the damaged files of failed cases")
    parser.add_argument("--random-cuts", type=int, default=30, help="random cut offsets per log (cut property)")
    parser.add_argument("--max-boundaries", type=int, default=40,
                        help="record boundaries cut per log, evenly spread (0: every one)")
    parser.add_argument("--no-property", action="store_true")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--results", default="", help="append every case's result to this JSON-lines file")
    parser.add_argument("--max-seconds", type=float, default=0.0,
                        help="stop starting cases after this long (0: run them all) and report the count")
    parser.add_argument("--progress", action="store_true")
    parser.add_argument("--config-cases", type=int, default=0,
                        help="cases of mutated configuration files (tools/fuzz_config.py) after the logs")
    parser.add_argument("--dataset-cases", type=int, default=0,
                        help="cases of damaged LeRobot datasets (tools/fuzz_datasets.py) after the logs")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--sources", default="", help=argparse.SUPPRESS)
    parser.add_argument("--indices", default="", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        return worker(args)
    root = Path(args.realdata)
    if not root.is_dir():
        print(f"fuzz: no real logs at {root}", file=sys.stderr)
        return 1
    logs = find_logs(root)
    if args.logs:
        names = set(args.logs.split(","))
        logs = [p for p in logs if p.name in names]
    sources = [Source(p, kind_of(p), frame_pair(p)) for p in logs]
    indices = [int(i) for i in args.only.split(",")] if args.only else list(range(args.cases))
    start = time.perf_counter()
    results = run_workers(sources, args.seed, indices, args)
    fuzz_seconds = time.perf_counter() - start
    failures = [r for r in results if r["status"] != "ok"]
    statuses = Counter(r["status"] for r in results)
    properties: list[dict[str, Any]] = []
    config: dict[str, Any] = {}
    if args.config_cases:
        import fuzz_config  # beside this file

        config_args = fuzz_config.parse_args(["--cases", str(args.config_cases), "--seed", str(args.seed),
                                              "--jobs", str(args.jobs), "--realdata", args.realdata,
                                              *(["--keep", args.keep] if args.keep else [])])
        start = time.perf_counter()
        config = fuzz_config.summarise(fuzz_config.run_workers(list(range(args.config_cases)), config_args),
                                       time.perf_counter() - start)
    datasets: dict[str, Any] = {}
    if args.dataset_cases:
        import fuzz_datasets  # beside this file

        dataset_args = fuzz_datasets.parse_args(["--cases", str(args.dataset_cases), "--seed", str(args.seed),
                                                 *(["--keep", args.keep] if args.keep else [])])
        datasets = fuzz_datasets.summary(dataset_args)
    if not args.no_property:
        rng = random.Random(args.seed)
        properties = [check_cuts(s.path, s.kind, rng, args.random_cuts, args.max_boundaries)
                      for s in sources if s.kind != "ros2"]
    summary = {
        "cases": len(results), "seconds": round(fuzz_seconds, 1), "statuses": dict(statuses),
        "exit_codes": dict(Counter(str(r.get("exit")) for r in results)),
        "mutations": dict(Counter(r.get("mutation", "?") for r in results)),
        "max_rss_mb": max((r.get("max_rss_mb", 0) for r in results), default=0),
        "slowest_s": max((r.get("seconds", 0.0) for r in results), default=0.0),
        "logs": [str(s.path.relative_to(root)) for s in sources],
        "failures": failures[:20], "failure_count": len(failures),
        "cut_property": properties,
        "cut_property_problems": sum(p["problem_count"] for p in properties),
        "config": config,
        "datasets": datasets,
    }
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(f"{len(results)} cases over {len(sources)} real logs in {fuzz_seconds:.0f} s: "
              f"{', '.join(f'{k} {v}' for k, v in sorted(statuses.items()))}; "
              f"max worker RSS {summary['max_rss_mb']} MB, slowest case {summary['slowest_s']} s")
        for r in failures[:20]:
            print(f"  case {r['case']} ({r.get('log')}, {r.get('command')}, {r.get('what')}): {r['status']}")
            if r.get("traceback"):
                print("    " + r["traceback"].strip().replace("\n", "\n    "))
        for p in properties:
            print(f"  cut property {Path(p['log']).name}: {p['cuts']} cuts, {p['problem_count']} problems")
            for text in p["problems"]:
                print(f"    {text}")
        if config:
            print(fuzz_config_line(config))
        if datasets:
            print(fuzz_config_line(datasets).replace("configuration cases", "dataset cases", 1))
    bad = config.get("failure_count") or datasets.get("failure_count")
    return 0 if not failures and not summary["cut_property_problems"] and not bad else 1


def fuzz_config_line(config: dict[str, Any]) -> str:
    """The configuration cases in one line, and their failures."""
    lines = [f"{config['cases']} configuration cases in {config['seconds']:.0f} s: "
             f"{', '.join(f'{k} {v}' for k, v in sorted(config['statuses'].items()))}"]
    lines += [f"  case {r['case']} ({r.get('target')}, {r.get('command')}: {r.get('what')}): {r['status']}"
              for r in config["failures"]]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
