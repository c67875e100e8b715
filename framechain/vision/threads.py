"""How one run's image work is spread over the cores: forked processes, threads, and blocks of rows.

A command runs one episode on every core the process may use. Its cameras are measured at once
(:func:`framechain.analysis.egomotion.run.measure_cameras`): on Linux each in a process forked from the
command (:func:`map_forked`), which shares everything the command has loaded and read, and whose result is
pickled back; elsewhere on threads. One camera's frame pairs are split into blocks measured at once
(:func:`framechain.vision.two_view.rotations_along_translation`: NumPy releases the interpreter's lock for each
pass over a block) when it has the cores to itself. A batch's worker processes run an episode per core already,
and set :data:`THREADS_ENV` to 1.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import os
import pickle
import selectors
import signal
import sys
import threading
import traceback
import warnings
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar, cast

import numpy as np

from framechain.errors import FramechainError

__all__ = ["THREADS_ENV", "by_row_blocks", "forks", "map_forked", "run_threads", "sharing_threads",
           "split_over_threads", "threads_here", "usable_cpus"]

#: Threads one run uses: FRAMECHAIN_CAMERA_THREADS, else one per core this process may use.
THREADS_ENV = "FRAMECHAIN_CAMERA_THREADS"

T = TypeVar("T")
R = TypeVar("R")
A = TypeVar("A", bound="np.ndarray[Any, Any]")
B = TypeVar("B", bound="np.ndarray[Any, Any]")


def usable_cpus() -> int:
    """The CPUs this process may run on (a container's or taskset's share, not the machine's)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def run_threads() -> int:
    """How many threads one run uses (:data:`THREADS_ENV`, else the cores this process may use)."""
    given = os.environ.get(THREADS_ENV, "")
    if given.isdigit() and int(given) > 0:
        return int(given)
    return usable_cpus()


#: The threads the work of the calling thread may use (unset: the run's).
_share = threading.local()


@contextlib.contextmanager
def sharing_threads(count: int) -> Iterator[None]:
    """Within the block the calling thread's work is split over at most ``count`` threads: cameras measured at once
    share the run's threads (two cameras on two cores: one each, or splitting one's measurement only waits for the
    other's)."""
    before = getattr(_share, "count", None)
    _share.count = count
    try:
        yield
    finally:
        _share.count = before


def threads_here() -> int:
    """The threads the calling thread's work may be split over (:func:`sharing_threads`, else the run's)."""
    count = getattr(_share, "count", None)
    return run_threads() if count is None else int(count)


def split_over_threads(work: Callable[[T], R], parts: Sequence[T]) -> list[R]:
    """``work`` of each of ``parts``, at once on the process's pool of the run's threads, in their order (in turn in
    this thread when it may use one thread)."""
    if len(parts) < 2 or threads_here() < 2:
        return [work(part) for part in parts]
    return list(_shared_pool(run_threads()).map(work, parts))


def by_row_blocks(work: Callable[[slice], tuple[A, B]], rows: int, least: int) -> tuple[A, B]:
    """``work`` of blocks of the ``rows`` rows (``least`` rows at least each), one per thread the calling thread may
    use, at once, each of its two arrays joined back in the rows' order: ``work(slice(0, rows))`` with one thread or
    too few rows. When each row's arithmetic is its own, the numbers are those of one block, to the last bit."""
    blocks = min(threads_here(), rows // least)
    if blocks < 2:
        return work(slice(0, rows))
    edges = np.linspace(0, rows, blocks + 1).round().astype(int)
    done = split_over_threads(work, [slice(int(a), int(b)) for a, b in itertools.pairwise(edges)])
    return cast(A, np.concatenate([a for a, _ in done])), cast(B, np.concatenate([b for _, b in done]))


@functools.lru_cache(maxsize=1)
def _shared_pool(threads: int) -> ThreadPoolExecutor:
    """One pool for the process: cameras measured at once share it, their blocks waiting their turn."""
    return ThreadPoolExecutor(max_workers=threads, thread_name_prefix="framechain-split")


# -- forked processes ------------------------------------------------------------------------------------------------
def forks() -> bool:
    """Whether :func:`map_forked` forks here: on Linux (macOS's system libraries are not safe to use in a forked
    child, and Windows has no fork)."""
    return sys.platform.startswith("linux") and hasattr(os, "fork")


def map_forked(work: Callable[[T], R], items: Sequence[T], processes: int) -> list[R]:
    """``work`` of each item, in the items' order, each in a process forked from this one, at most ``processes`` at
    once; in this process, one after another, with one process or item, or where :func:`forks` is False.

    Why processes: two cameras measured on two threads of one process contend for the interpreter's lock (their
    Python between NumPy's passes), and a forked child starts with everything this process has imported and read
    (its pages shared until written), so it costs a few milliseconds, not an interpreter's start-up. A generated
    two-camera 224x224 episode: attributed in 2.16 s against 2.36 s on two threads (median of 10 alternations).

    A child runs ``work`` on none of this process's other threads (a pool it splits work over is its own). Its
    result, or its exception (with the child's traceback as a note, unless a user's mistake), comes back pickled
    (:func:`_portable`). An item whose child ends without a result (killed, crashed), or that no child could be
    forked for, is done here instead.
    """
    if processes < 2 or len(items) < 2 or not forks():
        return [work(item) for item in items]
    results: dict[int, tuple[bool, object]] = {}
    running: dict[int, tuple[int, int]] = {}  # item -> (pid, read end of its pipe)
    received: dict[int, bytearray] = {}
    pending = list(range(len(items)))
    with selectors.DefaultSelector() as selector:
        try:
            while pending or running:
                while pending and len(running) < processes:
                    index = pending.pop(0)
                    try:
                        running[index] = _fork(work, items[index])
                    except OSError:  # no process to be had (a limit reached): its item is done here
                        results[index] = (False, None)
                        continue
                    received[index] = bytearray()
                    selector.register(running[index][1], selectors.EVENT_READ, index)
                if not running:
                    break
                for key, _events in selector.select():
                    index = key.data
                    chunk = os.read(key.fd, 1 << 20)
                    if chunk:
                        received[index] += chunk
                        continue
                    selector.unregister(key.fd)
                    pid, read_end = running.pop(index)
                    os.close(read_end)
                    with contextlib.suppress(ChildProcessError):  # reaped already (SIGCHLD ignored)
                        os.waitpid(pid, 0)
                    results[index] = _reply(received.pop(index))
        finally:
            for pid, read_end in running.values():  # an error or Ctrl-C here: the children are not left running
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)
                    os.waitpid(pid, 0)
                os.close(read_end)
    return [_result(work, item, *results[index]) for index, item in enumerate(items)]


def _result(work: Callable[[T], R], item: T, done: bool, value: object) -> R:
    """An item's result from its child's reply: its value, its exception raised, or done here (no reply)."""
    if not done and value is None:
        return work(item)
    if not done:
        raise cast(BaseException, value)
    return cast(R, value)


def _fork(work: Callable[[T], R], item: T) -> tuple[int, int]:
    """A child doing ``work(item)`` and writing its pickled reply to a pipe: its pid and the pipe's read end."""
    read_end, write_end = os.pipe()
    # Ctrl-C is held until each side is where it can take it: the parent with the child known, the child inside the
    # block that always ends it (never in the parent's code).
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        with warnings.catch_warnings():
            # Python 3.12 warns of forking a process with threads (a lock another thread holds stays held in the
            # child): the child only runs ``work``, on none of those threads' locks.
            warnings.simplefilter("ignore", DeprecationWarning)
            pid = os.fork()
    except OSError:
        os.close(read_end)
        os.close(write_end)
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
        raise
    if pid:
        os.close(write_end)
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
        return pid, read_end
    status = 1
    try:  # the child: it never returns into the parent's code
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
        os.close(read_end)
        _shared_pool.cache_clear()  # the parent's pool threads are not in the child
        # Its warnings are shown by the parent (whose filters they meet there), not written to a stream whose lock
        # another of the parent's threads may have held at the fork.
        with warnings.catch_warnings(record=True) as caught:
            try:
                with sharing_threads(1):
                    reply: tuple[bool, object] = (True, work(item))
            except Exception as err:  # the parent raises it, with where it happened here
                if not isinstance(err, FramechainError):  # a user's mistake stays one line
                    err.add_note("".join(traceback.format_exception(err)).rstrip())
                reply = (False, _portable(err))
        shown = [(str(w.message), w.category, w.filename, w.lineno) for w in caught]
        data = pickle.dumps((*reply, shown), protocol=pickle.HIGHEST_PROTOCOL)
        view = memoryview(data)
        while view:
            view = view[os.write(write_end, view):]
        status = 0
    finally:
        os._exit(status)  # no interpreter teardown, no flush of buffers the parent will flush itself


def _portable(err: Exception) -> Exception:
    """``err`` when it survives pickling (every :class:`~framechain.errors.FramechainError` does), else its type's
    name and message in a RuntimeError."""
    try:
        pickle.loads(pickle.dumps(err, protocol=pickle.HIGHEST_PROTOCOL))
        return err
    except Exception:  # another library's exception whose arguments do not rebuild it
        return RuntimeError(f"{type(err).__name__}: {err}")


def _reply(data: bytearray) -> tuple[bool, object]:
    """A child's reply, its warnings shown here, or (False, None) when it ended without one."""
    try:
        done, value, shown = pickle.loads(data)
    except Exception:  # empty or cut short: the child died
        return False, None
    for message, category, filename, lineno in shown:
        warnings.warn_explicit(message, category, filename, lineno)
    return bool(done), value
