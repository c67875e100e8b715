"""``framechain replay``: replay a log's chain and stream it to Rerun (save, connect or spawn)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from framechain.cli.common import add_log_arguments, print_suggested_chain, progress_reporter

if TYPE_CHECKING:
    from framechain.analysis.alignment import AlignedEvidence
    from framechain.analysis.attribute import Finding
    from framechain.pipeline import LoadedRun
    from framechain.replay import ReplayResult
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
    from framechain.pipeline import load_log
    from framechain.replay import replay
    from framechain.sinks.overlay import ImageSelection
    from framechain.sinks.rerun import RerunOptions, stream_replay

    quiet = args.quiet or args.json
    findings: Sequence[Finding] = ()
    evidence: AlignedEvidence | None = None
    with progress_reporter(quiet, "replaying") as progress:
        loaded = load_log(args.log, args.chain, episode=args.episode, robot=args.robot, progress=not quiet)
        notes = list(loaded.notes)
        timeline = loaded.timeline
        if loaded.chain_suggested and loaded.info is not None:
            notes.extend(_unused_point_topics(loaded))
        result = replay(timeline, loaded.chain.frames, latency_budget_s=loaded.chain.latency_budget_s,
                        ignore_labels=loaded.chain.evidence.ignore_labels)
        # A bearing-only static target replays nothing on its own (no depth): attribute replays its rays.
        bearing_only = loaded.chain.evidence.static_target and not result.replayed.any()
        if args.attribute and (result.replayed.any() or bearing_only):
            from framechain.analysis.attribute import attribute
            from framechain.analysis.static import StaticTargetError
            from framechain.timeline import FramechainError

            try:
                attribution = attribute(timeline, loaded.chain, seed=args.seed, progress=progress)
            except FramechainError as err:  # the replay is still worth recording: say why there are no findings
                # With nothing replayed the line below says what is missing, unless rays were replayed.
                if result.replayed.any() or isinstance(err.__cause__, StaticTargetError):
                    print(f"framechain replay: not attributed: {err}", file=sys.stderr)
                    notes.append(f"not attributed: {err}")
            else:
                result, findings, evidence = attribution.replay, attribution.findings, attribution.aligned
                notes.extend(n for n in attribution.notes if n not in notes)
        why = loaded.why_nothing_replayed(result.counts())
        if why is not None:
            # Still write the recording: the frame tree, the cameras and any rejected observations
            # are worth looking at; say why nothing was replayed and what to add.
            print(f"framechain replay: {why}", file=sys.stderr)
        if progress is not None:
            progress("writing the Rerun recording")
        outcome = stream_replay(
            timeline, result, _target(args, loaded.path), findings=findings, evidence=evidence,
            reference_point=loaded.chain.evidence.reference_point,
            options=RerunOptions(recording_name=loaded.path.name, max_images=args.max_images,
                                 images=ImageSelection(args.images)),
            notify=lambda msg: print(f"framechain replay: {msg}", file=sys.stderr),
        )
    if loaded.chain_suggested:
        print_suggested_chain(loaded.suggestion or loaded.chain, quiet)
    if args.json:
        print(json.dumps(_report(loaded, result, outcome, notes, findings)))
    else:  # --quiet silences progress and the suggested chain, not the result
        _print_text(loaded, result, outcome, notes, findings)
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


def _unused_point_topics(loaded: LoadedRun) -> list[str]:
    """Without a chain the log does not say which topic holds which hop's point: say so."""
    topics = sorted(t.name for t in getattr(loaded.info, "topics", ())
                    if str(t.msgtype).rsplit("/", 1)[-1] in _POINT_TYPES
                    and t.name not in loaded.chain.evidence_topics())
    if not topics:
        return []
    return [f"point topics {', '.join(topics)} not used as evidence: name their roles "
            "(evidence: hops, target, reference) in CHAIN.yaml and pass --chain"]


def _report(
    loaded: LoadedRun, result: ReplayResult, outcome: RerunOutcome, notes: list[str], findings: Sequence[Finding]
) -> dict[str, Any]:
    from framechain.sinks.rerun import FindingView

    frames = loaded.chain.frames
    return {
        "log": str(loaded.path),
        "source": str(getattr(loaded.info, "format", "timeline")),
        "frames": {"camera": frames.camera, "body": frames.body, "world": frames.world},
        "chain_suggested": loaded.chain_suggested,
        "latency_budget_s": loaded.chain.latency_budget_s,
        "counts": result.counts(),
        "findings": [FindingView.of(f).text() for f in findings],
        "output": {
            "mode": outcome.mode.value, "path": None if outcome.path is None else str(outcome.path),
            "url": outcome.url, "fell_back": outcome.fell_back,
        },
        "notes": [*notes, *outcome.notes],
        "entities": dict(outcome.rows),
    }


def _print_text(
    loaded: LoadedRun, result: ReplayResult, outcome: RerunOutcome, notes: list[str], findings: Sequence[Finding]
) -> None:
    from framechain.sinks.rerun import FindingView

    frames = loaded.chain.frames
    counts = result.counts()
    rejected = counts["rejected"]
    assert isinstance(rejected, dict)
    detail = ", ".join(f"{reason} {n}" for reason, n in sorted(rejected.items()))
    source = getattr(loaded.info, "format", "timeline")
    print(f"log           {loaded.path} ({source})")
    print(f"chain         {frames.camera} -> {frames.body} -> {frames.world} "
          f"(latency budget {loaded.chain.latency_budget_s * 1e3:g} ms)")
    line = f"observations  {counts['total']} total, {counts['replayed']} replayed, {sum(rejected.values())} rejected"
    if detail:
        line += f" ({detail})"
    print(f"{line}, {counts['stale']} stale")
    for note in notes:
        print(f"note          {note}")
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
