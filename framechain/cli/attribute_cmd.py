"""``framechain attribute``: name the hop, the fault, its size and the fix."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from framechain.cli.common import (
    add_log_arguments,
    imports_set_aside,
    make_out_dir,
    non_negative_int,
    positive_int,
    print_findings,
    print_suggested_chain,
    progress_reporter,
    say_generated_robot,
    warner,
)

if TYPE_CHECKING:
    from framechain.analysis.run import Run
    from framechain.analysis.verdict.findings import Attribution

FORMATS = ("json", "md", "html")


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "attribute",
        help="which hop, which fault, how big, and the fix",
        description="Replay LOG, pick the best evidence present (logged hops, target, reference, static target), "
        "fit the fault catalogue and write DIR/attribution.json, evidence.parquet, inputs.json and reports. "
        "Exit 0 when the log could be analysed, whatever was found.",
    )
    add_log_arguments(parser, episodes_help="LeRobot datasets: attribute these episodes (all, or e.g. 0-9,20) and fit "
                      "each camera's link and mount across them; writes DIR/recording.json, fleet_cameras.parquet, "
                      "the fleet table and report, one result per episode in DIR/results")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--format", default="json,md,html", help="comma-separated: json, md, html (default: all)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    parser.add_argument("--bootstrap", type=non_negative_int, default=30,
                        help="bootstrap resamples for intervals, 0 for none (default 30)")
    parser.add_argument("--json", action="store_true", help="print attribution.json to stdout")
    parser.add_argument("--jobs", "-j", type=positive_int, metavar="N",
                        help="with --episodes: worker processes (default: the CPU count)")
    parser.set_defaults(run=run)


def _attribute(args: argparse.Namespace, out: Path, report_formats: list[str]
               ) -> tuple[Run, Attribution, dict[str, Path]]:
    from framechain import pipeline
    from framechain.sinks.evidence_files import write_attribution
    from framechain.sinks.plots import start_renderers

    with imports_set_aside(), progress_reporter(args.quiet or args.json, "attributing") as progress:
        made = pipeline.run(args.log, args.chain, episode=args.episode, robot=args.robot, seed=args.seed,
                            bootstrap=args.bootstrap, progress=progress,
                            warn=warner(getattr(args, "command", None) or "attribute"), when_read=start_renderers,
                            generated_robot_at=out / "robot.yaml")
        say_generated_robot(made, getattr(args, "command", None) or "attribute", out / "robot.yaml")
        result = made.attributed()  # none: one line saying why, exit 1
        if progress is not None:
            progress("writing the outputs")
        if report_formats:
            from framechain.sinks.report import write_outputs

            paths = write_outputs(made, out, formats=report_formats, say=progress or (lambda _m: None))
        else:
            paths = write_attribution(made, out)
    return made, result, paths


def parse_formats(text: str) -> list[str]:
    from framechain.errors import FramechainError

    formats = [f.strip() for f in text.split(",") if f.strip()]
    unknown = sorted(set(formats) - set(FORMATS))
    if unknown or not formats:
        raise FramechainError(f"--format: unknown {unknown or text!r}; choose from {', '.join(FORMATS)}")
    return formats


def run(args: argparse.Namespace, *, default_formats: list[str] | None = None) -> int:
    from framechain.sinks.plots import EPISODE_RENDERERS, RENDERERS, renderers

    formats = default_formats or parse_formats(args.format)
    out = Path(args.out)
    make_out_dir(out)  # fail on an unusable --out before the analysis, not after
    report_formats = [f for f in formats if f in ("md", "html")]
    if getattr(args, "episodes", False) is not False:
        from framechain.cli.recording_cmd import attribute_recording

        return attribute_recording(args, out, report_formats)
    # Started once a log is read (start_renderers): they load matplotlib while this process replays and attributes on
    # one core; during the read they would compete with its two threads. A LeRobot episode's read is one thread
    # (Parquet rows, a URDF) and its cameras' measurement after it takes both cores: its renderer starts at once, on
    # the core the read leaves idle (a generated two-camera episode: 7% less wall time, a one-camera one 5%), and
    # forks a twin for its few figures (EPISODE_RENDERERS). The test is dataset_info.is_lerobot_dataset's, made here:
    # importing the adapters takes 0.3 s of that core, which the renderer loads matplotlib on meanwhile (the same
    # episode: 4% less wall time than starting it after that import).
    early = (Path(args.log) / "meta" / "info.json").is_file()
    with renderers(None if report_formats else 0, start_now=early, usual=EPISODE_RENDERERS if early else RENDERERS,
                   twins=early):
        made, result, paths = _attribute(args, out, report_formats)
    if made.chain_suggested:
        print_suggested_chain(made.suggestion or made.chain, args.quiet or args.json, args.log)
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
        return 0
    print_findings(result)
    for name, path in paths.items():
        print(f"{name}: {path}")
    return 0
