"""``framechain attribute DATASET --episodes all|SPEC``: a recording's episodes, its cameras fitted across them.

Each episode is one work unit of :func:`framechain.fleet.run_batch` (a process pool, resumable in
``OUT/results``); the recording-level fit (one link and one mount per camera, each episode's own
offset, the episodes that depart and why) is printed and written as ``OUT/recording.json`` and
``OUT/fleet_cameras.parquet``, beside the fleet table and report.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

if TYPE_CHECKING:
    from framechain.analysis.egomotion.recording import CameraRecordingFit
    from framechain.sinks.fleet_report import FleetLog

__all__ = ["attribute_recording"]


def attribute_recording(args: argparse.Namespace, out: Path, report_formats: list[str]) -> int:
    """Run the episodes, then say what was found: how many episodes came to what, why each that failed did,
    the episodes asked for that the dataset lacks, and each camera's fit across the episodes. A dataset that
    cannot run at all (no robot.yaml for an arm framechain does not know) is one error before any work; so is a
    run in which no episode could be analysed (exit 1); one in which some could exits 0, its failures said."""
    from framechain.cli.common import print_not_analysed, print_notes, print_recordings, stdout_console
    from framechain.fleet import run_batch
    from framechain.sinks.fleet_report import NOT_ANALYSED, fleet_logs
    from framechain.timeline import read_parquet

    result = run_batch([args.log], out, chain=args.chain, robot=args.robot, episodes=args.episodes,
                       jobs=args.jobs, seed=args.seed, bootstrap=args.bootstrap, report_formats=report_formats,
                       raise_input_problems=True, generated_robot_at=None if args.robot else out / "robot.yaml")
    _say_generated_robot(args, out, [int(r["episode"]) for r in result.records if r.get("episode") is not None])
    logs = fleet_logs(read_parquet(result.table_path))
    if all(log.status in NOT_ANALYSED for log in logs):
        _fail_with_every_reason(args.log, logs, result.notes)
    console = stdout_console(120)
    counts = ", ".join(f"{n} {status}" for status, n in sorted(result.status_counts().items()))
    episodes = len(result.records)
    console.print(f"[bold]{episodes} episode{'s' if episodes != 1 else ''}: {counts}.[/bold]")
    print_notes(console, result.notes)
    print_not_analysed(console, logs)
    if not result.recordings:
        console.print("No episode's cameras showed their link, mount or offset (not measured, or measured and not "
                      "observable: each episode's verdict in the fleet report says which): no recording-level fit.")
    print_recordings(console, result.recordings)
    if args.robot is None:
        _print_recording_fixes(console, result.recordings, out / "robot.yaml")
    for name, path in result.report_paths.items():
        print(f"{name}: {path}")
    print(f"fleet table: {result.table_path}")
    return 0


def _print_recording_fixes(console: Any, recordings: Mapping[str, Sequence[CameraRecordingFit]], robot_yaml: Path
                           ) -> None:
    """One fix per camera placed from its images: the recording's mount, position, focal length and offset, to set
    in the robot.yaml made for it (each episode's own fixes differ a little)."""
    from framechain.sinks.fleet_cameras import recording_fix

    for fits in recordings.values():
        for fit in fits:
            if fix := recording_fix(fit, str(robot_yaml)):
                console.print(f"fix (camera {fit.camera}, recording): {fix}", markup=False, highlight=False,
                              soft_wrap=True)


def _say_generated_robot(args: argparse.Namespace, out: Path, episodes: list[int]) -> None:
    """A known arm run without robot.yaml: the robot.yaml made from the first episode run, written to ``out`` and
    said in one line on stderr (even with --quiet), as attribute of one episode does (each episode guessed its own).
    Nothing for a folder that is not one dataset, or one whose first episode cannot be read (its error is said)."""
    from framechain.adapters import LeRobotAdapter
    from framechain.cli.common import tell_generated_robot
    from framechain.errors import FramechainError
    from framechain.suggest.lerobot import generated_robot

    if args.robot is not None or args.chain is not None or not episodes or not LeRobotAdapter().probe(Path(args.log)):
        return
    try:
        generated = generated_robot(args.log, episode=min(episodes))
    except FramechainError:
        return
    if generated is None:
        return
    tell_generated_robot(generated, "attribute", out / "robot.yaml", args.log,
                         lead=f"made from episode {generated.episode}: ")


def _fail_with_every_reason(dataset: str, logs: list[FleetLog], notes: list[str]) -> NoReturn:
    """No episode was analysed: the error. One reason shared by every episode is the error line itself (as
    attribute of one episode says it); several are said first (on stderr, as batch says them), then the error."""
    from rich.console import Console

    from framechain.cli.common import print_not_analysed, print_notes
    from framechain.errors import FramechainError
    from framechain.sinks.fleet_report import not_analysed_reasons

    reasons = not_analysed_reasons(logs)
    stderr = Console(stderr=True, width=None if sys.stderr.isatty() else 120)
    print_notes(stderr, notes)
    if len(reasons) == 1:
        (reason,) = reasons
        which = reason.example + (f" and {reason.logs - 1} more" if reason.logs > 1 else "")
        raise FramechainError(f"{which}: {reason.reason}")
    print_not_analysed(stderr, logs, most=len(reasons))
    raise FramechainError(f"{dataset}: no episode could be analysed ({len(logs)} run; each one's reason above)")
