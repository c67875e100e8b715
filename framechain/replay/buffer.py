"""TransformBuffer: a time-indexed frame graph with tf2 lookup semantics, vectorised over time.

Semantics follow tf2 (``tf2/src/cache.cpp``, ``buffer_core.cpp``):

- one parent per child frame; frame names lose a leading ``/``;
- a dynamic edge is sampled at its header stamps: between two samples the translation is
  interpolated linearly and the rotation by slerp, ratio ``(t - t_old) / (t_new - t_old)``; an
  exact stamp returns that sample; the oldest and newest stamps themselves are exact hits;
- static edges (``/tf_static``) are timeless; the latest sample of a static edge is used;
- :data:`LATEST` asks for the latest time common to every dynamic edge of the path (tf2's
  ``time 0``);
- outside an edge's recorded span the result is an extrapolation, reported per time and never
  clamped; ``tolerance_ns`` may allow the nearest sample within that bound, reported as
  :attr:`LookupStatus.NEAREST`.

The walk over the graph (:meth:`TransformBuffer.path`) is separate from what is computed along it
(:meth:`TransformBuffer.sample`, :func:`compose`), so consumers can use the per-hop samples.

``T_a_b`` maps points in frame b into frame a; a lookup ``(target, source, t)`` returns
``T_target_source`` at t, as tf2's ``lookupTransform``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Final, overload

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from framechain.arrays import FloatArray, IntArray
from framechain.geometry.rotations import (
    IDENTITY,
    Quat4,
    Vec3,
    compose,
    invert,
    quat_conjugate,
    quat_multiply,
    quat_multiply_into,
    quat_rotate,
    quat_rotate_into,
    quat_to_rotvec,
)
from framechain.replay.errors import ConnectivityError, ExtrapolationError, FrameGraphError
from framechain.timeline import Timeline, TransformTable, normalize_frame


class _Latest:
    """Sentinel type of :data:`LATEST`."""

    _instance: _Latest | None = None

    def __new__(cls) -> _Latest:
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "LATEST"


#: The latest time common to every dynamic edge of a path (tf2's ``time 0``); explicit, not 0.
LATEST: Final = _Latest()

TimesLike = npt.ArrayLike | _Latest


class LookupStatus(IntEnum):
    """Per-time outcome of a lookup, ordered by severity (the worst hop wins)."""

    OK = 0
    NEAREST = 1  # outside the span but within the tolerance: the nearest sample was used
    EXTRAPOLATED_PAST = 2
    EXTRAPOLATED_FUTURE = 3
    NO_PATH = 4


@dataclass(frozen=True)
class Edge:
    """The samples of one edge ``T_parent_child``, sorted by header stamp (duplicates dropped)."""

    parent: str
    child: str
    is_static: bool
    stamps_ns: IntArray
    translation: FloatArray
    quat_xyzw: FloatArray
    source: str
    #: rotation vectors (3, n-1) of ``R_i^-1 R_(i+1)``: slerp becomes one exp per query.
    delta_rotvec: FloatArray = field(repr=False)
    #: components-first copies (3, n) and (4, n) for the vectorised hot path.
    translation_soa: FloatArray = field(repr=False)
    quat_soa: FloatArray = field(repr=False)

    @property
    def first_ns(self) -> int:
        return int(self.stamps_ns[0])

    @property
    def last_ns(self) -> int:
        return int(self.stamps_ns[-1])


@dataclass(frozen=True)
class PathHop:
    """One edge on a path; ``inverse`` when the walk goes from parent to child."""

    parent: str
    child: str
    inverse: bool
    is_static: bool


@dataclass(frozen=True)
class FramePath:
    """The edges joining ``source`` to ``target`` through their nearest common ancestor."""

    target: str
    source: str
    hops: tuple[PathHop, ...]
    #: Why there is no path (unknown frame, disconnected trees); empty when there is one.
    problem: str = ""

    @property
    def connected(self) -> bool:
        return not self.problem

    @property
    def frames(self) -> tuple[str, ...]:
        """Frame names from source to target."""
        names = [self.source]
        for hop in self.hops:
            names.append(hop.child if hop.inverse else hop.parent)
        return tuple(names)


@dataclass(frozen=True)
class HopSamples:
    """What one hop of a path used at every query time."""

    hop: PathHop
    times_ns: IntArray
    stamp_before_ns: IntArray  # stamp of the older sample used (static: the static sample's)
    stamp_after_ns: IntArray  # stamp of the newer sample used (== before for an exact hit)
    weight: FloatArray  # interpolation ratio in [0, 1]
    status: npt.NDArray[np.uint8]
    translation_soa: FloatArray  # (3, N) T_parent_child at each time (NaN where not usable)
    quat_soa: FloatArray  # (4, N)
    first_ns: int
    last_ns: int

    @property
    def translation(self) -> FloatArray:
        """(N, 3) translation of ``T_parent_child`` used at each time."""
        return self.translation_soa.T

    @property
    def quat_xyzw(self) -> FloatArray:
        """(N, 4) rotation of ``T_parent_child`` used at each time."""
        return self.quat_soa.T

    @property
    def gap_ns(self) -> IntArray:
        """Query time minus the stamp of the nearest sample used (0 for static edges)."""
        if self.hop.is_static:
            return np.zeros_like(self.times_ns)
        near = np.where(
            np.abs(self.times_ns - self.stamp_before_ns) <= np.abs(self.stamp_after_ns - self.times_ns),
            self.stamp_before_ns,
            self.stamp_after_ns,
        )
        return self.times_ns - near


@dataclass(frozen=True)
class LookupResult:
    """``T_target_source`` at N times, with the per-hop samples and a status per time."""

    target: str
    source: str
    times_ns: IntArray
    translation: FloatArray  # (N, 3), NaN where status is not usable
    quat_xyzw: FloatArray  # (N, 4), NaN where status is not usable
    status: npt.NDArray[np.uint8]
    hops: tuple[HopSamples, ...]
    path: FramePath

    def __len__(self) -> int:
        return int(self.times_ns.shape[0])

    @property
    def ok(self) -> npt.NDArray[np.bool_]:
        """Times whose transform is usable (exact, interpolated, or nearest within tolerance)."""
        return self.status <= LookupStatus.NEAREST

    def rotation(self) -> Rotation:
        """Rotations as one scipy Rotation (identity where the lookup failed)."""
        q = np.where(self.ok[:, None], self.quat_xyzw, np.array([0.0, 0.0, 0.0, 1.0]))
        return Rotation.from_quat(q)

    def matrix(self) -> FloatArray:
        """Homogeneous matrices (N, 4, 4); NaN where the lookup failed."""
        out = np.tile(np.eye(4), (len(self), 1, 1))
        out[:, :3, :3] = self.rotation().as_matrix()
        out[:, :3, 3] = self.translation
        out[~self.ok, :3, :] = np.nan
        return out

    def apply(self, points: npt.ArrayLike) -> FloatArray:
        """Map points (N, 3) given in ``source`` into ``target``; NaN where the lookup failed."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return (quat_rotate(self.quat_xyzw.T, p.T) + self.translation.T).T

    def raise_for_status(self) -> None:
        """Raise the tf2-like exception of the first failing time, if any."""
        if not self.path.connected:
            raise ConnectivityError(self.path.problem)
        bad = np.flatnonzero(~self.ok)
        if bad.size == 0:
            return
        i = int(bad[0])
        for hop in self.hops:
            if hop.status[i] > LookupStatus.NEAREST:
                raise ExtrapolationError(
                    hop.hop.parent, hop.hop.child, int(hop.times_ns[i]), hop.first_ns, hop.last_ns
                )


class TransformBuffer:
    """A frame graph built from a Timeline's transforms, queried with tf2 semantics."""

    def __init__(self, transforms: TransformTable) -> None:
        self._edges: dict[str, Edge] = {}
        self._interpolants: dict[str, _Interpolant] = {}
        self.warnings: list[str] = []
        self._build(transforms)

    @classmethod
    def from_timeline(cls, timeline: Timeline) -> TransformBuffer:
        return cls(timeline.transforms)

    # -- construction -------------------------------------------------------------------
    def _build(self, table: TransformTable) -> None:
        if len(table) == 0:
            return
        children, child_idx = np.unique(table.child, return_inverse=True)
        order = np.lexsort((table.log_time_ns, table.stamp_ns, child_idx))
        bounds = np.searchsorted(child_idx[order], np.arange(children.size + 1))
        for k, child in enumerate(children.tolist()):
            rows = order[bounds[k] : bounds[k + 1]]
            parents = np.unique(table.parent[rows])
            if parents.size > 1:
                sources = sorted(set(table.source[rows].tolist()) - {""})
                raise FrameGraphError(
                    f"frame {child!r} has two parents, {parents[0]!r} and {parents[1]!r}"
                    + (f" (published on {', '.join(sources)})" if sources else "")
                )
            parent = str(parents[0])
            if parent == child:
                raise FrameGraphError(f"frame {child!r} is its own parent")
            static = table.is_static[rows]
            if static.any() and not static.all():
                self.warnings.append(
                    f"edge {parent} -> {child} is published both static and dynamic; treated as dynamic"
                )
                rows = rows[~static]
            is_static = bool(static.all())
            if is_static:
                # tf2's StaticCache keeps the latest sample; every sample stays in the Timeline.
                last = rows[np.argmax(table.log_time_ns[rows])]
                rows = np.array([last])
            else:
                stamps = table.stamp_ns[rows]
                # Keep the last-logged sample of equal stamps (rows are sorted by log time within).
                keep = np.append(stamps[1:] != stamps[:-1], True)
                if not keep.all():
                    self.warnings.append(
                        f"edge {parent} -> {child}: {int((~keep).sum())} samples repeat a stamp; kept the last"
                    )
                rows = rows[keep]
            quats = table.quat_xyzw[rows]
            q_soa = np.ascontiguousarray(quats.T)
            delta = quat_to_rotvec(quat_multiply(quat_conjugate(q_soa[:, :-1]), q_soa[:, 1:]))
            edge_sources: list[str] = np.unique(table.source[rows]).tolist()
            self._edges[child] = Edge(
                parent=parent, child=child, is_static=is_static, stamps_ns=table.stamp_ns[rows].copy(),
                translation=table.translation[rows].copy(), quat_xyzw=quats.copy(),
                source=",".join(edge_sources), delta_rotvec=delta,
                translation_soa=np.ascontiguousarray(table.translation[rows].T), quat_soa=q_soa,
            )
        self._check_acyclic()

    def _check_acyclic(self) -> None:
        for start in self._edges:
            seen = {start}
            frame = start
            while frame in self._edges:
                frame = self._edges[frame].parent
                if frame in seen:
                    raise FrameGraphError(f"the frame graph has a cycle through {frame!r}")
                seen.add(frame)

    # -- the graph ------------------------------------------------------------------------
    @property
    def frames(self) -> list[str]:
        """Every frame named by an edge, sorted."""
        names = set(self._edges)
        names.update(edge.parent for edge in self._edges.values())
        return sorted(names)

    @property
    def edges(self) -> dict[str, Edge]:
        """Edges keyed by child frame."""
        return dict(self._edges)

    def parent_of(self, frame: str) -> str | None:
        """The parent of ``frame`` in the tree (None for a root or an unknown frame)."""
        edge = self._edges.get(normalize_frame(frame))
        return edge.parent if edge else None

    def _ancestors(self, frame: str) -> list[str]:
        chain = [frame]
        while chain[-1] in self._edges:
            chain.append(self._edges[chain[-1]].parent)
        return chain

    def path(self, target: str, source: str) -> FramePath:
        """The hops from ``source`` up to the common ancestor, then down to ``target``."""
        target, source = normalize_frame(target), normalize_frame(source)
        known = set(self.frames)
        for name in (target, source):
            if name not in known:
                return FramePath(target, source, (), problem=f"frame {name!r} does not exist in the buffer")
        up = self._ancestors(source)
        down = self._ancestors(target)
        common = next((f for f in up if f in set(down)), None)
        if common is None:
            return FramePath(
                target, source, (),
                problem=f"frames {source!r} and {target!r} are in disconnected trees "
                f"(roots {up[-1]!r} and {down[-1]!r})",
            )
        hops: list[PathHop] = []
        for frame in up[: up.index(common)]:
            e = self._edges[frame]
            hops.append(PathHop(e.parent, e.child, inverse=False, is_static=e.is_static))
        for frame in reversed(down[: down.index(common)]):
            e = self._edges[frame]
            hops.append(PathHop(e.parent, e.child, inverse=True, is_static=e.is_static))
        return FramePath(target, source, tuple(hops))

    def latest_common_time(self, path: FramePath) -> int:
        """Latest stamp every dynamic edge of the path has data for (0 when all are static)."""
        lasts = [self._edges[h.child].last_ns for h in path.hops if not h.is_static]
        return min(lasts) if lasts else 0

    # -- sampling along a path --------------------------------------------------------------
    def _interpolant(self, child: str) -> _Interpolant:
        """The hot-path tables of a dynamic edge, built on its first lookup (about 190 bytes a sample)."""
        interp = self._interpolants.get(child)
        if interp is None:
            interp = self._interpolants[child] = _Interpolant.of(self._edges[child])
        return interp

    def sample(self, hop: PathHop, times_ns: IntArray, *, tolerance_ns: int = 0) -> HopSamples:
        """Interpolate one edge ``T_parent_child`` at every time (tf2 cache semantics)."""
        edge = self._edges[hop.child]
        t = np.asarray(times_ns, dtype=np.int64)
        if edge.is_static:
            return _static_samples(hop, edge, t)
        interp = self._interpolant(hop.child)
        out = _HopBuffers(t.shape[0])
        work = _Workspace(min(t.shape[0], _CHUNK))
        for k in range(0, t.shape[0], _CHUNK):
            sl = slice(k, k + _CHUNK)
            chunk = t[sl]
            interp.sample_into(chunk, tolerance_ns, out.view(sl), work.sized(chunk.shape[0]))
        return out.samples(hop, t, edge)

    # -- lookups ------------------------------------------------------------------------------
    @overload
    def lookup(self, target: str, source: str, times: TimesLike, /, *, tolerance_ns: int = 0) -> LookupResult: ...

    @overload
    def lookup(
        self, target: str, target_times: TimesLike, source: str, source_times: TimesLike, fixed: str, /,
        *, tolerance_ns: int = 0,
    ) -> LookupResult: ...

    def lookup(self, *args: object, tolerance_ns: int = 0) -> LookupResult:
        """``T_target_source`` at every time, as tf2's ``lookupTransform``.

        ``lookup(target, source, times)``: one time per query, an int64 array of ns (or
        :data:`LATEST`). ``lookup(target, target_times, source, source_times, fixed)``: tf2's
        time-travel form, ``T_target_fixed(target_times) @ T_fixed_source(source_times)`` (e.g. a
        camera sample at one time carried through a body pose at another).
        """
        if len(args) == 3:
            target, source, times = args
            return self._lookup(str(target), str(source), times, tolerance_ns)  # type: ignore[arg-type]
        if len(args) == 5:
            target, t_target, source, t_source, fixed = args
            return self.lookup_full(
                str(target), t_target, str(source), t_source, str(fixed),  # type: ignore[arg-type]
                tolerance_ns=tolerance_ns,
            )
        raise TypeError("lookup(target, source, times) or lookup(target, t_target, source, t_source, fixed)")

    def lookup_full(
        self, target: str, target_times: TimesLike, source: str, source_times: TimesLike, fixed: str,
        *, tolerance_ns: int = 0,
    ) -> LookupResult:
        """tf2's time-travel lookup: ``T_target_fixed(t_target) @ T_fixed_source(t_source)``."""
        fixed_from_source = self._lookup(fixed, source, source_times, tolerance_ns)
        target_from_fixed = self._lookup(target, fixed, target_times, tolerance_ns)
        n = max(len(fixed_from_source), len(target_from_fixed))
        t, q = compose(
            target_from_fixed.translation.T, target_from_fixed.quat_xyzw.T,
            fixed_from_source.translation.T, fixed_from_source.quat_xyzw.T,
        )
        t, q = np.broadcast_to(t, (3, n)), np.broadcast_to(q, (4, n))
        status = np.maximum(target_from_fixed.status, fixed_from_source.status).astype(np.uint8)
        problem = fixed_from_source.path.problem or target_from_fixed.path.problem
        path = FramePath(
            normalize_frame(target), normalize_frame(source),
            fixed_from_source.path.hops + target_from_fixed.path.hops, problem,
        )
        return LookupResult(
            target=path.target, source=path.source, times_ns=np.broadcast_to(fixed_from_source.times_ns, (n,)),
            translation=t.T, quat_xyzw=q.T, status=np.broadcast_to(status, (n,)),
            hops=fixed_from_source.hops + target_from_fixed.hops, path=path,
        )

    def _lookup(self, target: str, source: str, times: TimesLike, tolerance_ns: int) -> LookupResult:
        path = self.path(target, source)
        if isinstance(times, _Latest):
            t = np.array([self.latest_common_time(path) if path.connected else 0], dtype=np.int64)
        else:
            t = np.atleast_1d(np.asarray(times))
            if t.dtype.kind == "f":
                raise TypeError("lookup times are integer nanoseconds (int64), not float seconds")
            t = t.astype(np.int64, copy=False)
        n = t.shape[0]
        if not path.connected:
            return LookupResult(
                target=path.target, source=path.source, times_ns=t, translation=np.full((n, 3), np.nan),
                quat_xyzw=np.full((n, 4), np.nan), status=np.full(n, LookupStatus.NO_PATH, dtype=np.uint8),
                hops=(), path=path,
            )
        dynamic = [(hop, self._interpolant(hop.child)) for hop in path.hops if not hop.is_static]
        buffers = [_HopBuffers(n) for _ in dynamic]
        plan = self._plan(path)
        translation = np.empty((3, n))
        quat = np.empty((4, n))
        work = _Workspace(min(n, _CHUNK))
        troubled = False  # some time is outside some edge's span (or only its nearest sample is used)
        for k in range(0, n, _CHUNK):
            sl = slice(k, k + _CHUNK)
            chunk = t[sl]
            ws = work.sized(chunk.shape[0])
            views = [b.view(sl) for b in buffers]
            for (_, interp), view in zip(dynamic, views, strict=True):
                troubled |= interp.sample_into(chunk, tolerance_ns, view, ws)
            _compose_chunk(plan, views, translation[:, sl], quat[:, sl], ws)
        by_child = {hop.child: b for (hop, _), b in zip(dynamic, buffers, strict=True)}
        samples = tuple(
            _static_samples(hop, self._edges[hop.child], t) if hop.is_static
            else by_child[hop.child].samples(hop, t, self._edges[hop.child])
            for hop in path.hops
        )
        status = np.zeros(n, dtype=np.uint8)
        if troubled:
            for b in buffers:
                np.maximum(status, b.status, out=status)
            bad = status > LookupStatus.NEAREST
            if bad.any():
                translation[:, bad] = np.nan
                quat[:, bad] = np.nan
        return LookupResult(
            target=path.target, source=path.source, times_ns=t, translation=translation.T, quat_xyzw=quat.T,
            status=status, hops=samples, path=path,
        )

    def _plan(self, path: FramePath) -> list[_Step]:
        """The hops from the source as steps: runs of static hops folded into one constant transform."""
        steps: list[_Step] = []
        const: tuple[FloatArray, FloatArray] | None = None
        index = 0
        for hop in path.hops:
            edge = self._edges[hop.child]
            if hop.is_static:
                t_e, q_e = edge.translation_soa[:, :1], edge.quat_soa[:, :1]
                if hop.inverse:
                    t_e, q_e = invert(t_e, q_e)
                const = (t_e, q_e) if const is None else compose(t_e, q_e, *const)
                continue
            if const is not None:
                steps.append(_Step.constant(*const))
                const = None
            steps.append(_Step(dynamic=index, inverse=hop.inverse))
            index += 1
        if const is not None:
            steps.append(_Step.constant(*const))
        return steps

    def can_transform(self, target: str, source: str, times: TimesLike) -> npt.NDArray[np.bool_]:
        """Per time: would :meth:`lookup` succeed."""
        return self.lookup(target, source, times).ok


#: Times per chunk of a lookup: big enough that NumPy's per-call cost vanishes, small enough that
#: the chunk's scratch rows stay in cache.
_CHUNK = 1 << 14
#: Bucket index: buckets per sample, and the most samples a refinement may step over before a
#: plain binary search is cheaper (irregular stamps).
_BUCKETS_PER_SAMPLE = 1
_MAX_BUCKET_STEPS = 4
#: Smallest slerp angle used as a divisor: below it slerp and lerp agree to 1e-24.
_MIN_HALF_ANGLE = 1e-12
_INT64_MAX = np.iinfo(np.int64).max
_INT64_MIN = np.iinfo(np.int64).min
# Scratch rows of a chunk's workspace: 0-2 sampling; the rest composing.
_SCRATCH_ROWS = 25
_PAIR_A_T, _PAIR_A_Q = slice(3, 6), slice(6, 10)
_PAIR_B_T, _PAIR_B_Q = slice(10, 13), slice(13, 17)
_SCRATCH = slice(17, 22)
_DELTA = slice(22, 25)
_IN_OUTPUT = 2
_IDENTITY_STEP: tuple[Vec3, Quat4] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


# Columns of an interpolant's rows (one row per sample; row i describes samples i and i + 1).
_T, _STEP, _Q, _QN, _HALF, _SIN = slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 14), 14, 15
_N_COLS = 16  # 128 bytes: two cache lines per gathered row


@dataclass(frozen=True)
class _Interpolant:
    """Tables of one dynamic edge for the lookup hot path, laid out for random access.

    ``rows`` (m, 16) holds per sample ``i``: the translation, the step to the next translation, the
    quaternion, the next quaternion on the short arc, the half-angle ``W`` between them and its sine.
    The last row stands for the newest sample itself with a zero step, so an exact hit on it needs
    no special case. One 128-byte row per time is gathered (two cache lines, not a miss per column:
    random query times make these gathers the main cost). Slerp is ``q(w) = a q_i + b q_(i+1)``
    with ``b = sin(w W) / sin W`` and ``a = cos(w W) - cos W b``: at ``w = 0`` exactly ``q_i``, so an
    exact stamp returns the sample bit for bit. The weight is ``(t - t_i) / (t_(i+1) - t_i)`` in
    integer nanoseconds, as tf2.

    The sample at or before each time comes from buckets of equal width over the recorded span:
    ``buckets`` row ``k`` holds the index ``j`` of the last sample before bucket ``k`` and the stamps of
    samples ``j .. j + steps + 1``; counting those at or before the time gives the index, and the
    row also holds the stamps of the samples used. Stamps too irregular for a few steps fall back to
    a binary search.
    """

    stamps: IntArray  # (m,)
    first_ns: int
    last_ns: int
    rows: FloatArray  # (m, 16), 64-byte aligned
    stamps_padded: IntArray  # (m + 2,) int64 min, the stamps, int64 max
    buckets: IntArray | None  # (n_buckets + 1, 4 or 8), 64-byte aligned; None: binary search
    bucket_origin: float
    bucket_scale: float
    bucket_top: float
    bucket_steps: int
    small_steps: bool  # no two consecutive samples are more than 90 degrees apart

    @classmethod
    def of(cls, edge: Edge) -> _Interpolant:
        stamps = edge.stamps_ns
        m = stamps.shape[0]
        trans = edge.translation_soa
        quat = edge.quat_soa
        quat_next = quat.copy()
        quat_next[:, :-1] = quat[:, 1:]
        dot = np.einsum("ij,ij->j", quat[:, :-1], quat[:, 1:])
        quat_next[:, :-1] *= np.where(dot < 0, -1.0, 1.0)
        rel = quat_multiply(quat_conjugate(quat), quat_next)  # q_i^-1 q_(i+1), w >= 0
        half = np.maximum(np.arctan2(np.sqrt(rel[0] ** 2 + rel[1] ** 2 + rel[2] ** 2), np.abs(rel[3])),
                          _MIN_HALF_ANGLE)
        rows = _aligned_empty((m, _N_COLS), np.float64)
        rows[...] = 0.0
        rows[:, _T] = trans.T
        rows[:-1, _STEP] = np.diff(trans, axis=1).T
        rows[:, _Q] = quat.T
        rows[:, _QN] = quat_next.T
        rows[:, _HALF] = half
        rows[:, _SIN] = np.sin(half)
        first, last = int(stamps[0]), int(stamps[-1])
        buckets: IntArray | None = None
        origin, scale, top, steps = float(first), 0.0, 0.0, 0
        if m >= 2 and float(last) > origin:  # (stamps a few ns apart may be one float64 apart)
            n_buckets = _BUCKETS_PER_SAMPLE * m
            top = float(n_buckets)
            scale = n_buckets / (float(last) - origin)
            of_stamp = _bucket(stamps, origin, scale, top)
            ids = np.arange(n_buckets + 1)
            lowest = np.searchsorted(of_stamp, ids, side="left") - 1  # samples surely before the bucket
            highest = np.searchsorted(of_stamp, ids, side="right") - 1  # samples possibly in it
            steps = int((highest - lowest).max())
            if steps <= _MAX_BUCKET_STEPS:
                ext = np.concatenate([[_INT64_MIN], stamps, np.full(steps + 1, _INT64_MAX)])
                buckets = _aligned_empty((n_buckets + 1, 4 if steps <= 1 else 8), np.int64)  # 32 or 64 bytes
                buckets[...] = 0
                buckets[:, 0] = lowest
                for j in range(steps + 2):
                    buckets[:, 1 + j] = ext[lowest + 1 + j]
        return cls(
            stamps=stamps, first_ns=first, last_ns=last, rows=rows,
            stamps_padded=np.concatenate([[_INT64_MIN], stamps, [_INT64_MAX]]).astype(np.int64),
            buckets=buckets, bucket_origin=origin, bucket_scale=scale, bucket_top=top, bucket_steps=steps,
            small_steps=bool(half.max() <= np.pi / 4),
        )

    def index_into(self, t: IntArray, lo: IntArray, before: IntArray, after: IntArray, ws: _Workspace) -> None:
        """``lo`` = the sample at or before each time (-1: none), ``before``/``after`` = its and the next stamp."""
        c = t.shape[0]
        if self.buckets is None:
            np.subtract(np.searchsorted(self.stamps, t, side="right"), 1, out=lo)
            np.add(lo, 1, out=ws.i[0])
            np.take(self.stamps_padded, ws.i[0], out=before, mode="clip")
            ws.i[0] += 1
            np.take(self.stamps_padded, ws.i[0], out=after, mode="clip")
            return
        f = ws.f[0]
        np.copyto(f, t, casting="unsafe")
        np.subtract(f, self.bucket_origin, out=f)
        np.multiply(f, self.bucket_scale, out=f)
        np.clip(f, 0.0, self.bucket_top, out=f)
        probe = ws.i[0]
        np.copyto(probe, f, casting="unsafe")
        width = self.buckets.shape[1]
        rows = ws.bucket_rows(width)
        np.take(self.buckets, probe, axis=0, out=rows, mode="clip")
        count = ws.i[1]
        count[...] = 0
        for j in range(self.bucket_steps):
            np.less_equal(rows[:, 2 + j], t, out=ws.mask)
            count += ws.mask
        np.add(rows[:, 0], count, out=lo)
        flat = rows.reshape(-1)
        np.multiply(ws.arange[:c], width, out=probe)
        probe += count
        probe += 1
        np.take(flat, probe, out=before, mode="clip")
        probe += 1
        np.take(flat, probe, out=after, mode="clip")

    def sample_into(self, t: IntArray, tolerance_ns: int, out: _HopViews, ws: _Workspace) -> bool:
        """Fill ``out`` for the times ``t`` (one chunk); True when some time is not plainly inside the span."""
        lo = ws.lo
        self.index_into(t, lo, out.before, out.after, ws)
        outside = bool(t.shape[0]) and (int(t.min()) < self.first_ns or int(t.max()) > self.last_ns)
        if outside:
            past = t < self.first_ns
            np.maximum(lo, 0, out=lo)
            out.before[past] = self.first_ns
        g = ws.gathered
        np.take(self.rows, lo, axis=0, out=g, mode="clip")
        dt, span = ws.i[1], ws.i[0]
        np.subtract(t, out.before, out=dt)
        np.subtract(out.after, out.before, out=span)  # > 0 inside the span (the newest: int64 max - stamp)
        weight = out.weight
        if outside:
            with np.errstate(divide="ignore", invalid="ignore"):
                np.divide(dt, span, out=weight)
        else:
            np.divide(dt, span, out=weight)
        if outside:
            future = t > self.last_ns
            out.status[past] = LookupStatus.EXTRAPOLATED_PAST
            out.status[future] = LookupStatus.EXTRAPOLATED_FUTURE
            if tolerance_ns > 0:
                near = (past & (self.first_ns - t <= tolerance_ns)) | (future & (t - self.last_ns <= tolerance_ns))
                out.status[near] = LookupStatus.NEAREST
            weight[past | future] = 0.0  # the oldest or newest sample itself
        np.equal(weight, 0.0, out=ws.mask)
        np.copyto(out.after, out.before, where=ws.mask)  # exact hits and single samples: one stamp
        f1, f2, f3 = ws.f[0], ws.f[1], ws.f[2]
        for k in range(3):
            np.multiply(g[:, 3 + k], weight, out=f1)
            np.add(g[:, k], f1, out=out.translation[k])
        np.multiply(g[:, _HALF], weight, out=f1)
        np.sin(f1, out=f2)
        sin_half = g[:, _SIN]
        if self.small_steps:  # cos = sqrt(1 - sin^2): exact to an ulp while the angle is below pi/4
            np.multiply(f2, f2, out=f3)
            np.subtract(1.0, f3, out=f3)
            np.sqrt(f3, out=f3)  # cos(w W)
            np.multiply(sin_half, sin_half, out=f1)
            np.subtract(1.0, f1, out=f1)
            np.sqrt(f1, out=f1)  # cos W
        else:
            np.cos(f1, out=f3)
            np.cos(g[:, _HALF], out=f1)
        np.divide(f2, sin_half, out=f2)  # b
        f1 *= f2
        np.subtract(f3, f1, out=f3)  # a = cos(w W) - cos W b
        for k in range(4):
            row = out.quat[k]
            np.multiply(g[:, 6 + k], f3, out=row)
            np.multiply(g[:, 10 + k], f2, out=f1)
            row += f1
        if not outside:
            return False
        bad = out.status > LookupStatus.NEAREST
        if bad.any():
            out.translation[:, bad] = np.nan
            out.quat[:, bad] = np.nan
        return True


def _aligned_empty(shape: tuple[int, int], dtype: type[np.generic], align: int = 64) -> npt.NDArray[Any]:
    """An uninitialised C-ordered array whose data starts on a cache-line boundary."""
    itemsize = np.dtype(dtype).itemsize
    count = shape[0] * shape[1]
    raw = np.empty(count + align // itemsize, dtype=dtype)
    skip = (-raw.ctypes.data % align) // itemsize
    out: npt.NDArray[Any] = raw[skip : skip + count].reshape(shape)
    return out


def _bucket(t: IntArray, origin: float, scale: float, top: float) -> IntArray:
    """Bucket of each time: monotone in t, the same arithmetic as :meth:`_Interpolant.index_into`."""
    f = t.astype(np.float64)
    np.subtract(f, origin, out=f)
    np.multiply(f, scale, out=f)
    np.clip(f, 0.0, top, out=f)
    return f.astype(np.int64)


@dataclass(frozen=True)
class _HopViews:
    """Rows of one chunk in a hop's output buffers."""

    before: IntArray
    after: IntArray
    weight: FloatArray
    status: npt.NDArray[np.uint8]
    translation: FloatArray  # (3, c)
    quat: FloatArray  # (4, c)


class _HopBuffers:
    """The output arrays of one dynamic hop over a whole lookup, filled chunk by chunk."""

    def __init__(self, n: int) -> None:
        self.before = np.empty(n, dtype=np.int64)
        self.after = np.empty(n, dtype=np.int64)
        self.weight = np.empty(n)
        self.status = np.zeros(n, dtype=np.uint8)
        self.translation = np.empty((3, n))
        self.quat = np.empty((4, n))

    def view(self, sl: slice) -> _HopViews:
        return _HopViews(self.before[sl], self.after[sl], self.weight[sl], self.status[sl],
                         self.translation[:, sl], self.quat[:, sl])

    def samples(self, hop: PathHop, t: IntArray, edge: Edge) -> HopSamples:
        return HopSamples(
            hop=hop, times_ns=t, stamp_before_ns=self.before, stamp_after_ns=self.after, weight=self.weight,
            status=self.status, translation_soa=self.translation, quat_soa=self.quat, first_ns=edge.first_ns,
            last_ns=edge.last_ns,
        )


class _Workspace:
    """Scratch rows for one chunk, allocated once per lookup and reused by every chunk."""

    def __init__(self, size: int, *, _parent: _Workspace | None = None) -> None:
        self.size = size
        if _parent is None:
            self._f = np.empty((_SCRATCH_ROWS, size))
            self._i = np.empty((3, size), dtype=np.int64)
            self._mask = np.empty(size, dtype=bool)
            self._gathered = _aligned_empty((size, _N_COLS), np.float64)
            self._buckets: dict[int, IntArray] = {}
            self.arange = np.arange(size, dtype=np.int64)
        else:
            self._f, self._i, self._mask = _parent._f, _parent._i, _parent._mask
            self._gathered, self._buckets, self.arange = _parent._gathered, _parent._buckets, _parent.arange
        self.f = self._f[:, :size]
        self.i = self._i[:, :size]
        self.lo = self.i[2]
        self.mask = self._mask[:size]
        self.gathered = self._gathered[:size]

    def bucket_rows(self, width: int) -> IntArray:
        """A (size, width) block for gathered bucket rows."""
        block = self._buckets.get(width)
        if block is None:
            block = self._buckets[width] = _aligned_empty((self._gathered.shape[0], width), np.int64)
        return block[: self.size]

    def sized(self, size: int) -> _Workspace:
        """This workspace cut to a (last, shorter) chunk."""
        return self if size == self.size else _Workspace(size, _parent=self)


@dataclass(frozen=True)
class _Step:
    """One step of a composition plan: a dynamic hop (by index), or a constant (folded static hops)."""

    dynamic: int = -1
    inverse: bool = False
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    @classmethod
    def constant(cls, t: FloatArray, q: FloatArray) -> _Step:
        tr = t.reshape(3)
        qu = q.reshape(4)
        return cls(translation=(float(tr[0]), float(tr[1]), float(tr[2])),
                   quat=(float(qu[0]), float(qu[1]), float(qu[2]), float(qu[3])))


def _compose_chunk(
    plan: list[_Step], hops: list[_HopViews], out_t: FloatArray, out_q: FloatArray, ws: _Workspace
) -> None:
    """``T_target_source`` for one chunk: the plan's steps applied from the source, into ``out_t``/``out_q``.

    Walking from the source the running transform is ``T_current_source``; each step multiplies it
    on the left. Intermediate products alternate between two scratch pairs, so no product writes
    over its own inputs; the last one goes straight into the output rows.
    """
    scratch = ws.f[_SCRATCH]
    delta = ws.f[_DELTA]
    pairs = ((ws.f[_PAIR_A_T], ws.f[_PAIR_A_Q]), (ws.f[_PAIR_B_T], ws.f[_PAIR_B_Q]))
    current: tuple[Vec3, Quat4] | None = None
    held = -1  # the pair holding ``current`` (-1: a hop's own rows or a constant; _IN_OUTPUT: the output)
    for i, step in enumerate(plan):
        last = i == len(plan) - 1
        dest = _IN_OUTPUT if last else (1 if held == 0 else 0)
        t_out, q_out = (out_t, out_q) if last else pairs[dest]
        if step.dynamic < 0:  # a constant (folded static hops) on the left
            if current is None:  # only constants so far (a plan never holds two in a row)
                current, held = (step.translation, step.quat), -1
                continue
            quat_rotate_into(step.quat, current[0], t_out, scratch)
            for k in range(3):
                t_out[k] += step.translation[k]
            quat_multiply_into(step.quat, current[1], q_out, scratch)
        else:
            hop = hops[step.dynamic]
            t_e: Vec3 = (hop.translation[0], hop.translation[1], hop.translation[2])
            q_e: Quat4 = (hop.quat[0], hop.quat[1], hop.quat[2], hop.quat[3])
            if current is None and not step.inverse:
                current, held = (t_e, q_e), -1  # read only: the hop's own rows
                continue
            t_x, q_x = current if current is not None else _IDENTITY_STEP
            if step.inverse:  # inv(E) X = (conj(q_E) (t_X - t_E), conj(q_E) q_X)
                for k in range(3):
                    np.subtract(t_x[k], t_e[k], out=delta[k])
                quat_rotate_into(q_e, (delta[0], delta[1], delta[2]), t_out, scratch, conjugate_q=True)
                quat_multiply_into(q_e, q_x, q_out, scratch, conjugate_a=True)
            else:  # E X = (q_E t_X + t_E, q_E q_X)
                quat_rotate_into(q_e, t_x, t_out, scratch)
                for k in range(3):
                    t_out[k] += t_e[k]
                quat_multiply_into(q_e, q_x, q_out, scratch)
        current, held = ((t_out[0], t_out[1], t_out[2]), (q_out[0], q_out[1], q_out[2], q_out[3])), dest
    if held != _IN_OUTPUT:  # the result is not in the output rows yet: a hop's rows, a constant, or nothing
        t_c, q_c = current if current is not None else _IDENTITY_STEP
        for k in range(3):
            out_t[k] = t_c[k]
        for k in range(4):
            out_q[k] = q_c[k]


def _static_samples(hop: PathHop, edge: Edge, t: IntArray) -> HopSamples:
    """A static hop at every time: broadcast views of its one sample."""
    n = t.shape[0]
    stamp = np.broadcast_to(np.int64(edge.first_ns), (n,))
    return HopSamples(
        hop=hop, times_ns=t, stamp_before_ns=stamp, stamp_after_ns=stamp,
        weight=np.broadcast_to(0.0, (n,)), status=np.zeros(n, dtype=np.uint8),
        translation_soa=np.broadcast_to(edge.translation_soa[:, :1], (3, n)),
        quat_soa=np.broadcast_to(edge.quat_soa[:, :1], (4, n)),
        first_ns=edge.first_ns, last_ns=edge.last_ns,
    )


def compose_hops(samples: tuple[HopSamples, ...], n: int) -> tuple[FloatArray, FloatArray]:
    """Chain the hops of a path into ``T_target_source``: translations (3, n), quaternions (4, n).

    Walking from the source, the running transform is ``T_current_source``. Runs of static hops
    are folded into one constant transform before they touch the arrays.
    """
    trans: FloatArray | None = None  # None while the running transform is still a constant
    quat: FloatArray | None = None
    const: tuple[FloatArray, FloatArray] | None = None  # folded static hops; None = identity
    for s in samples:
        if s.hop.is_static:
            t_edge, q_edge = s.translation_soa[:, :1], s.quat_soa[:, :1]
        else:
            t_edge, q_edge = s.translation_soa, s.quat_soa
        if s.hop.inverse:
            t_edge, q_edge = invert(t_edge, q_edge)
        if s.hop.is_static:
            const = (t_edge, q_edge) if const is None else compose(t_edge, q_edge, *const)
            continue
        t_step, q_step = (t_edge, q_edge) if const is None else compose(t_edge, q_edge, *const)
        if trans is None or quat is None:
            trans, quat = t_step, q_step
        else:
            trans, quat = compose(t_step, q_step, trans, quat)
        const = None
    if trans is None or quat is None:
        t_c, q_c = const if const is not None else (np.zeros((3, 1)), IDENTITY[:, None])
        return np.repeat(t_c, n, axis=1), np.repeat(q_c, n, axis=1)
    if const is None:
        return np.array(trans, copy=True), np.array(quat, copy=True)
    return compose(*const, trans, quat)
