"""``framechain demo``: the main job on a generated failed episode, end to end."""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from framechain.cli.common import make_out_dir

if TYPE_CHECKING:
    from framechain.sim.scene import SceneSpec

DEFAULT_FAULTS = ("missing_rotation", "latency:-0.03")


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "demo",
        help="generate a failed episode, replay it, attribute it, write the report and an .rrd",
        description="Generate a failed episode (by default a mast camera pitched down 30 deg whose extrinsic lost "
        "its rotation, plus a 30 ms pose latency, with the robot's hop points logged), write it as a real log, "
        "then replay, attribute and report it like any log. Deterministic in --seed.",
    )
    parser.add_argument(
        "--out", default="framechain-demo", metavar="DIR", help="output directory (default ./framechain-demo)"
    )
    parser.add_argument(
        "--fault",
        action="append",
        metavar="KIND[:VALUE][@data]",
        help="fault to inject instead of the default (repeatable): latency:-0.03, missing_rotation, "
        "rotation_error:3, translation_error:0.05 (m, along the body's y), depth_scale:1.05, intrinsics:2, "
        "axis_flip, wrong_world_frame, "
        "inverted_transform; @data puts it in the recorded data instead of the robot",
    )
    parser.add_argument(
        "--evidence",
        choices=("hops", "target", "reference", "static"),
        default="hops",
        help="what the episode logs besides its raw inputs (default hops)",
    )
    parser.add_argument(
        "--container",
        default="mcap-ros2",
        choices=("mcap-ros2", "mcap-ros1", "rosbag1", "rosbag2-sqlite", "rosbag2-mcap"),
    )
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--no-rrd", action="store_true", help="skip the Rerun recording")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress output (results are still printed)")
    parser.add_argument("--json", action="store_true", help="print attribution.json")
    parser.set_defaults(run=run)


def parse_fault(text: str) -> Any:
    from framechain.catalogue import Fault
    from framechain.errors import FramechainError
    from framechain.sim.scene import InjectedFault

    where = "robot"
    if text.endswith("@data"):
        text, where = text[: -len("@data")], "data"
    kind_text, _, value = text.partition(":")
    try:
        kind = Fault(kind_text)
    except ValueError as err:
        raise FramechainError(
            f"--fault: unknown fault {kind_text!r}; choose from {', '.join(k.value for k in Fault)}"
        ) from err
    try:
        number = float(value) if value else None
    except ValueError as err:
        raise FramechainError(f"--fault {text}: {value!r} is not a number") from err
    params: dict[str, Any] = {}
    if kind == Fault.LATENCY:
        params["offset_s"] = number if number is not None else -0.03
    elif kind == Fault.ROTATION_ERROR:
        params.update(angle_deg=number if number is not None else 3.0, axis=[0.0, 1.0, 0.0])
    elif kind == Fault.TRANSLATION_ERROR:
        params["offset_m"] = [0.0, number if number is not None else 0.05, 0.0]
    elif kind == Fault.DEPTH_SCALE:
        params["factor"] = number if number is not None else 1.05
    elif kind == Fault.INTRINSICS:
        params["scale"] = number if number is not None else 2.0
    elif kind == Fault.AXIS_FLIP:
        params["permutation"] = [[1, 0, 0], [0, -1, 0], [0, 0, -1]]
    elif kind == Fault.INVERTED_TRANSFORM:
        params["hop"] = "camera_to_body"
    return InjectedFault(kind, where, params)  # type: ignore[arg-type]


def run(args: argparse.Namespace) -> int:
    from framechain import pipeline
    from framechain.cli.common import imports_set_aside, print_findings, progress_reporter
    from framechain.sim.scene import SceneSpec
    from framechain.sinks.plots import renderers
    from framechain.sinks.report import write_outputs

    started = time.perf_counter()
    faults = tuple(parse_fault(f) for f in (args.fault or DEFAULT_FAULTS))
    robot_side = [f.kind.value for f in faults if f.where == "robot"]
    if robot_side and args.evidence in ("reference", "static"):
        # The robot's own mistakes leave the recording right: against truth there is nothing to find.
        print(f"framechain demo: note: {', '.join(robot_side)} {'is' if len(robot_side) == 1 else 'are'} injected in "
              f"the robot's computation, which --evidence {args.evidence} cannot see (the recorded data is right); "
              "add @data to a --fault to put it in the recording", file=sys.stderr)
    out = Path(args.out)
    make_out_dir(out)
    spec = SceneSpec(
        seed=args.seed,
        duration_s=8.0,
        width=320,
        height=240,
        focal_px=300.0,
        evidence=args.evidence,
        depth_images=True,
        color_images=True,
        faults=faults,
    )
    with renderers(), imports_set_aside(), progress_reporter(args.quiet or args.json, "demo") as progress:
        say = progress or (lambda _m: None)
        log_path, chain_path = _write_episode(spec, out, args.container, say)
        made = pipeline.run(log_path, chain_path, seed=args.seed, progress=progress)
        result = made.attributed()
        paths: dict[str, Path] = {"log": log_path, "chain": chain_path}
        paths.update(write_outputs(made, out, formats=("md", "html"), say=say))
        if not args.no_rrd:
            from framechain.sinks.rerun import RerunTarget, stream_replay

            say("writing the Rerun recording")
            rrd = out / "episode.rrd"
            stream_replay(made, RerunTarget.save(rrd))
            paths["rrd"] = rrd
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
        return 0
    injected = ", ".join(f"{f.kind.value}{' ' + str(f.params) if f.params else ''} ({f.where})" for f in faults)
    print(f"injected: {injected}")
    print_findings(result)
    for name, path in paths.items():
        print(f"{name}: {path}")
    viewer = f" or `rerun {paths['rrd']}`" if "rrd" in paths else ""
    print(f"done in {time.perf_counter() - started:.1f} s; open {paths['html']}{viewer}")
    return 0


def _write_episode(spec: SceneSpec, out: Path, container: str, say: Callable[[str], None]) -> tuple[Path, Path]:
    """Generate the episode of ``spec`` and write it as a log in ``container`` (replacing one there) with its chain:
    the log's path and the chain's."""
    from framechain.sim.logs import SUFFIX, write_scene
    from framechain.sim.scene import generate

    say("generating the episode")
    scene = generate(spec)
    log_path = out / f"episode{SUFFIX[container]}"
    if log_path.exists():
        shutil.rmtree(log_path) if log_path.is_dir() else log_path.unlink()
    say(f"writing {log_path}")
    write_scene(scene, log_path, container=container)
    chain_path = out / "chain.yaml"
    chain_path.write_text(scene.chain.to_yaml())
    return log_path, chain_path
