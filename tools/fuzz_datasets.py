"""Fuzz LeRobot datasets: damaged copies through ``info``, ``info --episode``, ``tf`` and ``attribute``.

Sources: two generated SO-101 datasets with wrist video (``framechain.sim.lerobot_video``: v3.0 with
two episodes sharing files, v2.1 with one file per episode, each with its robot.yaml), and the real
v2.0 and v2.1 datasets under ``../shared/realdata/lerobot`` (``info`` only: they have no robot.yaml).
A case copies one dataset and damages it the way disks and recorders do: a file under ``meta/``,
``data/`` or ``videos/`` cut, bit-flipped, zeroed, emptied or removed, or an ``info.json`` or
episodes index that disagrees with the files (totals, fps, features, path templates, lengths,
indices). A case fails on a traceback, a hang, an exit code other than 0 or 1, or an exit 1 whose
stderr is not exactly one line (the verdicts of ``tools/fuzz_config.py``).

    python tools/fuzz_datasets.py --cases 300 --seed 0      # what `make fuzz` runs (through tools/fuzz.py)
    python tools/fuzz_datasets.py --cases 24 --seed 1 --json   # the tests' run

``--only N`` reruns case N; ``--keep DIR`` keeps the damaged datasets of failures.
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
REALDATA = ROOT.parent / "shared" / "realdata"
sys.path.insert(0, str(Path(__file__).resolve().parent))

import fuzz_config  # noqa: E402  (beside this file: the per-case verdicts)

COMMANDS = ("info", "info_episode", "tf", "attribute")
FILE_DAMAGE = ("cut", "bit_flips", "zeroed_block", "empty", "removed")
INFO_EDITS = ("total_episodes", "total_frames", "fps", "chunks_size", "data_path", "video_path", "features",
              "codebase_version", "shape", "names")
INDEX_EDITS = ("length", "duplicate_episode", "missing_file", "from_index")


def generate_sources(folder: Path) -> list[tuple[Path, Path | None]]:
    """The generated datasets (with their robot.yaml) and the real ones (without)."""
    from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset, write_robot_yaml

    urdf = REALDATA / "urdf" / "so101" / "so101_new_calib.urdf"
    out: list[tuple[Path, Path | None]] = []
    for version, episodes in (("v3.0", 2), ("v2.1", 2)):
        truth = generate_video_dataset(folder / f"gen_{version}" / "dataset", VideoDatasetSpec(
            urdf, seed=7, duration_s=1.0, episodes=episodes, version=version, video_delay_s=0.04))
        out.append((truth.root, write_robot_yaml(truth, folder / f"gen_{version}" / "robot.yaml")))
    out += [(p, None) for p in sorted((REALDATA / "lerobot").glob("*")) if (p / "meta" / "info.json").is_file()]
    return out


def _files(root: Path) -> dict[str, list[Path]]:
    groups: dict[str, list[Path]] = {"meta_parquet": [], "data": [], "info": [], "jsonl": [], "video": []}
    for path in sorted(root.rglob("*")):
        if not path.is_file():
            continue
        rel = path.relative_to(root).parts
        if path.name == "info.json":
            groups["info"].append(path)
        elif rel[0] == "meta" and path.suffix == ".parquet":
            groups["meta_parquet"].append(path)
        elif rel[0] == "meta" and path.suffix in (".jsonl", ".json"):
            groups["jsonl"].append(path)
        elif rel[0] == "data":
            groups["data"].append(path)
        elif rel[0] == "videos":
            groups["video"].append(path)
    return {k: v for k, v in groups.items() if v}


def damage_file(path: Path, how: str, rng: random.Random) -> str:
    data = path.read_bytes()
    n = len(data)
    if how == "removed":
        path.unlink()
        return "removed"
    if how == "empty" or n < 32:
        path.write_bytes(b"")
        return "emptied"
    if how == "cut":
        at = rng.choice((rng.randrange(1, n), n - rng.randrange(1, min(n, 64)), rng.randrange(1, min(n, 256))))
        path.write_bytes(data[:at])
        return f"cut at byte {at} of {n}"
    out = bytearray(data)
    if how == "bit_flips":
        flips = [rng.randrange(0, n * 8) for _ in range(rng.choice((1, 4, 32)))]
        for bit in flips:
            out[bit // 8] ^= 1 << (bit % 8)
        path.write_bytes(bytes(out))
        return f"{len(flips)} bit flips"
    size = min(rng.choice((8, 64, 512, 4096)), n)
    at = rng.randrange(0, n - size + 1)
    out[at:at + size] = bytes(size)
    path.write_bytes(bytes(out))
    return f"{size} bytes zeroed at {at}"


def edit_info(root: Path, how: str, rng: random.Random) -> str:
    path = root / "meta" / "info.json"
    info = json.loads(path.read_text())
    odd = rng.choice((0, -1, 1e12, "30", None, [1], float("nan")))
    if how in ("total_episodes", "total_frames", "chunks_size", "fps"):
        info[how] = rng.choice((odd, (info.get(how) or 0) + rng.choice((-1, 1, 1000))))
    elif how == "data_path":
        info[how] = rng.choice(("data/{robot}/episode_{episode_index:06d}.parquet", "data/{chunk_index:03d",
                                "data/file.parquet", None, 7))
    elif how == "video_path":
        info[how] = rng.choice(("videos/{camera}/{episode_index}.mp4", None, "videos/{video_key}.mp4"))
    elif how == "codebase_version":
        info[how] = rng.choice(("v9.0", "", None, 3.0))
    else:
        features = info.get("features") or {}
        key = rng.choice(sorted(features)) if features else "observation.state"
        if how == "features":
            features.pop(key, None)
        elif how == "shape" and key in features:
            features[key]["shape"] = rng.choice(([0], [10**9], ["a"], None, [3, 2]))
        elif key in features:
            features[key]["names"] = rng.choice((["a"], None, {"x": [1, 2]}, "names"))
    path.write_text(json.dumps(info, allow_nan=True))
    return f"info.json {how}"


def edit_index(root: Path, how: str, rng: random.Random) -> str:
    """The episodes index (v3.0 parquet, v2.x jsonl) disagreeing with the data files."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    files = sorted((root / "meta" / "episodes").rglob("*.parquet"))
    if files:
        table = pq.read_table(files[0])
        rows = table.to_pylist()
        if how == "length":
            rows[0]["length"] += rng.choice((-3, 5))
        elif how == "duplicate_episode" and len(rows) > 1:
            rows[1]["episode_index"] = rows[0]["episode_index"]
        elif how == "missing_file":
            rows[-1]["data/file_index"] = 9
        else:
            rows[0]["dataset_from_index"] = 10**6
        pq.write_table(pa.Table.from_pylist(rows), files[0])
        return f"episodes parquet {how}"
    path = root / "meta" / "episodes.jsonl"
    lines = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    if how == "length":
        lines[0]["length"] += rng.choice((-3, 5))
    elif how == "duplicate_episode" and len(lines) > 1:
        lines[1]["episode_index"] = lines[0]["episode_index"]
    else:
        lines[0]["episode_index"] = rng.choice((999, -1, "0", None))
    path.write_text("\n".join(json.dumps(line) for line in lines) + "\n")
    return f"episodes.jsonl {how}"


def materialise(index: int, seed: int, sources: list[tuple[Path, Path | None]], workdir: Path
                ) -> tuple[str, str, list[str]]:
    """The damaged copy of case ``index``: its source's name, the damage, and the command line."""
    rng = random.Random(f"{seed}:{index}")
    source, robot = sources[index % len(sources)]
    command = COMMANDS[(index // len(sources)) % len(COMMANDS)]
    if robot is None and command in ("tf", "attribute"):
        command = "info_episode"
    root = Path(shutil.copytree(source, workdir / "dataset"))
    kind = rng.choice(("file", "file", "file", "info", "index"))
    if kind == "info":
        what = edit_info(root, rng.choice(INFO_EDITS), rng)
    elif kind == "index":
        what = edit_index(root, rng.choice(INDEX_EDITS), rng)
    else:
        groups = _files(root)
        group = rng.choice(sorted(groups))
        path = rng.choice(groups[group])
        what = f"{path.relative_to(root)} {damage_file(path, rng.choice(FILE_DAMAGE), rng)}"
    episode = ["--episode", str(rng.choice((0, 0, 1)))]
    argv: dict[str, Callable[[], list[str]]] = {
        "info": lambda: ["info", str(root), *(["--json"] if rng.random() < 0.5 else [])],
        "info_episode": lambda: ["info", str(root), *episode],
        "tf": lambda: ["tf", str(root), "world", "gripper_link", *episode, "--robot", str(robot), "--json"],
        "attribute": lambda: ["attribute", "-q", str(root), *episode, "--robot", str(robot), "--out",
                              str(workdir / "out"), "--format", "json", "--bootstrap", "0"],
    }
    return source.name, what, argv[command]()


def run(args: argparse.Namespace) -> list[dict[str, Any]]:
    indices = [int(i) for i in args.only.split(",")] if args.only else list(range(args.cases))
    results = []
    with tempfile.TemporaryDirectory(prefix="fuzzdata") as tmp:
        sources = generate_sources(Path(tmp) / "sources")
        for index in indices:
            with tempfile.TemporaryDirectory(prefix="case", dir=tmp) as case:
                name, what, argv = materialise(index, args.seed, sources, Path(case))
                result = {"case": index, "target": name, "command": " ".join(argv[:1] + [a for a in argv
                                                                                        if a == "--episode"]),
                          "what": what, **fuzz_config.run_command(argv, args.timeout)}
                if result["status"] != "ok" and args.keep:
                    shutil.copytree(case, Path(args.keep) / f"case{index}", dirs_exist_ok=True)
            results.append(result)
            if args.progress and len(results) % 50 == 0:
                bad = sum(r["status"] != "ok" for r in results)
                print(f"  {len(results)} dataset cases, {bad} failures", file=sys.stderr, flush=True)
    return results


def summary(args: argparse.Namespace) -> dict[str, Any]:
    """Run the cases and summarise them as tools/fuzz_config.py does."""
    start = time.perf_counter()
    return fuzz_config.summarise(run(args), time.perf_counter() - start)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--cases", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds per case before it counts as a hang")
    parser.add_argument("--only", default="", help="comma-separated case numbers to run")
    parser.add_argument("--keep", default="", help="directory for the damaged datasets of failed cases")
    parser.add_argument("--progress", action="store_true")
    parser.add_argument("--json", action="store_true")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if not (REALDATA / "urdf" / "so101" / "so101_new_calib.urdf").is_file():
        print(f"fuzz_datasets: the SO-101 URDF is not under {REALDATA}", file=sys.stderr)
        return 1
    result = summary(args)
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(f"{result['cases']} dataset cases in {result['seconds']:.0f} s: "
              f"{', '.join(f'{k} {v}' for k, v in sorted(result['statuses'].items()))}; exit codes "
              f"{result['exit_codes']}")
        for r in result["failures"]:
            print(f"  case {r['case']} ({r.get('target')}, {r.get('command')}: {r.get('what')}): {r['status']}")
            for text in (r.get("traceback"), r.get("stderr")):
                if text:
                    print("    " + text.strip().replace("\n", "\n    "))
    return 0 if not result["failure_count"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
