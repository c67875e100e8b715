"""Where a frame (a depth image or a camera image) lives in the log, and the small LRU reader that
fetches frames back on demand: lazy tables re-read a frame from the log only when it is needed."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

#: Fetches the decoded message at (topic, log_time_ns, ordinal among equal log times).
FrameFetch = Callable[[str, int, int], Any]

T = TypeVar("T")


@dataclass(frozen=True)
class FrameLocator:
    """Where a depth frame or an image lives in the log: topic, log time and its rank among equal log times."""

    topic: str
    log_time_ns: int
    ordinal: int


def cached_reader(read: Callable[[int], T], size: int) -> Callable[[int], T]:
    """``read(i)`` behind a small LRU cache: lazy tables re-read a frame from the log on demand, and
    replay and the sinks ask for the same few frames in a row. Safe from several threads (cameras measured at
    once): the cache is changed under a lock, and ``read`` guards its own reader."""
    cache: OrderedDict[int, T] = OrderedDict()
    lock = threading.Lock()

    def load(i: int) -> T:
        with lock:
            if i in cache:
                cache.move_to_end(i)
                return cache[i]
        out = read(i)
        with lock:
            cache[i] = out
            if len(cache) > size:
                cache.popitem(last=False)
        return out

    return load
