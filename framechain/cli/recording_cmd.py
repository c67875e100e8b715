"""``framechain attribute DATASET --episodes all|SPEC``: a recording's episodes, its cameras fitted across them.

Each episode is one work unit of :func:`framechain.fleet.run_batch` (a process pool, resumable in
``OUT/results``); the recording-level fit (one link and one mount per camera, each episode's own
offset, the episodes that depart and why) is printed and written as ``OUT/recording.json`` and
``OUT/fleet_cameras.parquet``, beside the fleet table and report.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["attribute_recording"]


def attribute_recording(args: argparse.Namespace, out: Path, report_formats: list[str]) -> int:
    from rich.console import Console

    from framechain.fleet import run_batch
    from framechain.sinks.fleet_cameras import camera_summary

    result = run_batch([args.log], out, chain=args.chain, robot=args.robot, episodes=args.episodes,
                       jobs=args.jobs, seed=args.seed, bootstrap=args.bootstrap, report_formats=report_formats)
    console = Console(width=None if console_is_terminal() else 120)
    counts = ", ".join(f"{n} {status}" for status, n in sorted(result.status_counts().items()))
    console.print(f"[bold]{len(result.records)} episodes: {counts}.[/bold]")
    if not result.recordings:
        console.print("No camera's own motion was measured in any episode: no recording-level fit.")
    for log, fits in result.recordings.items():
        for fit in fits:
            console.print(camera_summary(log, fit), markup=False, highlight=False, soft_wrap=True)
            for departure in fit.departures:
                console.print(f"  episode {departure.episode}: {departure.why}", markup=False, highlight=False,
                              soft_wrap=True)
    for name, path in result.report_paths.items():
        print(f"{name}: {path}")
    print(f"fleet table: {result.table_path}")
    return 0


def console_is_terminal() -> bool:
    import sys

    return sys.stdout.isatty()
