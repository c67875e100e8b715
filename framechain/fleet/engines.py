"""The engines that map :func:`~framechain.fleet.units.run_unit` over units: a pool of worker processes
(:func:`map_local`) or Ray tasks (:func:`map_ray`)."""

from __future__ import annotations

import importlib
import logging
import multiprocessing
import os
import signal
from collections import deque
from collections.abc import Iterator, Sequence
from multiprocessing.connection import Connection, wait
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    pass


from framechain.errors import one_line
from framechain.fleet.units import BatchError, UnitTask, crashed_record, run_unit
from framechain.vision.threads import THREADS_ENV


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
    os.environ.setdefault(THREADS_ENV, "1")  # one episode per worker per core: its cameras in turn
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


def run_unit_alone(task: UnitTask) -> dict[str, Any]:
    """:func:`run_unit` in a worker that has one core (a Ray task): its cameras measured in turn."""
    os.environ.setdefault(THREADS_ENV, "1")
    return run_unit(task)


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
            raise BatchError(f"--engine ray: cannot start or join {where}: {one_line(err)}") from err
    try:
        remote = ray.remote(max_retries=2)(run_unit_alone)  # retries are for lost nodes; run_unit never raises
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
                    record = crashed_record(task, f"ray: {one_line(err).split('. ')[0]}")
                yield record
    finally:
        if started:
            ray.shutdown()


