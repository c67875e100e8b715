"""Fleets of logs: every log (or LeRobot episode) through attribute, resumably, on a process pool or Ray.

One log, or one episode of a LeRobot dataset, is one unit of work. :func:`run_unit` is a pure
function of its :class:`UnitTask` (paths, chain, options) that returns a JSON-able record and
never raises for a bad log: a log that cannot be read or analysed is a record with its error.
The engines map it over units (:func:`map_local`: in this process or a pool of worker processes;
:func:`map_ray`: Ray tasks on a local instance or an existing cluster), and the driver writes
each record as it arrives into a :class:`ResultStore`: one JSON file per unit, named by a hash of
the log's path, size, modification time, episode, chain, robot.yaml, seed and bootstrap, written
atomically; a rerun skips every unit whose record is there. The records gather into one fleet
table (:func:`fleet_table`, Parquet: one row per log and finding) and a fleet report.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from framechain.analysis.egomotion.recording import CameraRecordingFit
from framechain.config.chain import ChainConfig
from framechain.files import write_atomically
from framechain.fleet.engines import map_local, map_ray
from framechain.fleet.recordings import recording_fits, write_recordings
from framechain.fleet.units import (
    FINAL_STATUSES,
    RESULTS_DIR,
    SCHEMA,
    TABLE_NAME,
    BatchError,
    Engine,
    FoundUnits,
    LogUnit,
    UnitTask,
    crashed_record,
    find_units,
    run_unit,
    unit_key,
)
from framechain.timeline import read_parquet
from framechain.vision.threads import usable_cpus


# -- the store --------------------------------------------------------------------------------
class ResultStore:
    """One JSON record per unit in ``OUT/results/<key>.json``, each written atomically."""

    def __init__(self, out_dir: str | Path) -> None:
        self.directory = Path(out_dir) / RESULTS_DIR
        self.directory.mkdir(parents=True, exist_ok=True)
        # A batch killed while writing a record (SIGKILL: no cleanup runs) leaves its temporary file: never a record.
        for stale in self.directory.glob(".*.tmp"):
            stale.unlink(missing_ok=True)

    def path_for(self, key: str) -> Path:
        return self.directory / f"{key}.json"

    def load(self, key: str) -> dict[str, Any] | None:
        """The stored record (None: absent, unreadable or of another schema)."""
        try:
            record = json.loads(self.path_for(key).read_text())
        except (OSError, ValueError):
            return None
        return record if isinstance(record, dict) and record.get("schema") == SCHEMA else None

    def has_recording(self, key: str) -> bool:
        """The unit's record names a Rerun recording that is there."""
        record = self.load(key) or {}
        return bool(record.get("rrd")) and Path(str(record["rrd"])).is_file()

    def is_done(self, key: str) -> bool:
        record = self.load(key)
        return record is not None and record.get("status") in FINAL_STATUSES

    def write(self, record: dict[str, Any]) -> Path:
        """Write to a temporary file beside the target, then rename: a killed batch never leaves half a record."""
        target = self.path_for(str(record["key"]))

        def write(tmp: Path) -> None:
            with tmp.open("w") as f:
                json.dump(record, f, indent=1)
                f.flush()
                os.fsync(f.fileno())

        write_atomically(target, write)
        return target


# -- the batch --------------------------------------------------------------------------------
@dataclass(frozen=True)
class BatchResult:
    """What a batch did: every unit's record (in input order), how many were skipped as done."""

    records: list[dict[str, Any]]
    skipped: int
    computed: int
    table_path: Path
    report_paths: dict[str, Path] = field(default_factory=dict)
    #: What the batch left out and why (files framechain wrote among the inputs, episodes asked for that a dataset
    #: lacks).
    notes: list[str] = field(default_factory=list)
    #: Per LeRobot dataset, each camera fitted across its episodes (:mod:`framechain.fleet.recordings`).
    recordings: dict[str, tuple[CameraRecordingFit, ...]] = field(default_factory=dict)

    def status_counts(self) -> dict[str, int]:
        counts: dict[str, int] = {}
        for record in self.records:
            counts[record["status"]] = counts.get(record["status"], 0) + 1
        return counts


def run_batch(
    inputs: Sequence[str | Path],
    out_dir: str | Path,
    *,
    chain: str | Path | None = None,
    robot: str | Path | None = None,
    episodes: Iterable[int] | None = None,
    jobs: int | None = None,
    engine: Engine = "local",
    ray_address: str | None = None,
    seed: int = 0,
    bootstrap: int = 30,
    report_formats: Sequence[str] = ("md", "html"),
    on_start: Callable[[int, int], None] | None = None,
    on_record: Callable[[dict[str, Any]], None] | None = None,
    rrd: str | Path | None = None,
    raise_input_problems: bool = False,
    generated_robot_at: str | Path | None = None,
) -> BatchResult:
    """Attribute every unit of ``inputs`` not already in ``OUT/results``; write the fleet table and report.

    ``jobs``: worker processes for the local engine (None: the CPUs this process may use; 1: in this
    process), tasks in flight for Ray (None: twice the cluster's CPUs). Worker processes start the
    main module again, so a script that calls this with ``jobs > 1`` needs the
    ``if __name__ == "__main__":`` guard, as for any process pool.
    ``on_start(total, skipped)`` is called once the units are known; ``on_record(record)`` for each
    unit computed now, as it finishes. ``rrd``: a Rerun recording of each dataset's cameras across its
    episodes, and each unit's own recording in ``<rrd>.episodes/``. Each log is analysed with the chain file beside it
    (``<log name>.chain.yaml``, else ``chain.yaml`` or ``CHAIN.yaml`` in its folder), else ``chain``.
    ``raise_input_problems``: an input that cannot run at all (a LeRobot dataset without robot.yaml, one whose
    metadata cannot be read) raises :class:`BatchError` with its problem before any work, rather than being a
    row of the table (``attribute DATASET --episodes``: one dataset, nothing else to run).
    ``generated_robot_at``: where the caller writes the robot.yaml framechain makes for a known arm without one (the
    episodes' fixes name it).
    """
    found = _units(inputs, chain, robot, episodes, raise_input_problems)
    store = ResultStore(out_dir)
    rrd_dir = None if rrd is None else str(_episode_recordings(rrd).resolve())
    tasks = _unit_tasks(found.units, chain=chain, robot=robot, seed=seed, bootstrap=bootstrap, rrd_dir=rrd_dir,
                        generated_robot_at=None if generated_robot_at is None else str(generated_robot_at))
    # A unit done before without its recording, when one is asked for now, is done again.
    todo = [t for t in tasks if not store.is_done(t.key) or (rrd_dir is not None and not store.has_recording(t.key))]
    if on_start is not None:
        on_start(len(tasks), len(tasks) - len(todo))
    records: Iterator[dict[str, Any]]
    if engine == "ray":
        records = map_ray(todo, address=ray_address, max_in_flight=jobs)
    else:
        records = map_local(todo, jobs=jobs or usable_cpus())
    for record in records:
        store.write(record)
        if on_record is not None:
            on_record(record)
    gathered = [store.load(t.key) or crashed_record(t, "no record was written") for t in tasks]
    table_path = write_fleet_table(gathered, Path(out_dir) / TABLE_NAME)
    fits = recording_fits(gathered, seed=seed)
    paths = _write_views(table_path, fits, out_dir, rrd=rrd, report_formats=report_formats, notes=found.notes)
    return BatchResult(records=gathered, skipped=len(tasks) - len(todo), computed=len(todo),
                       table_path=table_path, report_paths=paths, notes=found.notes, recordings=fits)


def _units(inputs: Sequence[str | Path], chain: str | Path | None, robot: str | Path | None,
           episodes: Iterable[int] | None, raise_input_problems: bool) -> FoundUnits:
    """The units among ``inputs`` (:func:`run_batch`); a bad chain or robot file, or no log at all, raises."""
    chain_config = ChainConfig.from_yaml(chain) if chain is not None else None  # a bad chain is one line, now
    robot_given = robot is not None or bool(chain_config and chain_config.robot and (
        "config" in chain_config.robot or "urdf" in chain_config.robot))
    if robot is not None and not Path(robot).is_file():
        raise BatchError(f"--robot {robot}: no such file")
    found = find_units(inputs, episodes=episodes, robot_given=robot_given)
    if not found.units:
        raise BatchError("no logs among the inputs" + (f" ({'; '.join(found.notes)})" if found.notes else ""))
    if raise_input_problems:
        problems = [unit.problem for unit in found.units if unit.problem is not None]
        if problems:
            raise BatchError("; ".join(problems))
    return found


def _unit_tasks(units: Sequence[LogUnit], *, chain: str | Path | None, robot: str | Path | None, seed: int,
                bootstrap: int, rrd_dir: str | None, generated_robot_at: str | None = None) -> list[UnitTask]:
    """Each unit's task, keyed by what its record depends on; the chain beside a log wins over ``chain``."""
    from framechain import suggest as suggestions

    chain_arg = None if chain is None else os.path.abspath(chain)
    robot_arg = None if robot is None else str(Path(robot).resolve())
    tasks = []
    for u in units:  # the chain beside a log (suggestions.chain_files_beside) wins over --chain
        unit_chain = next((str(c) for c in suggestions.chain_files_beside(u.path)), chain_arg)
        tasks.append(UnitTask(unit=u, key=unit_key(u, chain=unit_chain, robot=robot_arg, seed=seed,
                                                   bootstrap=bootstrap),
                              chain=unit_chain, robot=robot_arg, seed=seed, bootstrap=bootstrap, rrd_dir=rrd_dir,
                              generated_robot_at=generated_robot_at))
    return tasks


def _write_views(table_path: Path, fits: dict[str, tuple[CameraRecordingFit, ...]], out_dir: str | Path, *,
                 rrd: str | Path | None, report_formats: Sequence[str], notes: list[str]) -> dict[str, Path]:
    """The recordings' fits, their Rerun view (with ``rrd``) and the fleet report: the paths written."""
    recording_paths = write_recordings(fits, out_dir)
    if rrd is not None and fits:
        from framechain.sinks.rerun_recording import write_recording_view

        recording_paths["rrd"] = write_recording_view(fits, rrd)
    report_paths: dict[str, Path] = {}
    if report_formats:
        from framechain.sinks.fleet_report import render_fleet_report

        report_paths = render_fleet_report(read_parquet(table_path), out_dir, formats=report_formats,
                                           notes=notes, recordings=fits)
    return {**recording_paths, **report_paths}


def _episode_recordings(rrd: str | Path) -> Path:
    from framechain.sinks.rerun_recording import episode_recordings_dir

    return episode_recordings_dir(rrd)


# -- the fleet table --------------------------------------------------------------------------
FLEET_SCHEMA = pa.schema([
    ("log", pa.string()),
    ("episode", pa.int64()),
    ("unit", pa.string()),
    ("key", pa.string()),
    ("status", pa.string()),
    ("error", pa.string()),
    ("error_type", pa.string()),
    ("verdict", pa.string()),
    ("metric", pa.string()),
    ("chain", pa.string()),  # the chain file the log was analysed with (null: the suggested chain)
    ("chain_suggested", pa.bool_()),
    ("start_ns", pa.int64()),
    ("end_ns", pa.int64()),
    ("span_s", pa.float64()),
    ("observations", pa.int64()),
    ("replayed", pa.int64()),
    ("error_median_m", pa.float64()),
    ("error_p95_m", pa.float64()),
    ("residual_median_m", pa.float64()),
    ("finding", pa.int64()),  # 1-based rank of the finding within its log; null: the log has none
    ("fault", pa.string()),
    ("hop", pa.string()),
    ("camera", pa.string()),  # the camera a finding concerns (a rig's); null: the chain as a whole
    ("estimate_json", pa.string()),
    ("estimate_text", pa.string()),
    ("estimate_name", pa.string()),
    ("estimate_value", pa.float64()),
    ("estimate_unit", pa.string()),
    ("share", pa.float64()),
    ("finding_error_m", pa.float64()),
    ("confidence", pa.float64()),
    ("fix", pa.string()),
    ("strength", pa.string()),  # strong, weak, note (under the tolerance: no action needed) or undetermined
    ("actionable", pa.bool_()),  # whether its effect passes the tolerance: a fix to make
    ("elapsed_s", pa.float64()),
    # the first camera's video/state time offset from its own motion, and its 95% interval (null: none measured)
    ("video_camera", pa.string()),
    ("video_offset_s", pa.float64()),
    ("video_offset_low_s", pa.float64()),
    ("video_offset_high_s", pa.float64()),
])
_FINDING_COLUMNS = ("fault", "hop", "camera", "estimate_json", "estimate_text", "estimate_name", "estimate_value",
                    "estimate_unit", "share", "finding_error_m", "confidence", "fix", "strength", "actionable")


def fleet_table(records: Sequence[dict[str, Any]]) -> pa.Table:
    """One row per log and finding (one row with empty finding columns for a log without findings)."""
    rows = []
    for record in records:
        start, end = record.get("start_ns"), record.get("end_ns")
        base = {name: record.get(name) for name in FLEET_SCHEMA.names if name not in _FINDING_COLUMNS}
        base["span_s"] = None if start is None or end is None else (end - start) * 1e-9
        findings = record.get("findings") or []
        if not findings:
            rows.append({**base, "finding": None, **dict.fromkeys(_FINDING_COLUMNS)})
        for rank, finding in enumerate(findings, start=1):
            rows.append({**base, "finding": rank, **{k: finding.get(k) for k in _FINDING_COLUMNS}})
    return pa.Table.from_pylist(rows, schema=FLEET_SCHEMA)


def write_fleet_table(records: Sequence[dict[str, Any]], path: Path) -> Path:
    """Write the fleet table atomically (a reader never sees half a file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, lambda tmp: pq.write_table(fleet_table(records), tmp))
    return path


__all__ = [
    "FLEET_SCHEMA",
    "BatchError",
    "BatchResult",
    "FoundUnits",
    "LogUnit",
    "ResultStore",
    "UnitTask",
    "crashed_record",
    "find_units",
    "fleet_table",
    "map_local",
    "map_ray",
    "run_batch",
    "run_unit",
    "unit_key",
    "write_fleet_table",
]
