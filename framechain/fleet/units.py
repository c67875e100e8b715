"""One unit of a batch: a log or an episode, found on disk, keyed, and run to a JSON-able record."""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from framechain import __version__
from framechain.errors import FramechainError, one_line

if TYPE_CHECKING:
    from framechain.analysis.run import Run


SCHEMA = "framechain/batch@1"
RESULTS_DIR = "results"
TABLE_NAME = "fleet.parquet"

Status = Literal["findings", "inconclusive", "clean", "no_evidence", "nothing_replayed", "error", "crashed"]
#: Statuses a rerun keeps: the record is the answer for these inputs. "crashed" (a worker that
#: died, an unexpected exception) may be transient and is computed again.
FINAL_STATUSES = frozenset({"findings", "inconclusive", "clean", "no_evidence", "nothing_replayed", "error"})
Engine = Literal["local", "ray"]


class BatchError(FramechainError):
    """The batch itself cannot run (no logs among the inputs, an engine that is not installed)."""


@dataclass(frozen=True)
class LogUnit:
    """One unit of work: a log (file or bag directory), or one episode of a LeRobot dataset.

    ``problem`` is set when the unit is known to fail before any work (a LeRobot dataset without
    --robot, a dataset whose metadata cannot be read); it becomes the unit's error record.
    """

    path: Path
    episode: int | None = None
    size_bytes: int = 0
    mtime_ns: int = 0
    problem: str | None = None

    @property
    def label(self) -> str:
        return str(self.path) if self.episode is None else f"{self.path} episode {self.episode}"


@dataclass(frozen=True)
class UnitTask:
    """Everything :func:`run_unit` needs, picklable, with the key its record is stored under."""

    unit: LogUnit
    key: str
    chain: str | None = None  # CHAIN.yaml path (beside the log, else --chain); None: the log's suggested chain
    robot: str | None = None  # robot.yaml path (LeRobot datasets)
    seed: int = 0
    bootstrap: int = 30
    #: Where the unit also saves its replay as a Rerun recording of its own (None: it does not).
    rrd_dir: str | None = None
    #: Where the caller writes the robot.yaml made for a known arm without one (its fixes name it; None: nowhere).
    generated_robot_at: str | None = None


# -- finding the units ------------------------------------------------------------------------
@dataclass(frozen=True)
class FoundUnits:
    """The units of work among the inputs, and a note for what the inputs hold that is no unit: each file
    skipped as framechain's own output, the episodes asked for that a dataset lacks."""

    units: list[LogUnit]
    notes: list[str] = field(default_factory=list)


def episode_ranges(episodes: Iterable[int]) -> str:
    """``[0, 1, 2, 3, 7, 9, 10]`` -> ``0-3,7,9-10``: episode numbers as the --episodes spec that names them."""
    runs: list[list[int]] = []
    for episode in sorted(set(episodes)):
        if runs and episode == runs[-1][1] + 1:
            runs[-1][1] = episode
        else:
            runs.append([episode, episode])
    return ",".join(str(lo) if lo == hi else f"{lo}-{hi}" for lo, hi in runs)


def find_units(
    inputs: Sequence[str | Path], *, episodes: Iterable[int] | None = None, robot_given: bool = False,
) -> FoundUnits:
    """Every log among ``inputs``: files, ROS 2 bag directories, LeRobot datasets (one unit per episode,
    only ``episodes`` when given), saved timelines, and directories walked for any of these. Files framechain
    wrote (an exported MCAP holds a copy of a log) are skipped with a note, as are episodes asked for that a
    dataset lacks; an input that yields no unit is an error (for a dataset holding none of ``episodes``, one
    that names it, the episodes asked for and those it has). Paths stay as the user gave them (made absolute,
    symlinks kept): the table names the logs the way the user does."""
    from framechain.pipeline import LOG_SUFFIXES

    wanted = None if episodes is None else frozenset(episodes)
    units: list[LogUnit] = []
    notes: list[str] = []
    for item in inputs:
        path = Path(os.path.abspath(item))
        if not path.exists():
            raise BatchError(f"{item}: no such file or directory")
        if path.is_file():
            units.extend(_log_file(path, notes))
        else:
            lacking: list[str] = []  # datasets under this input that hold none of the episodes asked for
            found = list(_walk(path, wanted, robot_given, notes, lacking))
            if not found and lacking:
                raise BatchError("; ".join(lacking))
            if not found:
                raise BatchError(f"{item}: no logs in this directory (looked for {', '.join(LOG_SUFFIXES)} files, "
                                 "ROS 2 bag directories, LeRobot datasets and saved timelines)")
            notes.extend(lacking)  # other logs under this input were found: the empty dataset is a note
            units.extend(found)
    seen: set[tuple[Path, int | None]] = set()
    unique = []
    for unit in units:  # an input named twice (or a file inside a walked directory) is one unit
        if (unit.path.resolve(), unit.episode) not in seen:
            seen.add((unit.path.resolve(), unit.episode))
            unique.append(unit)
    return FoundUnits(unique, notes)


def _walk(directory: Path, episodes: frozenset[int] | None, robot_given: bool, notes: list[str],
          lacking: list[str]) -> Iterator[LogUnit]:
    from framechain import adapters
    from framechain.pipeline import LOG_SUFFIXES

    if adapters.LeRobotAdapter().probe(directory):
        yield from _dataset_units(directory, episodes, robot_given, notes, lacking)
        return
    if (directory / "timeline.json").is_file() or (directory / "metadata.yaml").is_file():
        yield _dir_unit(directory)
        return
    for child in sorted(directory.iterdir()):
        if child.name.startswith("."):
            continue
        if child.is_dir():
            yield from _walk(child, episodes, robot_given, notes, lacking)
        elif child.suffix.lower() in LOG_SUFFIXES and not _inside_bag(child):
            yield from _log_file(child, notes)


def _log_file(path: Path, notes: list[str]) -> list[LogUnit]:
    """A log file's unit; none, with a note in ``notes``, for a file framechain wrote."""
    from framechain import adapters

    wrote = adapters.framechain_output(path)
    if wrote is not None:
        notes.append(f"{path} skipped: written by {wrote}, not a recording")
        return []
    st = path.stat()
    return [LogUnit(path=path, size_bytes=st.st_size, mtime_ns=st.st_mtime_ns)]


def _inside_bag(path: Path) -> bool:
    return (path.parent / "metadata.yaml").is_file()


def _dir_unit(directory: Path, episode: int | None = None, problem: str | None = None) -> LogUnit:
    size, mtime = _tree_fingerprint(directory)
    return LogUnit(path=directory, episode=episode, size_bytes=size, mtime_ns=mtime, problem=problem)


def _tree_fingerprint(directory: Path) -> tuple[int, int]:
    """Total size and newest modification time of the files under ``directory``."""
    size = mtime = 0
    for root, _dirs, files in os.walk(directory):
        for name in files:
            st = os.stat(os.path.join(root, name))
            size += st.st_size
            mtime = max(mtime, st.st_mtime_ns)
    return size, mtime


def _dataset_units(directory: Path, episodes: frozenset[int] | None, robot_given: bool, notes: list[str],
                   lacking: list[str]) -> Iterator[LogUnit]:
    """One unit per episode asked for; without robot.yaml, only for an arm framechain bundles a URDF for (each
    episode's robot.yaml is then generated), else one unit whose problem says what to give. Episodes asked for
    that the dataset lacks are a note in ``notes``; a dataset holding none of them is no unit, its line in
    ``lacking``."""
    from framechain.adapters.lerobot.reader import DatasetReader
    from framechain.robot.known_arms import known_arm
    from framechain.suggest import dataset_needs

    size, mtime = _tree_fingerprint(directory)
    try:
        reader = DatasetReader(directory)
        found = reader.episodes()
        if episodes is not None and not episodes <= set(found):
            spec, missing = episode_ranges(episodes), sorted(episodes - set(found))
            has = (f"it has {len(found)} episode{'s' if len(found) != 1 else ''}: {episode_ranges(found)}" if found
                   else "it has no episodes")
            if episodes.isdisjoint(found):
                lacking.append(f"{directory}: --episodes {spec}: the dataset has no such episode ({has})")
                return
            lacks = f"episode {missing[0]} is" if len(missing) == 1 else f"episodes {episode_ranges(missing)} are"
            notes.append(f"{directory}: --episodes {spec}: {lacks} not in the dataset ({has})")
        problem = None if robot_given or known_arm(reader.robot_type) else dataset_needs(
            directory, episode=found[0] if found else 0, robot_given=False)
    except FramechainError as err:
        problem = str(err)
    if problem is not None:
        yield LogUnit(path=directory, size_bytes=size, mtime_ns=mtime, problem=problem)
        return
    for episode in found:
        if episodes is None or episode in episodes:
            yield LogUnit(path=directory, episode=episode, size_bytes=size, mtime_ns=mtime)


def unit_key(unit: LogUnit, *, chain: str | Path | None, robot: str | Path | None, seed: int, bootstrap: int) -> str:
    """The store key: a hash of everything the unit's record depends on (the log by path, size and mtime)."""
    identity = {
        "schema": SCHEMA,
        "path": str(unit.path.resolve()),  # the same log through a symlink is the same unit
        "episode": unit.episode,
        "size_bytes": unit.size_bytes,
        "mtime_ns": unit.mtime_ns,
        "chain": _file_digest(chain),
        "robot": _file_digest(robot),
        "seed": seed,
        "bootstrap": bootstrap,
    }
    return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:32]


def _file_digest(path: str | Path | None) -> str | None:
    if path is None:
        return None
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# -- the pure per-unit function ---------------------------------------------------------------
def run_unit(task: UnitTask) -> dict[str, Any]:
    """Attribute one log or episode; the record of the outcome (never raises for a bad log)."""
    from framechain import pipeline

    unit = task.unit
    start, start_cpu = time.perf_counter(), time.process_time()
    record = _record_head(task)
    if unit.problem is not None:
        return {**record, "status": "error", "error": unit.problem, "error_type": "BatchError"}
    try:
        written = None if task.generated_robot_at is None else Path(task.generated_robot_at)
        made = pipeline.run(unit.path, task.chain, seed=task.seed, bootstrap=task.bootstrap, episode=unit.episode,
                            robot=task.robot if unit.episode is not None else None, generated_robot_at=written)
    except FramechainError as err:  # unreadable log, chain that does not fit it
        record.update(status="error", error=one_line(err), error_type=type(err).__name__)
        record.update(_span_of(unit))
    except Exception as err:  # a bug, not a bad log: this unit's record, never the end of the batch
        record.update(status="crashed", error=one_line(err), error_type=type(err).__name__)
        record.update(_span_of(unit))
    else:
        record.update(_outcome(made))
        if task.rrd_dir is not None:
            record["rrd"] = _save_recording(made, Path(task.rrd_dir), unit)
    record["elapsed_s"] = round(time.perf_counter() - start, 4)
    record["cpu_s"] = round(time.process_time() - start_cpu, 4)
    return record


def _outcome(made: Run) -> dict[str, Any]:
    """A run's part of its unit's record: its findings, or why there are none."""
    info = made.info
    span = {"start_ns": None if info is None else int(info.start_ns),
            "end_ns": None if info is None else int(info.end_ns)}
    result = made.attribution
    if result is None:  # read, but not attributed (nothing replayed): the message names the key to add
        assert made.not_attributed is not None
        error = f"{made.path}: {made.not_attributed.detail}"
        return {"status": "nothing_replayed", "error": one_line(Exception(error)), "error_type": "AnalysisError",
                **span}
    findings = [_finding_row(f) for f in result.findings]
    # Findings under the tolerance are notes: a log with only those is clean; one whose deciding fits are undetermined
    # is inconclusive, whatever else it found.
    status: Status = ("no_evidence" if result.nothing_checked else "inconclusive" if result.undetermined
                      else "findings" if any(f.actionable for f in result.findings) else "clean")
    counts = result.counts()
    return {
        "status": status, "verdict": result.verdict, "metric": result.metric, "chain_suggested": made.chain_suggested,
        **span, "observations": int(counts["total"]), "replayed": int(counts["replayed"]),
        "error_median_m": result.error_summary()["median"], "error_p95_m": result.error_summary()["p95"],
        "residual_median_m": result.error_summary(result.error_after)["median"],
        "findings": findings, "notes": list(result.notes),
        **_video_offset([entry for entry in result.camera_motion if _measured(entry)]),
        "cameras": [_camera_record(entry) for entry in result.camera_motion if _measured(entry)],
        "cameras_left_out": [{"camera": entry["camera"], "why": _why_unmeasured(entry)}
                             for entry in result.camera_motion if not _measured(entry)],
    }


def _measured(entry: dict[str, Any]) -> bool:
    """A camera's motion measured something: fitted to a link, and something observable (not an episode too short
    or an arm too still, whose fit carries a link and an offset that show nothing)."""
    return bool(entry.get("link")) and any(o.get("observable") for o in entry.get("observable") or ())


def _why_unmeasured(entry: dict[str, Any]) -> str:
    """Why a camera's ``camera_motion`` entry carries no fit: its first reason not to observe, else its first note."""
    reasons = [o["why"] for o in entry.get("observable") or () if o.get("why")]
    return next(iter([*reasons, *(entry.get("notes") or ())]), "its motion was not measured")


#: What a recording-level fit needs of each camera's ``camera_motion`` entry (framechain.fleet.recordings).
_CAMERA_KEYS = ("camera", "name", "link", "declared_link", "offset_s", "offset_interval_s", "q_link_cam",
                "mount_error_deg", "mount_error_interval_deg", "focal_scale", "explained", "link_misfits",
                "mount_evidence", "pairing", "position", "focal_px")


def _camera_record(entry: dict[str, Any]) -> dict[str, Any]:
    return {key: entry.get(key) for key in _CAMERA_KEYS}


def _save_recording(made: Run, directory: Path, unit: LogUnit) -> str:
    """The unit's replay saved as a Rerun recording of its own (``<log>: episode N``) in ``directory``."""
    from framechain.sinks.rerun import RerunOptions, RerunTarget, stream_replay

    name = unit.path.name if unit.episode is None else f"{unit.path.name}_episode_{unit.episode}"
    path = directory / f"{name}.rrd"
    label = unit.path.name if unit.episode is None else f"{unit.path.name}: episode {unit.episode}"
    stream_replay(made, RerunTarget.save(path), options=RerunOptions(recording_id=label), notify=lambda _m: None)
    return str(path)


def _video_offset(entries: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The video/state time offset the first measured camera's own motion shows, and its 95% interval."""
    for entry in entries:
        if entry.get("offset_s") is not None:
            low, high = entry.get("offset_interval_s") or (None, None)
            return {"video_camera": entry["camera"], "video_offset_s": entry["offset_s"], "video_offset_low_s": low,
                    "video_offset_high_s": high}
    return {}


def _record_head(task: UnitTask) -> dict[str, Any]:
    unit = task.unit
    return {
        "schema": SCHEMA, "key": task.key, "log": str(unit.path), "episode": unit.episode, "unit": unit.label,
        "status": "crashed", "error": None, "error_type": None, "verdict": None, "metric": None,
        # A LeRobot dataset's robot.yaml is its chain file (its cameras, and its chain: section).
        "chain": task.chain or task.robot, "chain_suggested": task.chain is None and task.robot is None,
        "start_ns": None, "end_ns": None,
        "observations": None, "replayed": None, "error_median_m": None, "error_p95_m": None, "residual_median_m": None,
        "findings": [], "notes": [], "framechain": __version__, "pid": os.getpid(),
    }


def _span_of(unit: LogUnit) -> dict[str, int | None]:
    """The log's time span from its index alone, for a unit that could not be analysed (None: unreadable)."""
    from framechain import adapters

    try:
        info = adapters.scan_dataset(unit.path, unit.episode) if unit.episode is not None else adapters.scan_log(
            unit.path)
    except Exception:  # the span is a courtesy; the error already says what is wrong
        return {"start_ns": None, "end_ns": None}
    return {"start_ns": int(info.start_ns), "end_ns": int(info.end_ns)}


#: estimate_scalars' names and their units in the table
_ESTIMATE_UNITS = {"offset_s": "s", "angle_deg": "deg", "factor": "ratio", "scale": "ratio", "distance_m": "m"}


def _finding_row(finding: Any) -> dict[str, Any]:
    from framechain.analysis.model.estimates import estimate_scalars, format_estimate

    data = finding.to_json()
    scalars = estimate_scalars(finding.estimate)
    name, value = next(iter(scalars.items()), (None, None))
    return {
        "fault": data["fault"], "hop": data["hop"], "camera": data.get("camera"),
        "estimate_json": json.dumps(data["estimate"], sort_keys=True),
        "estimate_text": format_estimate(finding.estimate),
        "estimate_name": name, "estimate_value": None if value is None else float(value),
        "estimate_unit": None if name is None else _ESTIMATE_UNITS.get(name, ""),
        "share": data["share"], "finding_error_m": data["error_m"], "confidence": data["confidence"],
        "fix": data["fix"], "strength": data["strength"], "actionable": data["actionable"],
    }


def crashed_record(task: UnitTask, why: str) -> dict[str, Any]:
    """The record of a unit whose worker died (killed, out of memory, a crash in native code)."""
    record = _record_head(task)
    record.update(status="crashed", error=why, error_type="WorkerDied", elapsed_s=None, pid=None)
    return record


