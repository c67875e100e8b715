"""``framechain replay``: replay a log's chain and stream it to Rerun (save, connect or spawn)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from framechain.cli.common import (
    add_log_arguments,
    chain_text,
    imports_set_aside,
    incomplete_chain_line,
    print_suggested_chain,
    progress_reporter,
    say_generated_robot,
    say_unattributed,
    warner,
)

if TYPE_CHECKING:
    from framechain.analysis.run import Run
    from framechain.sinks.rerun import RerunOutcome, RerunTarget

DESCRIPTION = """\
Replay every observation of LOG through the chain (pixel -> camera -> body -> world) and stream
it to Rerun: the frame tree over time, the camera as a pinhole with its depth frames and
detections, each hop's point recomputed and as the robot logged it, error arrows, per-hop error
and time-gap series, rejected observations, the findings of `framechain attribute` and a
summary, in a default layout (--no-attribute skips the fit and logs the replay alone).

Output: --save FILE.rrd (no viewer needed), --connect URL (a running viewer, e.g.
rerun+http://127.0.0.1:9876/proxy), or --spawn (a local viewer). Without one of them the viewer
is spawned when a display is available, otherwise the recording is saved to ./<LOG name>.rrd.
--spawn without a display (DISPLAY and WAYLAND_DISPLAY unset) says so on stderr and saves.
"""

EPILOG = """\
exit codes:
  0    the recording was written (whatever the replay found; when no observation could be
       replayed, one line on stderr says why and which chain key to add)
  1    bad input: the log, the chain or the output could not be used, or the log has no
       observation to replay (one line on stderr says why and what to add)
  2    usage error
"""

#: Message types a robot logs its own points (hop points, targets, references) with.
_POINT_TYPES = frozenset({"PointStamped", "PoseStamped"})


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "replay", help="replay the chain of a log and stream it to Rerun (.rrd, viewer)",
        description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_log_arguments(parser)
    out = parser.add_mutually_exclusive_group()
    out.add_argument("--spawn", action="store_true", help="start a local Rerun viewer (saves when there is no display)")
    out.add_argument("--connect", metavar="URL", help="send to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy")
    out.add_argument("--save", metavar="FILE.rrd", help="write a recording file (no viewer needed)")
    parser.add_argument("--attribute", action=argparse.BooleanOptionalAction, default=True,
                        help="attribute the error and log the findings (default: on)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed of the attribution (default 0)")
    parser.add_argument("--max-images", type=int, default=30, metavar="N",
                        help="depth frames logged at most, nearest the observations (default 30)")
    parser.add_argument("--images", choices=("near", "all", "none"), default="near",
                        help="camera images logged: those nearest the observations (default), all, or none")
    parser.add_argument("--json", action="store_true", help="print counts and the output as one JSON object")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from framechain import pipeline
    from framechain.sinks.overlay import ImageSelection
    from framechain.sinks.rerun import RerunOptions, stream_replay

    quiet = args.quiet or args.json
    with imports_set_aside(), progress_reporter(quiet, "replaying") as progress:
        made = pipeline.run(args.log, args.chain, episode=args.episode, robot=args.robot, attribute=args.attribute,
                            seed=args.seed, progress=progress, warn=warner("replay"))
        notes = list(made.notes)
        if made.chain_suggested and made.info is not None:
            notes.extend(_unused_point_topics(made))
        # The recording is still written without findings, or with nothing replayed: the frame tree, the
        # cameras and any rejected observations are worth looking at.
        notes.extend(say_unattributed(made, "replay"))
        if made.attribution is not None:
            notes.extend(n for n in made.attribution.notes if n not in notes)
        if progress is not None:
            progress("writing the Rerun recording")
        outcome = stream_replay(
            made, _target(args, made.path),
            options=RerunOptions(recording_name=made.path.name, max_images=args.max_images,
                                 images=ImageSelection(args.images)),
            notify=lambda msg: print(f"framechain replay: {msg}", file=sys.stderr),
        )
    say_generated_robot(made, "replay", None if outcome.path is None else Path(outcome.path).with_suffix(".robot.yaml"))
    if made.chain_suggested:
        print_suggested_chain(made.suggestion or made.chain, quiet, args.log)
    if args.json:
        print(json.dumps(_report(made, outcome, notes)))
    else:  # --quiet silences progress and the suggested chain, not the result
        _print_text(made, outcome, notes)
    return 0


def _target(args: argparse.Namespace, log: Path) -> RerunTarget:
    from framechain.sinks.rerun import RerunTarget, display_available

    default_file = Path.cwd() / f"{_log_name(log)}.rrd"
    if args.save:
        return RerunTarget.save(args.save)
    if args.connect:
        return RerunTarget.connect(args.connect)
    if args.spawn or display_available():
        return RerunTarget.spawn(default_file)
    return RerunTarget.save(default_file)


def _log_name(path: Path) -> str:
    name = path.resolve().name or "framechain"
    return name.removesuffix(path.suffix) if path.is_file() else name


def _unused_point_topics(loaded: Run) -> list[str]:
    """Without a chain the log does not say which topic holds which hop's point: say so."""
    topics = sorted(t.name for t in (loaded.info.topics if loaded.info is not None else ())
                    if str(t.msgtype).rsplit("/", 1)[-1] in _POINT_TYPES
                    and t.name not in loaded.chain.evidence_topics())
    if not topics:
        return []
    return [f"point topics {', '.join(topics)} not used as evidence: name their roles "
            "(evidence: hops, target, reference) in CHAIN.yaml and pass --chain"]


def _source(loaded: Run) -> str:
    """The log's format, or ``timeline`` for a saved timeline."""
    return loaded.info.format if loaded.info is not None else "timeline"


def _report(loaded: Run, outcome: RerunOutcome, notes: list[str]) -> dict[str, Any]:
    from framechain.sinks.text import FindingView

    frames = loaded.chain.frames
    suggestion = loaded.suggestion if loaded.chain_suggested else None
    return {
        "log": str(loaded.path),
        "source": _source(loaded),
        "frames": {"camera": frames.camera, "body": frames.body, "world": frames.world},
        "chain_suggested": loaded.chain_suggested,
        "placeholders": sorted(suggestion.placeholders) if suggestion is not None else [],
        "chain_incomplete": incomplete_chain_line(loaded),
        "latency_budget_s": loaded.chain.latency_budget_s,
        "counts": loaded.replay.counts(),
        "findings": [FindingView.of(f).text() for f in loaded.findings],
        "output": {
            "mode": outcome.mode.value, "path": None if outcome.path is None else str(outcome.path),
            "url": outcome.url, "fell_back": outcome.fell_back,
        },
        "notes": [*notes, *outcome.notes],
        "entities": dict(outcome.rows),
    }


def _print_text(loaded: Run, outcome: RerunOutcome, notes: list[str]) -> None:
    from framechain.sinks.text import FindingView, measured_instead

    findings = loaded.findings
    counts = loaded.replay.counts()
    rejected = counts["rejected"]
    assert isinstance(rejected, dict)
    detail = ", ".join(f"{reason} {n}" for reason, n in sorted(rejected.items()))
    print(f"log           {loaded.path} ({_source(loaded)})")
    suggested = "suggested; " if loaded.chain_suggested else ""
    print(f"chain         {chain_text(loaded)} ({suggested}latency budget {loaded.chain.latency_budget_s * 1e3:g} ms)")
    incomplete = incomplete_chain_line(loaded)
    if incomplete is not None:
        print(f"note          {incomplete}")
    line = f"observations  {counts['total']} total, {counts['replayed']} replayed, {sum(rejected.values())} rejected"
    if detail:
        line += f" ({detail})"
    instead = measured_instead(loaded.attribution)
    print(f"observations  {instead}" if instead else f"{line}, {counts['stale']} stale")
    for note in notes:
        print(f"note          {note}")
    if loaded.attribution is not None:  # the findings and what the log could not show
        print(f"verdict       {loaded.attribution.verdict}")
    for i, finding in enumerate(findings, start=1):
        print(f"finding {i}     {FindingView.of(finding).headline()}")
    if findings:
        print("              (evidence and fixes: `framechain attribute`, or the text log in the viewer)")
    if outcome.path is not None:
        print(f"rerun         saved {outcome.path} (open with: rerun {outcome.path})")
    elif outcome.url is not None:
        print(f"rerun         sent to {outcome.url}")
    else:
        print("rerun         sent to a spawned viewer")
