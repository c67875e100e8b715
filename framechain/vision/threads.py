"""How many threads one run's image work may use, and the pool its measurements are split over.

A command runs one episode on every core the process may use: its cameras are measured on threads of
their own (:func:`framechain.analysis.egomotion.run.measure_cameras`), and one camera's frame pairs are
split into blocks measured at once (:func:`framechain.vision.two_view.rotations_along_translation`:
NumPy releases the interpreter's lock for each pass over a block). A batch's worker processes run an
episode per core already, and set :data:`THREADS_ENV` to 1.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar, cast

import numpy as np

__all__ = ["THREADS_ENV", "by_row_blocks", "run_threads", "sharing_threads", "split_over_threads", "threads_here",
           "usable_cpus"]

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
