"""Options and rendering shared by the commands that read a log."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from framechain.analysis.run import Run


def add_log_arguments(parser: argparse.ArgumentParser) -> None:
    """LOG, --chain, and the LeRobot options, the same for every command that reads a log."""
    parser.add_argument(
        "log",
        metavar="LOG",
        help="MCAP file, ROS 1 .bag, ROS 2 bag directory (or bare .db3/.mcap), LeRobot dataset "
        "directory, or a saved timeline directory",
    )
    parser.add_argument(
        "--chain",
        metavar="CHAIN.yaml",
        help="chain configuration (frames, topics, evidence, calibration, mounts); default: the one "
        "`framechain info LOG --chain` suggests, printed (`framechain info LOG` lists what the log lacks)",
    )
    parser.add_argument("--episode", type=int, metavar="N", help="LeRobot datasets: the episode index")
    parser.add_argument("--robot", metavar="ROBOT.yaml", help="LeRobot datasets: URDF, joint mapping and cameras")
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="no progress output and no suggested chain (results are still printed)")


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


def make_out_dir(out: Path) -> None:
    """Create ``--out``; a path that exists and is not a directory is a user mistake, said in one line."""
    from framechain.timeline import FramechainError

    if out.exists() and not out.is_dir():
        raise FramechainError(f"--out {out}: exists and is not a directory (give a directory for the outputs)")
    out.mkdir(parents=True, exist_ok=True)


@contextmanager
def progress_reporter(quiet: bool, label: str) -> Iterator[Callable[[str], None] | None]:
    """A rich status line on stderr that follows the analysis steps (None when quiet)."""
    if quiet or not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console

    console = Console(stderr=True)
    with console.status(label) as status:
        yield lambda message: status.update(f"{label}: {message}")


def print_suggested_chain(chain: Any, quiet: bool) -> None:
    """Say which configuration was used when none was given (stderr, so --json stays clean).

    ``chain``: the SuggestedChain (its YAML marks the frames the log lacks) or a ChainConfig."""
    if quiet:
        return
    from rich.console import Console

    console = Console(stderr=True)
    console.print("[dim]no --chain given; using the suggested configuration (edit it and pass --chain):[/dim]")
    console.print(chain.to_yaml().rstrip(), markup=False, highlight=False)


def say_unattributed(run: Run, command: str) -> list[str]:
    """Say on stderr why a replayed run has no findings, and why nothing was replayed (with the chain key to
    add); the outputs are still written. Returns the note to record beside them."""
    from framechain.analysis.findings import Unattributed

    # Reasons the user hears otherwise: asked for none, or why nothing replayed (below).
    said_elsewhere = {Unattributed.NOT_ASKED, Unattributed.NO_DETECTIONS, Unattributed.NOTHING_REPLAYED}
    notes = []
    why = run.not_attributed
    if why is not None and why.reason not in said_elsewhere:
        print(f"framechain {command}: not attributed: {why.detail}", file=sys.stderr)
        notes.append(f"not attributed: {why.detail}")
    if run.nothing_replayed is not None:
        print(f"framechain {command}: {run.nothing_replayed}", file=sys.stderr)
    return notes


def print_findings(result: Any) -> None:
    """The verdict, the counts, the findings, the per-hop summary, the fixes and the notes, with rich."""
    from rich.console import Console
    from rich.table import Table

    from framechain.sinks.report import HOP_COLUMNS, hop_rows
    from framechain.sinks.text import FindingView

    console = Console(width=None if sys.stdout.isatty() else 120)  # piped output keeps the table readable
    console.print(f"[bold]{result.verdict}[/bold]")
    counts = result.counts()
    console.print(
        f"observations: {counts['total']} total, {counts['replayed']} replayed, "
        f"rejected {counts['rejected'] or 'none'}, {counts['stale']} stale"
    )
    if result.findings:
        table = Table()
        cameras = any(f.camera for f in result.findings)
        for col in ("#", "fault", "hop", *(("camera",) if cameras else ()), "estimate", "95% interval", "share",
                    "confidence"):
            table.add_column(col, overflow="fold")
        for i, f in enumerate(result.findings, start=1):
            c = FindingView.of(f).cells()
            table.add_row(str(i), c.fault, c.hop, *((c.camera,) if cameras else ()), c.estimate, c.interval, c.share,
                          c.confidence)
        console.print(table)
    hops = Table()
    for col in HOP_COLUMNS:
        hops.add_column(col, overflow="fold")
    for row in hop_rows(result):
        hops.add_row(*row)
    console.print(hops)
    for i, f in enumerate(result.findings, start=1):
        on = f" (camera {f.camera})" if f.camera else ""
        console.print(f"fix {i}{on}: {f.fix}", markup=False, highlight=False, soft_wrap=True)
    for note in result.notes:
        console.print(f"note: {note}", markup=False, highlight=False, soft_wrap=True)
