"""``framechain tf LOG TARGET SOURCE [--at STAMP | --series] [--json | --csv]``: tf2_echo for a recorded log."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from framechain.cli.common import add_dataset_arguments

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from framechain.replay import LookupResult, TransformBuffer

#: --at values at or above this many seconds are seconds since the epoch; below, relative to the log start.
EPOCH_THRESHOLD_S = 1e8


def register(sub: Any) -> None:
    p = sub.add_parser(
        "tf",
        help="T_target_source from a recorded log at a time or over time (tf2_echo for logs)",
        description="Look up T_target_source (maps points in SOURCE into TARGET) in a recorded log with tf2 "
        "semantics: linear interpolation of translation and slerp of rotation between the two samples bracketing "
        "the time, static edges timeless, extrapolation an error that names the edge and its recorded span.",
    )
    p.add_argument("log", help="an .mcap file, a ROS 1 .bag, a ROS 2 bag directory, a bare .db3, or a LeRobot "
                   "dataset directory or Hugging Face Hub id (with --episode and --robot: the frame tree from "
                   "forward kinematics)")
    p.add_argument("target", help="target frame (the transform maps points into it)")
    p.add_argument("source", help="source frame")
    when = p.add_mutually_exclusive_group()
    when.add_argument("--at", metavar="STAMP",
                      help="header-stamp time in seconds: since the epoch if >= 1e8, else relative to the first "
                      "stamp in the log (default: the latest time common to the path, tf2's time 0)")
    when.add_argument("--series", action="store_true",
                      help="the transform at every sample time of the path's dynamic edges (CSV by default)")
    fmt = p.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true", help="print JSON")
    fmt.add_argument("--csv", action="store_true", help="print CSV")
    p.add_argument("--chain", metavar="CHAIN.yaml",
                   help="a chain file whose mounts, urdf and pose topics (topics.odometry) add edges to the log's")
    add_dataset_arguments(p)
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar while reading")
    p.set_defaults(run=run)


def parse_stamp(text: str, log_start_ns: int) -> int:
    """``--at`` in ns: seconds since the epoch (>= 1e8), else seconds after ``log_start_ns``."""
    from decimal import Decimal, InvalidOperation

    from framechain.errors import FramechainError

    try:
        seconds = Decimal(text.strip())
    except InvalidOperation as err:
        raise FramechainError(f"--at: expected seconds (e.g. 1700000000.25 or 12.5), got {text!r}") from err
    if not seconds.is_finite() or abs(seconds) > Decimal("9e9"):
        raise FramechainError(f"--at: {text!r} is not a time in seconds within the span of an int64 nanosecond stamp")
    ns = int(seconds * 1_000_000_000)
    return ns if seconds >= Decimal(EPOCH_THRESHOLD_S) else log_start_ns + ns


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from framechain import pipeline
    from framechain.adapters import LeRobotAdapter
    from framechain.adapters.api import TREE_KINDS
    from framechain.errors import FramechainError
    from framechain.replay import LATEST, TransformBuffer

    show_progress = sys.stderr.isatty() and not (args.json or args.csv or args.quiet)
    salvage: dict[str, Any] | None = None
    if LeRobotAdapter().probe(Path(args.log)):  # the episode's tree comes from robot.yaml and the URDF
        transforms = pipeline.load_log(args.log, episode=args.episode, robot=args.robot).timeline.transforms
    else:
        if args.episode is not None or args.robot is not None:
            raise FramechainError(f"{args.log}: --episode and --robot are for LeRobot datasets; this is not one")
        loaded = pipeline.read_log(args.log, pipeline.load_chain(args.chain), kinds=TREE_KINDS,
                                   progress=show_progress)
        transforms = loaded.timeline.transforms
        salvage = loaded.info.salvage
        if salvage and not args.quiet:  # a damaged log: say what the answer rests on
            unknown = " and parts of unknown count" if salvage["lost_unknown_parts"] else ""
            cut = f", and it is cut short after byte {salvage['cut_at']}" if salvage["cut_at"] is not None else ""
            print(f"note: {args.log} is damaged ({salvage['reason']}): recovered {salvage['recovered_total']} "
                  f"messages, lost {salvage['lost_total']}{unknown}{cut}; `framechain info` says where",
                  file=sys.stderr)
    if not len(transforms):
        raise FramechainError(
            f"{args.log}: no transforms in this log (no /tf, /tf_static, TransformStamped or Odometry)")
    _check_frames(args, transforms)
    buffer = TransformBuffer(transforms)
    dynamic = ~transforms.is_static
    log_start = int(transforms.stamp_ns[dynamic].min()) if dynamic.any() else 0
    if args.series:
        try:
            return _series(args, buffer, log_start)
        except BrokenPipeError:  # e.g. piped into `head`
            import os

            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 0
    times: Any = LATEST if args.at is None else np.array([parse_stamp(args.at, log_start)], dtype=np.int64)
    result = buffer.lookup(args.target, args.source, times)
    result.raise_for_status()
    record = _record(result, 0, log_start, {child: e.source for child, e in buffer.edges.items()})
    if salvage:
        record["salvage"] = salvage
    if args.json:
        print(json.dumps(record, indent=2))
    elif args.csv:
        writer = csv.writer(sys.stdout)
        writer.writerow(_CSV_HEADER)
        writer.writerow(_csv_row(record))
    else:
        _render(record, result.matrix()[0])
    return 0


def _check_frames(args: argparse.Namespace, transforms: Any) -> None:
    """A frame no transform mentions: one line with what it may have meant, and where else frames come from."""
    from framechain.errors import FramechainError
    from framechain.suggest import did_you_mean, or_list
    from framechain.suggest.facts import chain_files_beside

    known = set(transforms.parent.tolist()) | set(transforms.child.tolist())
    unknown = [n for n in dict.fromkeys((args.target, args.source)) if n not in known and n.lstrip("/") not in known]
    if not unknown:
        return
    where = "the log (no transform names it)" if args.chain is None else \
        f"the log (no transform names it) nor in the mounts or urdf of {args.chain}"
    parts = []
    for name in unknown:
        close = did_you_mean(name, known)
        parts.append(f"frame {name!r} does not exist in {where}" + (f"; did you mean {or_list(close)}?"
                                                                      if close else ""))
    text = f"{args.log}: {'; '.join(parts)}"
    if args.chain is None:
        beside = chain_files_beside(Path(args.log))
        text += f" (frames from a chain file's mounts: or urdf: need --chain {beside[0] if beside else 'CHAIN.yaml'})"
    raise FramechainError(text)


def _rpy_deg(quat_xyzw: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Fixed-axis roll, pitch, yaw in degrees (tf2's getRPY) of one quaternion (4,) or rows (N, 4)."""
    import numpy as np

    from framechain.geometry.rotations import quat_to_rpy

    out: npt.NDArray[np.float64] = np.degrees(quat_to_rpy(quat_xyzw.T).T)
    return out


def _record(result: LookupResult, i: int, log_start: int, sources: dict[str, str] | None = None) -> dict[str, Any]:
    stamp = int(result.times_ns[i])
    q = result.quat_xyzw[i]
    hops = []
    for h in result.hops:
        before, after = int(h.stamp_before_ns[i]), int(h.stamp_after_ns[i])
        hops.append({
            "parent": h.hop.parent, "child": h.hop.child, "static": h.hop.is_static, "inverse": h.hop.inverse,
            "stamps_ns": [before] if h.hop.is_static or before == after else [before, after],
            "weight": float(h.weight[i]), "source": (sources or {}).get(h.hop.child, ""),
        })
    # A path of static edges only is timeless (tf2 stamps it 0): say so rather than print a stamp.
    timeless = all(h.hop.is_static for h in result.hops)
    return {
        "target": result.target, "source": result.source, "timeless": timeless,
        "stamp_ns": None if timeless else stamp,
        "t_rel_s": None if timeless else (stamp - log_start) * 1e-9,
        "translation": [float(x) for x in result.translation[i]], "quat_xyzw": [float(x) for x in q],
        "rpy_deg": [float(x) for x in _rpy_deg(q)], "path": list(result.path.frames), "hops": hops,
    }


_CSV_HEADER = ["stamp_ns", "t_rel_s", "x", "y", "z", "qx", "qy", "qz", "qw", "roll_deg", "pitch_deg", "yaw_deg"]


def _csv_row(r: dict[str, Any]) -> list[Any]:
    stamp = ["", ""] if r["timeless"] else [r["stamp_ns"], f"{r['t_rel_s']:.9f}"]
    return [*stamp, *(repr(x) for x in r["translation"]),
            *(repr(x) for x in r["quat_xyzw"]), *(f"{x:.6f}" for x in r["rpy_deg"])]


def _series(args: argparse.Namespace, buffer: TransformBuffer, log_start: int) -> int:
    import numpy as np

    from framechain.errors import FramechainError
    from framechain.replay import ConnectivityError

    path = buffer.path(args.target, args.source)
    if not path.connected:
        raise ConnectivityError(path.problem)
    edges = buffer.edges
    dyn = [edges[h.child] for h in path.hops if not h.is_static]
    if dyn:
        times = np.unique(np.concatenate([e.stamps_ns for e in dyn]))
        first = max(e.first_ns for e in dyn)
        last = min(e.last_ns for e in dyn)
        times = times[(times >= first) & (times <= last)]
        if times.size == 0:
            spans = "; ".join(f"{e.parent} -> {e.child} {e.first_ns * 1e-9:.3f}..{e.last_ns * 1e-9:.3f} s" for e in dyn)
            raise FramechainError(
                f"the dynamic edges of {args.source} -> {args.target} never overlap in time ({spans})")
    else:
        times = np.array([0], dtype=np.int64)
    result = buffer.lookup(args.target, args.source, times)
    result.raise_for_status()
    t_rel = (result.times_ns - log_start) * 1e-9
    rpy = _rpy_deg(result.quat_xyzw)
    if args.json:
        print(json.dumps({
            "target": result.target, "source": result.source, "path": list(result.path.frames),
            "timeless": not dyn, "stamp_ns": None if not dyn else result.times_ns.tolist(),
            "translation": result.translation.tolist(),
            "quat_xyzw": result.quat_xyzw.tolist(), "rpy_deg": rpy.tolist(),
        }))
        return 0
    writer = csv.writer(sys.stdout)
    writer.writerow(_CSV_HEADER)
    for i in range(len(result)):
        stamp = [int(result.times_ns[i]), f"{t_rel[i]:.9f}"] if dyn else ["", ""]  # timeless: no stamp
        writer.writerow([*stamp, *(repr(float(x)) for x in result.translation[i]),
                         *(repr(float(x)) for x in result.quat_xyzw[i]), *(f"{x:.6f}" for x in rpy[i])])
    return 0


def _render(r: dict[str, Any], matrix: npt.NDArray[np.float64]) -> None:
    from rich.markup import escape
    from rich.table import Table

    from framechain.cli.common import stdout_console
    from framechain.timeline import format_stamp

    console = stdout_console()
    name = f"[bold]T_{escape(r['target'])}_{escape(r['source'])}[/]"
    if r["timeless"]:
        console.print(f"{name}: every edge of the path is static (timeless)")
    else:
        console.print(f"{name} at stamp {format_stamp(r['stamp_ns'])} s ({r['t_rel_s']:+.6f} s from the first stamp)")
    t, q, rpy = r["translation"], r["quat_xyzw"], r["rpy_deg"]
    console.print(f"- Translation: [{t[0]:.6f}, {t[1]:.6f}, {t[2]:.6f}]")
    console.print(f"- Rotation: in Quaternion (xyzw) [{q[0]:.6f}, {q[1]:.6f}, {q[2]:.6f}, {q[3]:.6f}]")
    console.print(f"            in RPY (degree) [{rpy[0]:.3f}, {rpy[1]:.3f}, {rpy[2]:.3f}]")
    console.print("- Matrix:")
    for row in matrix:
        console.print("  " + " ".join(f"{x:10.6f}" for x in row), highlight=False)
    console.print(f"- Path: {' -> '.join(escape(f) for f in r['path'])}")
    table = Table(title="Hops (samples used)", title_justify="left")
    for col in ("edge", "kind", "sample stamps (s)", "weight"):
        table.add_column(col)
    for h in r["hops"]:
        arrow = f"{h['child']} <- {h['parent']}" if h["inverse"] else f"{h['parent']} -> {h['child']}"
        kind = "static" if h["static"] else "dynamic"
        if h.get("source"):  # where the edge came from: a topic, or a chain file's mounts / urdf
            kind += f" ({h['source']})"
        stamps = ", ".join(format_stamp(s) for s in h["stamps_ns"])
        table.add_row(escape(arrow), kind, stamps, "-" if h["static"] else f"{h['weight']:.3f}")
    console.print(table)
