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

import hashlib
import importlib
import json
import logging
import multiprocessing
import os
import signal
import tempfile
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import pyarrow as pa
import pyarrow.parquet as pq

from framechain import __version__
from framechain.config.chain import ChainConfig
from framechain.timeline import FramechainError

if TYPE_CHECKING:
    from framechain.analysis.run import Run

SCHEMA = "framechain/batch@1"
RESULTS_DIR = "results"
TABLE_NAME = "fleet.parquet"
#: File suffixes a directory walk takes for logs (a ROS 2 bag directory, a LeRobot dataset and a
#: saved timeline are recognised by their metadata files instead).
LOG_SUFFIXES = (".mcap", ".bag", ".db3")

Status = Literal["findings", "clean", "no_evidence", "nothing_replayed", "error", "crashed"]
#: Statuses a rerun keeps: the record is the answer for these inputs. "crashed" (a worker that
#: died, an unexpected exception) may be transient and is computed again.
FINAL_STATUSES = frozenset({"findings", "clean", "no_evidence", "nothing_replayed", "error"})
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
    chain: str | None = None  # CHAIN.yaml path; None: each log's suggested chain
    robot: str | None = None  # robot.yaml path (LeRobot datasets)
    seed: int = 0
    bootstrap: int = 30


# -- finding the units ------------------------------------------------------------------------
def find_units(
    inputs: Sequence[str | Path], *, episodes: Iterable[int] | None = None, robot_given: bool = False,
) -> list[LogUnit]:
    """Every log among ``inputs``: files, ROS 2 bag directories, LeRobot datasets (one unit per episode,
    only ``episodes`` when given), saved timelines, and directories walked for any of these."""
    wanted = None if episodes is None else frozenset(episodes)
    units: list[LogUnit] = []
    for item in inputs:
        path = Path(item).resolve()
        if not path.exists():
            raise BatchError(f"{item}: no such file or directory")
        if path.is_file():
            units.append(_file_unit(path))
        else:
            found = list(_walk(path, wanted, robot_given))
            if not found:
                raise BatchError(f"{item}: no logs in this directory (looked for {', '.join(LOG_SUFFIXES)} files, "
                                 "ROS 2 bag directories, LeRobot datasets and saved timelines)")
            units.extend(found)
    seen: set[tuple[Path, int | None]] = set()
    unique = []
    for unit in units:  # an input named twice (or a file inside a walked directory) is one unit
        if (unit.path, unit.episode) not in seen:
            seen.add((unit.path, unit.episode))
            unique.append(unit)
    return unique


def _walk(directory: Path, episodes: frozenset[int] | None, robot_given: bool) -> Iterator[LogUnit]:
    from framechain import adapters

    if adapters.LeRobotAdapter().probe(directory):
        yield from _dataset_units(directory, episodes, robot_given)
        return
    if (directory / "timeline.json").is_file() or (directory / "metadata.yaml").is_file():
        yield _dir_unit(directory)
        return
    for child in sorted(directory.iterdir()):
        if child.name.startswith("."):
            continue
        if child.is_dir():
            yield from _walk(child, episodes, robot_given)
        elif child.suffix.lower() in LOG_SUFFIXES and not _inside_bag(child):
            yield _file_unit(child)


def _inside_bag(path: Path) -> bool:
    return (path.parent / "metadata.yaml").is_file()


def _file_unit(path: Path) -> LogUnit:
    st = path.stat()
    return LogUnit(path=path, size_bytes=st.st_size, mtime_ns=st.st_mtime_ns)


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


def _dataset_units(directory: Path, episodes: frozenset[int] | None, robot_given: bool) -> Iterator[LogUnit]:
    from framechain.adapters.lerobot.format import DatasetReader

    size, mtime = _tree_fingerprint(directory)
    if not robot_given:
        yield LogUnit(path=directory, size_bytes=size, mtime_ns=mtime,
                      problem="a LeRobot dataset needs --robot robot.yaml (URDF, joints, cameras)")
        return
    try:
        found = DatasetReader(directory).episodes()
    except FramechainError as err:
        yield LogUnit(path=directory, size_bytes=size, mtime_ns=mtime, problem=str(err))
        return
    for episode in found:
        if episodes is None or episode in episodes:
            yield LogUnit(path=directory, episode=episode, size_bytes=size, mtime_ns=mtime)


def unit_key(unit: LogUnit, *, chain: str | Path | None, robot: str | Path | None, seed: int, bootstrap: int) -> str:
    """The store key: a hash of everything the unit's record depends on (the log by path, size and mtime)."""
    identity = {
        "schema": SCHEMA,
        "path": str(unit.path),
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
        made = pipeline.run(unit.path, task.chain, seed=task.seed, bootstrap=task.bootstrap, episode=unit.episode,
                            robot=task.robot if unit.episode is not None else None)
    except FramechainError as err:  # unreadable log, chain that does not fit it
        record.update(status="error", error=_one_line(err), error_type=type(err).__name__)
        record.update(_span_of(unit))
    except Exception as err:  # a bug, not a bad log: this unit's record, never the end of the batch
        record.update(status="crashed", error=_one_line(err), error_type=type(err).__name__)
        record.update(_span_of(unit))
    else:
        record.update(_outcome(made))
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
        return {"status": "nothing_replayed", "error": _one_line(Exception(error)), "error_type": "AnalysisError",
                **span}
    findings = [_finding_row(f) for f in result.findings]
    status: Status = "no_evidence" if result.metric == "none" else "findings" if findings else "clean"
    counts = result.counts()
    return {
        "status": status, "verdict": result.verdict, "metric": result.metric, "chain_suggested": made.chain_suggested,
        **span, "observations": int(counts["total"]), "replayed": int(counts["replayed"]),
        "error_median_m": result.error_summary()["median"], "error_p95_m": result.error_summary()["p95"],
        "residual_median_m": result.error_summary(result.error_after)["median"],
        "findings": findings, "notes": list(result.notes),
    }


def _record_head(task: UnitTask) -> dict[str, Any]:
    unit = task.unit
    return {
        "schema": SCHEMA, "key": task.key, "log": str(unit.path), "episode": unit.episode, "unit": unit.label,
        "status": "crashed", "error": None, "error_type": None, "verdict": None, "metric": None,
        "chain_suggested": task.chain is None, "start_ns": None, "end_ns": None, "observations": None,
        "replayed": None, "error_median_m": None, "error_p95_m": None, "residual_median_m": None,
        "findings": [], "notes": [], "framechain": __version__, "pid": os.getpid(),
    }


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split())
    return text or type(err).__name__


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
    from framechain.analysis.estimates import estimate_scalars, format_estimate

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
        "fix": data["fix"],
    }


def crashed_record(task: UnitTask, why: str) -> dict[str, Any]:
    """The record of a unit whose worker died (killed, out of memory, a crash in native code)."""
    record = _record_head(task)
    record.update(status="crashed", error=why, error_type="WorkerDied", elapsed_s=None, pid=None)
    return record


# -- the store --------------------------------------------------------------------------------
class ResultStore:
    """One JSON record per unit in ``OUT/results/<key>.json``, each written atomically."""

    def __init__(self, out_dir: str | Path) -> None:
        self.directory = Path(out_dir) / RESULTS_DIR
        self.directory.mkdir(parents=True, exist_ok=True)

    def path_for(self, key: str) -> Path:
        return self.directory / f"{key}.json"

    def load(self, key: str) -> dict[str, Any] | None:
        """The stored record (None: absent, unreadable or of another schema)."""
        try:
            record = json.loads(self.path_for(key).read_text())
        except (OSError, ValueError):
            return None
        return record if isinstance(record, dict) and record.get("schema") == SCHEMA else None

    def is_done(self, key: str) -> bool:
        record = self.load(key)
        return record is not None and record.get("status") in FINAL_STATUSES

    def write(self, record: dict[str, Any]) -> Path:
        """Write to a temporary file beside the target, then rename: a killed batch never leaves half a record."""
        target = self.path_for(str(record["key"]))
        fd, tmp = tempfile.mkstemp(dir=self.directory, prefix=f".{target.stem}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "w") as f:
                json.dump(record, f, indent=1)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, target)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return target


# -- engines ----------------------------------------------------------------------------------
def map_local(tasks: Sequence[UnitTask], jobs: int = 1) -> Iterator[dict[str, Any]]:
    """Records in completion order: in this process (``jobs == 1``) or on ``jobs`` worker processes.

    Each worker has its own pipes (no shared queue whose lock a killed worker could hold), so a
    worker that dies costs only its own unit (a "crashed" record) and is replaced.
    """
    if jobs <= 1 or len(tasks) <= 1:
        for task in tasks:
            yield run_unit(task)
        return
    # Workers fork from a server that has framechain loaded already: fast, and no threads of the
    # driver (the progress bar's) are copied into them. Where there is no fork server (Windows), spawn.
    context: Any
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(["framechain.fleet", "framechain.pipeline", "framechain.adapters"])
    else:
        context = multiprocessing.get_context("spawn")
    pending = deque(tasks)
    workers = [_Worker(context) for _ in range(min(jobs, len(tasks)))]
    try:
        for i in range(len(workers)):
            _assign(workers, i, pending.popleft(), context)
        while busy := [w for w in workers if w.task is not None]:
            wait([w.conn for w in busy] + [w.process.sentinel for w in busy])
            for worker in busy:
                record = worker.collect()
                if record is None:
                    continue
                yield record
                if pending:
                    _assign(workers, workers.index(worker), pending.popleft(), context)
    finally:
        for worker in workers:
            worker.stop()


def _assign(workers: list[_Worker], i: int, task: UnitTask, context: Any) -> None:
    """Give ``task`` to worker ``i``, or to a fresh one in its place when it has died."""
    if workers[i].process.is_alive():
        try:
            workers[i].assign(task)
            return
        except OSError:  # it died between its last record and this task
            pass
    workers[i].stop()
    workers[i] = _Worker(context)
    workers[i].assign(task)


class _Worker:
    def __init__(self, context: Any) -> None:
        self.conn, child = context.Pipe()
        self.process = context.Process(target=_worker_main, args=(child,), daemon=True)
        self.process.start()
        child.close()
        self.task: UnitTask | None = None

    def assign(self, task: UnitTask) -> None:
        self.conn.send(task)
        self.task = task

    def collect(self) -> dict[str, Any] | None:
        """The record of the unit it ran, or of its death; None while it is still working."""
        if self.task is None:
            return None
        if self.conn.poll():
            try:
                record: dict[str, Any] = self.conn.recv()
            except (EOFError, OSError):
                self.process.join(timeout=5.0)  # its end of the pipe closed: it died or is dying
            else:
                self.task = None
                return record
        elif self.process.is_alive():
            return None  # still working
        task, self.task = self.task, None
        return crashed_record(task, f"the worker process died (exit code {self.process.exitcode}) on this log")

    def stop(self) -> None:
        """Let an idle worker exit; end one still in a unit (an interrupted batch: its unit is redone next run)."""
        if self.process.is_alive() and self.task is None:
            try:
                self.conn.send(None)
                self.process.join(timeout=2.0)
            except OSError:
                pass
        if self.process.is_alive():
            self.process.terminate()
        self.process.join(timeout=2.0)
        self.conn.close()


def _worker_main(conn: Connection) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's to handle
    while True:
        try:
            task = conn.recv()
        except EOFError:
            return  # the driver is gone
        if task is None:
            return
        try:
            conn.send(run_unit(task))
        except (BrokenPipeError, OSError):
            return


def map_ray(tasks: Sequence[UnitTask], *, address: str | None = None, max_in_flight: int | None = None,
            ) -> Iterator[dict[str, Any]]:
    """Records in completion order from Ray tasks running :func:`run_unit`.

    Uses the Ray instance already initialised in this process, else ``ray.init(address)`` (None:
    ``RAY_ADDRESS``, else a cluster started on this machine, else a new local instance).
    framechain must be importable on every node.
    """
    if not tasks:
        return  # nothing left to do: no cluster to start or join
    try:
        # Optional and typed as Any on purpose: mypy passes with and without the ray extra installed.
        ray: Any = importlib.import_module("ray")
    except ImportError as err:
        raise BatchError("--engine ray needs Ray: pip install 'framechain[ray]'") from err
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(address=address, include_dashboard=False, logging_level=logging.WARNING, log_to_driver=False)
        except (ConnectionError, ValueError, RuntimeError) as err:
            where = f"the cluster at {address}" if address else "a local Ray instance"
            raise BatchError(f"--engine ray: cannot start or join {where}: {_one_line(err)}") from err
    try:
        remote = ray.remote(max_retries=2)(run_unit)  # retries are for lost nodes; run_unit itself never raises
        limit = max_in_flight or max(2 * int(ray.cluster_resources().get("CPU", 1)), 1)
        pending = deque(tasks)
        in_flight: dict[Any, UnitTask] = {}
        while pending or in_flight:
            while pending and len(in_flight) < limit:
                task = pending.popleft()
                in_flight[remote.remote(task)] = task
            done, _ = ray.wait(list(in_flight), num_returns=1)
            for ref in done:
                task = in_flight.pop(ref)
                try:
                    record: dict[str, Any] = ray.get(ref)
                except ray.exceptions.RayError as err:
                    record = crashed_record(task, f"ray: {_one_line(err).split('. ')[0]}")
                yield record
    finally:
        if started:
            ray.shutdown()


def usable_cpus() -> int:
    """The CPUs this process may run on (a container's or taskset's share, not the machine's)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


# -- the batch --------------------------------------------------------------------------------
@dataclass(frozen=True)
class BatchResult:
    """What a batch did: every unit's record (in input order), how many were skipped as done."""

    records: list[dict[str, Any]]
    skipped: int
    computed: int
    table_path: Path
    report_paths: dict[str, Path] = field(default_factory=dict)

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
) -> BatchResult:
    """Attribute every unit of ``inputs`` not already in ``OUT/results``; write the fleet table and report.

    ``jobs``: worker processes for the local engine (None: the CPUs this process may use; 1: in this
    process), tasks in flight for Ray (None: twice the cluster's CPUs). Worker processes start the
    main module again, so a script that calls this with ``jobs > 1`` needs the
    ``if __name__ == "__main__":`` guard, as for any process pool.
    ``on_start(total, skipped)`` is called once the units are known; ``on_record(record)`` for each
    unit computed now, as it finishes.
    """
    chain_config = ChainConfig.from_yaml(chain) if chain is not None else None  # a bad chain is one line, now
    robot_given = robot is not None or bool(chain_config and chain_config.robot and (
        "config" in chain_config.robot or "urdf" in chain_config.robot))
    if robot is not None and not Path(robot).is_file():
        raise BatchError(f"--robot {robot}: no such file")
    units = find_units(inputs, episodes=episodes, robot_given=robot_given)
    if not units:
        raise BatchError("no logs among the inputs")
    store = ResultStore(out_dir)
    chain_arg = None if chain is None else str(Path(chain).resolve())
    robot_arg = None if robot is None else str(Path(robot).resolve())
    tasks = [UnitTask(unit=u, key=unit_key(u, chain=chain_arg, robot=robot_arg, seed=seed, bootstrap=bootstrap),
                      chain=chain_arg, robot=robot_arg, seed=seed, bootstrap=bootstrap) for u in units]
    todo = [t for t in tasks if not store.is_done(t.key)]
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
    report_paths: dict[str, Path] = {}
    if report_formats:
        from framechain.sinks.fleet_report import render_fleet_report

        report_paths = render_fleet_report(pq.read_table(table_path), out_dir, formats=report_formats)
    return BatchResult(records=gathered, skipped=len(tasks) - len(todo), computed=len(todo),
                       table_path=table_path, report_paths=report_paths)


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
    ("elapsed_s", pa.float64()),
])
_FINDING_COLUMNS = ("fault", "hop", "camera", "estimate_json", "estimate_text", "estimate_name", "estimate_value",
                    "estimate_unit", "share", "finding_error_m", "confidence", "fix")


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
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    pq.write_table(fleet_table(records), tmp)
    os.replace(tmp, path)
    return path


__all__ = [
    "FLEET_SCHEMA",
    "BatchError",
    "BatchResult",
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
