"""The rows of one log as it is read, one accumulator per table, each built into its table once.

An accumulator keeps a Python list per column: the message handlers and the layout feeders
(:mod:`framechain.adapters.formats.fast_cdr`) append primitives, never a row object, and
:meth:`table` turns the lists into arrays in one conversion per column. Tables come back in
canonical order: log time, then topic, file order within a topic. What the building drops or
reorders is said in ``notes``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.messages.locator import FrameLocator
from framechain.timeline import (
    CameraTable,
    JointStateTable,
    ObservationTable,
    PointTable,
    TransformTable,
    normalize_frames,
)
from framechain.timeline.tables import MAX_DISTORTION_COEFFS, QUATERNION_NORM_TOLERANCE


def log_order(log_time_ns: npt.NDArray[np.int64], source: npt.NDArray[np.str_]) -> npt.NDArray[np.intp]:
    """Stable order by log time, then topic; file order within a topic is kept."""
    return np.lexsort((source, log_time_ns))


@dataclass
class TransformRows:
    """Edge samples: per row its frames, header stamp and seven values; per message its log time,
    row count, static flag, topic and kind (``"tf"``, or ``"odometry"``: those yield to /tf)."""

    parent: list[str] = field(default_factory=list)
    child: list[str] = field(default_factory=list)
    stamp_ns: list[int] = field(default_factory=list)
    values: list[float] = field(default_factory=list)  # x y z qx qy qz qw per row
    message_log_ns: list[int] = field(default_factory=list)
    message_rows: list[int] = field(default_factory=list)
    message_static: list[bool] = field(default_factory=list)
    message_topic: list[str] = field(default_factory=list)
    message_kind: list[str] = field(default_factory=list)

    def end_message(self, topic: str, log_ns: int, rows: int, *, static: bool, kind: str = "tf") -> None:
        """Close a message whose ``rows`` edge rows were just appended."""
        self.message_log_ns.append(log_ns)
        self.message_rows.append(rows)
        self.message_static.append(static)
        self.message_topic.append(topic)
        self.message_kind.append(kind)

    def add_edge(self, topic: str, log_ns: int, parent: str, child: str, stamp_ns: int, values: Iterable[float], *,
                 static: bool, kind: str = "tf") -> None:
        """A message of one edge sample."""
        self.parent.append(parent)
        self.child.append(child)
        self.stamp_ns.append(stamp_ns)
        self.values.extend(values)
        self.end_message(topic, log_ns, 1, static=static, kind=kind)

    def extend_messages(self, topic: str, log_ns: Sequence[int], rows_per_message: int, *, parent: list[str],
                        child: list[str], stamp_ns: list[int], values: list[float], static: bool) -> None:
        """Many /tf messages of one topic with the same row count, rows message after message."""
        n = len(log_ns)
        self.parent.extend(parent)
        self.child.extend(child)
        self.stamp_ns.extend(stamp_ns)
        self.values.extend(values)
        self.message_log_ns.extend(log_ns)
        self.message_rows.extend([rows_per_message] * n)
        self.message_static.extend([static] * n)
        self.message_topic.extend([topic] * n)
        self.message_kind.extend(["tf"] * n)

    def table(self, notes: list[str]) -> TransformTable:
        """The edges, less odometry that /tf also carries, a second odometry topic of one child, and
        samples that are not finite or not unit quaternions (each said in ``notes``)."""
        if not self.message_rows:
            return TransformTable.empty()
        rows = np.asarray(self.message_rows, dtype=np.int64)
        vals = np.asarray(self.values, dtype=np.float64).reshape(-1, 7)
        parent = normalize_frames(self.parent)
        child = normalize_frames(self.child)
        stamp = np.asarray(self.stamp_ns, dtype=np.int64)
        log = np.repeat(np.asarray(self.message_log_ns, dtype=np.int64), rows)
        static = np.repeat(np.asarray(self.message_static, dtype=bool), rows)
        topic = np.repeat(np.asarray(self.message_topic, dtype=str), rows)
        kind = np.repeat(np.asarray(self.message_kind, dtype=str), rows)
        keep = _odometry_kept(parent, child, topic, kind == "odometry", notes)
        finite = np.isfinite(vals).all(axis=1)
        norm = np.linalg.norm(vals[:, 3:], axis=1)
        unit = np.abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE
        for mask, what in ((~finite, "translation or rotation NaN or Inf"),
                           (finite & ~unit, "quaternion not unit length")):
            bad = mask & keep
            if bad.any():
                for (t, p, c), count in Counter(zip(topic[bad].tolist(), parent[bad].tolist(), child[bad].tolist(),
                                                    strict=True)).items():
                    first = int(stamp[bad & (topic == t) & (parent == p) & (child == c)][0])
                    notes.append(
                        f"topic {t}: {count} transform{'s' if count != 1 else ''} {p} -> {c} with {what} dropped "
                        f"(first at stamp {first * 1e-9:.9f} s)"
                    )
                keep &= ~mask
        table = TransformTable(parent=parent[keep], child=child[keep], stamp_ns=stamp[keep], log_time_ns=log[keep],
                               translation=vals[keep, :3], quat_xyzw=vals[keep, 3:], is_static=static[keep],
                               source=topic[keep])
        _note_backwards(table, notes)
        return table.take(log_order(table.log_time_ns, table.source))


def _odometry_kept(parent: npt.NDArray[np.str_], child: npt.NDArray[np.str_], topic: npt.NDArray[np.str_],
                   odom: npt.NDArray[np.bool_], notes: list[str]) -> npt.NDArray[np.bool_]:
    """Rows to keep: odometry carries an edge only where /tf does not, and from one topic per child."""
    keep = np.ones(child.size, dtype=bool)
    if not odom.any():
        return keep
    tf_children = set(child[~odom].tolist())
    dup = odom & np.isin(child, list(tf_children))
    for t in np.unique(topic[dup]).tolist():
        sel = dup & (topic == t)
        notes.append(f"topic {t}: odometry edge {parent[sel][0]} -> {child[sel][0]} is also on /tf; "
                     "the /tf samples are used")
    keep &= ~dup
    # Two odometry topics for one child: keep the one with most samples.
    sel_odom = odom & keep
    owners: dict[str, str] = {}
    for c in np.unique(child[sel_odom]).tolist():
        ts, counts = np.unique(topic[sel_odom & (child == c)], return_counts=True)
        owners[c] = str(ts[np.argmax(counts)])
        for other in ts.tolist():
            if other != owners[c]:
                notes.append(f"topic {other}: odometry for {c!r} also comes from {owners[c]}; {owners[c]} is used")
    for c, t in owners.items():
        keep &= ~(sel_odom & (child == c) & (topic != t))
    return keep


def _note_backwards(table: TransformTable, notes: list[str]) -> None:
    dyn = ~table.is_static
    if not dyn.any():
        return
    key = np.char.add(np.char.add(table.parent[dyn], "\x1f"), table.child[dyn])
    order = np.lexsort((table.log_time_ns[dyn], key))
    k, s = key[order], table.stamp_ns[dyn][order]
    back = (k[1:] == k[:-1]) & (s[1:] < s[:-1])
    if back.any():
        for name, count in Counter(k[1:][back].tolist()).items():
            p, _, c = name.partition("\x1f")  # a damaged log's names may hold the separator
            notes.append(
                f"edge {p} -> {c}: header stamps go backwards {count} time{'s' if count != 1 else ''} in log order; "
                "samples are ordered by stamp for lookups"
            )


@dataclass
class CameraRows:
    """Camera models as logged: frame, stamps, size, distortion model, topic, K (9) and D per row."""

    frame: list[str] = field(default_factory=list)
    stamp_ns: list[int] = field(default_factory=list)
    log_time_ns: list[int] = field(default_factory=list)
    width: list[int] = field(default_factory=list)
    height: list[int] = field(default_factory=list)
    model: list[str] = field(default_factory=list)
    topic: list[str] = field(default_factory=list)
    k: list[list[float]] = field(default_factory=list)
    d: list[list[float]] = field(default_factory=list)

    def append(self, topic: str, log_ns: int, frame: str, stamp_ns: int, width: int, height: int, model: str,
               k: Iterable[Any], d: Iterable[Any]) -> None:
        self.extend(topic, [log_ns], frame=[frame], stamp_ns=[stamp_ns], width=[width], height=[height],
                    model=[model], k=[[float(x) for x in k]], d=[[float(x) for x in d]])

    def extend(self, topic: str, log_ns: Sequence[int], *, frame: list[str], stamp_ns: list[int], width: list[int],
               height: list[int], model: list[str], k: list[list[float]], d: list[list[float]]) -> None:
        self.frame.extend(frame)
        self.stamp_ns.extend(stamp_ns)
        self.log_time_ns.extend(log_ns)
        self.width.extend(width)
        self.height.extend(height)
        self.model.extend(model)
        self.topic.extend([topic] * len(log_ns))
        self.k.extend(k)
        self.d.extend(d)

    def table(self, notes: list[str]) -> CameraTable:
        """The usable models (an uncalibrated camera's K is all zero: dropped, and said in ``notes``)."""
        if not self.frame:
            return CameraTable.empty()
        kk = np.array([k if len(k) == 9 else [0.0] * 9 for k in self.k], dtype=np.float64).reshape(-1, 3, 3)
        n_d = np.array([min(len(d), MAX_DISTORTION_COEFFS) for d in self.d], dtype=np.int64)
        dist = np.zeros((len(self.d), MAX_DISTORTION_COEFFS))
        for i, d in enumerate(self.d):
            dist[i, : n_d[i]] = d[:MAX_DISTORTION_COEFFS]
        usable = np.isfinite(kk).all(axis=(1, 2)) & kk.any(axis=(1, 2)) & (kk[:, 0, 0] > 0) & (kk[:, 1, 1] > 0)
        topics = np.asarray(self.topic, dtype=str)
        if not usable.all():
            for t, count in Counter(topics[~usable].tolist()).items():
                notes.append(
                    f"topic {t}: {count} CameraInfo with K all zero or focal lengths not positive "
                    "(an uncalibrated camera) dropped"
                )
        models = np.asarray([_distortion_model_name(m) for m in self.model], dtype=str)
        table = CameraTable(frame=np.asarray(self.frame, dtype=str), stamp_ns=np.asarray(self.stamp_ns, dtype=np.int64),
                            log_time_ns=np.asarray(self.log_time_ns, dtype=np.int64),
                            width=np.asarray(self.width, dtype=np.int64),
                            height=np.asarray(self.height, dtype=np.int64),
                            K=np.where(usable[:, None, None], kk, np.eye(3)), distortion_model=models,
                            distortion=dist, n_distortion=n_d, source=topics).take(usable)
        return table.take(log_order(table.log_time_ns, table.source))


def _distortion_model_name(model: str) -> str:
    """ROS names; librealsense's "Brown Conrady" is plumb_bob, empty is none."""
    low = model.strip().lower()
    if not low:
        return "none"
    if low in ("brown conrady", "brown_conrady", "modified brown conrady"):
        return "plumb_bob"
    if low in ("kannala_brandt", "fisheye", "equidistant"):
        return "equidistant"
    return model.strip()


@dataclass
class ObservationRows:
    """Pixel observations: the detector's id as text, stamps, camera frame, (u, v, depth), label, score."""

    id_text: list[str] = field(default_factory=list)
    stamp_ns: list[int] = field(default_factory=list)
    log_time_ns: list[int] = field(default_factory=list)
    frame: list[str] = field(default_factory=list)
    uvd: list[float] = field(default_factory=list)  # u v depth_m per row
    label: list[str] = field(default_factory=list)
    score: list[float] = field(default_factory=list)
    topic: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.stamp_ns)

    def append(self, topic: str, log_ns: int, ident: str, stamp_ns: int, frame: str, u: float, v: float,
               depth_m: float, label: str, score: float) -> None:
        self.id_text.append(ident)
        self.stamp_ns.append(stamp_ns)
        self.log_time_ns.append(log_ns)
        self.frame.append(frame)
        self.uvd.extend((u, v, depth_m))
        self.label.append(label)
        self.score.append(score)
        self.topic.append(topic)

    def extend(self, topic: str | list[str], *, id_text: list[str], stamp_ns: list[int], log_time_ns: list[int],
               frame: list[str], uvd: list[float], label: list[str], score: list[float]) -> None:
        """Many rows; ``topic`` one for all or one per row."""
        self.id_text.extend(id_text)
        self.stamp_ns.extend(stamp_ns)
        self.log_time_ns.extend(log_time_ns)
        self.frame.extend(frame)
        self.uvd.extend(uvd)
        self.label.extend(label)
        self.score.extend(score)
        self.topic.extend([topic] * len(stamp_ns) if isinstance(topic, str) else topic)

    def pixels(self, start: int, end: int) -> tuple[list[str], list[int], list[int], npt.NDArray[np.float64]]:
        """Frame, stamp, log time and (u, v, depth) of rows ``start:end`` (what the depth keeper needs)."""
        uvd = np.asarray(self.uvd[3 * start : 3 * end], dtype=np.float64).reshape(-1, 3)
        return self.frame[start:end], self.stamp_ns[start:end], self.log_time_ns[start:end], uvd

    def table(self, notes: list[str]) -> tuple[ObservationTable, npt.NDArray[np.int64]]:
        """The table, and every row's obs_id in append order: the detector's numeric ids when they are
        unique, the others numbered after them in log order."""
        n = len(self.stamp_ns)
        if n == 0:
            return ObservationTable.empty(), np.zeros(0, dtype=np.int64)
        ids = np.full(n, -1, dtype=np.int64)
        numeric = np.array([t.strip().lstrip("-").isdigit() for t in self.id_text])
        if numeric.any():
            ids[numeric] = [int(t) for t, ok in zip(self.id_text, numeric, strict=True) if ok]
        if np.unique(ids[numeric]).size != int(numeric.sum()):
            notes.append("detection ids repeat (tracking ids?); observations are numbered in log order instead")
            numeric[:] = False
        start = int(ids[numeric].max()) + 1 if numeric.any() else 0
        ids[~numeric] = np.arange(start, start + int((~numeric).sum()))
        uvd = np.asarray(self.uvd, dtype=np.float64).reshape(-1, 3)
        table = ObservationTable(
            obs_id=ids.copy(), stamp_ns=np.asarray(self.stamp_ns, dtype=np.int64),
            log_time_ns=np.asarray(self.log_time_ns, dtype=np.int64), camera_frame=np.asarray(self.frame, dtype=str),
            u=uvd[:, 0], v=uvd[:, 1], depth_m=uvd[:, 2], label=np.asarray(self.label, dtype=str),
            score=np.asarray(self.score, dtype=np.float64), source=np.asarray(self.topic, dtype=str),
        )
        return table.take(log_order(table.log_time_ns, table.source)), ids


@dataclass
class PointRows:
    """Logged points: frame, stamps, (x y z qx qy qz qw) with NaN rotation for a bare point, topic."""

    frame: list[str] = field(default_factory=list)
    stamp_ns: list[int] = field(default_factory=list)
    log_time_ns: list[int] = field(default_factory=list)
    values: list[float] = field(default_factory=list)
    topic: list[str] = field(default_factory=list)

    def append(self, topic: str, log_ns: int, frame: str, stamp_ns: int, values: Iterable[float]) -> None:
        self.frame.append(frame)
        self.stamp_ns.append(stamp_ns)
        self.log_time_ns.append(log_ns)
        self.values.extend(values)
        self.topic.append(topic)

    def extend(self, topic: str, log_ns: Sequence[int], *, frame: list[str], stamp_ns: list[int],
               values: list[float]) -> None:
        self.frame.extend(frame)
        self.stamp_ns.extend(stamp_ns)
        self.log_time_ns.extend(log_ns)
        self.values.extend(values)
        self.topic.extend([topic] * len(log_ns))

    def table(self, roles: Mapping[str, str]) -> PointTable:
        """The points, each with its topic's role (``reference`` when the chain names none)."""
        n = len(self.stamp_ns)
        if n == 0:
            return PointTable.empty()
        vals = np.asarray(self.values, dtype=np.float64).reshape(-1, 7)
        topics = np.asarray(self.topic, dtype=str)
        role = np.asarray([roles.get(t, "reference") for t in self.topic], dtype=str)
        table = PointTable(frame=np.asarray(self.frame, dtype=str), stamp_ns=np.asarray(self.stamp_ns, dtype=np.int64),
                           log_time_ns=np.asarray(self.log_time_ns, dtype=np.int64), xyz=vals[:, :3],
                           quat_xyzw=vals[:, 3:], role=role, obs_id=np.full(n, -1, dtype=np.int64), source=topics)
        return table.take(log_order(table.log_time_ns, table.source))


@dataclass
class JointRows:
    """Joint states in long form: per message its stamps, topic and joint count; per joint its name
    and position, velocity and effort (an array per message)."""

    stamp_ns: list[int] = field(default_factory=list)
    log_time_ns: list[int] = field(default_factory=list)
    rows: list[int] = field(default_factory=list)
    topic: list[str] = field(default_factory=list)
    name: list[str] = field(default_factory=list)
    position: list[npt.NDArray[np.float64]] = field(default_factory=list)
    velocity: list[npt.NDArray[np.float64]] = field(default_factory=list)
    effort: list[npt.NDArray[np.float64]] = field(default_factory=list)

    def append(self, topic: str, log_ns: int, stamp_ns: int, names: list[str], position: Any, velocity: Any,
               effort: Any) -> None:
        """One message; a position, velocity or effort of another length than ``names`` is padded with NaN."""
        n = len(names)
        position, velocity, effort = _fit(position, n), _fit(velocity, n), _fit(effort, n)
        self.stamp_ns.append(stamp_ns)
        self.log_time_ns.append(log_ns)
        self.rows.append(n)
        self.topic.append(topic)
        self.name.extend(names)
        self.position.append(position)
        self.velocity.append(velocity)
        self.effort.append(effort)

    def table(self) -> JointStateTable:
        if not self.rows:
            return JointStateTable.empty()
        rows = np.asarray(self.rows, dtype=np.int64)
        table = JointStateTable(
            stamp_ns=np.repeat(np.asarray(self.stamp_ns, dtype=np.int64), rows),
            log_time_ns=np.repeat(np.asarray(self.log_time_ns, dtype=np.int64), rows),
            joint=np.asarray(self.name, dtype=str),
            position=np.concatenate(self.position), velocity=np.concatenate(self.velocity),
            effort=np.concatenate(self.effort), source=np.repeat(np.asarray(self.topic, dtype=str), rows),
        )
        return table.take(log_order(table.log_time_ns, table.source))


def _fit(values: Any, n: int) -> npt.NDArray[np.float64]:
    arr = np.asarray(values, dtype=np.float64).reshape(-1)
    if arr.size == n:
        return arr
    out = np.full(n, np.nan)
    out[: min(arr.size, n)] = arr[:n]
    return out


@dataclass
class FrameRows:
    """Depth or camera images, metadata only: frame, stamps, size, encoding, topic, and where each
    lives in the log (its pixels stay there until a lazy table fetches them)."""

    frame: list[str] = field(default_factory=list)
    stamp_ns: list[int] = field(default_factory=list)
    log_time_ns: list[int] = field(default_factory=list)
    width: list[int] = field(default_factory=list)
    height: list[int] = field(default_factory=list)
    encoding: list[str] = field(default_factory=list)
    topic: list[str] = field(default_factory=list)
    locators: list[FrameLocator] = field(default_factory=list)
    _seen: Counter[tuple[str, int]] = field(default_factory=Counter)

    def __len__(self) -> int:
        return len(self.frame)

    def append(self, topic: str, log_ns: int, frame: str, stamp_ns: int, width: int, height: int,
               encoding: str) -> None:
        self.frame.append(frame)
        self.stamp_ns.append(stamp_ns)
        self.log_time_ns.append(log_ns)
        self.width.append(width)
        self.height.append(height)
        self.encoding.append(encoding)
        self.topic.append(topic)
        ordinal = self._seen[(topic, log_ns)]  # its rank among frames of the topic at this log time
        self._seen[(topic, log_ns)] += 1
        self.locators.append(FrameLocator(topic, log_ns, ordinal))

    def columns(self) -> dict[str, Any]:
        """The columns depth and image frame tables share, in append order."""
        return {"frame": np.asarray(self.frame, dtype=str), "stamp_ns": np.asarray(self.stamp_ns, dtype=np.int64),
                "log_time_ns": np.asarray(self.log_time_ns, dtype=np.int64),
                "width": np.asarray(self.width, dtype=np.int64), "height": np.asarray(self.height, dtype=np.int64),
                "encoding": np.asarray(self.encoding, dtype=str), "source": np.asarray(self.topic, dtype=str)}
