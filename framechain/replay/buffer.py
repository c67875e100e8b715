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

from typing import overload

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray, IntArray, distinct_names, names_and_codes
from framechain.geometry.rotations import compose, invert, quat_conjugate, quat_multiply, quat_to_rotvec
from framechain.replay.composition import Step, compose_chunk
from framechain.replay.errors import FrameGraphError
from framechain.replay.interpolation import CHUNK, HopBuffers, Interpolant, Workspace, static_samples
from framechain.replay.samples import (
    LATEST,
    Edge,
    FramePath,
    HopSamples,
    LookupResult,
    LookupStatus,
    PathHop,
    TimesLike,
    _Latest,
)
from framechain.timeline import Timeline, TransformTable, normalize_frame

__all__ = ["LATEST", "Edge", "FramePath", "HopSamples", "LookupResult", "LookupStatus", "PathHop", "TransformBuffer"]


class TransformBuffer:
    """A frame graph built from a Timeline's transforms, queried with tf2 semantics."""

    def __init__(self, transforms: TransformTable) -> None:
        self._edges: dict[str, Edge] = {}
        self._interpolants: dict[str, Interpolant] = {}
        self.warnings: list[str] = []
        self._build(transforms)

    @classmethod
    def from_timeline(cls, timeline: Timeline) -> TransformBuffer:
        return cls(timeline.transforms)

    # -- construction -------------------------------------------------------------------
    def _build(self, table: TransformTable) -> None:
        if len(table) == 0:
            return
        children, child_idx = names_and_codes(table.child)
        order = np.lexsort((table.log_time_ns, table.stamp_ns, child_idx))
        bounds = np.searchsorted(child_idx[order], np.arange(children.size + 1))
        for k, child in enumerate(children.tolist()):
            rows = order[bounds[k] : bounds[k + 1]]
            parents = distinct_names(table.parent[rows])
            if len(parents) > 1:
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
            edge_sources = distinct_names(table.source[rows])
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
    def _interpolant(self, child: str) -> Interpolant:
        """The hot-path tables of a dynamic edge, built on its first lookup (about 190 bytes a sample)."""
        interp = self._interpolants.get(child)
        if interp is None:
            interp = self._interpolants[child] = Interpolant.of(self._edges[child])
        return interp

    def sample(self, hop: PathHop, times_ns: IntArray, *, tolerance_ns: int = 0) -> HopSamples:
        """Interpolate one edge ``T_parent_child`` at every time (tf2 cache semantics)."""
        edge = self._edges[hop.child]
        t = np.asarray(times_ns, dtype=np.int64)
        if edge.is_static:
            return static_samples(hop, edge, t)
        interp = self._interpolant(hop.child)
        out = HopBuffers(t.shape[0])
        work = Workspace(min(t.shape[0], CHUNK))
        for k in range(0, t.shape[0], CHUNK):
            sl = slice(k, k + CHUNK)
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
        buffers = [HopBuffers(n) for _ in dynamic]
        plan = self._plan(path)
        translation = np.empty((3, n))
        quat = np.empty((4, n))
        work = Workspace(min(n, CHUNK))
        troubled = False  # some time is outside some edge's span (or only its nearest sample is used)
        for k in range(0, n, CHUNK):
            sl = slice(k, k + CHUNK)
            chunk = t[sl]
            ws = work.sized(chunk.shape[0])
            views = [b.view(sl) for b in buffers]
            for (_, interp), view in zip(dynamic, views, strict=True):
                troubled |= interp.sample_into(chunk, tolerance_ns, view, ws)
            compose_chunk(plan, views, translation[:, sl], quat[:, sl], ws)
        by_child = {hop.child: b for (hop, _), b in zip(dynamic, buffers, strict=True)}
        samples = tuple(
            static_samples(hop, self._edges[hop.child], t) if hop.is_static
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

    def _plan(self, path: FramePath) -> list[Step]:
        """The hops from the source as steps: runs of static hops folded into one constant transform."""
        steps: list[Step] = []
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
                steps.append(Step.constant(*const))
                const = None
            steps.append(Step(dynamic=index, inverse=hop.inverse))
            index += 1
        if const is not None:
            steps.append(Step.constant(*const))
        return steps

    def can_transform(self, target: str, source: str, times: TimesLike) -> npt.NDArray[np.bool_]:
        """Per time: would :meth:`lookup` succeed."""
        return self.lookup(target, source, times).ok
