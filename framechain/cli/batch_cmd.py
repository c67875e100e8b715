"""``framechain batch``: every log of a fleet (or episode of a LeRobot dataset) through attribute."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from framechain.cli.common import (
    PlainProgress,
    add_revision_argument,
    episode_set,
    make_out_dir,
    non_negative_int,
    positive_int,
)

EPILOG = """exit codes:
  0    the batch ran: every log has its row in DIR/fleet.parquet (a log that failed is a row with its error)
  1    bad input: no logs among the inputs (or none of --episodes in a dataset), the chain configuration,
       --robot or an option could not be used
  2    usage error: unknown command or option
  130  interrupted (a rerun resumes: finished logs are kept in DIR/results)
"""


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "batch",
        help="attribute a fleet of logs into one table and report",
        description="Attribute every log among INPUTS (files, ROS 2 bag directories, directories walked for "
        "logs, every episode of a LeRobot dataset) and write DIR/fleet.parquet (one row per log and finding), "
        "DIR/fleet_report.html and .md. Each log's record is kept in DIR/results; a rerun skips the logs "
        "already done (same path, size, mtime, chain and options).",
        epilog=EPILOG,
        formatter_class=_WrapProseKeepTables,
    )
    parser.add_argument("inputs", nargs="+", metavar="INPUT", help="log file, bag directory, LeRobot dataset (a folder "
                        "or a Hugging Face Hub id), or a directory of any of these")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory (results are resumed from it)")
    parser.add_argument("--chain", metavar="CHAIN.yaml",
                        help="chain configuration for the logs that have none beside them (<log name>.chain.yaml, "
                        "or chain.yaml / CHAIN.yaml in the log's folder, wins); default: each log's suggested chain")
    parser.add_argument("--robot", metavar="ROBOT.yaml", help="LeRobot datasets: URDF, joint mapping and cameras")
    parser.add_argument("--episodes", type=episode_set, metavar="SPEC",
                        help="LeRobot datasets: only these episodes, e.g. 0-9,20 (default: all)")
    add_revision_argument(parser)
    parser.add_argument("--jobs", "-j", type=positive_int, metavar="N",
                        help="worker processes (local; 1: in this process; default: the CPU count), or tasks "
                        "in flight (ray; default: twice the cluster's CPUs)")
    parser.add_argument("--engine", choices=("local", "ray"), default="local",
                        help="local: a process pool on this machine; ray: Ray tasks (pip install 'framechain[ray]')")
    parser.add_argument("--ray-address", metavar="ADDR",
                        help="Ray cluster to join (default: RAY_ADDRESS, else the cluster `ray start` left "
                        "running on this machine, else a new local instance)")
    parser.add_argument("--format", default="md,html", help="fleet report formats: md, html, none (default md,html)")
    parser.add_argument("--rrd", metavar="FILE.rrd", help="LeRobot datasets: a Rerun recording of each camera's offset "
                        "and mount across the episodes (departing episodes marked), and each episode's own recording "
                        "in FILE.rrd.episodes/ (open them together: rerun FILE.rrd FILE.rrd.episodes/*.rrd)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    parser.add_argument("--bootstrap", type=non_negative_int, default=30,
                        help="bootstrap resamples per log, 0 for none (default 30)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


class _WrapProseKeepTables(argparse.HelpFormatter):
    """Wrap the one-paragraph description; keep the exit-code table laid out in lines."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if "\n" in text.strip("\n"):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


def parse_report_formats(text: str) -> list[str]:
    from framechain.errors import FramechainError

    formats = [f.strip() for f in text.split(",") if f.strip()]
    if formats == ["none"]:
        return []
    unknown = sorted(set(formats) - {"md", "html"})
    if unknown or not formats:
        raise FramechainError(f"--format: unknown {unknown or text!r}; choose from md, html, none")
    return formats


def run(args: argparse.Namespace) -> int:
    from framechain.fleet import run_batch

    formats = parse_report_formats(args.format)
    out = Path(args.out)
    make_out_dir(out)
    with _progress(args.quiet) as (on_start, on_record):
        result = run_batch(
            args.inputs, out, chain=args.chain, robot=args.robot, episodes=args.episodes, jobs=args.jobs,
            engine=args.engine, ray_address=args.ray_address, seed=args.seed, bootstrap=args.bootstrap,
            report_formats=formats, on_start=on_start, on_record=on_record, rrd=args.rrd,
        )
    _print_summary(result)
    return 0


@contextmanager
def _progress(quiet: bool) -> Iterator[tuple[Callable[[int, int], None], Callable[[dict[str, Any]], None]]]:
    """A rich progress bar on stderr; plain lines at most every few seconds when stderr is not a terminal (a CI
    log); nothing when quiet."""
    if quiet:
        yield (lambda total, skipped: None), (lambda record: None)
        return
    if not sys.stderr.isatty():
        lines = PlainProgress("batch")
        counts = [0, 0]  # done, to do

        def start(total: int, skipped: int) -> None:
            counts[:] = [0, total - skipped]
            lines("attributing logs", 0, counts[1], "logs")

        def done(record: dict[str, Any]) -> None:
            counts[0] += 1
            lines("attributing logs", counts[0], counts[1], "logs")

        yield start, done
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    console = Console(stderr=True)
    progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                        TimeRemainingColumn(), TextColumn("[dim]{task.fields[last]}"), console=console)
    task = progress.add_task("attributing", total=None, last="")

    def on_start(total: int, skipped: int) -> None:
        if skipped:
            console.print(f"[dim]{skipped} of {total} logs already done in this --out; resuming[/dim]")
        progress.update(task, total=total - skipped)

    def on_record(record: dict[str, Any]) -> None:
        progress.update(task, advance=1, last=f"{Path(record['unit']).name}: {record['status']}")

    with progress:
        yield on_start, on_record


def _print_summary(result: Any) -> None:
    from rich.table import Table

    from framechain.cli.common import print_not_analysed, print_notes, print_recordings, stdout_console
    from framechain.sinks.fleet_report import chains_line, estimate_spread, fleet_logs, summary_line
    from framechain.timeline import read_parquet

    console = stdout_console(120)
    logs = fleet_logs(read_parquet(result.table_path))
    console.print(f"[bold]{summary_line(logs)}[/bold]", highlight=False)
    console.print(f"computed {result.computed}, kept from an earlier run {result.skipped}", highlight=False)
    console.print(chains_line(logs), markup=False, highlight=False, soft_wrap=True)
    print_notes(console, result.notes)
    spread = estimate_spread(logs)
    if spread:
        table = Table()
        for col in ("fault", "hop", "logs", "estimate (median log)", "p5 .. p95"):
            table.add_column(col)
        for row in spread:  # the texts of format_estimate and format_interval, as attribute prints them
            table.add_row(row.fault, row.hop, str(row.logs), row.median_text, row.p5_p95_text)
        console.print(table)
    print_not_analysed(console, logs)
    print_recordings(console, result.recordings)
    print(f"table: {result.table_path}")
    for name, path in result.report_paths.items():
        print(f"{name.removeprefix('fleet_')}: {path}")
