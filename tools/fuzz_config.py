"""Fuzz the configuration files: mutated copies of valid files through the commands that read them.

Three valid files are mutated, each read by the command a user would run:

- ``chain``: the tutorial's chain.yaml for the tagslam_stairs bag, through ``info LOG --chain``, and
  ``attribute LOG --chain`` for every ``--attribute-every``-th chain case;
- ``calibration``: the Kalibr ``cameras.yaml`` beside that bag, or a ROS camera_info YAML made from
  its cam0, named by the same chain, through ``info LOG --chain``;
- ``robot``: a robot.yaml for the unitree_g1_v21 LeRobot dataset (a generated arm URDF, an inline
  camera, the chain section), through ``info DATASET --episode 5 --robot``.

A mutation replaces one to three values (a key's value, a list element, or a whole section) by
null, NaN, +-inf, huge or tiny numbers, a unit slip (x1000, x0.001), strings, lists, mappings
(one with mixed int and str keys), booleans, or removes the key. A case fails on a traceback (an
exception escaping the CLI, or "Traceback" on stderr), an exit code other than 0 or 1, an exit 1
whose stderr is not exactly one line, or a hang (over ``--timeout`` seconds).

    python tools/fuzz_config.py --cases 1500 --seed 0       # what `make fuzz` runs (through tools/fuzz.py)
    python tools/fuzz_config.py --cases 210 --seed 1 --mix chain=5,calibration=1,robot=1 --json  # the tests' run

Cases are reproducible: ``--only N`` reruns case N and ``--keep DIR`` keeps the mutated files of failures.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import math
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
REALDATA = ROOT.parent / "shared" / "realdata"
TARGETS = ("chain", "calibration", "robot")
#: Cases of each target in a cycle: chains are the most varied, twice the share.
DEFAULT_MIX = "chain=2,calibration=1,robot=1"

#: The tutorial's chain for the tagslam_stairs bag (docs/tutorial.md).
STAIRS_CHAIN: dict[str, Any] = {
    "frames": {"camera": "t265_fisheye1_optical_frame", "body": "basalt_pose_frame", "world": "world"},
    "topics": {"detections": "/t265/fisheye1/tags", "odometry": "/vio_node/odom"},
    "calibration": {"file": "cameras.yaml", "camera": "cam0"},
    "mounts": [{"parent": "basalt_pose_frame", "child": "t265_fisheye1_optical_frame",
                "xyz": [0.010699, 0.000025, -0.000092], "rotvec": [-0.0135696, 0.0062165, -3.1391944]}],
    "evidence": {"static_target": True,
                 "tag_size_m": {"default": 0.16, **dict.fromkeys(range(100, 108), 0.1)}},
}

#: Values a mutation puts in place of another.
VALUES: tuple[Any, ...] = (
    None, math.nan, math.inf, -math.inf, 1e308, -1e308, 10**40, 1e-300, 0, -1, 0.5, 160, 180, 1000.0, "", "x",
    "/nope", "0.16", "NaN", [], [1, 2, 3], [0, 0, 180], [[1]], [None], {}, {"a": 1}, {1: "x", "b": 2}, True, False,
)


# -- the valid files --------------------------------------------------------------------------------
def stairs_log(realdata: Path) -> Path:
    return realdata / "tagslam_stairs" / "tag_detections.bag"


def unitree_dataset(realdata: Path) -> Path:
    return realdata / "lerobot" / "unitree_g1_v21"


def ros_camera_info(kalibr: dict[str, Any]) -> dict[str, Any]:
    """cam0 of a Kalibr camchain as a ROS camera_info YAML (camera_calibration_parsers' layout)."""
    cam = kalibr["cam0"]
    fx, fy, cx, cy = cam["intrinsics"]
    width, height = cam["resolution"]
    return {"image_width": width, "image_height": height, "camera_name": "cam0",
            "camera_matrix": {"rows": 3, "cols": 3, "data": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]},
            "distortion_model": "equidistant",
            "distortion_coefficients": {"rows": 1, "cols": 4, "data": list(cam["distortion_coeffs"])}}


def arm_urdf(names: list[str]) -> str:
    links = "".join(f'<link name="l{i}"/>' for i in range(len(names) + 1))
    joints = "".join(
        f'<joint name="{n}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
        f'<origin xyz="0.1 0 0" rpy="0 0 0"/><axis xyz="0 {i % 2} {1 - i % 2}"/><limit lower="-3" upper="3"/></joint>'
        for i, n in enumerate(names))
    return f'<?xml version="1.0"?><robot name="left_arm">{links}{joints}</robot>'


def unitree_robot(realdata: Path) -> tuple[dict[str, Any], list[str]]:
    """A robot.yaml for the unitree dataset's left arm, and the arm's joint names."""
    info = json.loads((unitree_dataset(realdata) / "meta" / "info.json").read_text())
    arm = [str(n) for n in info["features"]["observation.state"]["names"][0][:7]]
    robot = {
        "urdf": "arm.urdf", "default_unit": "rad",
        "joints": {**{n: n for n in arm[:6]}, arm[6]: {"joint": arm[6], "unit": "rad", "sign": 1, "offset": 0.0}},
        "world_from_base": {"xyz": [0.0, 0.0, 0.8], "rpy": [0.0, 0.0, 0.1]},
        "cameras": {"head": {
            "intrinsics": {"fx": 300.0, "fy": 300.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480},
            "mount": {"parent": "l7", "xyz": [0.05, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0], "optical": False},
            "video_key": "observation.images.cam_high", "timing": {"offset_s": 0.0}}},
        "chain": {"camera": "head", "latency_budget_s": 0.02,
                  "evidence": {"reference_point": [0.4, 0.1, 0.02], "static_target": True}},
    }
    return robot, arm


# -- mutations --------------------------------------------------------------------------------------
Path_ = tuple[Any, ...]


def paths(node: Any, prefix: Path_ = ()) -> Iterator[Path_]:
    """Every key and list position below ``node`` (sections as well as leaves)."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield (*prefix, key)
            yield from paths(value, (*prefix, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield (*prefix, i)
            yield from paths(value, (*prefix, i))


def _parent(doc: Any, path: Path_) -> Any:
    for step in path[:-1]:
        doc = doc[step]
    return doc


def mutate(doc: dict[str, Any], rng: random.Random) -> tuple[dict[str, Any], list[str]]:
    """A copy of ``doc`` with one to three values replaced or removed, and what was done."""
    out = copy.deepcopy(doc)
    done: list[str] = []
    for _ in range(rng.choice((1, 1, 2, 3))):
        candidates = list(paths(out))
        if not candidates:
            break
        path = rng.choice(candidates)
        parent = _parent(out, path)
        key = path[-1]
        where = ".".join(map(str, path))
        roll = rng.random()
        old = parent[key]
        if roll < 0.15:
            del parent[key]
            done.append(f"{where} removed")
        elif roll < 0.3 and isinstance(old, int | float) and not isinstance(old, bool):
            factor = rng.choice((1000.0, 0.001, -1.0, 1e6))
            parent[key] = old * factor
            done.append(f"{where} x{factor:g}")
        else:
            value = copy.deepcopy(rng.choice(VALUES))
            parent[key] = value
            done.append(f"{where} = {value!r}")
    return out, done


# -- the cases --------------------------------------------------------------------------------------
def parse_mix(text: str) -> list[str]:
    """``chain=2,calibration=1,robot=1`` as the cycle of targets ``[chain, chain, calibration, robot]``."""
    cycle: list[str] = []
    for part in text.split(","):
        name, _, count = part.partition("=")
        if name not in TARGETS or not count.isdigit():
            raise SystemExit(f"fuzz_config: --mix takes {'|'.join(TARGETS)}=COUNT,...; got {part!r}")
        cycle += [name] * int(count)
    return cycle


def materialise(index: int, seed: int, realdata: Path, workdir: Path, cycle: list[str], attribute_every: int
                ) -> tuple[str, list[str], list[str]]:
    """Write case ``index``'s files into ``workdir``: its target, what was mutated, the command line."""
    rng = random.Random(f"config:{seed}:{index}")
    target = cycle[index % len(cycle)]
    kalibr = yaml.safe_load((realdata / "tagslam_stairs" / "cameras.yaml").read_text())
    chain = copy.deepcopy(STAIRS_CHAIN)
    log = stairs_log(realdata)
    if target == "chain":
        chain, done = mutate(chain, rng)
        files = {"cameras.yaml": kalibr}
    elif target == "calibration":
        if rng.random() < 0.5:
            calibration, done = mutate(kalibr, rng)
            files = {"cameras.yaml": calibration}
        else:
            calibration, done = mutate(ros_camera_info(kalibr), rng)
            chain["calibration"] = {"file": "cam0.yaml"}
            files = {"cam0.yaml": calibration}
    else:
        robot, arm = unitree_robot(realdata)
        robot, done = mutate(robot, rng)
        (workdir / "arm.urdf").write_text(arm_urdf(arm))
        _write_yaml(workdir / "robot.yaml", robot)
        return target, done, ["info", str(unitree_dataset(realdata)), "--episode", "5", "--robot",
                              str(workdir / "robot.yaml")]
    for name, doc in files.items():
        _write_yaml(workdir / name, doc)
    _write_yaml(workdir / "chain.yaml", chain)
    # Which chain case this is, counting chain cases only: every attribute_every-th runs attribute.
    chain_case = cycle.count("chain") * (index // len(cycle)) + cycle[:index % len(cycle)].count("chain")
    if target == "chain" and attribute_every and chain_case % attribute_every == 0:
        return target, done, ["attribute", "-q", str(log), "--chain", str(workdir / "chain.yaml"), "--out",
                              str(workdir / "out"), "--format", "json", "--bootstrap", "0"]
    return target, done, ["info", str(log), "--chain", str(workdir / "chain.yaml")]


def _write_yaml(path: Path, doc: Any) -> None:
    path.write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True))


class CaseTimeoutError(BaseException):
    """A case ran past its time (a BaseException, so no ``except Exception`` swallows it)."""


def _on_alarm(signum: int, frame: Any) -> None:
    raise CaseTimeoutError


def run_command(argv: list[str], timeout: float) -> dict[str, Any]:
    """Run the CLI in this process: its status (ok, traceback, hang, bad exit, not one line) and output."""
    from framechain.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    result: dict[str, Any] = {}
    signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    start = time.perf_counter()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code: Any = main(argv)
    except CaseTimeoutError:
        result["status"] = "hang"
        code = None
    except SystemExit as exc:
        code = exc.code
    except BaseException:
        result["status"] = "traceback"
        result["traceback"] = traceback.format_exc(limit=-8)
        code = None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    result["seconds"] = round(time.perf_counter() - start, 3)
    stderr = err.getvalue()
    if "status" not in result:
        result["exit"] = code
        lines = [line for line in stderr.splitlines() if line.strip()]
        if "Traceback (most recent call last)" in stderr:
            result["status"] = "traceback"
        elif code not in (0, 1):
            result["status"] = "bad exit"
        elif code == 1 and len(lines) != 1:
            result["status"] = "not one line"
        else:
            result["status"] = "ok"
    if code == 1 or result["status"] != "ok":
        result["stderr"] = stderr[-2000:]
    return result


def run_cases(indices: list[int], args: argparse.Namespace) -> Iterator[dict[str, Any]]:
    keep = Path(args.keep) if args.keep else None
    for index in indices:
        with tempfile.TemporaryDirectory(prefix="fuzzcfg") as tmp:
            workdir = Path(tmp)
            target, done, argv = materialise(index, args.seed, Path(args.realdata), workdir, parse_mix(args.mix),
                                             args.attribute_every)
            result = {"case": index, "target": target, "command": argv[0], "what": "; ".join(done),
                      **run_command(argv, args.timeout)}
            if result["status"] != "ok" and keep is not None:
                shutil.copytree(workdir, keep / f"case{index}", dirs_exist_ok=True)
        yield result


def run_workers(indices: list[int], args: argparse.Namespace) -> list[dict[str, Any]]:
    """The cases split over ``--jobs`` worker processes (each runs its share in order)."""
    jobs = max(1, args.jobs)
    results: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="fuzzcfg") as tmp:
        procs = []
        for k, share in enumerate(indices[i::jobs] for i in range(jobs)):
            if not share:
                continue
            cmd = [sys.executable, __file__, "--worker", "--seed", str(args.seed), "--realdata", args.realdata,
                   "--only", ",".join(map(str, share)), "--timeout", str(args.timeout), "--mix", args.mix,
                   "--attribute-every", str(args.attribute_every), *(["--keep", args.keep] if args.keep else [])]
            out = Path(tmp) / f"worker{k}.jsonl"  # a file, not a pipe: no worker waits on another's reader
            with out.open("w") as sink:
                procs.append((subprocess.Popen(cmd, stdout=sink, stderr=subprocess.DEVNULL, text=True), out))
        for proc, out in procs:
            proc.wait()
            results += [json.loads(line) for line in out.read_text().splitlines() if line.startswith("{")]
    done = {r["case"] for r in results}
    results += [{"case": i, "status": "crash", "what": "worker died"} for i in indices if i not in done]
    return sorted(results, key=lambda r: int(r["case"]))


def summarise(results: list[dict[str, Any]], seconds: float) -> dict[str, Any]:
    failures = [r for r in results if r["status"] != "ok"]
    return {
        "cases": len(results), "seconds": round(seconds, 1),
        "statuses": dict(Counter(r["status"] for r in results)),
        "exit_codes": dict(Counter(str(r.get("exit")) for r in results)),
        "targets": dict(Counter(f"{r.get('target')} {r.get('command')}" for r in results)),
        "failures": failures[:20], "failure_count": len(failures),
    }


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--cases", type=int, default=1500)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds per case before it counts as a hang")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--mix", default=DEFAULT_MIX, help="cases of each target in a cycle (default %(default)s)")
    parser.add_argument("--attribute-every", type=int, default=3,
                        help="every N-th chain case runs attribute instead of info (0: never)")
    parser.add_argument("--realdata", default=str(REALDATA))
    parser.add_argument("--only", default="", help="comma-separated case numbers to run")
    parser.add_argument("--keep", default="", help="directory for the files of failed cases")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    realdata = Path(args.realdata)
    indices = [int(i) for i in args.only.split(",")] if args.only else list(range(args.cases))
    parse_mix(args.mix)
    if args.worker:
        for result in run_cases(indices, args):
            print(json.dumps(result), flush=True)
        return 0
    if not stairs_log(realdata).is_file() or not unitree_dataset(realdata).is_dir():
        print(f"fuzz_config: the tagslam_stairs bag or the unitree dataset is not under {realdata}", file=sys.stderr)
        return 1
    start = time.perf_counter()
    results = run_workers(indices, args)
    summary = summarise(results, time.perf_counter() - start)
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(f"{summary['cases']} configuration cases in {summary['seconds']:.0f} s: "
              f"{', '.join(f'{k} {v}' for k, v in sorted(summary['statuses'].items()))}; exit codes "
              f"{summary['exit_codes']}")
        for r in summary["failures"]:
            print(f"  case {r['case']} ({r.get('target')}, {r.get('command')}: {r.get('what')}): {r['status']}")
            for text in (r.get("traceback"), r.get("stderr")):
                if text:
                    print("    " + text.strip().replace("\n", "\n    "))
    return 0 if not summary["failure_count"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
