"""The one decode loop every reader runs: raw messages in, the collector's rows and notes out.

Each reader (the MCAP reader, indexed or scanning a damaged file; rosbags' reader; the ROS 1 and
ROS 2 salvage scanners) yields its messages as ``(key, log time, payload)``, the key naming a
channel or connection, and says once per key how that key's messages reach the collector: a
:class:`Route` (topic, decoder, handler and, for types :mod:`fast_cdr` knows, how to decode many
at a time), or None to pass them by. The loop keeps the routes, hands each message on, counts
per topic the messages that fail to decode (one bad message never ends a read) and writes the
notes: a topic skipped for its schema, messages that could not be decoded.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Hashable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from framechain.adapters.errors import SchemaError
from framechain.adapters.formats.decoders import Decoder
from framechain.adapters.formats.fast_cdr import Feeder, KnownLayouts, LayoutError, decode_batches
from framechain.adapters.messages.collect import OBSERVATION_KINDS, Collector
from framechain.adapters.messages.kinds import Kind

Handler = Callable[[str, int, Any], None]
ProgressFn = Callable[[int], None]
#: Messages of a route gathered before they are decoded together (bounds the memory they hold).
BATCH_MESSAGES = 8192
#: Progress is reported every this many messages.
PROGRESS_STEP = 4096


@dataclass(frozen=True)
class Batched:
    """How a route's messages are decoded many at a time by their byte layout (:mod:`fast_cdr`)."""

    store: Any  # the rosbags typestore defining the type
    typename: str  # rosbags' spelling, pkg/msg/Type
    ros1: bool
    feeder: Feeder
    layouts: KnownLayouts = field(default_factory=dict, compare=False)  # met so far (filled as the read goes)


@dataclass(frozen=True, slots=True)
class Route:
    """Where the messages of one channel or connection go."""

    topic: str
    kind: Kind
    decode: Decoder
    handle: Handler
    batched: Batched | None = None


@dataclass(slots=True)
class _Waiting:
    """A batched route's messages waiting to be decoded together."""

    route: Route
    log_times: list[int] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)


class DecodeLoop:
    """Hands a reader's messages to the collector; see the module docstring.

    ``resolve(key)`` gives a key's route (None: not read); a :class:`SchemaError` it raises
    becomes the note "<what>: topic <topic> skipped". ``skip`` holds (topic, log time) pairs
    already delivered by an earlier read that stopped at damage: they are passed by, once each.
    With ``count_delivered``, :attr:`delivered` counts the pairs this loop hands on.
    """

    def __init__(self, col: Collector, resolve: Callable[[Any], Route | None], progress: ProgressFn | None = None,
                 *, skip: Counter[tuple[str, int]] | None = None, count_delivered: bool = False) -> None:
        self.col = col
        self._resolve = resolve
        self._progress = progress
        self._skip = skip
        self._count_delivered = count_delivered
        self.delivered: Counter[tuple[str, int]] = Counter()
        self._routes: dict[Hashable, Route | None] = {}
        self._waiting: dict[Hashable, _Waiting] = {}
        self._failures: Counter[str] = Counter()
        self._first_error: dict[str, str] = {}

    def route(self, key: Hashable) -> Route | None:
        """The route of ``key``, resolved on first use."""
        if key in self._routes:
            return self._routes[key]
        try:
            route = self._resolve(key)
        except SchemaError as err:
            note = f"{err.what}: topic {err.topic} skipped"
            if note not in self.col.notes:
                self.col.notes.append(note)
            route = None
        self._routes[key] = route
        if route is not None and route.batched is not None:
            self._waiting[key] = _Waiting(route)
        return route

    def run(self, messages: Iterable[tuple[Hashable, Any, bytes | memoryview]]) -> None:
        """Hand on every message of ``messages``; the batched ones wait for :meth:`flush`."""
        routes, waiting, skip, progress = self._routes, self._waiting, self._skip, self._progress
        delivered = self.delivered if self._count_delivered else None
        self.col.flush_observations = self._flush_observations
        done = 0
        try:
            for key, log_time, data in messages:
                route = routes[key] if key in routes else self.route(key)
                if route is None:
                    continue
                topic = route.topic
                if not isinstance(log_time, int):  # a damaged sqlite row: its timestamp is not a number
                    self._fail(topic, _damaged_stamp(log_time))
                    continue
                if skip is not None and skip[(topic, log_time)] > 0:
                    skip[(topic, log_time)] -= 1
                    continue
                if delivered is not None:
                    delivered[(topic, log_time)] += 1
                batch = waiting.get(key)
                if batch is not None:
                    batch.log_times.append(log_time)
                    batch.payloads.append(bytes(data))
                    if len(batch.payloads) >= BATCH_MESSAGES:
                        self._feed(batch)
                else:
                    self._handle(route, log_time, data)
                done += 1
                if progress is not None and done % PROGRESS_STEP == 0:
                    progress(PROGRESS_STEP)
        finally:
            self.col.flush_observations = None

    def flush(self) -> None:
        """Decode every batched message still waiting."""
        for batch in self._waiting.values():
            self._feed(batch)

    def finish(self, reader_notes: Sequence[str] = ()) -> None:
        """Flush, note the messages that could not be decoded, then the reader's notes not yet made."""
        self.flush()
        notes = self.col.notes
        for topic, n in self._failures.items():
            notes.append(f"topic {topic}: {n} message{'s' if n != 1 else ''} could not be decoded "
                         f"({self._first_error[topic]}); skipped")
        notes.extend(n for n in reader_notes if n not in notes)

    def _handle(self, route: Route, log_time: int, data: bytes | memoryview) -> None:
        try:
            route.handle(route.topic, log_time, route.decode(data))
        except Exception as err:  # one undecodable message must not end the read
            self._fail(route.topic, f"{type(err).__name__}: {err}")

    def _fail(self, topic: str, why: str) -> None:
        self._failures[topic] += 1
        self._first_error.setdefault(topic, why)

    def _feed(self, batch: _Waiting) -> None:
        """Decode a route's waiting messages by layout; the rest one by one, in file order."""
        if not batch.payloads:
            return
        route = batch.route
        fast = route.batched
        assert fast is not None
        log_times = np.asarray(batch.log_times, dtype=np.int64)
        batches, rest = decode_batches(fast.store, fast.typename, batch.payloads, ros1=fast.ros1, known=fast.layouts)
        slow = [rest]
        for b in batches:
            try:
                fast.feeder(self.col, route.topic, log_times[b.rows], b)
            except (KeyError, LayoutError):  # a layout without the fields the feeder reads
                slow.append(b.rows)
        for row in np.sort(np.concatenate(slow)).tolist():
            self._handle(route, int(log_times[row]), batch.payloads[row])
        batch.log_times.clear()
        batch.payloads.clear()

    def _flush_observations(self) -> None:
        """Decode the waiting detections: the depth keeper needs them before it cuts windows."""
        for batch in self._waiting.values():
            if batch.route.kind in OBSERVATION_KINDS:
                self._feed(batch)


def _damaged_stamp(log_time: Any) -> str:
    if isinstance(log_time, bytes | bytearray | memoryview):
        return f"damaged row: its timestamp {bytes(log_time)[:16]!r} is not a number"
    return f"damaged row: its timestamp {log_time!r} is not a number"
