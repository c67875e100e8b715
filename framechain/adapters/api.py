"""``open_log`` and ``scan_log``: pick the reader by content, decode only what the chain needs."""

from __future__ import annotations

import os
import sys
import threading
import weakref
from collections.abc import Callable, Collection, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from framechain.adapters.errors import AdapterError, EmptyLogError, UnsupportedLogError
from framechain.adapters.formats.mcap import MCAP_MAGIC
from framechain.adapters.messages.collect import Collector
from framechain.adapters.messages.kinds import POSE_TYPES, Kind, normalize_msgtype, select_topics
from framechain.adapters.model import LoadedLog
from framechain.adapters.mounts import chain_additions
from framechain.config.chain import ChainConfig
from framechain.progress import Progress
from framechain.timeline import LogInfo, Timeline

if TYPE_CHECKING:
    from framechain.adapters.formats.mcap.reader import McapLog
    from framechain.adapters.formats.rosbag.reader import RosbagsLog

ROSBAG1_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
#: Logs with more messages than this get a progress bar when ``progress=True``.
PROGRESS_MIN_MESSAGES = 20_000


class LogAdapter(Protocol):
    """An extension point: another layout (e.g. LeRobot) registers itself with :func:`register_adapter`."""

    name: str

    def probe(self, path: Path) -> bool: ...

    def open(self, path: Path, chain: ChainConfig | None, *, progress: bool = False) -> LoadedLog: ...

    def scan(self, path: Path) -> LogInfo: ...


_ADAPTERS: list[LogAdapter] = []


def register_adapter(adapter: LogAdapter) -> None:
    """Add a reader for another layout; it is asked (``probe``) before the built-in ones."""
    if all(a.name != adapter.name for a in _ADAPTERS):
        _ADAPTERS.append(adapter)


def _plugin_for(path: Path) -> LogAdapter | None:
    return next((a for a in _ADAPTERS if a.probe(path)), None)


def detect(path: str | Path) -> tuple[str, Path, list[str]]:
    """(format, path to open, notes) by content: ``mcap``, ``rosbag1`` or ``rosbag2``."""
    p = Path(path)
    if not p.exists():
        raise AdapterError(p, "no such file or directory")
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return "rosbag2", p, []
        if (p / "meta" / "info.json").is_file():
            raise UnsupportedLogError(
                p, "a LeRobot dataset, not a log: read an episode with "
                "framechain.adapters.lerobot.adapter.open_dataset(path, episode=..., robot=robot.yaml)",
            )
        storage = sorted(p.glob("*.db3")) + sorted(p.glob("*.mcap"))
        if len(storage) == 1:
            fmt, target, notes = detect(storage[0])
            note = f"the directory has no metadata.yaml; read its only storage file {storage[0].name} directly"
            return fmt, target, [note, *notes]
        if storage:
            raise UnsupportedLogError(
                p, f"not a ROS 2 bag: metadata.yaml is missing and there are {len(storage)} storage files "
                f"({', '.join(s.name for s in storage[:4])}); open one of them directly",
            )
        raise UnsupportedLogError(p, "a directory that is not a bag (no metadata.yaml, .db3 or .mcap inside)")
    if p.name == "metadata.yaml":
        return "rosbag2", p.parent, []
    with p.open("rb") as f:
        head = f.read(16)
    if not head:
        raise EmptyLogError(p, "the file is empty (0 bytes)")
    if head.startswith(MCAP_MAGIC):
        return "mcap", p, []
    if head.startswith(ROSBAG1_MAGIC):
        if p.suffix != ".bag":
            raise UnsupportedLogError(p, "a ROS 1 bag whose name does not end in .bag; rename it to *.bag")
        return "rosbag1", p, []
    if head.startswith(b"#ROSBAG V"):
        version = head.split(b"\n")[0].decode("ascii", "replace")
        raise UnsupportedLogError(p, f"ROS 1 bag format {version!r} is not supported (only V2.0)")
    if head.startswith(SQLITE_MAGIC):
        return "rosbag2", p, []
    raise UnsupportedLogError(p, "not a log framechain can read (expected MCAP, a ROS 1 bag or a ROS 2 bag)")


@contextmanager
def _source(fmt: str, target: Path) -> Iterator[McapLog | RosbagsLog]:
    src = _reader(fmt, target)
    try:
        yield src
    finally:
        src.close()


def _reader(fmt: str, target: Path, summary: Any = None) -> McapLog | RosbagsLog:
    """The log's reader, imported only for the format at hand (a LeRobot run needs neither)."""
    if fmt == "mcap":
        from framechain.adapters.formats.mcap.reader import McapLog

        return McapLog(target, summary)
    from framechain.adapters.formats.rosbag.reader import RosbagsLog

    return RosbagsLog(target)


class _KeptOpenFetcher:
    """Fetches messages lazily from one log, keeping the reader (and its decoders) open between calls.

    Depth frames are fetched one at a time as observations need them; re-opening the file and
    rebuilding its decoders for every frame cost 50 ms a frame. The reader closes with this object.
    An MCAP is re-opened with the summary the read parsed (``summary``), not parsed again.
    """

    def __init__(self, fmt: str, target: Path, summary: Any = None) -> None:
        self._fmt = fmt
        self._target = target
        self._summary = summary
        self._log: McapLog | RosbagsLog | None = None
        self._finalizer: weakref.finalize[Any, Any] | None = None
        self._lock = threading.Lock()
        _FETCHERS.add(self)

    def forget_reader(self) -> None:
        """In a process forked from the one that opened the reader: open one of its own when next asked. The
        inherited reader shares its file position with the parent's and the other children's (a camera measured in
        each, :func:`framechain.vision.threads.map_forked`), and its lock may have been held by a thread the fork
        did not copy; it is left to the parent to close."""
        if self._finalizer is not None:
            self._finalizer.detach()
        self._log, self._finalizer, self._lock = None, None, threading.Lock()

    def __call__(self, topic: str, log_time_ns: int, ordinal: int) -> Any:
        with self._lock:  # one reader, one file position: cameras measured in threads fetch in turn
            if self._log is None:
                self._log = _reader(self._fmt, self._target, self._summary)
                self._finalizer = weakref.finalize(self, self._log.close)
            return self._log.fetch(topic, log_time_ns, ordinal)


#: Every fetcher alive, so that a forked child opens its own readers (:meth:`_KeptOpenFetcher.forget_reader`).
_FETCHERS: weakref.WeakSet[_KeptOpenFetcher] = weakref.WeakSet()


def _forget_readers_in_child() -> None:
    for fetcher in list(_FETCHERS):
        fetcher.forget_reader()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_readers_in_child)


def _fetcher(fmt: str, target: Path, summary: Any = None) -> Callable[[str, int, int], Any]:
    return _KeptOpenFetcher(fmt, target, summary)


def scan_log(path: str | Path) -> LogInfo:
    """What a log holds (format, span, topics with types, counts, rates) from its index."""
    p = Path(path)
    plugin = _plugin_for(p)
    if plugin is not None:
        return plugin.scan(p)
    fmt, target, notes = detect(p)
    with _source(fmt, target) as src:
        return src.info().with_notes(notes)


def open_log(
    path: str | Path, chain: ChainConfig | None = None, *, progress: bool | Progress = False,
    kinds: Collection[str] | None = None, point_roles: Callable[[LogInfo], Mapping[str, str]] | None = None,
) -> LoadedLog:
    """Read a log into the Timeline: only the topics ``chain`` needs (all it understands if None).

    ``kinds`` narrows further to some message kinds (:class:`Kind` values, e.g. ``{"tf"}``);
    ``progress`` shows a progress bar on stderr for large logs (True), or is told the messages read (a
    :class:`~framechain.progress.Progress`); ``point_roles``, given what the log
    holds, names point topics to read as evidence beside the chain's, with their roles (a suggested
    chain's evidence, so that a log without a chain is read once).

    Every table comes in log-time order (ties: by topic, then file order). Depth pixels stay in
    the log until :meth:`DepthFrameTable.load` asks for a frame.
    """
    p = Path(path)
    plugin = _plugin_for(p)
    if plugin is not None:
        return plugin.open(p, chain, progress=progress is True)
    fmt, target, notes = detect(p)
    additions = chain_additions(chain)  # a missing calibration file fails before the log is read
    if chain is not None and chain.evidence.markers is not None:  # a bad dictionary too, naming the chain file
        from framechain.vision.markers import dictionary_id

        dictionary_id(chain.evidence.markers.dictionary, where=str(chain_file(chain)))
    notes.extend(additions.notes)
    col = Collector(chain)
    col.chain_edges.extend(additions.edges)
    col.file_cameras.extend(additions.cameras)
    with _source(fmt, target) as src:
        info = src.info().with_notes(notes)
        types = {t.name: normalize_msgtype(t.msgtype) for t in info.topics}
        selected = _selected_topics(types, info, chain, col, kinds=kinds, point_roles=point_roles)
        if chain is not None:
            notes.extend(_check_chain_topics(chain, types))
        total = sum(t.count for t in info.topics if t.name in selected)
        if callable(progress):
            _read_told(src, selected, col, progress, total, f"reading {p.name}")
        else:
            with _progress(progress and total >= PROGRESS_MIN_MESSAGES, total, p.name) as advance:
                src.read(selected, col, advance)
        info = info.with_notes(src.notes)
        summary = getattr(src, "summary", None)
    col.notes[:0] = notes
    if chain is not None and chain.topics.detections_table:
        from framechain.adapters.messages.side_table import read_side_table, resolve_side_table

        table_path = resolve_side_table(chain.topics.detections_table, p)
        col.add_side_detections(read_side_table(table_path), table_path.name)
    metadata: dict[str, Any] = {
        "source_path": str(p), "format": info.format, "container": info.container,
        "start_ns": info.start_ns, "end_ns": info.end_ns,
    }
    timeline, found = col.build(_fetcher(fmt, target, summary), metadata)
    info = info.with_notes(found)
    timeline = timeline.replace(metadata={**timeline.metadata, "notes": list(info.notes)})
    if chain is not None:
        _check_camera_models(p, chain, timeline, info)
    return LoadedLog(timeline=timeline, info=info, decoded_topics={t: k.value for t, k in selected.items()})


def _check_camera_models(path: Path, chain: ChainConfig, timeline: Timeline, info: LogInfo) -> None:
    """The chain's CameraInfo topic gave no usable camera model: an error saying why (from the reader's notes)."""
    if chain.topics.camera_info and not len(timeline.cameras):
        bad = [n for n in info.notes if chain.topics.camera_info in n]
        if bad:
            raise AdapterError(path, bad[0].split(": ", 1)[-1] + "; no usable camera model",
                               topic=chain.topics.camera_info)


def _selected_topics(
    types: dict[str, str], info: LogInfo, chain: ChainConfig | None, col: Collector, *,
    kinds: Collection[str] | None, point_roles: Callable[[LogInfo], Mapping[str, str]] | None,
) -> dict[str, Kind]:
    """Topic -> kind of the topics to decode (``types``: topic -> normalised type): those ``chain`` needs, the
    point topics ``point_roles`` names (their roles given to ``col``), narrowed to ``kinds``."""
    selected = select_topics(types, chain)
    if point_roles is not None:  # read as a chain naming them would: as points, with their roles
        extra = {t: r for t, r in point_roles(info).items() if t in types}
        selected.update(dict.fromkeys(extra, Kind.POINT))
        col.roles = {**col.roles, **extra}
    if kinds is not None:
        wanted = {Kind(k) for k in kinds}
        selected = {t: k for t, k in selected.items() if k in wanted}
    return selected


def chain_file(chain: ChainConfig) -> Path | str:
    """The chain's file (its directory and name) for error messages, or "chain" when it came from no file."""
    if chain.origin == "chain":
        return "chain"
    return Path(chain.base_dir) / chain.origin if chain.base_dir else Path(chain.origin)


def _check_chain_topics(chain: ChainConfig, types: dict[str, str]) -> list[str]:
    """A note per topic the chain names that the log does not have."""
    t = chain.topics
    wanted = [
        (t.camera_info, "camera_info"), (t.detections, "detections"), (t.depth, "depth"),
        (t.pixel_points, "pixel_points"), *((p.topic, "odometry") for p in chain.pose_topics()),
        *((topic, f"evidence {role}") for topic, role in chain.evidence_topics().items()),
        *((topic, f"camera {c.frame}'s topic") for c in chain.cameras for topic in c.topics()),
    ]
    notes = [f"topic {topic}: named by the chain as {slot} but not in the log" for topic, slot in wanted
             if topic and topic not in types]
    evidence = chain.evidence_topics()
    notes.extend(
        f"topic {p.topic}: named by the chain as odometry but its type {types[p.topic]} is not a pose "
        f"({', '.join(sorted(POSE_TYPES))}); not read" for p in chain.pose_topics()
        if p.topic in types and types[p.topic] not in POSE_TYPES and p.topic not in evidence
    )
    return notes


def _read_told(src: McapLog | RosbagsLog, selected: dict[str, Kind], col: Collector, progress: Progress,
               total: int, stage: str) -> None:
    """Read, telling ``progress`` how many of the index's ``total`` messages are read."""
    done = 0

    def advance(n: int) -> None:
        nonlocal done
        done = min(done + n, total)
        progress(stage, done, total, "messages")

    progress(stage, 0, total, "messages")
    src.read(selected, col, advance)
    progress(stage, total, total, "messages")


@contextmanager
def _progress(enabled: bool, total: int, label: str) -> Iterator[Callable[[int], None] | None]:
    if not enabled:
        yield None
        return
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(
        TextColumn(f"reading {label}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
        console=Console(file=sys.stderr), transient=True,
    ) as bar:
        task = bar.add_task("read", total=total)
        yield lambda n: bar.advance(task, n)


#: The kinds that make the frame tree (what ``framechain tf`` reads).
TREE_KINDS = frozenset({Kind.TF.value, Kind.TRANSFORM.value, Kind.ODOMETRY.value, Kind.POSE.value,
                        Kind.RS_EXTRINSIC.value, Kind.URDF.value})
