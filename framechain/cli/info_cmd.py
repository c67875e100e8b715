"""``framechain info LOG [--json] [--chain]``: what a log holds, its frame tree and a chain to start from."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from framechain.cli.common import add_dataset_arguments

if TYPE_CHECKING:
    from framechain.adapters import LoadedLog
    from framechain.suggest import EdgeInfo, SuggestedChain
    from framechain.timeline import CameraTable, LogInfo


#: Columns of text written to a file or a pipe (no terminal to fit).
PIPED_WIDTH = 200


def register(sub: Any) -> None:
    p = sub.add_parser(
        "info",
        help="format, topics, frame tree, cameras, what the chain needs and a suggested chain of a log",
        description="Read a log (MCAP, ROS 1 bag, ROS 2 bag) and show its format and span, the topics with "
        "types, counts and rates, the frame tree (parent, child, static or dynamic, rate, span, and the delay "
        "between header stamp and log time per edge), the cameras, what the chain needs (camera frame, "
        "intrinsics, detections, depth, mount, pose, evidence: found, or missing with the chain key that "
        "supplies it) and a suggested chain configuration. With --chain CHAIN.yaml the log is read through "
        "that chain (its calibration files, mounts, urdf and pose topics) and checked against it.",
    )
    p.add_argument("log", help="an .mcap file, a ROS 1 .bag, a ROS 2 bag directory, a bare .db3, or a LeRobot "
                   "dataset directory or Hugging Face Hub id (with --episode and --robot for its frame tree)")
    add_dataset_arguments(p)
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the tree")
    p.add_argument("--chain", nargs="?", const=True, default=None, metavar="CHAIN.yaml",
                   help="alone: print only the suggested chain configuration as YAML (framechain info LOG --chain "
                   "> chain.yaml); with a file: read the log through that chain and check what it needs")
    p.add_argument("--chain-file", metavar="CHAIN.yaml", help="the same as --chain CHAIN.yaml")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar while reading")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from framechain.errors import FramechainError
    from framechain.suggest import frame_tree

    chain_file = args.chain_file or (args.chain if isinstance(args.chain, str) else None)
    print_chain = args.chain is True
    if print_chain and args.json:
        raise FramechainError("--chain alone prints the suggested chain as YAML; it does not go with --json")
    loaded, suggestion, skeleton = _read(args, chain_file)
    edges = frame_tree(loaded.timeline.transforms)
    if skeleton is not None:
        if print_chain:
            print(skeleton, end="")
        elif args.json:
            print(json.dumps({**_as_json(loaded, edges, None), "robot_yaml": skeleton}, indent=2))
        else:
            _render(loaded, edges, None, chain_given=False)
            print(f"Suggested robot.yaml (framechain info {args.log} --episode {args.episode} --chain > robot.yaml):")
            print(skeleton, end="")
        return 0
    if print_chain:
        if suggestion is None:
            raise FramechainError(f"{args.log}: a LeRobot dataset's robot.yaml comes from --episode N "
                                  f"(`framechain info {args.log} --episode N --chain > robot.yaml`)")
        print(suggestion.to_yaml(source=str(loaded.info.path)), end="")
        return 0
    if args.json:
        print(json.dumps(_as_json(loaded, edges, suggestion), indent=2))
        return 0
    _render(loaded, edges, suggestion, chain_given=chain_file is not None)
    return 0


def _read(args: argparse.Namespace, chain_file: str | None) -> tuple[LoadedLog, SuggestedChain | None, str | None]:
    """The log as ``info`` shows it, the chain to check against it (given or suggested, with its needs), and for a
    dataset without robot.yaml the robot.yaml to start from."""
    from framechain import pipeline
    from framechain.adapters import LeRobotAdapter, LoadedLog
    from framechain.suggest import (
        SuggestedChain,
        calibration_disagreements,
        chain_needs,
        frame_id_disagreements,
        suggest,
    )

    suggestion: SuggestedChain | None = None
    skeleton: str | None = None
    dataset = LeRobotAdapter().probe(Path(args.log))
    if dataset and args.episode is not None and args.robot is None and chain_file is None:
        from framechain.suggest.lerobot import robot_yaml_skeleton

        # No robot.yaml yet: the dataset's episode, and a robot.yaml to start from.
        loaded, skeleton = _dataset_summary(args.log, args.episode), robot_yaml_skeleton(args.log, args.episode)
    elif dataset and (args.episode is not None or args.robot is not None or chain_file is not None):
        run_ = pipeline.load_log(args.log, chain_file, episode=args.episode, robot=args.robot)
        assert run_.info is not None  # a dataset is read with what it holds
        loaded = LoadedLog(timeline=run_.timeline, info=run_.info, decoded_topics={})
        suggestion = SuggestedChain(config=run_.chain)
    elif dataset:
        loaded = _dataset_summary(args.log)
    else:
        given = pipeline.load_chain(chain_file)
        loaded = pipeline.read_log(args.log, given, progress=sys.stderr.isatty() and not (args.json or args.quiet))
        suggestion = SuggestedChain(config=given) if given is not None else suggest(loaded)
    if suggestion is not None and not suggestion.needs:
        suggestion = SuggestedChain(config=suggestion.config,
                                    needs=tuple(chain_needs(loaded, suggestion.config)))
    # Names that disagree (detections stamped with another camera's frame, a calibration of another topic).
    warnings = [*(calibration_disagreements(suggestion.config, loaded.info) if suggestion is not None else []),
                *frame_id_disagreements(loaded)]
    loaded = LoadedLog(timeline=loaded.timeline, info=loaded.info.with_notes(warnings),
                       decoded_topics=loaded.decoded_topics)
    return loaded, suggestion, skeleton


def _dataset_summary(path: str, episode: int | None = None) -> LoadedLog:
    """A LeRobot dataset without --robot: what its metadata says (of one episode), no frame tree."""
    from framechain.adapters import LoadedLog, scan_dataset
    from framechain.timeline import Timeline

    info = scan_dataset(path, episode, clocks=True)
    note = (f"`framechain info {path} --episode N` prints a robot.yaml to start from (complete for an arm "
            "framechain bundles a URDF for); with --robot robot.yaml it shows the frame tree forward kinematics gives")
    return LoadedLog(timeline=Timeline(), info=info.with_notes([note]), decoded_topics={})


def _as_json(loaded: LoadedLog, edges: list[EdgeInfo], suggestion: SuggestedChain | None) -> dict[str, Any]:
    cams = loaded.timeline.cameras
    cameras = []
    for frame in dict.fromkeys(cams.frame.tolist()):
        i = int(list(cams.frame).index(frame))
        cameras.append({
            "frame": frame, "topic": str(cams.source[i]), "width": int(cams.width[i]), "height": int(cams.height[i]),
            "fx": float(cams.K[i, 0, 0]), "fy": float(cams.K[i, 1, 1]), "cx": float(cams.K[i, 0, 2]),
            "cy": float(cams.K[i, 1, 2]), "distortion_model": str(cams.distortion_model[i]),
            "distortion": cams.distortion[i, : int(cams.n_distortion[i])].tolist(),
            "count": int((cams.frame == frame).sum()),
        })
    needs = list(suggestion.needs) if suggestion is not None else []
    return {**loaded.info.to_dict(), "edges": [e.to_dict() for e in edges], "cameras": cameras,
            "suggested_chain": suggestion.config.to_dict() if suggestion is not None else {},
            "placeholders": dict(suggestion.placeholders) if suggestion is not None else {},
            "needs": [n.to_dict() for n in needs],
            "ready": bool(needs) and suggestion is not None and suggestion.ready}


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e3:.1f}"


def _edge_label(e: EdgeInfo) -> str:
    if e.is_static:
        return f"[bold]{e.child}[/]  [dim]static[/] [dim]({', '.join(e.sources)})[/]"
    span = (e.last_stamp_ns - e.first_stamp_ns) * 1e-9
    if e.clocks_differ:
        delay = (f"[yellow]stamps and log times in different clocks (log - stamp = {e.delay_mean_s or 0.0:.1f} s; "
                 "see notes)[/]")
    else:
        delay = f"delay mean {_ms(e.delay_mean_s)} ms, p95 {_ms(e.delay_p95_s)} ms, max {_ms(e.delay_max_s)} ms"
    return (f"[bold]{e.child}[/]  [cyan]{e.rate_hz:.1f} Hz[/], {e.count} samples over {span:.2f} s; {delay} "
            f"[dim]({', '.join(e.sources)})[/]")


def _render(loaded: LoadedLog, edges: list[EdgeInfo], suggestion: SuggestedChain | None, *,
            chain_given: bool) -> None:
    from rich.markup import escape

    from framechain.cli.common import stdout_console

    # Piped into a file, a terminal's width would cut topic names: wide, and a long name folds in its cell.
    console = stdout_console(PIPED_WIDTH)
    _render_topics(console, loaded)
    _render_tree(console, edges)
    _render_cameras(console, loaded.timeline.cameras)
    for note in loaded.info.notes:
        console.print(f"[yellow]note:[/] {escape(note)}")
    if suggestion is not None:
        _render_needs(console, suggestion, loaded.info, chain_given=chain_given)


def _render_topics(console: Any, loaded: LoadedLog) -> None:
    """The log's path, format, span and message count, and its topics."""
    from rich.markup import escape
    from rich.table import Table

    info = loaded.info
    console.print(f"[bold]{escape(str(info.path))}[/]")
    console.print(f"  format     {info.container or info.format}")
    span = f"log time {info.start_ns * 1e-9:.3f} .. {info.end_ns * 1e-9:.3f}"
    console.print(f"  duration   {info.duration_s:.3f} s  ({span})")
    console.print(f"  messages   {info.message_count}")
    topics = Table(title="Topics", title_justify="left")
    for col, justify in (("topic", "left"), ("type", "left"), ("count", "right"), ("rate (Hz)", "right"),
                         ("read as", "left")):
        topics.add_column(col, justify=justify, overflow="fold")  # type: ignore[arg-type]
    for t in info.topics:
        topics.add_row(escape(t.name), escape(t.msgtype), str(t.count), f"{t.rate_hz:.1f}",
                       loaded.decoded_topics.get(t.name, "[dim]-[/]"))
    console.print(topics)


def _render_tree(console: Any, edges: list[EdgeInfo]) -> None:
    """The frame tree, each edge with its rate, span and stamp delays."""
    from rich.markup import escape
    from rich.tree import Tree

    from framechain.suggest.frame_tree import children_of, tree_roots

    if not edges:
        console.print("[yellow]No transforms (/tf, /tf_static, TransformStamped, Odometry) in this log.[/]")
        return
    kids = children_of(edges)
    tree = Tree("[bold]Frame tree[/] (parent -> child; delay = log time - header stamp)")

    def add(node: Tree, frame: str, depth: int) -> None:
        for e in sorted(kids.get(frame, []), key=lambda e: e.child):
            branch = node.add(_edge_label(e))
            if depth < 64:
                add(branch, e.child, depth + 1)

    for root in tree_roots(edges):
        add(tree.add(f"[bold]{escape(root)}[/]"), root, 0)
    console.print(tree)


def _render_cameras(console: Any, cams: CameraTable) -> None:
    """One row per camera frame: its topic, size, intrinsics and distortion model."""
    from rich.markup import escape
    from rich.table import Table

    if not len(cams):
        return
    table = Table(title="Cameras", title_justify="left")
    for col in ("frame", "topic", "size", "fx", "fy", "cx", "cy", "distortion"):
        table.add_column(col, overflow="fold")
    for frame in dict.fromkeys(cams.frame.tolist()):
        i = int(list(cams.frame).index(frame))
        K = cams.K[i]
        table.add_row(escape(frame), escape(str(cams.source[i])), f"{cams.width[i]}x{cams.height[i]}",
                      f"{K[0, 0]:.2f}", f"{K[1, 1]:.2f}", f"{K[0, 2]:.2f}", f"{K[1, 2]:.2f}",
                      f"{cams.distortion_model[i]} ({int(cams.n_distortion[i])})")
    console.print(table)


def _render_needs(console: Any, suggestion: SuggestedChain, info: LogInfo, *, chain_given: bool) -> None:
    """What the chain needs, found or missing with the key that supplies it, and the suggested chain."""
    from rich.markup import escape

    from framechain.suggest.facts import chain_files_beside

    which = "the given chain" if chain_given else "the suggested chain"
    verdict = "[green]ready to replay[/]" if suggestion.ready else "[yellow]not ready: add the keys below[/]"
    console.print(f"[bold]What {which} needs[/] ({verdict})")
    colour = {"found": "green", "missing": "red", "none": "yellow"}
    for need in suggestion.needs:
        fix = f": {escape(need.fix())}" if need.key else ""
        console.print(f"  {escape(need.piece)}: [{colour[need.status.value]}]{need.status.value}[/] "
                      f"({escape(need.detail)}{fix})", highlight=False, soft_wrap=True)
    if not chain_given:
        beside = chain_files_beside(Path(str(info.path)))
        if beside:
            console.print(f"[yellow]note:[/] {escape(str(beside[0]))} lies beside the log: `framechain info LOG "
                          f"--chain {escape(str(beside[0]))}` checks it", highlight=False, soft_wrap=True)
        console.print("[bold]Suggested chain[/] (framechain info LOG --chain > chain.yaml):")
        console.print(escape(suggestion.to_yaml(source=str(info.path))), highlight=False, soft_wrap=True)
