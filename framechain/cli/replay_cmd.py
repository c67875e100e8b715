"""``framechain replay``: replay a log's chain and stream it to Rerun (save, connect or spawn)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from framechain.timeline import ChainConfig, ChainFrames, FramechainError

if TYPE_CHECKING:
    from framechain.replay import ReplayResult
    from framechain.sinks.rerun import RerunOutcome, RerunTarget
    from framechain.timeline import Timeline

DESCRIPTION = """\
Replay every observation of LOG through the chain (pixel -> camera -> body -> world) and stream
it to Rerun: the frame tree over time, the camera as a pinhole with its depth frames and
detections, each hop's point recomputed and as the robot logged it, error arrows, per-hop error
and time-gap series, rejected observations and a summary, with a default layout.

LOG is a robot log (MCAP, ROS 1 bag, ROS 2 bag directory) or a saved Timeline directory.
Without --chain the chain is suggested from the log (as `framechain info` shows it).
Output: --save FILE.rrd (works without a viewer), --connect URL (a running viewer, e.g.
rerun+http://127.0.0.1:9876/proxy), or --spawn (a local viewer). Without an option the viewer
is spawned when a display is available, otherwise the recording is saved to ./<LOG name>.rrd.
--spawn without a display (DISPLAY and WAYLAND_DISPLAY unset) says so and saves instead.
"""

EPILOG = """\
exit codes:
  0    the replay was written (whatever it found)
  1    bad input: the log, the chain or the output could not be used (one line on stderr)
  2    usage error
"""


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "replay", help="replay the chain of a log and stream it to Rerun (.rrd, viewer)",
        description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("log", metavar="LOG", help="robot log, or a saved Timeline directory")
    parser.add_argument("--chain", metavar="CHAIN.yaml", help="chain configuration (default: suggested from LOG)")
    out = parser.add_mutually_exclusive_group()
    out.add_argument("--spawn", action="store_true", help="start a local Rerun viewer (falls back to saving)")
    out.add_argument("--connect", metavar="URL", help="send to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy")
    out.add_argument("--save", metavar="FILE.rrd", help="write a recording file (no viewer needed)")
    parser.add_argument("--quiet", "-q", action="store_true", help="print nothing but errors and notes")
    parser.add_argument("--json", action="store_true", help="print counts and the output as one JSON object")
    parser.set_defaults(run=run)


#: Message types a robot logs its own points (hop points, targets, references) with.
_POINT_TYPES = frozenset({"PointStamped", "PoseStamped"})


@dataclass(frozen=True)
class _Loaded:
    timeline: Timeline
    chain: ChainConfig
    source: str  # "timeline" or the adapter's format
    notes: tuple[str, ...] = ()


def run(args: argparse.Namespace) -> int:
    from framechain.replay import replay
    from framechain.sinks.rerun import RerunOptions, RerunTarget, display_available, stream_replay

    path = Path(args.log)
    loaded = _load(path, args.chain, quiet=args.quiet or args.json)
    result = replay(loaded.timeline, loaded.chain.frames, latency_budget_s=loaded.chain.latency_budget_s)
    default_file = Path.cwd() / f"{_log_name(path)}.rrd"
    target: RerunTarget
    if args.save:
        target = RerunTarget.save(args.save)
    elif args.connect:
        target = RerunTarget.connect(args.connect)
    elif args.spawn or display_available():
        target = RerunTarget.spawn(default_file)
    else:
        target = RerunTarget.save(default_file)
    outcome = stream_replay(
        loaded.timeline, result, target, reference_point=loaded.chain.evidence.reference_point,
        options=RerunOptions(recording_name=path.name),
        notify=lambda msg: print(f"framechain replay: {msg}", file=sys.stderr),
    )
    if args.json:
        print(json.dumps(_report(path, loaded, result, outcome)))
    elif not args.quiet:
        _print_text(path, loaded, result, outcome)
    return 0


def _log_name(path: Path) -> str:
    name = path.resolve().name or "framechain"
    return name.removesuffix(path.suffix) if path.is_file() else name


def _load(path: Path, chain_path: str | None, *, quiet: bool) -> _Loaded:
    from framechain.timeline import Timeline

    chain = ChainConfig.from_yaml(chain_path) if chain_path else None
    if not path.exists():
        raise FramechainError(f"{path}: no such file or directory")
    if path.is_dir() and (path / "timeline.json").is_file():
        timeline = Timeline.load(path)
        return _Loaded(timeline, chain or _chain_for_timeline(timeline), "timeline")
    from framechain.adapters import open_log, suggest_chain

    loaded = open_log(path, chain, progress=not quiet)
    timeline = loaded.timeline
    notes = list(loaded.info.notes)
    if chain is None:
        chain = suggest_chain(loaded)
        # Without a chain the log does not say which topic holds which hop's point: leave them out.
        timeline = timeline.replace(points=type(timeline.points).empty())
        topics = sorted(t.name for t in loaded.info.topics
                        if t.msgtype.rsplit("/", 1)[-1] in _POINT_TYPES and t.name not in chain.evidence_topics())
        if topics:
            notes.append(f"point topics {', '.join(topics)} not used as evidence: name their roles "
                         "(evidence: hops, target, reference) in CHAIN.yaml and pass --chain")
    return _Loaded(timeline, chain, loaded.info.format, tuple(notes))


def _chain_for_timeline(timeline: Timeline) -> ChainConfig:
    """A saved Timeline's own chain (``metadata["chain"]``), else frames guessed from its tables."""
    import numpy as np

    raw = timeline.metadata.get("chain")
    if isinstance(raw, Mapping):
        return ChainConfig.from_dict(raw, where="timeline metadata chain")
    frames = set(timeline.transforms.parent.tolist()) | set(timeline.transforms.child.tolist())
    cameras = timeline.observations.camera_frame
    if cameras.size:
        names, counts = np.unique(cameras, return_counts=True)
        camera = str(names[int(np.argmax(counts))])
    elif len(timeline.cameras):
        camera = str(timeline.cameras.frame[0])
    else:
        camera = ChainFrames().camera
    body = next((b for b in ("base_link", "base_footprint") if b in frames), ChainFrames().body)
    world = next((w for w in ("map", "odom") if w in frames), ChainFrames().world)
    return ChainConfig(frames=ChainFrames(camera=camera, body=body, world=world))


def _report(path: Path, loaded: _Loaded, result: ReplayResult, outcome: RerunOutcome) -> dict[str, Any]:
    frames = loaded.chain.frames
    return {
        "log": str(path),
        "source": loaded.source,
        "frames": {"camera": frames.camera, "body": frames.body, "world": frames.world},
        "latency_budget_s": loaded.chain.latency_budget_s,
        "counts": result.counts(),
        "output": {
            "mode": outcome.mode.value, "path": None if outcome.path is None else str(outcome.path),
            "url": outcome.url, "fell_back": outcome.fell_back,
        },
        "notes": [*loaded.notes, *outcome.notes],
        "entities": dict(outcome.rows),
    }


def _print_text(path: Path, loaded: _Loaded, result: ReplayResult, outcome: RerunOutcome) -> None:
    frames = loaded.chain.frames
    counts = result.counts()
    rejected = counts["rejected"]
    assert isinstance(rejected, dict)
    n_rejected = sum(rejected.values())
    detail = ", ".join(f"{reason} {n}" for reason, n in sorted(rejected.items()))
    print(f"log           {path} ({loaded.source})")
    print(f"chain         {frames.camera} -> {frames.body} -> {frames.world} "
          f"(latency budget {loaded.chain.latency_budget_s * 1e3:g} ms)")
    line = f"observations  {counts['total']} total, {counts['replayed']} replayed, {n_rejected} rejected"
    if detail:
        line += f" ({detail})"
    line += f", {counts['stale']} stale"
    print(line)
    for note in loaded.notes:
        print(f"note          {note}")
    if outcome.path is not None:
        print(f"rerun         saved {outcome.path} (open with: rerun {outcome.path})")
    elif outcome.mode.value == "connect":
        print(f"rerun         sent to {outcome.url or 'the default viewer'}")
    else:
        print("rerun         sent to a spawned viewer")
