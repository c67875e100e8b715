"""Options and rendering shared by the commands that read a log."""

from __future__ import annotations

import argparse
import gc
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from framechain.analysis.egomotion.recording import CameraRecordingFit
    from framechain.analysis.run import ChainSuggestion, Run
    from framechain.config.chain import ChainConfig
    from framechain.config.robot import GeneratedRobot
    from framechain.progress import Progress
    from framechain.sinks.fleet_report import FleetLog


def add_log_arguments(parser: argparse.ArgumentParser, *, episodes_help: str | None = None) -> None:
    """LOG, --chain, and the LeRobot options, the same for every command that reads a log (with
    ``episodes_help``: --episodes too, see :func:`add_dataset_arguments`)."""
    parser.add_argument(
        "log",
        metavar="LOG",
        help="MCAP file, ROS 1 .bag, ROS 2 bag directory (or bare .db3/.mcap), LeRobot dataset "
        "directory or Hugging Face Hub id (lerobot/NAME), or a saved timeline directory",
    )
    parser.add_argument(
        "--chain",
        metavar="CHAIN.yaml",
        help="chain configuration (frames, topics, evidence, calibration, mounts); default: the one "
        "`framechain info LOG --chain` suggests, printed (`framechain info LOG` lists what the log lacks)",
    )
    add_dataset_arguments(parser, episodes_help=episodes_help)
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="no progress output and no suggested chain (results are still printed)")


def add_dataset_arguments(parser: argparse.ArgumentParser, *, episodes_help: str | None = None) -> None:
    """--episode, --robot and --revision: what a command reading one LeRobot episode takes; with ``episodes_help``
    also --episodes (all|SPEC), which argparse refuses beside --episode (one episode or many, not both)."""
    episode_options: argparse._ActionsContainer = parser
    if episodes_help is not None:
        episode_options = parser.add_mutually_exclusive_group()
    episode_options.add_argument("--episode", type=int, metavar="N", help="LeRobot datasets: the episode index")
    if episodes_help is not None:
        episode_options.add_argument("--episodes", type=episodes_or_all, default=False, metavar="all|SPEC",
                                     help=episodes_help)
    parser.add_argument("--robot", metavar="ROBOT.yaml", help="LeRobot datasets: URDF, joint mapping and cameras")
    add_revision_argument(parser)


def episode_set(text: str) -> frozenset[int]:
    """argparse type: ``0-9,20`` -> {0, ..., 9, 20}. A bad spec is named whole, with the part that is wrong."""
    out: set[int] = set()
    for part in (p.strip() for p in text.split(",")):
        try:
            if "-" in part.lstrip("-"):
                lo, hi = (int(x) for x in part.split("-", 1))
                if hi < lo or lo < 0:
                    raise ValueError
                out.update(range(lo, hi + 1))
            else:
                value = int(part)
                if value < 0:
                    raise ValueError
                out.add(value)
        except ValueError:
            wrong = f"{part!r} is no episode number or range" if part else "an empty part between commas"
            raise argparse.ArgumentTypeError(f"expected episode numbers like 0-9,20, got {text!r} ({wrong})") from None
    return frozenset(out)


def episodes_or_all(text: str) -> frozenset[int] | None:
    """argparse type: ``all`` (None: every episode) or an episode set (:func:`episode_set`)."""
    return None if text.strip() == "all" else episode_set(text)


def add_revision_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--revision", metavar="REV", help="a dataset named by its Hugging Face Hub id: the branch, "
                        "tag or commit (default: main)")


def resolve_datasets(args: argparse.Namespace) -> None:
    """A Hugging Face Hub id given as LOG (or as a batch INPUT) becomes its folder in the user's Hugging Face cache,
    fetched as far as the command needs (meta/, the asked episodes' data and videos); a path that exists stays
    as it is. The one place every command's dataset is resolved."""
    log, inputs = getattr(args, "log", None), getattr(args, "inputs", None)
    revision = getattr(args, "revision", None)
    if isinstance(log, str):
        episode, asked = getattr(args, "episode", None), getattr(args, "episodes", False)
        wanted: Sequence[int] | None = () if episode is None else (episode,)
        if isinstance(asked, frozenset) or asked is None:  # attribute --episodes: these episodes (None: all)
            wanted = None if asked is None else sorted(asked)
        args.log = _resolved(log, revision, wanted)
    elif isinstance(inputs, list):
        episodes = getattr(args, "episodes", None)
        args.inputs = [_resolved(item, revision, None if episodes is None else sorted(episodes)) for item in inputs]


def _resolved(spec: str, revision: str | None, episodes: Sequence[int] | None) -> str:
    if Path(spec).exists() and revision is None:  # the usual case, without loading the adapters
        return spec
    from framechain.adapters.lerobot.hub import resolve_dataset

    return str(resolve_dataset(spec, revision=revision, episodes=episodes))


@contextmanager
def imports_set_aside() -> Iterator[None]:
    """Around a command's run, once it has imported what it runs: the objects of those imports (about a
    million, with SciPy and pyarrow) are set aside from the garbage collector (``gc.freeze``), whose full
    collections, set off by the objects a read makes, would otherwise walk them all (counted by callgrind:
    0.1-0.16 billion instructions fewer on a read of the benchmark logs, a full collection or two). They are
    handed back after (``gc.unfreeze``), so a caller that runs commands in its own process (the tests) keeps
    its collector."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {value}")
    return value


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1 (a count of workers)."""
    value = non_negative_int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be 1 or more, got {value}")
    return value


def make_out_dir(out: Path) -> None:
    """Create ``--out``; a path that exists and is not a directory is a user mistake, said in one line."""
    from framechain.errors import FramechainError

    if out.exists() and not out.is_dir():
        raise FramechainError(f"--out {out}: exists and is not a directory (give a directory for the outputs)")
    out.mkdir(parents=True, exist_ok=True)


#: Plain progress lines (stderr not a terminal) come at most this often; FRAMECHAIN_PROGRESS_INTERVAL_S overrides.
PROGRESS_INTERVAL_S = 5.0


@contextmanager
def progress_reporter(quiet: bool, label: str) -> Iterator[Progress | None]:
    """Where a long run says how far it is (None when quiet): on a terminal a rich bar with counts, elapsed
    time and time left; otherwise (a CI log) a plain line on stderr at most every few seconds."""
    if quiet:
        yield None
        return
    if not sys.stderr.isatty():
        yield PlainProgress(label)
        return
    from rich.console import Console
    from rich.progress import BarColumn, SpinnerColumn, TextColumn, TimeElapsedColumn
    from rich.progress import Progress as Bar

    bar = Bar(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[count]}"),
              TimeElapsedColumn(), console=Console(stderr=True), transient=True)
    task = bar.add_task(label, total=None, count="")
    current: list[str | float] = ["", 0.0]  # the stage and when it began

    def report(stage: str, /, done: int | None = None, total: int | None = None, unit: str = "") -> None:
        now = time.monotonic()
        if current[0] != stage:  # a new stage: its own bar and clock
            current[:] = [stage, now]
            bar.reset(task, total=total or None, completed=done or 0, description=f"{label}: {stage}", count="")
        count = _how_far(done, total, unit, now - float(current[1])).lstrip()
        bar.update(task, total=total or None, completed=done or 0, count=count)

    with bar:
        yield report


class PlainProgress:
    """Progress as plain lines on stderr (``framechain: reading run.bag 45% (123,456 of 270,000 messages), 12 s
    left``), at most one every :data:`PROGRESS_INTERVAL_S`: readable in a CI log, never a flood. The first
    comes one interval into the run: a run shorter than that (or one that stops at once on bad input, whose
    error is one line) prints none."""

    def __init__(self, label: str, *, interval_s: float | None = None) -> None:
        self.label = label
        env = os.environ.get("FRAMECHAIN_PROGRESS_INTERVAL_S")
        self.interval_s = interval_s if interval_s is not None else float(env) if env else PROGRESS_INTERVAL_S
        self._last = time.monotonic() if self.interval_s > 0 else -math.inf
        self._stage = ""
        self._since = 0.0

    def __call__(self, stage: str, /, done: int | None = None, total: int | None = None, unit: str = "") -> None:
        now = time.monotonic()
        if stage != self._stage:
            self._stage, self._since = stage, now
        if now - self._last < self.interval_s:
            return
        self._last = now
        print(f"framechain: {stage}{_how_far(done, total, unit, now - self._since)}", file=sys.stderr, flush=True)


#: Counted steps of very unequal cost (a latency search against a fixed rotation): no time left is guessed.
_UNEVEN_UNITS = frozenset({"models"})


def _how_far(done: int | None, total: int | None, unit: str, elapsed_s: float) -> str:
    """`` 45% (123,456 of 270,000 messages), 12 s left`` ("" for a stage that does not count)."""
    if done is None or not total:
        return ""
    text = f" {100 * done // total}% ({done:,} of {total:,} {unit})".replace(" )", ")")
    if 0 < done < total and elapsed_s > 0 and unit not in _UNEVEN_UNITS:
        left = elapsed_s * (total - done) / done
        text += ", under 1 s left" if left < 1 else f", {left:.0f} s left" if left < 90 else \
            f", {left / 60:.0f} min left"
    return text


def stdout_console(width: int | None = None) -> Any:
    """A rich Console on stdout whose reader going away (``framechain tf ... | head -1``) ends the command quietly
    with exit 0, as :func:`framechain.cli.main.main` does for every command (rich's own handling exits 1 with no
    word). ``width`` when stdout is not a terminal (None: rich's default)."""
    from rich.console import Console

    class _Quiet(Console):
        def on_broken_pipe(self) -> None:
            raise BrokenPipeError  # main() redirects stdout and returns 0

    return _Quiet(width=None if sys.stdout.isatty() else width)


def print_suggested_chain(chain: ChainSuggestion | ChainConfig, quiet: bool, log: str | Path | None = None) -> None:
    """Say which configuration was used when none was given (stderr, so --json stays clean), first naming a chain
    file that lies beside ``log`` and was not used.

    ``chain``: the suggestion (its YAML marks the frames the log lacks) or a ChainConfig. The YAML is
    written as it is, never wrapped: a comment wrapped onto a new line would not be a comment when pasted."""
    if quiet:
        return
    from framechain.suggest import chain_files_beside

    beside = chain_files_beside(Path(log)) if log is not None else []
    if beside:
        print(f"no --chain given: {beside[0]} lies beside the log but is not used (pass --chain {beside[0]} to use "
              "it); using the suggested configuration:", file=sys.stderr)
    else:
        print("no --chain given; using the suggested configuration (edit it and pass --chain):", file=sys.stderr)
    print(chain.to_yaml().rstrip(), file=sys.stderr)


def say_generated_robot(run: Run, command: str, path: Path | None) -> None:
    """A dataset run without --robot on a known arm: write the robot.yaml it used to ``path`` (None: nowhere) and
    say, in one line on stderr (even with --quiet: it is what the results rest on), what it assumed."""
    if run.generated_robot is not None:
        tell_generated_robot(run.generated_robot, command, path, run.path)


def tell_generated_robot(generated: GeneratedRobot, command: str, path: Path | None, dataset: str | Path,
                         lead: str = "") -> None:
    """Write ``generated`` to ``path`` (None: nowhere) and say on stderr, in one line, what it assumed (``lead``
    first) and where it is to edit (or how ``info`` writes it)."""
    if path is not None:
        path.write_text(generated.text, encoding="utf-8")
        where = f"; wrote {path}: edit it and pass --robot {path}"
    else:
        where = f"; `framechain info {dataset} --episode {generated.episode} --chain > robot.yaml` writes it to edit"
    print(f"framechain {command}: no --robot given: {lead}{generated.line}{where}", file=sys.stderr)


def chain_text(run: Run) -> str:
    """The chain a run used, one line: its frames (a suggestion's placeholders marked FILL IN)."""
    frames = run.chain.frames
    if run.chain_suggested and run.suggestion is not None:
        return run.suggestion.frames_text()
    cameras = f"{{{', '.join(run.chain.camera_frames())}}}" if run.chain.is_rig else frames.camera
    world = frames.world if run.chain.has_pose else "(no pose)"
    return f"{cameras} -> {frames.body} -> {world}"


def incomplete_chain_line(run: Run) -> str | None:
    """When the run's chain was suggested and the log lacks pieces of it: one line saying so and what is missing."""
    if not run.chain_suggested or run.suggestion is None:
        return None
    return run.suggestion.incomplete_line()


def warner(command: str) -> Callable[[str], None]:
    """What disagrees before any fit (a calibration of another camera's topic), on stderr as soon as the log
    is read (``pipeline.run(warn=)``), before the findings that would measure it. Said even with --quiet; the
    notes of every output hold it too."""
    return lambda warning: print(f"framechain {command}: warning: {warning}", file=sys.stderr)


def say_unattributed(run: Run, command: str) -> list[str]:
    """Say on stderr why a replayed run has no findings, and why nothing was replayed (with the chain key to
    add); the outputs are still written. Returns the note to record beside them."""
    from framechain.analysis.verdict.findings import Unattributed

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


def print_notes(console: Any, notes: Sequence[str]) -> None:
    """What a batch left out and why (``note: ...``, one line each): files framechain wrote, episodes asked for
    that a dataset lacks. ``batch`` and ``attribute --episodes`` alike."""
    for note in notes:
        console.print(f"note: {note}", markup=False, highlight=False, soft_wrap=True)


def print_recordings(console: Any, recordings: Mapping[str, Sequence[CameraRecordingFit]]) -> None:
    """Each recording's cameras fitted across its episodes: one sentence per camera, then each departing episode and
    why. ``batch`` and ``attribute --episodes`` alike."""
    from framechain.sinks.fleet_cameras import camera_summary

    for log, fits in recordings.items():
        for fit in fits:
            console.print(camera_summary(log, fit), markup=False, highlight=False, soft_wrap=True)
            for departure in fit.departures:
                console.print(f"  episode {departure.episode}: {departure.why}", markup=False, highlight=False,
                              soft_wrap=True)


def print_not_analysed(console: Any, logs: Sequence[FleetLog], *, most: int = 3) -> None:
    """Why the logs (or episodes) of a batch that were not analysed were not: one line per reason, naming the
    first log that failed for it and how many more (``1 error (ds episode 1): ...mp4: cannot open video``), the
    ``most`` commonest reasons, then how many others the fleet report holds. ``batch`` and ``attribute
    --episodes`` alike."""
    from framechain.sinks.fleet_report import not_analysed_reasons

    reasons = not_analysed_reasons(logs)
    for reason in reasons[:most]:
        which = reason.example + (f" and {reason.logs - 1} more" if reason.logs > 1 else "")
        console.print(f"{reason.logs} {reason.status} ({which}): {reason.reason}", markup=False, highlight=False,
                      soft_wrap=True)
    if len(reasons) > most:
        console.print(f"... {len(reasons) - most} other reasons in the fleet report", highlight=False)


def _print_table(console: Any, columns: Sequence[str], rows: Sequence[Sequence[str]]) -> None:
    from rich.table import Table

    if not rows:
        return
    table = Table()
    for col in columns:
        table.add_column(col, overflow="fold")
    for row in rows:
        table.add_row(*row)
    console.print(table)


def print_findings(result: Any) -> None:
    """The verdict, the counts, the findings, the per-hop summary, the fixes and the notes, with rich."""
    from rich.table import Table

    from framechain.sinks.checks_view import BOUND_COLUMNS, bound_rows, label_columns, label_rows, label_summary
    from framechain.sinks.report import HOP_COLUMNS, hop_rows
    from framechain.sinks.text import FindingView, observation_counts

    console = stdout_console(120)  # piped output keeps the table readable
    console.print(f"[bold]{result.verdict}[/bold]")
    console.print(f"observations: {observation_counts(result)}", soft_wrap=True)  # one line, for grep
    if result.findings:
        table = Table()
        cameras = any(f.camera for f in result.findings)
        for col in ("#", "fault", "hop", *(("camera",) if cameras else ()), "estimate", "95% interval", "share",
                    "effect", "confidence", "strength"):
            # Names stay whole (a fault name folded mid-word reads as two); estimates and intervals fold.
            table.add_column(col, overflow="fold", no_wrap=col in ("fault", "hop", "effect", "strength"))
        for i, f in enumerate(result.findings, start=1):
            c = FindingView.of(f).cells()
            table.add_row(str(i), c.fault, c.hop, *((c.camera,) if cameras else ()), c.estimate, c.interval, c.share,
                          c.error, c.confidence, c.strength, style=None if f.actionable and c.strength == "strong"
                          else "dim")
        console.print(table)
    _print_table(console, BOUND_COLUMNS[:3], [row[:3] for row in bound_rows(result)])
    if result.labels.suggest_ignore or result.labels.wrongly_sized:  # every label only when some disagree
        _print_table(console, label_columns(result), label_rows(result))
    if len(result.labels.rows) > 1:  # one label (one object) has nothing to compare
        console.print(label_summary(result), markup=False, highlight=False, soft_wrap=True)
    hops = Table()
    for col in HOP_COLUMNS:
        hops.add_column(col, overflow="fold")
    for row in hop_rows(result):
        hops.add_row(*row)
    console.print(hops)
    for i, f in enumerate(result.findings, start=1):
        on = f" (camera {f.camera})" if f.camera else ""
        console.print(f"{FindingView.of(f).fix_label()} {i}{on}: {f.fix}", markup=False, highlight=False,
                      soft_wrap=True)
    for note in result.notes:
        console.print(f"note: {note}", markup=False, highlight=False, soft_wrap=True)
